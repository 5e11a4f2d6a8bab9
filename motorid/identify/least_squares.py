"""Least-squares identification with optimistix (Levenberg-Marquardt).

All channels are fitted jointly — running torque, breakaway torque, port A and
B flows, case flow — each residual divided by a noise level estimated from the
data (per channel and run).  The Jacobian comes from JAX.  Isolated spikes are
rejected (|r| > ``outlier_sigma`` σ) and counted; the noise levels and the
outlier set are re-estimated until they settle.

Parameters the logs cannot determine are found twice over: by rules that say
which data each parameter needs (:func:`coverage_reasons`) and by the null
space of the weighted Jacobian.  They are held fixed and reported as not
identifiable, never given a number.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple, Sequence


import jax
import jax.numpy as jnp
import numpy as np

from motorid import model
from motorid._aot import cached_jit
from motorid.model import Samples

RUNNING_CHANNELS = ("torque", "q_a", "q_b", "q_case")
CHANNELS = RUNNING_CHANNELS + ("breakaway",)
CHANNEL_UNITS = {"torque": "N·m", "q_a": "m³/s", "q_b": "m³/s", "q_case": "m³/s", "breakaway": "N·m"}


@dataclass
class FitOptions:
    """Settings of the least-squares fit (what to change when a fit fails)."""

    harmonics: int | None = None  # order M of K_L(θ); default: the spec's
    outlier_sigma: float = 5.0  # reject residuals beyond this many σ
    rounds: int = 2  # noise/outlier re-estimation rounds (robust start, then settled)
    rtol: float = 1e-9
    atol: float = 1e-9
    max_steps: int = 200
    null_space_tol: float = 1e-7  # relative singular value below which a direction is unidentified
    fixed: dict = field(default_factory=dict)  # parameters held at given values
    bins_per_pitch: int = 192  # shaft-angle cells per piston pitch (data reduction)
    compress: bool = True  # exact compression where the model is quadratic in the parameters
    # hold the noise levels (channel -> σ per run; "breakaway" -> σ) and the
    # inlier masks (channel -> bool per sample) of an earlier fit: to compare
    # models on equal terms, or to hold runs out of a fit
    fixed_noise: dict | None = None
    fixed_inliers: dict | None = None
    # carry the smoothed viscosity's run-level error (Dataset.viscosity_error) into the covariance
    viscosity_error: bool = True


@dataclass
class FitResult:
    """What a least-squares fit found; SI units throughout."""

    names: list  # every parameter of the model (fitted or not)
    free: list  # the fitted ones
    values: dict  # name -> value (None where not identifiable)
    std: dict  # name -> standard error (None where not identifiable)
    covariance: np.ndarray  # over `free`
    correlation: np.ndarray
    identifiable: dict  # name -> bool
    reasons: dict  # name -> words, for the not identifiable ones
    noise: dict  # channel -> pooled σ [SI]
    noise_by_run: dict  # channel -> array over runs (NaN where no data)
    outliers: dict  # channel -> count of rejected samples
    used: dict  # channel -> count of residuals used
    chi2: float
    dof: int
    steps: int
    converged: bool
    warnings: list
    residuals: dict  # channel -> array (measured − model; NaN where missing), aligned with the data
    sigma: dict  # channel -> per-sample σ used in the final round
    inliers: dict  # channel -> bool mask of samples used
    params_all: dict  # every parameter incl. held ones (for predictions)
    mechanisms: tuple = ()
    problem: object = None  # the reduced problem (cells, noise, inliers) for the sampler
    # the share of `covariance` that the smoothed viscosity's run-level error carries
    # (over `free`; None where every viscosity reading was used as read)
    covariance_viscosity: np.ndarray | None = None
    # channel -> per run, the variance the same error adds to the run's mean residual [SI²]
    viscosity_run_variance: dict = field(default_factory=dict)
    # γ of the breakaway events' variance model σ_i² = σ₀²(1 + γ x_i²/median x²) (0: one level)
    breakaway_noise_shape: float = 0.0
    # the share of `covariance` added where the breakaway events scatter more than their
    # variance model says (:func:`breakaway_sandwich`; over `free`, None where nothing was added)
    covariance_breakaway: np.ndarray | None = None

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / max(self.dof, 1)


# ----------------------------------------------------------------------------
# data coverage: what each parameter needs


def _spread(x) -> float:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size < 2:
        return 0.0
    lo, hi = np.percentile(x, [2, 98])
    return float((hi - lo) / max(np.max(np.abs(x)), 1e-300))


def _has(arr) -> np.ndarray:
    return np.isfinite(np.asarray(arr, dtype=float))


def coverage_reasons(data, spec, names: Sequence[str]) -> dict:
    """Reasons why the logs cannot identify a parameter, from what data exist.

    Returns name -> reason for parameters that lack the data they need
    (MODEL.md, "What the bench can identify").
    """
    reasons = {}
    s = data.running
    m = data.measured
    n_run = 0 if s is None else int(np.asarray(s.theta).size)
    tq = _has(m["torque"]) if n_run else np.zeros(0, bool)
    psum = np.asarray(s.p_a + s.p_b) if n_run else np.zeros(0)
    if tq.sum() < 3:
        for k in ("Kv", "KF", "TFc"):
            reasons[k] = "no running-torque samples in these logs"
    else:
        mu_w = np.asarray(s.viscosity * s.speed)[tq]
        if _spread(np.abs(mu_w)) < 0.05:
            reasons["Kv"] = "running torque at a single speed·viscosity level: viscous and Coulomb friction cannot be told apart"
        if _spread(psum[tq]) < 0.05:
            msg = "running torque at a single port-pressure sum P_A+P_B: K_F and T_Fc cannot be told apart"
            reasons["KF"] = msg
            reasons["TFc"] = msg
    n_ev = 0 if data.events is None else int(np.asarray(data.held_torque).size)
    good_ev = _has(data.held_torque) if n_ev else np.zeros(0, bool)
    if good_ev.sum() == 0:
        why = ("no startability breakaway found in these logs (ISO 4392-2 runs needed)" if n_ev == 0 else
               f"{n_ev} breakaway(s) found, but no torque reading while the shaft was held")
        for k in ("KFS", "Ks"):
            reasons[k] = why
    elif good_ev.sum() < 3 or _spread(np.asarray(data.events.p_a + data.events.p_b)[good_ev]) < 0.05:
        msg = "breakaway at a single port-pressure level: K_FS and K_s cannot be told apart"
        reasons["KFS"] = msg
        reasons["Ks"] = msg
    for k in ("KFS", "Ks"):
        if k not in reasons and ("KF" in reasons or "TFc" in reasons):
            reasons[k] = "static friction is measured relative to K_F and T_Fc, which these logs do not determine"
    flows = {c: _has(m[c]) if n_run else np.zeros(0, bool) for c in ("q_a", "q_b", "q_case")}
    case_info = flows["q_case"] | (flows["q_a"] & flows["q_b"])
    if case_info.sum() < 3:
        reasons["KL0"] = "no case-drain flow (nor both port flows) in these logs"
    else:
        pitch = 2 * np.pi / spec.pistons
        phase = np.mod(np.asarray(s.theta)[case_info], pitch) / pitch
        bins = np.unique(np.floor(phase * 12).astype(int))
        for name in names:
            if name.startswith("KL_") and len(bins) < 8:
                reasons[name] = "case-drain flow not seen over a whole piston pitch of shaft angle (a slow constant-speed run is needed)"
    port = flows["q_a"] | flows["q_b"]
    if port.sum() < 3:
        reasons["KAB"] = "no port flow in these logs"
    elif np.all(np.abs(np.asarray(s.p_a - s.p_b)[port]) < 1e3):
        reasons["KAB"] = "port flows only at zero pressure difference"
    if "KL0" in reasons:
        for name in names:
            if name.startswith("KL_"):
                reasons.setdefault(name, reasons["KL0"])
    return {k: v for k, v in reasons.items() if k in names}


# ----------------------------------------------------------------------------
# noise


def _median(x: np.ndarray) -> float:
    """Median of a 1-d array without NaN, by a partial sort (np.median's checks cost more
    than the work on the few hundred residuals of a run)."""
    n = x.size
    k = n // 2
    if n % 2:
        return float(np.partition(x, k)[k])
    part = np.partition(x, (k - 1, k))
    return 0.5 * float(part[k - 1] + part[k])


def _robust_std(x) -> float:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size < 2:
        return np.nan
    return 1.4826 * _median(np.abs(x - _median(x)))


BREAKAWAY_SHAPES = np.r_[0.0, np.logspace(-2.0, 3.0, 61)]  # γ grid of the breakaway variance model


def breakaway_noise(res: np.ndarray, x2: np.ndarray, k: int, lr_threshold: float = 0.0):
    """Variance model of the held breakaway torque → (σ₀ [N·m], γ, median x² [Pa²]).

    The held torque is compared with the torque the port pressures at the onset
    give, and a pressure transducer's error grows with its reading (a relative
    error, a supply ripple), so the events at high pressure scatter more:
    σ_i² = σ₀²·(1 + γ·x_i²/median x²), x_i² = P_A,i² + P_B,i².  σ₀ and γ ≥ 0 by
    maximum likelihood (σ₀² profiled as Σ r²/h² over n − k, k the parameters only
    the events determine; γ on a grid; 8 events at least, else one σ).  γ is
    always estimated (``lr_threshold`` = 0): with a few dozen events a test for it
    has little power (at 30 events and a variance that grows 2.6-fold over the
    loads, a χ²₁ test at 5 % kept it in a third of the campaigns), and one level for
    all events puts too little weight on the low-pressure ones and misstates the
    uncertainty of K_FS (too narrow) and K_s (too wide); where the scatter is in
    fact even, γ comes out near 0.  res, x2 : residuals and x² of the inlier
    events; σ of any event is then σ₀·√(1 + γ·x²/median x²).
    """
    r2 = np.asarray(res, dtype=float) ** 2
    x2 = np.asarray(x2, dtype=float)
    n = r2.size
    dof = max(n - k, 1)
    ref = float(np.median(x2)) if n and np.median(x2) > 0 else 1.0
    h2 = 1.0 + BREAKAWAY_SHAPES[:, None] * (x2[None, :] / ref)
    s0 = np.sum(r2[None, :] / h2, axis=1) / dof
    with np.errstate(divide="ignore", invalid="ignore"):
        nll = np.sum(np.log(h2), axis=1) + n * np.log(np.maximum(s0, 1e-300))
    best = int(np.nanargmin(nll)) if n >= 8 else 0
    if nll[0] - nll[best] <= lr_threshold:
        best = 0
    return float(np.sqrt(s0[best])), float(BREAKAWAY_SHAPES[best]), ref


def _by_run(values, run_of_sample, n_runs):
    """(run, finite values of that run) for every run, in one sort instead of a mask per run."""
    order = np.argsort(run_of_sample, kind="stable")
    runs = run_of_sample[order]
    bounds = np.searchsorted(runs, np.arange(n_runs + 1))
    vals = np.asarray(values, dtype=float)[order]
    for r in range(n_runs):
        v = vals[bounds[r]:bounds[r + 1]]
        yield r, v[np.isfinite(v)]


def _initial_noise(values, run_of_sample, n_runs) -> np.ndarray:
    """σ per run from first differences within the run (model-free start).

    The RMS of the differences over √2; a spike inflates its run's σ, which only
    lowers that run's weight in the first round (the residual MAD takes over after).
    """
    v = np.asarray(values, dtype=float)
    same = run_of_sample[1:] == run_of_sample[:-1]
    d = np.diff(v)
    ok = same & np.isfinite(d)
    runs = run_of_sample[1:][ok]
    count = np.bincount(runs, minlength=n_runs)
    ss = np.bincount(runs, weights=d[ok] ** 2, minlength=n_runs)
    return np.where(count >= 2, np.sqrt(ss / np.maximum(count, 1) / 2.0), np.nan)


def _spikiness(res, run_of, channel: str) -> np.ndarray:
    """How far each residual stands out from its neighbours in the run (Hampel).

    An isolated spike stands out from the running median of five samples; a
    sustained misfit (an offset over a run, a slow trend) does not, so outlier
    rejection removes spikes and leaves model error for the discrepancy search.
    Breakaway events are single samples: they stand against zero.
    """
    if channel == "breakaway" or res.size < 5:
        return res
    n = res.size
    idx = np.arange(n)
    # the five neighbours of each sample within its run (clamped at run ends)
    starts = np.r_[0, np.flatnonzero(np.diff(run_of)) + 1]
    first = np.repeat(starts, np.diff(np.r_[starts, n]))
    last = np.repeat(np.r_[starts[1:], n] - 1, np.diff(np.r_[starts, n]))
    cols = [res[np.clip(idx + j, first, last)] for j in range(-2, 3)]
    if np.isnan(res).any():
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a window of missing readings
            med = np.nanmedian(np.stack(cols, axis=1), axis=1)
    else:
        med = _median_of_five(*cols)
    return res - med


def _median_of_five(a, b, c, d, e):
    """Elementwise median of five arrays by a selection network (no sort, no gather).

    With a ≤ b and c ≤ d, min(a, c) lies below three others and max(b, d) above
    three others, so neither can be the median, and dropping one value on each
    side of it keeps it: the median of five is the median of max(a, c),
    min(b, d) and e.
    """
    a, b = np.minimum(a, b), np.maximum(a, b)
    c, d = np.minimum(c, d), np.maximum(c, d)
    x, y = np.maximum(a, c), np.minimum(b, d)
    lo, hi = np.minimum(x, y), np.maximum(x, y)
    return np.maximum(lo, np.minimum(hi, e))


def _residual_noise(res, run_of_sample, n_runs, robust: bool) -> np.ndarray:
    """σ per run from the residuals about the run's centre.

    robust: MAD (first round, before spikes are known); otherwise the standard
    deviation of the inlier residuals, which is 2.7 times as efficient for
    Gaussian noise (a short run's σ, and so its weight, scatters less).
    """
    out = np.full(n_runs, np.nan)
    if robust:
        for r, v in _by_run(res, run_of_sample, n_runs):
            if v.size >= 5:
                out[r] = _robust_std(v)
        return out
    # standard deviation per run in two vectorized passes (mean, then squares about it)
    ok = np.isfinite(res)
    runs, x = run_of_sample[ok], res[ok]
    count = np.bincount(runs, minlength=n_runs)
    mean = np.bincount(runs, weights=x, minlength=n_runs) / np.maximum(count, 1)
    ss = np.bincount(runs, weights=(x - mean[runs]) ** 2, minlength=n_runs)
    return np.where(count >= 5, np.sqrt(ss / np.maximum(count - 1, 1)), np.nan)


def _floor_noise(sig_runs: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """Fill runs with no estimate by the median, and keep σ above round-off."""
    finite = sig_runs[np.isfinite(sig_runs) & (sig_runs > 0)]
    pooled = float(np.median(finite)) if finite.size else np.nan
    scale = np.nanmax(np.abs(measured)) if np.any(np.isfinite(measured)) else 1.0
    floor = max(1e-9 * scale, 1e-300)
    if not np.isfinite(pooled):
        pooled = floor
    out = np.where(np.isfinite(sig_runs) & (sig_runs > 0), sig_runs, pooled)
    # a run's σ may not fall below a tenth of the pooled level (a short run's MAD is noisy)
    return np.maximum(out, max(0.1 * pooled, floor))


# ----------------------------------------------------------------------------
# the fit


class _Ctx(NamedTuple):
    """Everything the residual needs; arrays are traced, the rest is static."""

    spec: object
    mechanisms: tuple
    free: tuple
    positive: tuple
    scales: jax.Array
    held: dict
    running: object
    events: object
    observed: dict
    weights: dict


def _params(values: dict, ctx: _Ctx) -> dict:
    p = dict(ctx.held)
    p.update(values)
    return p


def _predictions(values: dict, ctx: _Ctx) -> dict:
    p = _params(values, ctx)
    out = {}
    if ctx.running is not None:
        ch = model.predict(p, ctx.spec, ctx.running, ctx.mechanisms)
        out.update(torque=ch.torque, q_a=ch.q_a, q_b=ch.q_b, q_case=ch.q_case)
    if ctx.events is not None:
        out["breakaway"] = model.predict_breakaway(p, ctx.spec, ctx.events, ctx.mechanisms)
    return out


def _residual_natural(values: dict, ctx: _Ctx):
    pred = _predictions(values, ctx)
    return jnp.concatenate([(ctx.observed[c] - pred[c]) * ctx.weights[c] for c in CHANNELS if c in ctx.observed])


def _from_unconstrained(y, ctx: _Ctx) -> dict:
    v = model.constrain(y, np.array(ctx.positive, dtype=bool), ctx.scales)
    return {k: v[i] for i, k in enumerate(ctx.free)}


def _to_unconstrained(values: dict, ctx: _Ctx):
    v = jnp.stack([jnp.asarray(values[k], dtype=jnp.float64) for k in ctx.free])
    return model.unconstrain(v, np.array(ctx.positive, dtype=bool), ctx.scales)


def _residual_unconstrained(y, ctx: _Ctx):
    return _residual_natural(_from_unconstrained(y, ctx), ctx)


_residual_jit = cached_jit(_residual_natural)


@cached_jit
def _normal_equations(values: dict, ctx: _Ctx):
    """JᵀJ, Jᵀr and rᵀr of the weighted residual over the free parameters (in
    the order of ``ctx.free``): the sufficient statistics of a Gauss-Newton step,
    computed where the data are, so that no tall matrix leaves the device."""
    r = _residual_natural(values, ctx)
    jac = jax.jacfwd(_residual_natural)(values, ctx)
    J = jnp.stack([jac[k] for k in ctx.free], axis=1)
    return J.T @ J, J.T @ r, r @ r
_predictions_jit = cached_jit(_predictions)


_SOLVER = []


def _optimistix():
    """(optimistix, the damped normal-equation solver), imported when a solver is first
    traced: a run whose compiled solvers come from disk (motorid._aot) never pays
    the import of optimistix, lineax and equinox."""
    import optimistix

    if not _SOLVER:
        _SOLVER.append(_dense_cholesky_solver())
    return optimistix, _SOLVER[0]


def _cholesky(A):
    """Lower Cholesky factor of a small SPD matrix in plain XLA operations [same units]."""
    n = A.shape[0]
    idx = jnp.arange(n)

    def column(j, L):
        s = A[:, j] - L @ L[j, :]  # columns ≥ j of L are still zero
        d = jnp.sqrt(jnp.maximum(s[j], jnp.finfo(A.dtype).tiny))
        return L.at[:, j].set(jnp.where(idx >= j, s / d, 0.0))

    return jax.lax.fori_loop(0, n, column, jnp.zeros_like(A))


def _cholesky_solve(L, b):
    """x with L Lᵀ x = b: forward then backward substitution."""
    n = b.shape[0]
    y = jax.lax.fori_loop(0, n, lambda i, y: y.at[i].set((b[i] - L[i, :] @ y) / L[i, i]), jnp.zeros_like(b))

    def back(k, x):
        i = n - 1 - k
        return x.at[i].set((y[i] - L[:, i] @ x) / L[i, i])

    return jax.lax.fori_loop(0, n, back, jnp.zeros_like(b))


def _dense_cholesky_solver():
    """lineax ``Normal(Cholesky)`` for the damped system of Levenberg-Marquardt, whose
    matrix is parameters × parameters: factorized in plain XLA operations, not by
    LAPACK, so that a compiled solver loads without importing scipy.linalg."""
    import jax.flatten_util as jfu
    import lineax as lx

    class DenseCholesky(lx.AbstractLinearSolver):
        def init(self, operator, options):
            return _cholesky(operator.as_matrix())

        def compute(self, state, vector, options):
            flat, unflatten = jfu.ravel_pytree(vector)
            return unflatten(_cholesky_solve(state, flat)), lx.RESULTS.successful, {}

        def transpose(self, state, options):
            return state, options  # symmetric

        def conj(self, state, options):
            return state, options  # real

        def assume_full_rank(self):
            return True

    return lx.Normal(DenseCholesky())


def _run_levenberg_marquardt(residual, y0, args, rtol, atol, max_steps):
    """Optimistix LM → (y, steps, converged), arrays only (so the program can be kept on disk)."""
    # normal equations with Cholesky: the damped system is parameters × parameters,
    # eight times faster than QR of a tall Jacobian; float64 and the log/scale
    # transform keep its condition number harmless
    optx, linear_solver = _optimistix()
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=linear_solver)
    sol = optx.least_squares(residual, solver, y0, args=args, max_steps=max_steps, throw=False)
    return sol.value, sol.stats["num_steps"], sol.result == optx.RESULTS.successful


@cached_jit
def _levenberg_marquardt(y0, ctx: _Ctx, rtol, atol, max_steps):
    """Optimistix LM on the full residual → (y, steps, converged)."""
    return _run_levenberg_marquardt(_residual_unconstrained, y0, ctx, rtol, atol, max_steps)


def bucket(n: int, minimum: int = 64) -> int:
    """Padded array length: the next power of two (so that campaigns of similar
    size share compiled functions instead of recompiling for every length)."""
    return max(minimum, 1 << max(int(n) - 1, 0).bit_length())


_PAD = {"viscosity": 1.0, "temperature": 40.0}


def pad_samples(s: Samples, size: int) -> Samples:
    """Samples padded to ``size`` with harmless values (weights there are zero)."""
    n = int(np.asarray(s.theta).size)
    return Samples(*[
        np.concatenate([np.asarray(f, dtype=np.float64), np.full(size - n, _PAD.get(name, 0.0))])
        for name, f in zip(Samples._fields, s)
    ])


def pad(x, size: int, value: float = 0.0):
    x = np.asarray(x, dtype=float)
    return np.concatenate([x, np.full(size - x.size, value)])


class _Problem:
    """The data of a fit, per sample and reduced to cells for the optimizer.

    The optimizer sees cell means: samples of one run that share a shaft-angle
    bin (``bins_per_pitch`` per piston pitch, over the whole revolution so that
    shaft-order effects survive).  Inside a steady run speed, pressures and
    viscosity hardly change, so the model of the cell mean is the mean of the
    model; the parameter-free S(θ) is averaged exactly, and the viscosity as its
    harmonic mean (the leakage goes as 1/μ).  The fit then costs the same for
    10 k or 3 M rows of the same runs.
    """

    def __init__(self, data, spec, free, held, mechanisms, bins_per_pitch=48):
        self.data, self.spec, self.free, self.held = data, spec, list(free), dict(held)
        self.mechanisms = tuple(mechanisms)
        self.has_running = data.running is not None and int(np.asarray(data.running.theta).size) > 0
        self.has_events = data.events is not None and int(np.asarray(data.held_torque).size) > 0
        self.measured = {c: np.asarray(data.measured[c], dtype=float) for c in RUNNING_CHANNELS} if self.has_running else {}
        self.held_torque = np.asarray(data.held_torque, dtype=float) if self.has_events else np.zeros(0)
        self.run_of = np.asarray(data.run_of_sample, dtype=int) if self.has_running else np.zeros(0, int)
        self.n_samples, self.n_cells = 0, 0
        if self.has_running:
            bins = bins_per_pitch * spec.pistons
            theta = np.mod(np.asarray(data.running.theta), 2 * np.pi)
            b = np.minimum((theta / (2 * np.pi) * bins).astype(np.int64), bins - 1)
            key = self.run_of.astype(np.int64) * bins + b
            # cells numbered in key order: a counting pass instead of a sort
            occupied = np.bincount(key, minlength=int(key.max()) + 1) > 0
            self.cell_of = (np.cumsum(occupied) - 1)[key]
            self.n_cells = int(occupied.sum())
            counts = np.bincount(self.cell_of, minlength=self.n_cells).astype(float)
            self.cell_run = np.zeros(self.n_cells, int)
            self.cell_run[self.cell_of] = self.run_of
            self.cell_size = bucket(self.n_cells)
            # cell means; θ wrapped first (a bin never straddles the wrap), so that
            # samples of one bin from different revolutions average to that bin
            fields = data.running._replace(theta=theta)
            means = Samples(*[
                np.bincount(self.cell_of, weights=np.asarray(f, dtype=float), minlength=self.n_cells) / counts
                for f in fields
            ])
            # the leakage flows go as 1/μ: the cell's viscosity is the harmonic mean of its
            # samples', so that the cell's leakage is their mean leakage (Jensen: the plain
            # mean would make the model's leakage too small by var(μ)/μ² and bias K_L, K_AB up;
            # on the demo campaign by 8.6·10⁻⁶, a quarter of K_L0's standard error).  The viscous
            # torque, ∝ μ, then sees the harmonic mean: off by the same var(μ)/μ² of its size,
            # a thousandth of K_v's standard error there
            with np.errstate(divide="ignore", invalid="ignore"):
                inv = np.bincount(self.cell_of, weights=1.0 / np.asarray(data.running.viscosity, dtype=float),
                                  minlength=self.n_cells) / counts
                means = means._replace(viscosity=np.where(inv > 0, 1.0 / inv, means.viscosity))
            self.cell_samples = pad_samples(means, self.cell_size)
            self.n_samples = int(self.run_of.size)
            self.running_padded = pad_samples(data.running, bucket(self.n_samples))
        if self.has_events:
            self.n_events = int(self.held_torque.size)
            self.events_padded = pad_samples(data.events, bucket(self.n_events, 16))
        self.cells = None

    def n_real(self, channel: str) -> int:
        """How many of a channel's (padded) cells or events are real."""
        return getattr(self, "n_events", 0) if channel == "breakaway" else self.n_cells

    def observed(self):
        out = dict(self.measured)
        if self.has_events:
            out["breakaway"] = self.held_torque
        return out

    def set_cells(self, inliers: dict, sigma_runs: dict, sigma_breakaway):
        """Cell means of each channel over its inlier samples, and their weights."""
        obs, w = {}, {}
        for c in RUNNING_CHANNELS if self.has_running else ():
            ok = inliers[c]
            y = np.where(ok, self.measured[c], 0.0)
            cnt = np.bincount(self.cell_of, weights=ok.astype(float), minlength=self.n_cells)
            tot = np.bincount(self.cell_of, weights=y, minlength=self.n_cells)
            obs[c] = pad(np.where(cnt > 0, tot / np.maximum(cnt, 1), 0.0), self.cell_size)
            w[c] = pad(np.sqrt(cnt) / sigma_runs[c][self.cell_run], self.cell_size)
        if self.has_events:
            ok = inliers["breakaway"]
            size = int(np.asarray(self.events_padded.theta).size)
            obs["breakaway"] = pad(np.where(ok, self.held_torque, 0.0), size)
            w["breakaway"] = pad(np.where(ok, 1.0 / np.broadcast_to(sigma_breakaway, ok.shape), 0.0), size)
        self.cells = (obs, w)
        self.cells_version = getattr(self, "cells_version", 0) + 1

    def ctx(self, scales=None) -> _Ctx:
        free = tuple(self.free)
        if scales is None:
            scales = np.ones(len(free))
        positive = tuple(bool(model.parameter_info(k, self.mechanisms).positive) for k in free)
        obs, w = self.cells
        return _Ctx(
            spec=self.spec, mechanisms=self.mechanisms, free=free, positive=positive,
            scales=np.asarray(scales, dtype=np.float64),
            held={k: np.asarray(v, dtype=np.float64) for k, v in self.held.items()},
            running=self.cell_samples if self.has_running else None,
            events=self.events_padded if self.has_events else None,
            observed=obs, weights=w,
        )

    def predictions(self, values: dict) -> dict:
        """Per-sample predictions of every channel (not the cells)."""
        ctx = _Ctx(
            spec=self.spec, mechanisms=self.mechanisms, free=tuple(self.free), positive=(),
            scales=np.zeros(0), held={k: np.asarray(v, dtype=np.float64) for k, v in self.held.items()},
            running=self.running_padded if self.has_running else None,
            events=self.events_padded if self.has_events else None, observed={}, weights={},
        )
        out = _predictions_jit(_as_jnp(values), ctx)
        n = {c: self.n_samples for c in RUNNING_CHANNELS}
        n["breakaway"] = getattr(self, "n_events", 0)
        return {c: np.asarray(v)[: n[c]] for c, v in out.items()}


def fit_least_squares(data, spec, mechanisms: Sequence = (), options: FitOptions | None = None,
                      initial: dict | None = None) -> FitResult:
    """Fit the model (plus ``mechanisms``) to extracted bench data.

    data : an :class:`motorid.identify.extract.Dataset` (running samples and their
        measured channels, breakaway events and their held torques)
    spec : :class:`motorid.spec.MotorSpec`
    mechanisms : extra physics (discrepancy catalog) whose parameters are fitted too
    initial : starting values (defaults: typical sizes, then a Gauss-Newton start)
    """
    opt = options or FitOptions()
    harmonics = spec.leak_harmonics if opt.harmonics is None else opt.harmonics
    names = model.parameter_names(harmonics)
    for mech in mechanisms:
        names += list(mech.parameters)
    start = model.default_parameters(spec)
    start = {k: start.get(k, 0.0) for k in model.parameter_names(harmonics)}
    for mech in mechanisms:
        start.update(mech.initial())
    if initial:
        start.update({k: float(v) for k, v in initial.items() if k in names and v is not None})

    reasons = coverage_reasons(data, spec, names)
    fixed = {k: float(v) for k, v in opt.fixed.items()}
    held = {k: start[k] for k in names if k in reasons}
    held.update(fixed)
    free = [k for k in names if k not in held]
    warnings: list[str] = []

    problem = _Problem(data, spec, free, held, mechanisms, opt.bins_per_pitch)
    obs = problem.observed()
    run_of = problem.run_of
    n_runs = int(run_of.max()) + 1 if run_of.size else 0

    # model-free start of the noise levels: first differences within each run
    sig_runs = {c: _floor_noise(_initial_noise(obs[c], run_of, n_runs), obs[c]) for c in RUNNING_CHANNELS if c in obs}
    sig_brk, brk_gamma = None, 0.0  # σ of each breakaway event (an array once the rounds settle it)
    if "breakaway" in obs:
        sig_brk = max(_robust_std(np.diff(obs["breakaway"])) / np.sqrt(2) if obs["breakaway"].size > 2 else 1.0, 1e-6)
        ev = data.events
        brk_x2 = np.asarray(ev.p_a, dtype=float) ** 2 + np.asarray(ev.p_b, dtype=float) ** 2
    inliers = {c: np.isfinite(v) for c, v in obs.items()}
    values = {k: float(start[k]) for k in free}

    steps_total, converged = 0, True
    first_final = False
    if opt.fixed_noise is not None:
        sig_runs = {c: np.asarray(opt.fixed_noise[c], dtype=float) for c in sig_runs}
        sig_brk = opt.fixed_noise.get("breakaway", sig_brk)
        if sig_brk is not None and "breakaway" in obs:
            sig_brk = np.broadcast_to(np.asarray(sig_brk, dtype=float), obs["breakaway"].shape).copy()
    if opt.fixed_inliers is not None:
        inliers = {c: np.asarray(opt.fixed_inliers[c], dtype=bool) & np.isfinite(obs[c]) for c in obs}
    rounds = 0 if (opt.fixed_noise is not None and opt.fixed_inliers is not None) else opt.rounds
    first_final = rounds == 0
    for round_ in range(rounds):
        problem.set_cells(inliers, sig_runs, sig_brk)
        values, steps, converged, free, reasons = _solve(problem, values, free, reasons, opt, first=(round_ == 0))
        steps_total += steps
        pred = problem.predictions(values)
        res = {c: obs[c] - pred[c] for c in obs}
        # re-estimate the noise from the residuals, then reject outliers against it
        new_inliers = {}
        for c in obs:
            r = np.where(inliers[c], res[c], np.nan)
            if opt.fixed_noise is not None:
                new_inliers[c] = np.isfinite(obs[c]) & (np.abs(_spikiness(res[c], run_of, c)) <= opt.outlier_sigma * (
                    sig_brk if c == "breakaway" else sig_runs[c][run_of]))
            elif c == "breakaway":
                finite = r[np.isfinite(r)]
                # one level for all events; after the first round the RMS of the inliers with
                # the breakaway-only parameters (K_FS, K_s) taken out of the degrees of freedom —
                # with a few dozen events the MAD would scatter by a fifth from campaign to campaign
                k = sum(1 for n in ("KFS", "Ks") if n in free)
                scale = np.nanmax(np.abs(obs[c])) if np.any(np.isfinite(obs[c])) else 1.0
                if round_ == 0 and finite.size >= 8:
                    est = _robust_std(finite)
                    sig_brk = float(max(est, 1e-9 * scale)) if np.isfinite(est) else 1.0
                elif finite.size > k + 1:
                    # one level, or a level growing with the port pressures (breakaway_noise)
                    use = np.isfinite(r)
                    s0, brk_gamma, ref = breakaway_noise(r[use], brk_x2[use], k)
                    sig_brk = np.maximum(s0 * np.sqrt(1.0 + brk_gamma * brk_x2 / ref), 1e-9 * scale)
                else:
                    sig_brk = 1.0
                new_inliers[c] = np.isfinite(obs[c]) & (np.abs(res[c]) <= opt.outlier_sigma * sig_brk)
            else:
                sig_runs[c] = _floor_noise(_residual_noise(r, run_of, n_runs, robust=round_ == 0), obs[c])
                new_inliers[c] = np.isfinite(obs[c]) & (np.abs(_spikiness(res[c], run_of, c)) <= opt.outlier_sigma * sig_runs[c][run_of])
        stable = all(np.array_equal(new_inliers[c], inliers[c]) for c in obs)
        inliers = new_inliers
        if stable and round_ >= 1:
            break
    # final solve with the settled noise and inliers
    problem.set_cells(inliers, sig_runs, sig_brk)
    values, steps, converged, free, reasons = _solve(problem, values, free, reasons, opt, first=first_final)
    steps_total += steps
    if not converged:
        warnings.append("Levenberg-Marquardt stopped at max_steps before converging; raise FitOptions.max_steps")

    # covariance in natural units from the weighted Jacobian of the cells at the optimum
    JtJ = np.zeros((0, 0))
    if free:
        JtJ = _backend(problem, values, free, opt).normal(values)[0]
    pred = problem.predictions(values)
    residuals = {c: obs[c] - pred[c] for c in obs}
    sig = {c: sig_runs[c][run_of] for c in sig_runs}
    if "breakaway" in obs:
        sig["breakaway"] = np.broadcast_to(np.asarray(sig_brk, dtype=float), obs["breakaway"].shape).copy()
    used = {c: int(np.sum(inliers[c])) for c in obs}
    chi2 = float(sum(np.sum((residuals[c][inliers[c]] / sig[c][inliers[c]]) ** 2) for c in obs))
    dof = max(sum(used.values()) - len(free), 1)
    cov = _covariance(JtJ) if free else np.zeros((0, 0))
    cov_visc, visc_run_var = (viscosity_covariance(problem, values, cov) if (free and opt.viscosity_error)
                              else (None, {}))
    cov_brk = breakaway_sandwich(problem, values, cov, residuals.get("breakaway"), sig.get("breakaway"),
                                 inliers.get("breakaway")) if free and "breakaway" in obs else None
    if cov_brk is not None:
        cov = cov + cov_brk
    if chi2 / dof > 1.0:
        cov = cov * (chi2 / dof)  # noise underestimated: widen, never narrow
        cov_brk = None if cov_brk is None else cov_brk * (chi2 / dof)
    if cov_visc is not None:
        cov = cov + cov_visc
    std = np.sqrt(np.clip(np.diag(cov), 0, None)) if free else np.zeros(0)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std) if free else cov

    all_params = {**{k: float(v) for k, v in problem.held.items()}, **{k: float(v) for k, v in values.items()}}
    out_values, out_std, ident = {}, {}, {}
    for k in names:
        if k in free:
            i = free.index(k)
            out_values[k], out_std[k], ident[k] = float(values[k]), float(std[i]), True
        elif k in fixed:
            out_values[k], out_std[k], ident[k] = float(fixed[k]), 0.0, True
            reasons.pop(k, None)
        else:
            out_values[k], out_std[k], ident[k] = None, None, False
    for k in free:
        info = model.parameter_info(k, mechanisms)
        if info.positive and out_values[k] < 1e-4 * abs(start.get(k) or info.typical):
            warnings.append(f"{k} is at its lower bound 0: the data show no sign of it")
        elif info.positive and out_std[k] > abs(out_values[k]):
            warnings.append(f"{k}: standard error exceeds the value; the logs barely constrain it")

    noise = {}
    for c in obs:
        has = np.isfinite(obs[c])
        if not has.any():
            noise[c] = None
        elif c == "breakaway":
            noise[c] = float(np.median(sig["breakaway"][has]))  # the events' median σ
        else:
            noise[c] = float(np.median(sig_runs[c][np.unique(run_of[has])]))
    return FitResult(
        names=names, free=free, values=out_values, std=out_std, covariance=cov, correlation=corr,
        identifiable=ident, reasons=reasons, noise=noise, noise_by_run=dict(sig_runs),
        outliers={c: int(np.sum(np.isfinite(obs[c]) & ~inliers[c])) for c in obs},
        used=used, chi2=chi2, dof=dof, steps=steps_total, converged=bool(converged), warnings=warnings,
        residuals=residuals, sigma=sig, inliers=inliers, params_all=all_params, mechanisms=tuple(mechanisms), problem=problem,
        covariance_viscosity=cov_visc, viscosity_run_variance=visc_run_var, breakaway_noise_shape=brk_gamma,
        covariance_breakaway=cov_brk,
    )


