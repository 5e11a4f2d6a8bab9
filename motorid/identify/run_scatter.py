"""Whether a parameter's runs agree with one another: a standard error widened where they do not.

A fit's covariance counts every cell mean as an independent reading about one law.  Where the law
holds only on average (the runs disagree beyond their own noise: an error of the acceleration the
model is given, a sensor whose error changes from run to run), the standard error is too small by
the runs' excess scatter.  Each run gives its own estimate of the parameter from the fit's weighted
residuals ρ over the cells the fit solved on (its weights, the noise levels and any widening for
correlated noise included, are the covariance's): δ_r = −Σ ρ ∂ρ/∂p / Σ (∂ρ/∂p)² over the run's
cells and events (δ_r is the run's departure from the common value), with standard error
1/√Σ(∂ρ/∂p)², widened where the run's viscosity was smoothed by what that curve's error
moves the run's score (the fit's ``viscosity_shifts``, from
:func:`~motorid.identify.covariance.viscosity_covariance`: an error common to the run's samples,
which the noise levels do not hold; without it, K_L0's runs scatter up to 1.7×
beyond their noise on clean simulated campaigns, 0.76-1.21× with it).  Their Birge ratio
R² = Σ (δ_r/se_r)² / (N − 1) is about 1 where the runs agree;
where R² exceeds the χ² test's 1 % point, the parameter's standard error is widened by R (Birge
1932; the "scale factor" of the Particle Data Group's averages, PDG Review of Particle Physics,
Introduction §5.2).  It widens, never narrows: the whole standard error, its viscosity and
breakaway shares included, and the row and column of the covariance (the correlations stay).
"""

from __future__ import annotations

import numpy as np

from motorid.identify.types import CHANNELS

#: least number of runs carrying information on the parameter for the check
MIN_RUNS = 4
#: false-alarm rate of the test R² > 1
ALPHA = 0.01


def _sums_by_run(runs, rho, slopes, n: int) -> tuple:
    """Σ(∂ρ/∂p)² and Σ ρ ∂ρ/∂p per run (runs × free each) over entries of run ``runs`` (−1: padding,
    left out, as are non-finite entries)."""
    use = np.flatnonzero((runs >= 0) & np.isfinite(rho))
    info, score = np.zeros((n, slopes.shape[1])), np.zeros((n, slopes.shape[1]))
    if not use.size:
        return info, score
    if np.any(np.diff(runs[use]) < 0):  # cells are numbered in run order; events need not be
        use = use[np.argsort(runs[use], kind="stable")]
    r = runs[use]
    s = slopes[use]
    s[~np.isfinite(s)] = 0.0
    starts = np.flatnonzero(np.r_[True, r[1:] != r[:-1]])
    info[r[starts]] = np.add.reduceat(s * s, starts, axis=0)
    s *= rho[use][:, None]
    score[r[starts]] = np.add.reduceat(s, starts, axis=0)
    return info, score


def per_run_sums(fit, problem, data) -> tuple | None:
    """Per run and free parameter of ``problem``: information Σ(∂ρ/∂p)² and score Σ ρ ∂ρ/∂p of ``fit``'s
    weighted residual ρ over the run's cells and events (runs × free each), or None where the entries
    and their runs do not line up.  Exact and in NumPy, channel by channel, from the fit's quadratic
    expansion where it has one (:mod:`motorid.identify.compress`); else a step of one standard error
    per parameter through the model."""
    from motorid.identify.problem import as_arrays, residual_jit

    values = {k: fit.params_all[k] for k in problem.free}
    by_channel = problem.entry_runs(data)
    obs, w = problem.cells
    order = [c for c in CHANNELS if c in obs]
    n = max([int(np.max(v)) + 1 for v in by_channel.values() if v.size] + [0])
    exp = problem.expansion
    if exp is not None and problem.expansion_key == tuple(problem.free) and all(c in exp.blocks for c in order):
        # the expansion is over problem.free, in its order
        d = np.array([values[k] for k in exp.names]) - exp.p0
        dz = exp.derivative(d)
        info, score = np.zeros((n, d.size)), np.zeros((n, d.size))
        for c in order:
            n_real, nz, X, _ = exp.blocks[c]
            wc = np.asarray(w[c], dtype=float)[:n_real]
            rho = wc * (np.asarray(obs[c], dtype=float)[:n_real] - exp.predict_channel(c, d))
            # einsum, not a threaded BLAS that wakes against XLA's threads (about 20× slower here)
            slopes = -wc[:, None] * np.einsum("tn,tp->np", X, dz[nz])
            i_c, s_c = _sums_by_run(np.asarray(by_channel[c])[:n_real], rho, slopes, n)
            info += i_c
            score += s_c
        return info, score
    runs = np.concatenate([by_channel[c] for c in order])  # as the residual is concatenated
    ctx = problem.ctx()
    rho = np.asarray(residual_jit(as_arrays(values), ctx), dtype=float)
    if runs.size != rho.size:
        return None
    slopes = np.zeros((rho.size, len(problem.free)))
    for i, k in enumerate(problem.free):
        std = fit.std.get(k)
        if std is None or not np.isfinite(std) or std <= 0:
            continue
        moved = np.asarray(residual_jit(as_arrays({**values, k: values[k] + std}), ctx), dtype=float)
        slopes[:, i] = (moved - rho) / std
    return _sums_by_run(runs, rho, slopes, n)


