"""Robust statistics: medians, MAD spreads, running medians, Hampel tests, robust lines.

One home for the estimators that an isolated spike cannot move, used by the
extraction, the fit's noise model, diagnosis and reports.  Every spread here is
the median absolute deviation (MAD) scaled to the standard deviation of a normal
distribution, σ ≈ 1.4826·MAD (Hampel 1974; Rousseeuw & Croux 1993).

Two medians, for two kinds of input:

- :func:`median` — of a 1-d array *without NaN*, by a partial sort (np.median's
  checks cost more than the work on the few hundred residuals of a run);
- :func:`nanmedian` — NaN skipped, NaN where nothing is left (sensor channels
  with missing readings).
"""

from __future__ import annotations

import math

import numpy as np

MAD_TO_STD = 1.4826  # MAD → standard deviation of a normal distribution: 1/Φ⁻¹(3/4)


def median(x) -> float:
    """Median of a 1-d array without NaN, by a partial sort [unit of x]."""
    x = np.asarray(x)
    n = x.size
    k = n // 2
    if n % 2:
        return float(np.partition(x, k)[k])
    part = np.partition(x, (k - 1, k))
    return 0.5 * float(part[k - 1] + part[k])


def nanmedian(x) -> float:
    """Median of the finite values of x, NaN where there are none [unit of x]."""
    x = np.asarray(x, dtype=float)
    return float(np.nanmedian(x)) if np.isfinite(x).any() else math.nan


def mad_std(x, centre=None) -> float:
    """Robust standard deviation of a 1-d array without NaN: 1.4826·median|x − centre|,
    centre the median of x unless given [unit of x]."""
    x = np.asarray(x)
    return MAD_TO_STD * median(np.abs(x - (median(x) if centre is None else centre)))