BREAKAWAY_ONLY = ("KFS", "Ks")  # parameters only the breakaway events determine


def breakaway_sandwich(problem: _Problem, values: dict, cov: np.ndarray, residual, sigma, inliers):
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
        return np.asarray(_normal_equations(_as_jnp(values), brk)[0])

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
def _viscosity_sensitivity(values: dict, ctx: _Ctx):
    """∂r/∂β (rows × free) and ∂r/∂μ (rows) of the weighted residual of the cells,
    r = w·(observed − predicted), μ the cells' viscosity (each cell's prediction
    depends on its own viscosity only, so one tangent of ones gives every cell's)."""
    jac = jax.jacfwd(_residual_natural)(values, ctx)
    J = jnp.stack([jac[k] for k in ctx.free], axis=1)

    def of_viscosity(mu):
        return _residual_natural(values, ctx._replace(running=ctx.running._replace(viscosity=mu)))

    mu = ctx.running.viscosity
    return J, jax.jvp(of_viscosity, (mu,), (jnp.ones_like(mu),))[1]


def _viscosity_jacobians(problem: _Problem, values: dict, ctx: _Ctx):
    """Of the weighted residual of the running cells, r_c = w·(observed − predicted) per
    channel c → (Σ_c (∂r_c/∂β)(∂r_c/∂μ), cells × free; {c: ∂r_c/∂μ}, cells each).

    Where the fit's exact quadratic expansion is at hand (:mod:`~motorid.identify.compress`)
    ∂r/∂β comes from it in NumPy, and ∂r/∂μ from a central difference of two
    passes of the cell predictions: no Jacobian program over every cell;
    elsewhere from :func:`_viscosity_sensitivity`."""
    n = problem.n_cells
    running = [c for c in CHANNELS if c in RUNNING_CHANNELS and c in ctx.observed]
    exp = getattr(problem, "_expansion", None)
    free = list(ctx.free)
    if exp is None or getattr(problem, "_expansion_key", None) != tuple(free):
        J, g = (np.asarray(x) for x in _viscosity_sensitivity(_as_jnp(values), ctx))
        size = {c: int(np.asarray(ctx.observed[c]).size) for c in CHANNELS if c in ctx.observed}
        start = {c: sum(size[d] for d in list(size)[:list(size).index(c)]) for c in running}
        gs = {c: g[start[c]:start[c] + n] for c in running}
        return sum(J[start[c]:start[c] + n] * gs[c][:, None] for c in running), gs
    p = len(free)
    d = np.array([values[k] for k in exp.names]) - exp.p0
    dz = np.zeros((p + len(exp.pairs), p))  # ∂[δ; u(δ)]/∂δ
    dz[:p] = np.eye(p)
    for k, (a, b) in enumerate(exp.pairs):
        dz[p + k, a] += exp.half[k] * d[b]
        dz[p + k, b] += exp.half[k] * d[a]
    mu = np.asarray(ctx.running.viscosity, dtype=float)
    eps = 1e-6
    up = _predictions_jit(_as_jnp(values), ctx._replace(running=ctx.running._replace(viscosity=mu * (1 + eps))))
    down = _predictions_jit(_as_jnp(values), ctx._replace(running=ctx.running._replace(viscosity=mu * (1 - eps))))
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