def birge_ratio(fit, name: str, data, shifts=None, per_run=None) -> tuple[float, int] | None:
    """(R², N runs) of fitted parameter ``name`` of ``fit`` (on ``data``, its Dataset), or None where
    fewer than :data:`MIN_RUNS` runs carry information on it (a run's own standard error within
    10× the fit's) or the fit keeps no problem.  ``shifts``: the viscosity's score shifts of the
    fit (runs × modes × free, ``FitResult.viscosity_shifts``);
    ``per_run``: :func:`per_run_sums` of the fit, where already made."""
    problem = getattr(fit, "problem", None)
    std, value = fit.std.get(name), fit.values.get(name)
    if (problem is None or name not in fit.free or name not in problem.free or std is None or value is None
            or getattr(problem, "cells", None) is None or not np.isfinite(std) or std <= 0):
        return None
    if per_run is None:
        per_run = per_run_sums(fit, problem, data)
        if per_run is None:
            return None
    i = problem.free.index(name)
    info, score = per_run[0][:, i], per_run[1][:, i]
    carry = info > 0.01 / std**2
    count = int(carry.sum())
    if count < MIN_RUNS:
        return None
    var = info.copy()
    if shifts is not None:  # the score's variance from the run's smoothed-viscosity error
        m = min(var.size, shifts.shape[0])
        var[:m] += np.sum(shifts[:m, :, i] ** 2, axis=1)
    return float(np.sum(score[carry] ** 2 / var[carry]) / (count - 1)), count


#: runs that disagree on a parameter this many times beyond their errors send the user to diagnose
DIAGNOSE_SCATTER = 10.0


def widen_by_run_scatter(fit, names, data) -> list[str]:
    """Widen the standard error of each of ``names`` (fitted parameters of ``fit``) by its Birge
    ratio where its runs disagree (:func:`birge_ratio`, R² above the χ² test's 1 % point), in place
    (``fit.std``, the row and column of ``fit.covariance``) → one line of words per widened
    parameter."""
    from scipy.special import chdtrc

    notes = []
    problem = getattr(fit, "problem", None)
    shifts = getattr(fit, "viscosity_shifts", None)  # None where the covariance does not count the viscosity
    per_run = None
    if problem is not None and getattr(problem, "cells", None) is not None and names:
        per_run = per_run_sums(fit, problem, data)
        if per_run is None:
            return []
    for name in names:
        out = birge_ratio(fit, name, data, shifts, per_run)
        if out is None:
            continue
        r2, runs = out
        if not chdtrc(runs - 1, r2 * (runs - 1)) < ALPHA:
            continue
        factor = float(np.sqrt(r2))
        i = fit.free.index(name)
        cov = np.array(fit.covariance, dtype=float, copy=True)
        cov[i, :] *= factor
        cov[:, i] *= factor
        fit.covariance = cov
        fit.std[name] = float(fit.std[name]) * factor
        fit.run_scatter = {**(getattr(fit, "run_scatter", None) or {}), name: factor}
        notes.append(f"{name}: its {runs} runs' own estimates scatter {factor:.3g}× beyond their errors, so its "
                     f"standard error is widened by that factor (a law that holds on average, an input of the "
                     f"model with errors of its own, or a transducer error the model does not hold)")
    worst = max((getattr(fit, "run_scatter", None) or {}).items(), key=lambda kv: kv[1], default=None)
    told = any("`motorid diagnose`" in w for w in getattr(fit, "warnings", None) or [])  # by the χ²/dof warning
    if worst is not None and worst[1] >= DIAGNOSE_SCATTER and not told:
        # a probe's churning torque ∝ ω²: K_v 3.9× its truth (z +13) with χ²/dof 1.6, and no word on what to do
        notes.append(f"the runs disagree on {worst[0]} {worst[1]:.3g}× beyond their errors: the 1992 model misses "
                     "something these runs see, and its values are biased by it beyond their (widened) std; "
                     "`motorid diagnose` locates it and names it where its catalog holds it")
    return notes
