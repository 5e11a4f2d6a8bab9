"""Uncertainty of the fitted parameters: covariance, its widenings, and the intervals.

(JᵀWJ)⁻¹ at the optimum; a sandwich widening where the breakaway events scatter
more than their variance model says; the smoothed viscosity's run-level error
carried into the covariance; Student-t intervals where a standard error rests on
the few breakaway events.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from motorid._aot import cached_jit
from motorid.identify.problem import (Ctx, Problem, as_arrays, normal_equations, over_cell_blocks, pad, predictions_jit,
                                      weighted_residual)
from motorid.identify.types import BREAKAWAY_ONLY, CHANNELS, RUNNING_CHANNELS, FitResult


def covariance_from_normal(JtJ: np.ndarray) -> np.ndarray:
    """(JᵀJ)⁻¹ from the normal matrix, computed on unit-norm columns."""
    norms = np.sqrt(np.clip(np.diag(JtJ), 0, None))
    norms = np.where(norms > 0, norms, 1.0)
    w, v = np.linalg.eigh(JtJ / np.outer(norms, norms))
    keep = w > w.max() * 1e-24
    inv = np.zeros_like(w)
    inv[keep] = 1.0 / w[keep]
    return ((v * inv) @ v.T) / np.outer(norms, norms)


def breakaway_sandwich(problem: Problem, values: dict, cov: np.ndarray, residual, sigma, inliers):
    """What to add to the covariance where the breakaway events scatter more than
    their variance model says → (p, p) array [SI²], or None where nothing is added.

    The events' σ come from a variance model (:func:`breakaway_noise`) fitted to a
    few dozen residuals; another bench's events may scatter in another way (a
    supply ripple the samples do not resolve, onsets that are harder to place at
    some loads), and then the model-based (JᵀWJ)⁻¹ understates K_FS and K_s.  With
    A_b = Σ_events J Jᵀ/σ² (their share of JᵀWJ) and its robust counterpart
    M_b = Σ J Jᵀ z²/σ² · n/(n − k) (z the standardized residuals; k the
    breakaway-only parameters; White's HC1), each breakaway-only parameter's
    variance by the sandwich, (V M_b V)_jj, against the model's, (V A_b V)_jj: where
    the sandwich's is larger, the difference is added to that parameter's variance
    (its row and column scaled, the correlations kept): widened, never narrowed, as
    the fit's χ²/dof scaling."""
    free = list(problem.free)
    brk_only = [free.index(k) for k in BREAKAWAY_ONLY if k in free]
    if not brk_only or residual is None or not problem.has_events or problem.cells is None:
        return None
    r = np.asarray(residual, dtype=float)
    s = np.broadcast_to(np.asarray(sigma, dtype=float), r.shape)
    use = np.asarray(inliers, dtype=bool) & np.isfinite(r) & np.isfinite(s) & (s > 0)
    n, k = int(use.sum()), len(brk_only)
    if n <= k + 2:
        return None
    w = np.where(use, 1.0 / np.where(use, s, 1.0), 0.0)
    z = np.where(use, r * w, 0.0)
    ctx = problem.ctx()
    size = int(np.asarray(ctx.observed["breakaway"]).size)

    def block(weights):
        brk = ctx._replace(running=None, observed={"breakaway": ctx.observed["breakaway"]},
                           weights={"breakaway": jnp.asarray(pad(weights, size))})
        return np.asarray(normal_equations(as_arrays(values), brk)[0])

    A_b = block(w)
    M_b = block(w * np.abs(z)) * n / (n - k)
    model_part = np.diag(cov @ A_b @ cov)[brk_only]
    robust_part = np.diag(cov @ M_b @ cov)[brk_only]
    with np.errstate(invalid="ignore", divide="ignore"):
        extra = np.where(np.isfinite(robust_part), np.maximum(robust_part - model_part, 0.0), 0.0)
    if not np.any(extra > 0):
        return None
    # each breakaway-only parameter's variance raised by its own excess: cov → D cov D, D
    # diagonal (1 elsewhere), which keeps the correlations and the matrix positive
    d = np.ones(len(free))
    d[brk_only] = np.sqrt(1.0 + extra / np.diag(cov)[brk_only])
    out = d[:, None] * cov * d[None, :] - cov
    return 0.5 * (out + out.T)


@cached_jit
def _viscosity_sensitivity(values: dict, ctx: Ctx):
    """(Σ_c (∂r_c/∂β)(∂r_c/∂μ), cells × free; ∂r_c/∂μ, channels × cells) of the weighted
    residual of the running cells, r_c = w·(observed − predicted) in the residual's
    order of the running channels, μ the cells' viscosity (each cell's prediction depends on its own
    viscosity only, so one tangent of ones gives every cell's); block by block, so that no
    Jacobian over every cell is held (:func:`~motorid.identify.problem.over_cell_blocks`)."""

    def block(c):
        jac = jax.jacfwd(weighted_residual)(values, c)
        J = jnp.stack([jac[k] for k in c.free], axis=1)

        def of_viscosity(mu):
            return weighted_residual(values, c._replace(running=c.running._replace(viscosity=mu)))

        mu = c.running.viscosity
        g = jax.jvp(of_viscosity, (mu,), (jnp.ones_like(mu),))[1]
        k = len(c.observed)
        J, g = J.reshape(k, -1, J.shape[1]), g.reshape(k, -1)
        return jnp.sum(J * g[:, :, None], axis=0), g

    Jg, g = over_cell_blocks(block, ctx)  # (blocks, size, free), (blocks, channels, size)
    return Jg.reshape(-1, Jg.shape[-1]), jnp.moveaxis(g, 1, 0).reshape(g.shape[1], -1)


def viscosity_jacobians(problem: Problem, values: dict, ctx: Ctx):
    """Of the weighted residual of the running cells, r_c = w·(observed − predicted) per
    channel c → (Σ_c (∂r_c/∂β)(∂r_c/∂μ), cells × free; {c: ∂r_c/∂μ}, cells each).

    Where the fit's exact quadratic expansion is at hand (:mod:`~motorid.identify.compress`)
    ∂r/∂β comes from it in NumPy, and ∂r/∂μ from a central difference of two
    passes of the cell predictions: no Jacobian program over every cell;
    elsewhere from :func:`_viscosity_sensitivity`."""
    n = problem.n_cells
    running = [c for c in CHANNELS if c in RUNNING_CHANNELS and c in ctx.observed]
    exp = problem.expansion
    free = list(ctx.free)
    if exp is None or problem.expansion_key != tuple(free):
        Jg, g = (np.asarray(x) for x in _viscosity_sensitivity(as_arrays(values), ctx))
        order = [c for c in RUNNING_CHANNELS if c in ctx.observed]  # the residual's order
        return Jg[:n], {c: g[order.index(c)][:n] for c in running}
    p = len(free)
    dz = exp.derivative(np.array([values[k] for k in exp.names]) - exp.p0)  # ∂[δ; u(δ)]/∂δ
    mu = np.asarray(ctx.running.viscosity, dtype=float)
    eps = 1e-6
    up = predictions_jit(as_arrays(values), ctx._replace(running=ctx.running._replace(viscosity=mu * (1 + eps))))
    down = predictions_jit(as_arrays(values), ctx._replace(running=ctx.running._replace(viscosity=mu * (1 - eps))))
    gs, rows, cols = {}, [], []
    for c in running:
        w = np.asarray(ctx.weights[c], dtype=float)[:n]
        with np.errstate(invalid="ignore"):
            slope = (np.asarray(up[c])[:n] - np.asarray(down[c])[:n]) / (2 * eps * mu[:n])
        gs[c] = -w * np.where(np.isfinite(slope), slope, 0.0)
        if c in exp.blocks:  # ∂r_c/∂β = −w·Xᵀ dz
            n_real, nz, X, _ = exp.blocks[c]
            rows.append(X[:, :n] * (-w * gs[c]))
            cols.append(dz[nz])
    # every channel's terms at once (einsum, not a threaded BLAS that wakes against XLA's threads)
    Jg = np.einsum("tn,tp->np", np.concatenate(rows), np.concatenate(cols)) if rows else np.zeros((n, p))
    return Jg, gs


def viscosity_covariance(problem: Problem, values: dict, cov: np.ndarray):
    """What the smoothed viscosity's run-level error does to the fit →
    (parameter covariance [SI²], channel → variance of each run's mean residual [SI²], score shifts).

    The extraction replaces each run's viscometer readings by a curve in time
    (:func:`motorid.identify.viscosity.smooth_viscosity`); the curve's error δμ_r =
    Σₖ modesₖ zₖ (z standard normal per run) is common to the run's samples, so
    it does not show in the residual scatter the noise levels come from.  To
    first order it moves the estimate by dβ/dz = (JᵀJ)⁻¹ Jᵀ (∂r/∂μ · modes) (J
    and r weighted; a two-step estimator's plug-in correction, Murphy & Topel
    1985), and adds Σ_run,k (dβ/dzₖ)(dβ/dzₖ)ᵀ to the covariance.  It also moves
    each run's mean residual by the run mean of ∂prediction/∂μ · modes, which a
    test of run means against the noise (:mod:`motorid.discrepancy.locate`) must
    count.  The score shifts Jᵀ ∂r/∂zₖ per run and mode (runs × modes × free, zero for a run whose
    viscosity was not smoothed) are what the error moves each run's score Σ r ∂r/∂β by: the runs'
    check (:mod:`motorid.identify.run_scatter`) counts them in each run's error.  ``cov`` is (JᵀJ)⁻¹
    over ``problem.free``.  (None, {}, None) where no run's viscosity was smoothed.
    """
    verr = getattr(problem.data, "viscosity_error", None)
    if verr is None or not verr.any or not problem.has_running or problem.cells is None:
        return None, {}, None
    n_cells, K = problem.n_cells, verr.factor.shape[1]
    counts = np.maximum(np.bincount(problem.cell_of, minlength=n_cells), 1)
    n_runs = max(len(problem.data.runs), int(problem.cell_run.max()) + 1)  # aligned with Dataset.runs
    # cells are numbered in run order: run r's cells are bounds[r]:bounds[r + 1]
    bounds = np.searchsorted(problem.cell_run, np.arange(n_runs + 1))
    smoothed = np.flatnonzero(np.any(verr.factor[:n_runs] != 0.0, axis=(1, 2)) & (np.diff(bounds) > 0))
    # cell means of the Chebyshev basis (one column at a time: no (samples × K) array), then the modes;
    # data reduced to cells as read bring their own (a cell's mean time is not enough)
    cell_basis = getattr(problem, "viscosity_basis", None)
    if cell_basis is None:
        u = (np.asarray(problem.data.running.time, dtype=float) - verr.center[problem.run_of]) / verr.half_span[problem.run_of]
        cell_basis = np.empty((n_cells, K))
        prev, cur = np.ones_like(u), u
        for k in range(K):
            col = prev if k == 0 else cur
            cell_basis[:, k] = np.bincount(problem.cell_of, weights=col, minlength=n_cells) / counts
            if k >= 1:
                prev, cur = cur, 2.0 * u * cur - prev
        del u, prev, cur
    cell_modes = np.zeros((n_cells, K))
    for r in smoothed:
        cell_modes[bounds[r]:bounds[r + 1]] = cell_basis[bounds[r]:bounds[r + 1]] @ verr.factor[r]
    ctx = problem.ctx()
    Jg, gs = viscosity_jacobians(problem, values, ctx)
    p = Jg.shape[1]
    # per-run sums over cells: reduceat over the runs that have cells (their starts increase)
    filled = np.flatnonzero(np.diff(bounds) > 0)
    run_var = {}
    for c, gc in gs.items():
        w = np.asarray(ctx.weights[c])[:n_cells]
        n_in = (w > 0) * w**2  # inlier count / σ_run²: the cell's weight in its run's mean
        with np.errstate(invalid="ignore", divide="ignore"):
            slope = np.where(w > 0, gc / w, 0.0)  # −∂prediction/∂μ (unweighted)
        tot = np.bincount(problem.cell_run, weights=n_in, minlength=n_runs)
        shift = np.zeros((n_runs, K))
        shift[filled] = np.add.reduceat((n_in * slope)[:, None] * cell_modes, bounds[filled], axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            run_var[c] = np.where(tot > 0, np.sum(shift**2, axis=1) / np.maximum(tot, 1e-300) ** 2, 0.0)
    # Jᵀ ∂r/∂z per run and mode: (modes of the run's cells)ᵀ · Jg of those cells
    shifts = np.zeros((n_runs, K, p))
    for r in smoothed:
        shifts[r] = cell_modes[bounds[r]:bounds[r + 1]].T @ Jg[bounds[r]:bounds[r + 1]]
    A = shifts[smoothed].reshape(-1, p) @ cov  # dβ/dz, one row per (run, mode)
    out = A.T @ A
    return 0.5 * (out + out.T), run_var, shifts


def interval_dof(ls: FitResult) -> dict:
    """Effective degrees of freedom of each fitted parameter's standard error.

    A standard error is as uncertain as the noise levels it rests on.  The
    running channels' levels come from dozens to hundreds of residuals per run
    (treated as exact here); the breakaway level σ_brk from one residual per
    event, n events less the breakaway-only parameters (K_FS, K_s) — the same
    count the fit divides by.  With V = (JᵀWJ)⁻¹ and A_brk the breakaway
    events' share of JᵀWJ, the share of parameter i's variance that scales with
    σ_brk² is f_i = (V A_brk V)_ii / V_ii, and Welch–Satterthwaite gives
    ν_i = ν_brk / f_i²: ≈ n − 2 for K_FS and K_s, effectively infinite for the
    parameters the running data determine.  Returns name → ν (inf where no
    breakaway noise enters).
    """
    free = list(ls.free)
    out = {k: float("inf") for k in free}
    problem = getattr(ls, "problem", None)
    if not free or problem is None or not getattr(problem, "has_events", False) or problem.cells is None:
        return out
    n_events = int(np.sum(ls.inliers.get("breakaway", np.zeros(0, bool))))
    nu_brk = (n_events - sum(1 for k in BREAKAWAY_ONLY if k in free)
              - (1 if getattr(ls, "breakaway_noise_shape", 0.0) > 0 else 0))  # the variance model's shape
    if nu_brk < 1:
        return out
    ctx = problem.ctx()
    brk = ctx._replace(running=None, observed={"breakaway": ctx.observed["breakaway"]},
                       weights={"breakaway": ctx.weights["breakaway"]})
    values = {k: np.asarray(ls.values[k], dtype=np.float64) for k in free}
    A_brk = np.asarray(normal_equations(values, brk)[0])
    total = np.asarray(ls.covariance)
    visc = getattr(ls, "covariance_viscosity", None)
    brk = getattr(ls, "covariance_breakaway", None)  # the sandwich's widening, also σ_brk's
    scale = max(ls.reduced_chi2, 1.0)
    V = (total - (0.0 if visc is None else visc) - (0.0 if brk is None else brk)) / scale
    d = np.diag(total)  # the viscosity's share rests on hundreds of readings per run: ν = ∞
    with np.errstate(invalid="ignore", divide="ignore"):
        # (the sandwich's widening scales with the events' scatter as the rest of their share)
        f = np.clip((np.diag(V @ A_brk @ V) + (0.0 if brk is None else np.diag(brk) / scale)) / d, 0.0, 1.0)
    for i, k in enumerate(free):
        if np.isfinite(f[i]) and f[i] > 1e-6:
            out[k] = float(nu_brk / f[i] ** 2)
    return out


def interval_factor(dof: float, level: float = 0.95) -> float:
    """Half-width of a central ``level`` interval in standard errors: Student-t
    with ``dof`` degrees of freedom (the normal quantile where dof is infinite).

    From ν = 5 on by the Cornish-Fisher expansion of the t quantile in 1/ν
    (Abramowitz & Stegun 26.7.5, four terms: relative error below 1e-4 at ν = 5,
    1e-7 at ν = 20), which keeps scipy.stats (a second of import) out of
    ``motorid fit``; below that, scipy's exact quantile.
    """
    from statistics import NormalDist

    q = 0.5 * (1.0 + level)
    if not np.isfinite(dof) or dof > 1e6:
        return NormalDist().inv_cdf(q)
    if dof < 5:
        from scipy import stats

        return float(stats.t.ppf(q, dof))
    z = NormalDist().inv_cdf(q)
    g = ((z**3 + z) / 4, (5 * z**5 + 16 * z**3 + 3 * z) / 96,
         (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / 384,
         (79 * z**9 + 776 * z**7 + 1482 * z**5 - 1920 * z**3 - 945 * z) / 92160)
    return float(z + sum(gk / dof ** (k + 1) for k, gk in enumerate(g)))