def viscosity_covariance(problem: _Problem, values: dict, cov: np.ndarray):
    """What the smoothed viscosity's run-level error does to the fit →
    (parameter covariance [SI²], channel → variance of each run's mean residual [SI²]).

    The extraction replaces each run's viscometer readings by a curve in time
    (:func:`motorid.identify.extract.smooth_viscosity`); the curve's error δμ_r =
    Σₖ modesₖ zₖ (z standard normal per run) is common to the run's samples, so
    it does not show in the residual scatter the noise levels come from.  To
    first order it moves the estimate by dβ/dz = (JᵀJ)⁻¹ Jᵀ (∂r/∂μ · modes) (J
    and r weighted; a two-step estimator's plug-in correction, Murphy & Topel
    1985), and adds Σ_run,k (dβ/dzₖ)(dβ/dzₖ)ᵀ to the covariance.  It also moves
    each run's mean residual by the run mean of ∂prediction/∂μ · modes, which a
    test of run means against the noise (:mod:`motorid.discrepancy.locate`) must
    count.  ``cov`` is (JᵀJ)⁻¹ over ``problem.free``.  (None, {}) where no run's
    viscosity was smoothed.
    """
    verr = getattr(problem.data, "viscosity_error", None)
    if verr is None or not verr.any or not problem.has_running or problem.cells is None:
        return None, {}
    n_cells, K = problem.n_cells, verr.factor.shape[1]
    counts = np.maximum(np.bincount(problem.cell_of, minlength=n_cells), 1)
    n_runs = max(len(problem.data.runs), int(problem.cell_run.max()) + 1)  # aligned with Dataset.runs
    # cells are numbered in run order: run r's cells are bounds[r]:bounds[r + 1]
    bounds = np.searchsorted(problem.cell_run, np.arange(n_runs + 1))
    smoothed = np.flatnonzero(np.any(verr.factor[:n_runs] != 0.0, axis=(1, 2)) & (np.diff(bounds) > 0))
    # cell means of the Chebyshev basis (one column at a time: no (samples × K) array), then the modes
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
    Jg, gs = _viscosity_jacobians(problem, values, ctx)
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
    B = np.stack([cell_modes[bounds[r]:bounds[r + 1]].T @ Jg[bounds[r]:bounds[r + 1]] for r in smoothed]) \
        if smoothed.size else np.zeros((0, K, p))
    A = B.reshape(-1, p) @ cov  # dβ/dz, one row per (run, mode)
    out = A.T @ A
    return 0.5 * (out + out.T), run_var


