"""Noise levels of the fitted channels and the spike test of their residuals.

Per channel and run: a model-free start from first differences, then the
residuals' MAD (first round) or standard deviation (later rounds), floored;
isolated spikes are residuals that stand out from their neighbours' running
median (Hampel).  The breakaway events have a variance model of their own that
grows with the port pressures (:func:`breakaway_noise`).
"""

from __future__ import annotations

import numpy as np

from motorid.robust import median_of_five, robust_std


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


def initial_noise(values, run_of_sample, n_runs) -> np.ndarray:
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


def spikiness(res, run_of, channel: str) -> np.ndarray:
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
        med = median_of_five(*cols)
    return res - med


#: bins of the shaft angle (and of the angle within a piston pitch) in which rejected samples are counted
LOCKED_BINS = 36
#: a bin holds structure where its rejected samples exceed what their share of all samples gives by this
#: many Poisson standard deviations (and by at least 5 samples) ...
LOCKED_SIGMAS = 6.0
#: ... and such bins hold at least this share of a channel's rejected samples
LOCKED_SHARE = 0.5


def shaft_locked(rejected, theta, pistons: int) -> np.ndarray:
    """The rejected samples that are not spikes but structure: those in the bins of the shaft angle (or of
    the angle within a piston pitch) where rejections crowd far beyond chance → bool mask (True: give
    back).  A spike of the electronics falls at any angle; a valve-plate notch, a port-timing pulse, a
    bearing defect repeats at its angle, and the running median of five samples takes each repeat for a
    spike (a second reader's notch of 3° per pitch: every sample in it rejected, and the flow the rest
    left behind named a displacement error).  Given back, it is the discrepancy search's to locate."""
    rejected = np.asarray(rejected, bool)
    out = np.zeros(rejected.shape, bool)
    n_rej = int(rejected.sum())
    theta = np.asarray(theta, float)
    if n_rej < 30 or theta.shape != rejected.shape:
        return out
    ok = np.isfinite(theta)
    for period in (2 * np.pi / max(int(pistons), 1), 2 * np.pi):  # a pitch's finer bins first
        b = np.minimum((np.mod(np.where(ok, theta, 0.0), period) / period * LOCKED_BINS).astype(int), LOCKED_BINS - 1)
        share = np.bincount(b[ok], minlength=LOCKED_BINS) / max(int(ok.sum()), 1)
        counts = np.bincount(b[rejected & ok], minlength=LOCKED_BINS)
        expected = n_rej * share
        locked = counts > expected + np.maximum(LOCKED_SIGMAS * np.sqrt(expected), 5.0)
        if counts[locked].sum() >= LOCKED_SHARE * n_rej:
            return rejected & ok & locked[b]
    return out


def residual_noise(res, run_of_sample, n_runs, robust: bool) -> np.ndarray:
    """σ per run from the residuals about the run's centre.

    robust: MAD (first round, before spikes are known); otherwise the standard
    deviation of the inlier residuals, which is 2.7 times as efficient for
    Gaussian noise (a short run's σ, and so its weight, scatters less).
    """
    out = np.full(n_runs, np.nan)
    if robust:
        for r, v in _by_run(res, run_of_sample, n_runs):
            if v.size >= 5:
                out[r] = robust_std(v)
        return out
    # standard deviation per run in two vectorized passes (mean, then squares about it)
    ok = np.isfinite(res)
    runs, x = run_of_sample[ok], res[ok]
    count = np.bincount(runs, minlength=n_runs)
    mean = np.bincount(runs, weights=x, minlength=n_runs) / np.maximum(count, 1)
    ss = np.bincount(runs, weights=(x - mean[runs]) ** 2, minlength=n_runs)
    return np.where(count >= 5, np.sqrt(ss / np.maximum(count - 1, 1)), np.nan)


def floor_noise(sig_runs: np.ndarray, measured: np.ndarray) -> np.ndarray:
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


#: integrated autocorrelation time of a channel's residuals above which its standard errors are
#: widened: white noise gives 1; the estimate's own scatter, about 2/√n, is allowed for by
#: :func:`correlation_threshold`
CORRELATED_TAU = 1.2
#: the longest lag summed [samples]; the sum stops earlier at the first ρ_k below RHO_STOP
MAX_LAG, RHO_STOP = 200, 0.05


def correlation_threshold(n: int) -> float:
    """τ above which n white-noise residuals would rarely reach: 1.2, or 1 + 6/√n on a short campaign."""
    return max(CORRELATED_TAU, 1.0 + 6.0 / np.sqrt(max(n, 1)))


def correlation_times(residuals: dict, sigma: dict, inliers: dict, run_of: np.ndarray) -> dict:
    """Integrated autocorrelation time τ = 1 + 2 Σ ρ_k [samples] of each running channel's
    normalized residuals, pooled over runs (channel → (τ, the samples it rests on)).

    The fit weighs n samples of a run as n independent readings; where the noise is band-limited
    (a sensor's filter, a DAQ sampling above the sensor's bandwidth, a log interpolated to a finer
    rate) neighbouring residuals move together and a run holds about n/τ independent ones: the
    standard errors then need √τ.  ρ_k is pooled over every run's samples (Σ e_t e_{t+k} / Σ e_t²,
    run means out; the runs laid end to end with MAX_LAG zeros between them, so that no pair
    crosses a run and each lag is one dot product), and the sum stops at the first ρ_k below
    :data:`RHO_STOP` (Sokal's window, made safe for white noise: a true τ of 1 stays 1).  A lag
    counts samples, so it is one time step only where a run's steady samples are consecutive."""
    run_of = np.asarray(run_of)
    out = {}
    if run_of.size == 0:
        return out
    boundary = np.r_[0, np.cumsum(run_of[1:] != run_of[:-1])]  # runs before each sample
    target = np.arange(run_of.size) + MAX_LAG * boundary
    for c, r in residuals.items():
        if c == "breakaway" or c not in sigma or c not in inliers:
            continue
        ok = np.asarray(inliers[c], bool) & np.isfinite(r)
        if ok.sum() < 100:
            continue
        z = np.where(ok, np.asarray(r, float) / np.asarray(sigma[c], float), 0.0)
        # run means out: a run's offset is the model's to answer for, not the noise's correlation
        counts = np.bincount(run_of, weights=ok.astype(float))
        means = np.bincount(run_of, weights=z) / np.maximum(counts, 1.0)
        z = np.where(ok, z - means[run_of], 0.0)
        denom = float(np.dot(z, z))
        if denom <= 0:
            continue
        padded = np.zeros(target[-1] + 1)
        padded[target] = z
        tau = 1.0
        for k in range(1, MAX_LAG + 1):
            rho = float(np.dot(padded[:-k], padded[k:])) / denom
            if rho < RHO_STOP:
                break
            tau += 2.0 * rho
        out[c] = (tau, int(ok.sum()))
    return out
