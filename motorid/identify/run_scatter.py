"""Whether a parameter's runs agree with one another: a standard error widened where they do not.

A fit's covariance counts every cell mean as an independent reading about one law.  Where the law
holds only on average (the runs disagree beyond their own noise: an error of the acceleration the
model is given, a sensor whose error changes from run to run), the standard error is too small by
the runs' excess scatter.  Each run gives its own estimate of the parameter from the fit's weighted
residuals ρ over the cells the fit solved on (its weights, the noise levels and any widening for
correlated noise included, are the covariance's): δ_r = −Σ ρ ∂ρ/∂p / Σ (∂ρ/∂p)² over the run's
cells and events (δ_r is the run's departure from the common value), with standard error
1/√Σ(∂ρ/∂p)².  Their Birge ratio R² = Σ (δ_r/se_r)² / (N − 1) is about 1 where the runs agree;
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


def birge_ratio(fit, name: str, data) -> tuple[float, int] | None:
    """(R², N runs) of fitted parameter ``name`` of ``fit`` (on ``data``, its Dataset), or None where
    fewer than :data:`MIN_RUNS` runs carry information on it (a run's own standard error within
    10× the fit's) or the fit keeps no problem."""
    from motorid.identify.problem import as_arrays, residual_jit

    problem = getattr(fit, "problem", None)
    std, value = fit.std.get(name), fit.values.get(name)
    if (problem is None or name not in fit.free or name not in problem.free or std is None or value is None
            or getattr(problem, "cells", None) is None or not np.isfinite(std) or std <= 0):
        return None
    by_channel = problem.entry_runs(data)
    runs = np.concatenate([by_channel[c] for c in CHANNELS if c in by_channel])  # as the residual is concatenated
    values = {k: fit.params_all[k] for k in problem.free}
    rho = np.asarray(residual_jit(as_arrays(values), problem.ctx()), dtype=float)
    moved = np.asarray(residual_jit(as_arrays({**values, name: value + std}), problem.ctx()), dtype=float)
    if runs.size != rho.size:
        return None
    slope = (moved - rho) / std  # ∂ρ/∂p
    use = (runs >= 0) & np.isfinite(rho) & np.isfinite(slope)
    n = int(runs.max()) + 1 if runs.size else 0
    r = np.where(use, runs, 0)
    info = np.bincount(r, weights=np.where(use, slope * slope, 0.0), minlength=n)
    score = np.bincount(r, weights=np.where(use, rho * slope, 0.0), minlength=n)
    carry = info > 0.01 / std**2
    count = int(carry.sum())
    if count < MIN_RUNS:
        return None
    return float(np.sum(score[carry] ** 2 / info[carry]) / (count - 1)), count


def widen_by_run_scatter(fit, names, data) -> list[str]:
    """Widen the standard error of each of ``names`` (fitted parameters of ``fit``) by its Birge
    ratio where its runs disagree (:func:`birge_ratio`, R² above the χ² test's 1 % point), in place
    (``fit.std``, the row and column of ``fit.covariance``) → one line of words per widened
    parameter."""
    from scipy.special import chdtrc

    notes = []
    for name in names:
        out = birge_ratio(fit, name, data)
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
        notes.append(f"{name}: its {runs} runs' own estimates scatter {factor:.3g}× beyond their errors, so its "
                     f"standard error is widened by that factor (a law that holds on average, or an input "
                     f"of the model with errors of its own)")
    return notes