def _scales(values: dict, free: list, mechanisms) -> np.ndarray:
    """Working scale of each free parameter: its current size, or its typical one at 0."""
    return np.array([abs(values[k]) or model.parameter_info(k, mechanisms).typical for k in free])


def _as_jnp(values: dict) -> dict:
    """Parameter values as float64 arrays (NumPy: a jitted call takes them without a JAX dispatch)."""
    return {k: np.asarray(v, dtype=np.float64) for k, v in values.items()}


def _covariance(JtJ: np.ndarray) -> np.ndarray:
    """(JᵀJ)⁻¹ from the normal matrix, computed on unit-norm columns."""
    norms = np.sqrt(np.clip(np.diag(JtJ), 0, None))
    norms = np.where(norms > 0, norms, 1.0)
    w, v = np.linalg.eigh(JtJ / np.outer(norms, norms))
    keep = w > w.max() * 1e-24
    inv = np.zeros_like(w)
    inv[keep] = 1.0 / w[keep]
    return ((v * inv) @ v.T) / np.outer(norms, norms)


def _null_space_names(JtJ: np.ndarray, free: list, tol: float) -> dict:
    """Parameters in directions the weighted Jacobian cannot see (relative
    singular value below ``tol``, from the eigenvalues of the normal matrix)."""
    norms = np.sqrt(np.clip(np.diag(JtJ), 0, None))
    out = {}
    for i, k in enumerate(free):
        if norms[i] == 0 or not np.isfinite(norms[i]):
            out[k] = "the fitted channels do not depend on it in these logs"
    cols = np.where((norms > 0) & np.isfinite(norms))[0]
    if cols.size == 0:
        return out
    Jn = JtJ[np.ix_(cols, cols)] / np.outer(norms[cols], norms[cols])
    w, v = np.linalg.eigh(Jn)
    s = np.sqrt(np.clip(w, 0, None))
    weak = np.where(s < tol * s.max())[0]
    vt = v.T
    for j in weak:
        involved = [free[cols[i]] for i in np.where(np.abs(vt[j]) > 0.2)[0]]
        for k in involved:
            others = [o for o in involved if o != k]
            out.setdefault(k, "cannot be told apart from " + ", ".join(others) + " with these logs"
                           if others else "the logs do not determine it")
    return out


