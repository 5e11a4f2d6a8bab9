"""Where a startability run's speed leaves rest (ISO 4392-2): the breakaway onset.

The rest level and noise come from the log itself (robust line and MAD), motion
is a sustained departure, and the onset is placed by a hinge fit of the initial
growth, or from the shaft angle where the growth shows too few samples
(:mod:`motorid.identify.onset_angle`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from motorid.identify.onset_angle import angle_agrees, angle_onset, lag_onset
from motorid.identify.types import Breakaway, NoBreakaway
from motorid.robust import median3, robust_polyfit


def _sustained(x: np.ndarray, length: int) -> np.ndarray:
    """Forward running minimum min(x[i:i+length]): a level x stays above for ``length`` samples."""
    out = x.copy()
    for j in range(1, length):
        out[:-j] = np.minimum(out[:-j], x[j:])
    return out


def _rest_level(t, w, line: bool, floor: float):
    """Rest speed of the stuck samples → (baseline function, noise σ [rad/s]).

    σ is the largest of: the MAD of the residuals, the standard deviation of their
    central 80 % (scaled to a normal σ; it does not collapse to zero when most
    quantized readings sit on one level), half the quantization step between the
    levels the readings keep returning to (rare off-level readings are spikes),
    and ``floor``.
    """
    t_ref = t[-1]
    coef, sigma = robust_polyfit(t - t_ref, w, 1 if line else 0)
    r = w - np.polyval(coef, t - t_ref)
    lo, hi = np.percentile(r, [10.0, 90.0])
    central = r[(r >= lo) & (r <= hi)]
    trimmed = 1.51 * float(central.std()) if central.size >= 5 else 0.0
    levels, counts = np.unique(w, return_counts=True)
    frequent = levels[counts >= max(3, 0.05 * w.size)]
    quantum = float(np.diff(frequent).min()) if frequent.size >= 2 else 0.0
    return (lambda tt: np.polyval(coef, tt - t_ref)), max(sigma, trimmed, 0.5 * quantum, floor)


def _hinge_costs(tt, yy, t0, quadratic: bool = True):
    """Least-squares cost of yy ≈ a·u + b·u², u = max(tt − t0, 0), a, b ≥ 0, for each t0.

    The two-column non-negative least squares in closed form, vectorized over
    ``t0``: the unconstrained solution where both coefficients come out ≥ 0,
    else the better of the one-column fits (the problem is convex, so the best
    feasible candidate is the optimum).  ``quadratic=False``: the linear hinge
    yy ≈ a·u alone (b = 0).
    """
    u = np.clip(tt[None, :] - np.asarray(t0, dtype=float)[:, None], 0.0, None)
    v = u * u
    uu, uv, vv = (u * u).sum(1), (u * v).sum(1), (v * v).sum(1)
    uy, vy, yy2 = u @ yy, v @ yy, float(yy @ yy)
    det = uu * vv - uv * uv
    with np.errstate(invalid="ignore", divide="ignore"):
        a2 = np.where(det > 0, (vv * uy - uv * vy) / det, -1.0)
        b2 = np.where(det > 0, (uu * vy - uv * uy) / det, -1.0)
        a1 = np.where(uu > 0, np.maximum(uy / uu, 0.0), 0.0)
        b1 = np.where(vv > 0, np.maximum(vy / vv, 0.0), 0.0)
    both = yy2 - (a2 * uy + b2 * vy)  # at the unconstrained optimum, SSE = yy − cᵀ(Xᵀy)
    only_a = yy2 - 2 * a1 * uy + a1 * a1 * uu
    if not quadratic:
        return np.maximum(only_a, 0.0)
    only_b = yy2 - 2 * b1 * vy + b1 * b1 * vv
    feasible = (a2 >= 0) & (b2 >= 0)
    return np.maximum(np.minimum(np.where(feasible, both, np.inf), np.minimum(only_a, only_b)), 0.0)


def _hinge_onset(t, dev, lo: int, last_rest: int, hi: int, noise: float = 0.0) -> float:
    """Onset t0 by fitting dev = a·u + b·u², u = max(t − t0, 0), a, b ≥ 0, over samples lo..hi.

    Rest before t0; after it, growth from zero at a rate that does not fall (the
    pressure keeps rising): linear when the static friction exceeds the kinetic
    one, quadratic when they are equal.  t0 is searched on a grid between
    sample ``lo`` and the first moving sample, then refined twice on finer grids
    around the best point (resolution 1/128 000 of that span).

    The linear hinge (b = 0) is fitted first; the quadratic term is taken only
    where it lowers the cost significantly (by more than a χ²₁ of p = 0.001 in
    units of the noise variance: ``noise``, the fit's own residual or 1e-4 of
    the largest deviation, whichever is largest) and three growth samples or
    more determine it.  With few growth samples the full model is not determined: two
    samples after the onset are fitted exactly by a line from any of a range of
    t0 with a matching b, and the grid would pick one of those at random.
    """
    tt, yy = t[lo:hi + 1], dev[lo:hi + 1]
    a, b = t[lo], t[last_rest + 1]

    def search(quadratic: bool):
        grid = np.linspace(a, b, 81)
        costs = _hinge_costs(tt, yy, grid, quadratic)
        k = int(np.argmin(costs))
        best, cost = float(grid[k]), float(costs[k])
        step = (b - a) / 80
        for _ in range(2):
            grid = np.linspace(max(best - step, a), min(best + step, b), 81)
            costs = _hinge_costs(tt, yy, grid, quadratic)
            k = int(np.argmin(costs))
            best, cost = float(grid[k]), float(costs[k])
            step = (grid[-1] - grid[0]) / 80
        return best, cost

    t_lin, c_lin = search(False)
    dof = tt.size - 3
    if dof < 1 or hi - last_rest < 3:  # b needs a third growth sample to be determined at all
        return t_lin
    t_quad, c_quad = search(True)
    # (the floor: the grid's own resolution and rounding leave a relative misfit of about 1e-5)
    var = max(noise * noise, c_quad / dof, (1e-4 * float(np.max(np.abs(yy)))) ** 2, 1e-300)
    return t_quad if c_lin - c_quad > 10.83 * var else t_lin


def find_breakaway(time, speed, rest_speed: float = 2e-3, theta=None) -> Breakaway:
    """Find the instant a startability run's speed leaves rest.

    time [s], speed [rad/s] of one run (NaN speeds are skipped).  The rest level
    and noise come from the early stuck phase (robust median/MAD, then a robust
    line over the whole stuck phase, so slight creep is absorbed); the first
    departure sustained over three samples by more than max(10 σ, rest_speed)
    marks motion; walking back gives the last sample within 3 σ of rest, and the
    onset is refined by fitting the initial growth of speed, zero before t0 and
    a(t − t0) + b(t − t0)² after, over the rest samples and the first growth
    samples (b only where the samples ask for it, :func:`_hinge_onset`).  Samples
    that may have met a speed limit (within 2 % or 5 σ of the sustained peak, as a
    dynamometer's limiter holds it) are left out of that fit.  Where fewer than two
    growth samples remain (fast breakaway at a low sample rate), ``theta`` (shaft
    angle [rad], optional) places the onset by the angle turned by the first moving
    sample (:func:`angle_onset`); without it the onset is the middle between the
    last sample at rest and the first moving one.  Where that first moving sample
    had already met the limit, the onset also depends on how long the shaft took
    to reach it: the result's ``limited`` keeps what :func:`place_limited_onset`
    needs once the acceleration is known (:func:`extract` takes it from the
    campaign's other events).  Raises :class:`NoBreakaway` with the reason when
    there is none.
    """
    t_all = np.asarray(time, dtype=float)
    w_all = np.asarray(speed, dtype=float)
    ok = np.flatnonzero(np.isfinite(t_all) & np.isfinite(w_all))
    t, w = t_all[ok], w_all[ok]
    n = t.size
    if n < 8:
        raise NoBreakaway(f"only {n} samples with a speed reading")
    rest = _leave_rest(t, w, rest_speed)
    end, limit, free_end = _growth_window(rest, n)
    th = None if theta is None else np.asarray(theta, dtype=float)[ok]
    onset, accel, on_limit = None, math.nan, None
    if end - rest.last_rest >= 2:
        onset, accel = _onset_from_growth(t, th, rest, end)
    elif rest.last_rest + 1 < n:  # fewer than two growth samples: the angle turned by the first moving one
        onset, accel, on_limit = _onset_from_angle(t, th, rest, limit, free_end)
    grow = rest.last_rest + 1
    if onset is None:  # the onset lies between the last sample at rest and the first moving one
        onset = 0.5 * float(t[rest.last_rest] + t[min(grow, n - 1)])
    return Breakaway(onset, rest.direction, int(ok[rest.last_rest]), float(rest.base(np.array([onset]))[0]),
                     rest.noise, accel, on_limit)


class _Rest(NamedTuple):
    """How a run's speed leaves rest (:func:`_leave_rest`)."""

    base: object  # rest speed as a function of time [rad/s]
    noise: float  # rest noise σ [rad/s]
    moving: float  # departure that counts as motion [rad/s]
    direction: float  # ±1, the way the shaft breaks away
    lasting: np.ndarray  # sustained departure in that direction, per sample [rad/s]
    dev: np.ndarray  # speed over rest in that direction [rad/s]
    last_rest: int  # last sample still within the rest noise


def _leave_rest(t, w, rest_speed: float) -> _Rest:
    """Rest level and noise, direction and last sample at rest, iterated until the last rest
    sample settles (the stuck phase that gives the rest level ends just before it)."""
    n = t.size
    floor = 1e-12 * (1.0 + np.abs(w).max())
    stuck_end, line, last = min(max(20, n // 10), n // 2), False, None
    for _ in range(5):
        base, noise = _rest_level(t[:stuck_end], w[:stuck_end], line, floor)
        r = w - base(t)
        moving = max(10.0 * noise, rest_speed)
        up, down = _sustained(r, 3), _sustained(-r, 3)
        if max(up.max(), down.max()) < moving:
            raise NoBreakaway(f"speed never left rest (largest sustained departure "
                              f"{max(up.max(), down.max()):.3g} rad/s, rest noise {noise:.3g} rad/s)")
        first = [int(np.argmax(x >= moving)) if x.max() >= moving else n for x in (up, down)]
        direction = 1.0 if first[0] <= first[1] else -1.0  # the first sustained departure
        lasting = up if direction > 0 else down
        dev = direction * r
        first_moving = min(first)
        # (one-sided: a reading against the direction of motion is noise, not motion)
        at_rest = np.flatnonzero(dev[:first_moving + 1] <= max(3.0 * noise, 0.1 * moving))
        if first_moving < 3 or at_rest.size == 0:
            raise NoBreakaway("the shaft is already turning at the start of the run")
        last_rest = int(at_rest[-1])
        if last_rest == last:
            break
        last = last_rest
        stuck_end = max(8, int(0.9 * (last_rest + 1)))
        line = stuck_end >= 20
    return _Rest(base, noise, moving, direction, lasting, dev, last_rest)


def _growth_window(rest: _Rest, n: int):
    """The initial growth: up to 30 σ (at least 6 samples), never past half the peak, nor into
    samples that may have met a speed limit → (last growth sample, (threshold, W) of the limit
    or None, last moving sample that met no limit)."""
    dev, noise, grow = rest.dev, rest.noise, rest.last_rest + 1
    peak = rest.lasting.max()
    high = np.flatnonzero(dev[grow:] >= max(30.0 * noise, rest.moving))
    end = max(grow + int(high[0]) if high.size else n - 1, grow + 5)
    half = np.flatnonzero(dev[grow:] >= 0.5 * peak)
    if half.size:
        end = min(end, grow + int(half[0]))
    end = min(end, grow + 20000, n - 1)
    # a speed limit clips the growth: samples near the sustained peak may have met it
    limit = peak - max(0.02 * abs(peak), 5.0 * noise)
    limited = np.flatnonzero(dev[grow:] >= limit)
    limit = (float(limit), float(np.median(dev[grow + limited]))) if limited.size else None
    if limited.size:
        end = min(end, grow + int(limited[0]) - 1)
    return end, limit, (grow + int(limited[0]) - 1 if limited.size else n - 1)


def _onset_from_growth(t, th, rest: _Rest, end: int):
    """Onset from two or more growth samples (hinge fit), checked against the rest samples and
    the angle → (onset [s] or None, growth rate [rad/s²] or NaN)."""
    dev, noise, last_rest, grow = rest.dev, rest.noise, rest.last_rest, rest.last_rest + 1
    lo = max(0, last_rest + 1 - max(5, end - last_rest))
    onset = _hinge_onset(t, median3(dev), lo, last_rest, end, noise)
    u = t[grow:end + 1] - onset  # the growth rate: a line from the onset through the growth samples
    accel = float(u @ dev[grow:end + 1] / (u @ u)) if np.all(u > 0) else math.nan
    # a line through a concave growth (a damped load near its speed within a sample or
    # two) reaches back too far: past a sample that still read rest (the line would have
    # it moving by six rest deviations), or past what the angle turned allows.  Then the
    # speed and angle of the first moving samples, with a lag of any time constant
    at_last_rest = accel * max(float(t[last_rest]) - onset, 0.0) if math.isfinite(accel) else 0.0
    past_rest = at_last_rest > 6.0 * noise + (dev[last_rest] if dev[last_rest] > 0 else 0.0)
    if past_rest or not angle_agrees(t, th, dev, rest.direction, last_rest, onset):
        lagged = lag_onset(t, dev, th, rest.direction, last_rest, end, noise)
        if lagged is not None:
            onset, accel = lagged, math.nan
        elif past_rest:
            onset, accel = None, math.nan
    return onset, accel


def _onset_from_angle(t, th, rest: _Rest, limit, free_end: int):
    """Onset from the angle turned by the first moving sample (fewer than two growth samples)
    → (onset [s] or None, growth rate [rad/s²] or NaN, ``limited`` of :class:`Breakaway`)."""
    dev, last_rest = rest.dev, rest.last_rest
    placed = angle_onset(t, th, dev, rest.direction, last_rest, limit)
    if placed is None:
        return None, math.nan, None
    onset, accel, on_limit = placed
    if on_limit is None and onset <= t[last_rest]:
        # a linear growth would need more time than the interval had: the speed rose
        # faster (a damped load near its speed at once); the lag model over the moving
        # samples that met no limit
        lagged = lag_onset(t, dev, th, rest.direction, last_rest, free_end, rest.noise)
        if lagged is not None:
            onset, accel = lagged, math.nan
    return onset, accel, on_limit