def robust_std(x) -> float:
    """Robust standard deviation of the finite values of x (NaN where fewer than two) [unit of x]."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size < 2:
        return np.nan
    return mad_std(x)


# ----------------------------------------------------------------- running medians


def odd_window(k: int) -> int:
    """The odd window length at or below k [samples]."""
    return k if k % 2 == 1 else k - 1


def window_median(windows: np.ndarray) -> np.ndarray:
    """Median of the finite values of each row (NaN where a row has none)."""
    out = np.full(windows.shape[0], np.nan)
    full = ~np.isnan(windows).any(axis=1)
    w = windows.shape[1]
    if full.any():  # rows without a gap: a partial sort is enough
        part = np.partition(windows[full], [(w - 1) // 2, w // 2], axis=1)
        out[full] = 0.5 * (part[:, (w - 1) // 2] + part[:, w // 2])
    if not full.all():
        ws = np.sort(windows[~full], axis=1)  # NaN last
        count = w - np.isnan(ws).sum(axis=1)
        rows = np.arange(ws.shape[0])
        lo, hi = ws[rows, np.maximum(count - 1, 0) // 2], ws[rows, np.maximum(count, 1) // 2]
        out[~full] = np.where(count > 0, 0.5 * (lo + hi), np.nan)
    return out


def moving_median(x, window: int) -> np.ndarray:
    """Centred moving median over ``window`` (odd) samples, NaN skipped, windows cut
    short at the ends (as pandas' ``rolling(window, center=True, min_periods=1).median()``)."""
    x = np.asarray(x, dtype=float)
    n, h = x.size, window // 2
    if n == 0 or window <= 1:
        return x.copy()
    padded = np.concatenate([np.full(h, np.nan), x, np.full(h, np.nan)])
    return window_median(np.lib.stride_tricks.sliding_window_view(padded, window))


def median3(x: np.ndarray) -> np.ndarray:
    """Running median of three: removes isolated spikes, leaves monotone runs and corners as they are."""
    if x.size < 3:
        return x.copy()
    out = x.copy()
    out[1:-1] = np.median(np.stack([x[:-2], x[1:-1], x[2:]]), axis=0)
    return out


def median_of_five(a, b, c, d, e):
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


# ----------------------------------------------------------------- Hampel test


def hampel_spikes(x, k: float = 6.0, half: int = 3) -> np.ndarray:
    """Isolated readings of one run's input channel → boolean mask (a Hampel filter).

    The fit averages a cell's inputs (pressures, speed, viscosity) over all its
    samples, and each output channel over its own inliers; a spike in an input
    moves its cell's model by δ/N — N·m on cells whose noise is hundredths, and no
    residual test of an output shows it.  A reading is a spike where it stands
    more than ``k`` deviations from the median of the 2·``half`` + 1 readings
    around it; the deviation is the larger of the window's own MAD (ripple, steps
    and transients widen it) and the run's: the MAD of each reading against the
    median of its four neighbours (itself left out: against a median that holds it,
    a reading is so often the median itself that the MAD collapses to zero), or
    where that is zero (quantized readings on their neighbours' level) the smallest
    step.  Two spikes in a row are still found.  NaN readings are never spikes.
    """
    x = np.asarray(x, dtype=float)
    out = np.zeros(x.size, bool)
    ok = np.flatnonzero(np.isfinite(x))
    if ok.size < 2 * half + 4:
        return out
    v = x[ok]
    view = np.lib.stride_tricks.sliding_window_view
    # the median of the four neighbours: (sum − largest − smallest)/2 inside, sorted at the ends
    a, b, c, d = v[:-4], v[1:-3], v[3:-1], v[4:]
    near = np.empty(v.size)
    near[2:-2] = 0.5 * (a + b + c + d - np.maximum(np.maximum(a, b), np.maximum(c, d))
                        - np.minimum(np.minimum(a, b), np.minimum(c, d)))
    pad2 = np.concatenate([[np.nan] * 2, v[:4], [np.nan] * 2])
    near[:2] = window_median(view(pad2, 5)[:2, [0, 1, 3, 4]])
    pad2 = np.concatenate([[np.nan] * 2, v[-4:], [np.nan] * 2])
    near[-2:] = window_median(view(pad2, 5)[-2:, [0, 1, 3, 4]])
    r = np.abs(v - near)
    mad = MAD_TO_STD * float(np.partition(r, r.size // 2)[r.size // 2])
    if not mad > 0:  # quantized readings that mostly sit on their neighbours' level: one step
        steps = r[r > 0]  # (unless only a few readings stand off a flat signal: those are spikes)
        mad = float(steps.min()) if steps.size >= max(3, 0.05 * r.size) else 0.0
    floor = max(mad, 1e-9 * float(np.max(np.abs(v))), 1e-300)
    # candidates: far from their neighbours' median (the window's median is within the
    # window's spread of it); for them the window's median and deviation
    i = np.flatnonzero(r > 0.5 * k * floor)
    if i.size:
        windows = view(np.concatenate([[np.nan] * half, v, [np.nan] * half]), 2 * half + 1)[i]
        med = window_median(windows)
        local = MAD_TO_STD * window_median(np.abs(windows - med[:, None]))
        out[ok[i]] = np.abs(v[i] - med) > k * np.maximum(local, floor)
    return out


# ----------------------------------------------------------------- robust lines


def robust_polyfit(x: np.ndarray, y: np.ndarray, degree: int, k: float = 3.5, iterations: int = 6):
    """Polynomial fit of y(x), readings beyond k robust deviations dropped → (coef, σ of the rest)."""

    def outside(r, sel):
        centre = median(r[sel])
        sigma = mad_std(r[sel], centre)
        return np.abs(r - centre) > max(k * sigma, 1e-300), sigma

    far, _ = outside(y, np.ones(x.size, bool))
    keep = ~far
    for _ in range(iterations):
        if degree > 0 and keep.sum() > degree + 2 and np.ptp(x[keep]) > 0:
            coef = np.polyfit(x[keep], y[keep], degree)
        else:
            coef = np.array([median(y[keep])])
        far, sigma = outside(y - np.polyval(coef, x), keep)
        if (~far).sum() < degree + 3 or np.array_equal(~far, keep):
            break
        keep = ~far
    return coef, float(sigma)


def theil_sen_line(x: np.ndarray, y: np.ndarray, k: float = 3.5) -> np.ndarray:
    """Robust line y ≈ c₁x + c₀ → polynomial coefficients (c₁, c₀).

    Theil-Sen first (the slope is the median of the pairwise slopes, the
    intercept the median of y − slope·x: it holds where the points sit at a few x
    only, so that a first cut on y alone would drop whole groups), then least
    squares on the points within ``k`` robust deviations of it (where at least
    three remain, spread in x)."""
    i, j = np.triu_indices(x.size, 1)
    apart = x[j] != x[i]
    slope = median((y[j] - y[i])[apart] / (x[j] - x[i])[apart])
    coef = np.array([slope, median(y - slope * x)])
    r = y - np.polyval(coef, x)
    keep = np.abs(r - median(r)) <= max(k * MAD_TO_STD * median(np.abs(r - median(r))), 1e-300)
    if keep.sum() >= 3 and np.ptp(x[keep]) > 0:
        coef = np.polyfit(x[keep], y[keep], 1)
    return coef