class _FullBackend:
    """The optimizer's view of the problem: every cell, through the JAX model."""

    def __init__(self, problem: _Problem):
        self.problem = problem

    def normal(self, values: dict):
        JtJ, Jtr, rr = _normal_equations(_as_jnp(values), self.problem.ctx())
        return np.asarray(JtJ), np.asarray(Jtr), float(rr)

    def chi2(self, values: dict, ctx=None) -> float:
        return float(jnp.sum(_residual_jit(_as_jnp(values), ctx or self.problem.ctx()) ** 2))

    def levenberg_marquardt(self, values: dict, free: list, opt: FitOptions):
        mechs = self.problem.mechanisms
        scales = _scales(values, free, mechs)
        ctx = self.problem.ctx(scales)
        y0 = _to_unconstrained(_as_jnp(values), ctx)
        y, steps, ok = _levenberg_marquardt(y0, ctx, opt.rtol, opt.atol, opt.max_steps)
        new = {k: float(v) for k, v in _from_unconstrained(y, ctx).items()}
        return new, int(steps), bool(ok)


class _CompressedCtx(NamedTuple):
    R0: jax.Array
    R1: jax.Array
    p0: jax.Array
    a: jax.Array
    b: jax.Array
    half: jax.Array
    positive: tuple
    scales: jax.Array


