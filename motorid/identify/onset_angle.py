"""A breakaway onset placed from the shaft angle the first moving samples had turned.

Where a fast breakaway at a low sample rate leaves fewer than two growth
samples of speed, or the growth is not linear (a damped load), the angle — the
integral of the speed — carries the time since the onset that one speed sample
does not (MODEL.md, "Static and kinetic friction").
"""

from __future__ import annotations

import math

import numpy as np


def angle_onset(t, theta, dev, direction: float, last_rest: int, limit) -> tuple | None:
    """Onset from the angle turned by the first moving samples, where the speed alone cannot place it.

    The angle is the integral of the speed, so it carries the time since the
    onset that one speed sample does not.  The speed grows linearly from t0
    (static friction above kinetic: the acceleration jumps at breakaway), ω = a·u,
    u = t − t0, up to a speed limit W (``limit`` = (threshold, W): a sample at or
    above the threshold has met the limit W; None: none did), so
    θ − θ_rest = a u²/2 until u_s = W/a, W (u − u_s/2) after.

    - first moving sample below the limit (ω₁): with a = ω₁/u₁, the angles of that
      sample and, where it met the limit, of the next one are fitted for u₁
      (least squares on a fine grid; one angle alone gives u₁ = 2 Δθ₁/ω₁);
    - first moving sample on the limit: Δθ₁ = W (u₁ − u_s/2) with 0 < u_s ≤ u₁,
      so u₁ lies between Δθ₁/W and 2 Δθ₁/W, and the middle of that interval is taken.

    u₁ is kept within the interval between the last rest sample and the first
    moving one.  Returns (t₀, a, limited) — a = ω₁/u₁ where the first moving
    sample is below the limit (NaN on it), limited as :class:`Breakaway` has it —
    or None where the angle gives nothing (no readings, no movement).
    """
    if theta is None:
        return None
    grow = last_rest + 1
    t_lr, t1 = float(t[last_rest]), float(t[grow])
    span = t1 - t_lr
    level = _rest_angle(theta, last_rest)
    if level is None or not math.isfinite(theta[grow]) or not span > 0.0:
        return None
    turned = lambda k: direction * math.remainder(float(theta[k]) - level, 2 * math.pi)  # noqa: E731
    w1 = float(dev[grow])
    if not w1 > 0.0:
        return None
    threshold, limit = (math.inf, math.inf) if limit is None else limit
    if w1 >= threshold:  # already on the limit at the first moving sample
        d1 = turned(grow)
        if not d1 > 0.0:
            return None
        lo, hi = min(d1 / limit, span), min(2.0 * d1 / limit, span)
        return t1 - 0.5 * (lo + hi), math.nan, (t1, d1 / limit, span, limit)
    use = [grow]
    if grow + 1 < t.size and dev[grow + 1] >= threshold and math.isfinite(theta[grow + 1]):
        use.append(grow + 1)
    if len(use) == 1:
        u1 = min(max(2.0 * turned(grow), 0.0) / w1, span)
        return t1 - u1, (w1 / u1 if u1 > 0 else math.nan), None
    obs = np.array([turned(k) for k in use])
    lag = np.array([float(t[k]) - t1 for k in use])
    u1 = np.linspace(0.0, span, 2001)[1:]
    for _ in range(3):  # grid, then two finer grids around the best point
        a = w1 / u1[:, None]
        u = u1[:, None] + lag[None, :]
        u_s = limit / a
        pred = np.where(u <= u_s, 0.5 * a * u * u, limit * (u - 0.5 * u_s))
        best = int(np.argmin(((pred - obs[None, :]) ** 2).sum(1)))
        step = u1[1] - u1[0]
        u1 = np.linspace(max(u1[best] - step, 1e-3 * step), min(u1[best] + step, span), 201)
    return t1 - float(u1[100]), w1 / float(u1[100]), None


def place_limited_onset(limited: tuple, acceleration: float) -> float:
    """Onset of a breakaway whose first moving sample had already met the speed limit W,
    given the acceleration a [rad/s²] with which the shaft left rest [s].

    limited = (t₁, Δθ₁/W, span, W) of :class:`Breakaway`: the shaft reached W after
    u_s = W/a and had turned Δθ₁ = W (u₁ − u_s/2) by t₁, so t₀ = t₁ − Δθ₁/W − u_s/2.
    u_s is kept where the angle allows it (u_s ≤ u₁: at most 2 Δθ₁/W) and u₁
    within the interval since the last sample at rest.
    """
    t1, turned_time, span, w_limit = limited
    u_s = min(w_limit / acceleration, 2.0 * turned_time) if acceleration > 0 else turned_time
    return t1 - min(turned_time + 0.5 * u_s, span)


ANGLE_STEP = math.radians(0.01)  # shaft-angle reading step assumed where the readings do not show one [rad]


def _rest_angle(theta, last_rest: int) -> float | None:
    """Shaft angle at rest [rad]: the circular median of the last ten readings up to
    ``last_rest`` about the last of them; None where none was read."""
    rest = np.arange(max(0, last_rest - 9), last_rest + 1)
    rest = rest[np.isfinite(theta[rest])]
    if rest.size == 0:
        return None
    ref = float(theta[rest[-1]])
    return ref + float(np.median(np.remainder(theta[rest] - ref + np.pi, 2 * np.pi) - np.pi))