def _compressed_residual(y, c: _CompressedCtx):
    d = model.constrain(y, np.array(c.positive, dtype=bool), c.scales) - c.p0
    return c.R0 - c.R1 @ jnp.concatenate([d, d[c.a] * d[c.b] * c.half])


@cached_jit
def _levenberg_marquardt_compressed(y0, c: _CompressedCtx, rtol, atol, max_steps):
    """Optimistix LM on the compressed residual → (y, steps, converged)."""
    return _run_levenberg_marquardt(_compressed_residual, y0, c, rtol, atol, max_steps)


class _CompressedBackend:
    """The same problem through its exact compression (:mod:`motorid.identify.compress`)."""

    def __init__(self, problem: _Problem, expansion):
        self.problem, self.exp = problem, expansion
        self.R0, self.R1 = expansion.compress(*problem.cells)
        self.p = len(expansion.names)

    def _delta(self, values):
        return np.array([values[k] for k in self.exp.names]) - self.exp.p0

    def residual(self, values):
        d = self._delta(values)
        return self.R0 - self.R1 @ np.concatenate([d, self.exp.products(d)])

    def jacobian(self, values):
        d = self._delta(values)
        du = np.zeros((len(self.exp.pairs), self.p))
        for k, (a, b) in enumerate(self.exp.pairs):
            du[k, a] += self.exp.half[k] * d[b]
            du[k, b] += self.exp.half[k] * d[a]
        return -(self.R1[:, : self.p] + self.R1[:, self.p:] @ du)

    def normal(self, values: dict):
        with np.errstate(over="ignore", invalid="ignore"):  # a wild trial point: the caller checks finiteness
            J, r = self.jacobian(values), self.residual(values)
            return J.T @ J, J.T @ r, float(r @ r)

    def chi2(self, values: dict, ctx=None) -> float:
        with np.errstate(over="ignore", invalid="ignore"):
            r = self.residual(values)
            return float(r @ r)

    def levenberg_marquardt(self, values: dict, free: list, opt: FitOptions):
        mechs = self.problem.mechanisms
        scales = _scales(values, free, mechs)
        positive = tuple(bool(model.parameter_info(k, mechs).positive) for k in free)
        c = _CompressedCtx(np.asarray(self.R0), np.asarray(self.R1), np.asarray(self.exp.p0),
                           np.asarray(self.exp.a), np.asarray(self.exp.b), np.asarray(self.exp.half),
                           positive, np.asarray(scales, dtype=np.float64))
        pos = np.array(positive)
        y0 = model.unconstrain(np.array([values[k] for k in free], dtype=float), pos, c.scales, xp=np)
        y, steps, ok = _levenberg_marquardt_compressed(y0, c, opt.rtol, opt.atol, opt.max_steps)
        p = model.constrain(np.asarray(y), pos, c.scales, xp=np)
        new = {k: float(p[i]) for i, k in enumerate(free)}
        return new, int(steps), bool(ok)


def _backend(problem: _Problem, values: dict, free: list, opt: FitOptions):
    """The compressed problem where the model is quadratic in the free parameters, else the full one."""
    if opt.compress and free:
        key = tuple(free)
        if getattr(problem, "_expansion_key", None) != key:
            from motorid.identify.compress import Expansion

            problem._expansion = Expansion.build(problem, values, list(free))
            problem._expansion_key = key
        if problem._expansion is not None:
            cached = getattr(problem, "_compressed", None)
            if cached is None or cached[0] != (key, problem.cells_version):
                problem._compressed = ((key, problem.cells_version), _CompressedBackend(problem, problem._expansion))
            return problem._compressed[1]
    return _FullBackend(problem)


def _solve(problem: _Problem, values: dict, free: list, reasons: dict, opt: FitOptions, first: bool):
    """Gauss-Newton start (first round), null-space check, then Levenberg-Marquardt."""
    mechs = problem.mechanisms
    values = dict(values)
    if first and free:
        # the base model is linear in most parameters: a few Gauss-Newton steps in
        # natural (scaled) coordinates land next to the optimum from any start
        for _ in range(8):
            backend = _backend(problem, values, free, opt)
            JtJ, Jtr, _ = backend.normal(values)
            scales = _scales(values, free, mechs)
            with np.errstate(over="ignore", invalid="ignore"):
                JtJ, Jtr = JtJ * np.outer(scales, scales), Jtr * scales
            if not (np.all(np.isfinite(JtJ)) and np.all(np.isfinite(Jtr))):
                break  # leave a point this wild to Levenberg-Marquardt
            bad = _null_space_names(JtJ, free, opt.null_space_tol)
            if bad:
                for k, why in bad.items():
                    reasons[k] = why
                    problem.held[k] = values.pop(k)
                free = [k for k in free if k not in bad]
                problem.free = free
                if not free:
                    break
                continue
            norms = np.sqrt(np.diag(JtJ))
            with np.errstate(all="ignore"):
                step = -np.linalg.solve(JtJ / np.outer(norms, norms), Jtr / norms) / norms
            trial = dict(values)
            for i, k in enumerate(free):
                new = values[k] + step[i] * scales[i]
                if model.parameter_info(k, mechs).positive and values[k] > 0:
                    # a positive parameter may shrink at most fivefold a step: a
                    # nonlinear one (a characteristic speed) must not jump to 0
                    new = max(new, 0.2 * values[k])
                trial[k] = new
            before, after = backend.chi2(values), backend.chi2(trial)
            if not np.all(np.isfinite(step)) or not np.isfinite(after) or after > before:
                break  # Gauss-Newton does not improve here: leave the rest to Levenberg-Marquardt
            values = trial
            if np.max(np.abs(step)) < 1e-10:
                break
        for k in free:
            info = model.parameter_info(k, mechs)
            if info.positive and values[k] <= 0:
                values[k] = 1e-3 * info.typical
    if not free:
        return values, 0, True, free, reasons
    backend = _backend(problem, values, free, opt)
    new, steps, ok = backend.levenberg_marquardt(values, free, opt)
    if backend.chi2(new) <= backend.chi2(values) * (1 + 1e-12):
        values = new
    return values, steps, ok, free, reasons