def _turned_since_rest(theta, direction: float, last_rest: int, idx) -> tuple | None:
    """Angle the shaft turned in the direction of motion since rest, at samples ``idx``
    after ``last_rest`` [rad] (rest: the median of the last ten readings at rest), and the
    angle's reading step [rad] → (turned, step); None where the readings give nothing."""
    if theta is None:
        return None
    idx = np.atleast_1d(np.asarray(idx, dtype=int))
    level = _rest_angle(theta, last_rest)
    if level is None or idx.size == 0 or not np.all(np.isfinite(theta[idx])):
        return None
    turned = direction * (np.unwrap(np.r_[level, theta[idx]])[1:] - level)
    # the reading step: at most the smallest gap between the distinct angles read in the run,
    # and taken as 0.01° (an encoder's or resolver's) where the readings do not show one
    gaps = np.diff(np.unique(np.mod(theta[np.isfinite(theta)], 2 * np.pi)))
    step = min(float(gaps.min()) if gaps.size else math.inf, ANGLE_STEP)
    return turned, step


def angle_agrees(t, theta, dev, direction: float, last_rest: int, onset: float) -> bool:
    """Does an onset agree with the angle the first moving sample had turned?

    A speed that rose from 0 at t₀ to ω₁ at t₁ as u^p (p = 0: a jump, 1: linear, 2:
    quadratic) turned the shaft Δθ₁ = ω₁ u₁/(1 + p), u₁ = t₁ − t₀; growth between a
    jump and a quadratic puts u₁ between Δθ₁/ω₁ and 3 Δθ₁/ω₁ (a fifth and three
    reading steps of slack; the step is taken no larger than Δθ₁).  True where the
    angle cannot tell."""
    grow = last_rest + 1
    got = _turned_since_rest(theta, direction, last_rest, grow)
    w1 = float(dev[grow])
    if got is None or not w1 > 0:
        return True
    (d1,), step = got
    if not d1 > 0:
        return True
    step = min(step, d1)  # a nonzero reading has turned at least one step
    u1 = float(t[grow]) - onset
    return 0.8 * (d1 - 3 * step) / w1 <= u1 <= 1.2 * (3.0 * d1 + 3 * step) / w1


def lag_onset(t, dev, theta, direction: float, last_rest: int, stop: int, noise: float) -> float | None:
    """Onset from the first moving samples' speed and angle, with a growth of any speed of response.

    After breakaway the shaft's speed follows a first-order lag and goes on rising
    with the load, ω = V (1 − e^(−u/τ)) + r u, u = t − t₀ (a load with damping; V = 0
    is the linear growth of an undamped one, small τ a jump), and the angle its
    integral, θ − θ_rest = V (u − τ (1 − e^(−u/τ))) + r u²/2.  The speed and angle of
    up to three moving samples (before ``stop``) are fitted for t₀ (between the last
    sample at rest and the first moving one), τ (a log grid) and V, r ≥ 0 (least
    squares), the speed weighted by its rest noise, the angle by its reading step.
    None where the angle gives nothing.
    """
    grow = last_rest + 1
    use = np.arange(grow, min(grow + 3, stop + 1, t.size))
    got = _turned_since_rest(theta, direction, last_rest, use) if use.size >= 2 else None
    if got is None:
        return None
    turned, step = got
    if not (turned[0] > 0 and np.all(np.diff(np.r_[0.0, turned]) < np.pi)):
        return None
    s_theta = max(min(step, turned[0]) / math.sqrt(12.0), 1e-9)
    s_speed = max(noise, 1e-12)
    t_lr, t1 = float(t[last_rest]), float(t[grow])
    t0 = np.linspace(t_lr, t1, 402)[:-1]
    u = np.maximum(t[use][None, :] - t0[:, None], 0.0)  # (t0, samples)
    span = t1 - t_lr
    y = np.r_[dev[use] / s_speed, turned / s_theta]
    ramp = np.concatenate([u / s_speed, 0.5 * u * u / s_theta], axis=1)  # a speed rising on with the load
    best, cost = None, math.inf
    for tau in span * np.logspace(-3.0, 3.0, 61):
        f = -np.expm1(-u / tau)
        lag = np.concatenate([f / s_speed, (u - tau * f) / s_theta], axis=1)  # (t0, 2 K)
        # least squares in (V, r) for every t0 at once: 2 × 2 normal equations
        a11, a12, a22 = (lag * lag).sum(1), (lag * ramp).sum(1), (ramp * ramp).sum(1)
        b1, b2 = lag @ y, ramp @ y
        det = a11 * a22 - a12 * a12
        with np.errstate(divide="ignore", invalid="ignore"):
            V = np.where(det > 0, (a22 * b1 - a12 * b2) / det, -1.0)
            r = np.where(det > 0, (a11 * b2 - a12 * b1) / det, -1.0)
            # V, r ≥ 0: where the pair is not, the better of each alone (the problem is convex)
            V_only, r_only = np.maximum(b1 / a11, 0.0), np.maximum(b2 / a22, 0.0)
        both = (V >= 0) & (r >= 0)
        c_both = ((y[None, :] - V[:, None] * lag - r[:, None] * ramp) ** 2).sum(1)
        c_V = ((y[None, :] - V_only[:, None] * lag) ** 2).sum(1)
        c_r = ((y[None, :] - r_only[:, None] * ramp) ** 2).sum(1)
        c = np.where(both, c_both, np.minimum(c_V, c_r))
        c = np.where(np.isfinite(c), c, np.inf)
        k = int(np.argmin(c))
        if c[k] < cost:
            best, cost = float(t0[k]), float(c[k])
    return best
