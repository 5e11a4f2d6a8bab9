"""The acceleration dω/dt of a running run, with a speed ripple locked to the shaft resolved.

J·dω/dt is part of the running torque (MODEL.md); a derivative of sampled speed
turns an aliased shaft-order ripple into a false slow acceleration, so the
ripple is fitted against the shaft angle and its own derivative added back; what
the run's slow trend and that ripple leave is left out where it is mostly the
speed sensor's noise amplified by the derivative (:func:`_without_noise`).
"""

from __future__ import annotations

import math

import numpy as np

from motorid.robust import odd_window


def _derivative_weights(k: int) -> np.ndarray:
    """The Savitzky-Golay first-derivative weights of a quadratic through ``k`` evenly spaced samples
    (per sample interval)."""
    x = np.arange(k) - k // 2
    powers = x[:, None] ** np.arange(3)[None, :]
    return np.linalg.solve(powers.T @ powers, powers.T)[1]


def smoothed_acceleration(time, speed, window: int = 9) -> np.ndarray:
    """dω/dt of one run by a local quadratic fit of speed against time [rad/s²].

    time [s], speed [rad/s] (NaN gaps are bridged).  Each sample's slope comes
    from a least-squares quadratic through the ``window`` samples around it (a
    Savitzky-Golay derivative when the sampling is even; uneven sampling is
    honoured).  Zero where the run is too short to tell.
    """
    t = np.asarray(time, dtype=float)
    w = np.asarray(speed, dtype=float)
    n = t.size
    ok = np.isfinite(w)
    if n < 5 or ok.sum() < 5:
        return np.zeros(n)
    if not ok.all():
        w = np.interp(t, t[ok], w[ok])
    k = odd_window(min(max(window, 5), n))
    dt = np.diff(t)
    scale = float(np.median(dt))
    # (for even sampling this is the Savitzky-Golay derivative, edges as its "interp" mode)
    first = np.clip(np.arange(n) - k // 2, 0, n - k)  # windows shift inwards at the ends
    if np.all(np.abs(dt - scale) <= 1e-3 * scale) and n > k:
        # even sampling (time stamps rounded to a few digits count as even: a 0.1 % jitter
        # moves the slope by 0.1 % at most): one set of derivative weights for every interior sample
        weights = _derivative_weights(k)
        out = np.empty(n)
        out[k // 2:n - k // 2] = np.correlate(w, weights, mode="valid")
        edge = np.r_[np.arange(k // 2), np.arange(n - k // 2, n)]
    else:
        out, edge = None, np.arange(n)
    idx = first[edge, None] + np.arange(k)[None, :]
    x = (t[idx] - t[edge, None]) / scale
    powers = x[:, :, None] ** np.arange(3)[None, None, :]  # (n, k, 3): 1, x, x²
    normal = np.einsum("nkp,nkq->npq", powers, powers)
    rhs = np.einsum("nkp,nk->np", powers, w[idx])
    slope = np.linalg.solve(normal, rhs[..., None])[:, 1, 0]
    if out is None:
        return slope / scale
    out[edge] = slope
    return out / scale


#: least F statistic of a shaft order of the speed ripple that running_acceleration keeps:
#: 2, Akaike's (an order's two coefficients must lower the misfit by more than two
#: residual variances each); a stricter test (30 before) left real ripples of fast
#: runs unresolved where the dynamometer's slow speed wander raised the residual
RIPPLE_F = 2.0


#: two shaft orders whose aliased frequencies differ by fewer cycles over the run than this
#: read as one (a least-squares fit separates frequencies about one cycle per record apart)
FOLD_CYCLES = 2.0


def aliased_cycles(time, speed, orders) -> dict:
    """Cycles that each shaft order of a steady run goes through as the samples see it
    (aliased) → {order: cycles over the run} [-].  Order k turns k·ω̄·Δt/2π cycles a
    sample; sampling folds that to its distance from the nearest whole number, 0 … ½.
    Near 0 the order is in step with the sampling: a speed ripple at it reads as a
    constant, and its acceleration, k·ω times its size, is invisible in the samples."""
    t = np.asarray(time, dtype=float)
    w = np.asarray(speed, dtype=float)
    ok = np.isfinite(t) & np.isfinite(w)
    if ok.sum() < 3:
        return {int(k): 0.0 for k in orders}
    dt = float(np.median(np.diff(np.sort(t[ok]))))
    turn = abs(float(np.mean(w[ok]))) * dt / (2 * np.pi)
    return {int(k): abs(k * turn - round(k * turn)) * int(ok.sum()) for k in orders}


def running_acceleration(time, speed, theta, steady, window: int = 9, orders=(1, 2)) -> np.ndarray:
    """dω/dt of a steady run with any speed ripple locked to the shaft angle resolved [rad/s²].

    A dynamometer's coupling or a shaft's eccentricity makes the speed wobble at
    shaft orders 1, 2, …; at high speed the samples alias that wobble, and a
    derivative of sampled speed (:func:`smoothed_acceleration`) turns it into a
    false slow acceleration, J·α of which lands in the torque.  Over the
    ``steady`` samples, speed = slow trend + Σₖ aₖ cos kθ + bₖ sin kθ is fitted
    by least squares (the trend a Chebyshev polynomial in time of degree about
    half the revolutions turned, 2 to 10: smooth over a revolution, so the two
    parts do not mix); the derivative of sampled speed is taken of the rest, and
    the ripple's own derivative, ω Σₖ k(bₖ cos kθ − aₖ sin kθ), is added back
    exactly.  Orders are taken lowest first, each kept where it lowers the misfit
    by F ≥ :data:`RIPPLE_F` and the sampling does not fold it onto an order
    already kept (an order fitted to noise adds that noise back k·ω times
    amplified; a real ripple left out adds itself); the plain derivative is
    returned where none is kept or the run turns less than two revolutions.
    """
    t = np.asarray(time, dtype=float)
    w = np.asarray(speed, dtype=float)
    th = np.asarray(theta, dtype=float)
    plain = smoothed_acceleration(t, w, window)
    sel = np.flatnonzero(np.asarray(steady, dtype=bool) & np.isfinite(w) & np.isfinite(th) & np.isfinite(t))
    orders = tuple(int(k) for k in orders)
    if not orders or sel.size < 50:
        return plain
    span = np.ptp(t[sel])
    if not span > 0:
        return plain
    if abs(float(np.mean(w[sel]))) * span / (2 * np.pi) < 2.0:  # no ripple to resolve: a quadratic trend
        u = 2.0 * (t[sel] - t[sel].min()) / span - 1.0
        coef = np.linalg.lstsq(np.polynomial.chebyshev.chebvander(u, 2), w[sel], rcond=None)[0]
        return _without_noise(plain, t, w, sel, coef, span, window)
    revolutions = abs(np.ptp(np.unwrap(th[sel]))) / (2 * np.pi)  # as sampled: order 1's aliased cycles
    u = 2.0 * (t[sel] - t[sel].min()) / max(span, 1e-300) - 1.0
    trend = np.polynomial.chebyshev.chebvander(u, int(np.clip(revolutions / 2, 2, 10)))
    m = trend.shape[1]
    X = np.column_stack([trend] + [np.column_stack([np.cos(k * th[sel]), np.sin(k * th[sel])]) for k in orders])
    y = w[sel] - np.mean(w[sel])  # (the trend holds the constant; centring keeps yᵀy − bᵀXᵀy exact)
    # every subset of orders from one Gram matrix (einsum: no threaded BLAS against XLA's threads)
    gram, xty, yy = np.einsum("ni,nj->ij", X, X), np.einsum("ni,n->i", X, y), float(y @ y)

    def fit(kept):
        cols = np.r_[np.arange(m), [m + 2 * orders.index(k) + j for k in kept for j in (0, 1)]].astype(int)
        g = gram[np.ix_(cols, cols)]
        lam = np.linalg.eigvalsh(g)
        cond = math.sqrt(lam[-1] / lam[0]) if lam[0] > 0 else math.inf  # of X: √ of its Gram's
        if not cond <= 1e8:
            return None, 0.0, 0, cond
        coef = np.linalg.solve(g, xty[cols])
        return coef, max(yy - float(coef @ xty[cols]), 0.0), sel.size - cols.size, cond

    # orders taken one at a time, lowest first: one that the sampling folds onto an order
    # already kept (at 1000 rpm and 50 Hz orders 1 and 2 alias to one frequency) is left
    # out, as is one that does not lower the misfit by F ≥ RIPPLE_F (an order fitted to
    # noise adds its noise back amplified k·ω times through the derivative; a real ripple
    # left out puts all of itself, k·ω times, into the acceleration)
    coef, rss_kept, _, _ = fit([])
    kept = []
    cycles = aliased_cycles(t[sel], w[sel], orders)
    for k in sorted(orders):
        # an order the sampling folds near 0 Hz is the trend's; near the Nyquist frequency its
        # cosine and sine read alike
        if not (cycles[k] >= m / 2 + 1 and 0.5 * sel.size - cycles[k] >= 1.0):
            continue
        # folded onto an order already kept (at 1000 rpm and 50 Hz, three samples a revolution,
        # orders 1 and 2 read at one frequency): the two cannot be told apart over the run, and
        # a near-collinear pair splits the ripple into large opposite parts whose derivatives,
        # weighted k·ω, no longer cancel; the lower order then stands for both (a true order-2
        # wobble at three samples a revolution reads as −½ of its acceleration: the samples
        # cannot tell the two apart)
        if any(abs(cycles[k] - cycles[j]) < FOLD_CYCLES for j in kept):
            continue
        c, rss, dof, cond = fit(kept + [k])
        if c is None or dof < 20 or cond > 1e6 or not rss > 0:
            continue
        if ((rss_kept - rss) / 2.0) / (rss / dof) >= RIPPLE_F:
            kept, coef, rss_kept = kept + [k], c, rss
    trend_coef = coef[:m] + np.r_[np.mean(w[sel]), np.zeros(m - 1)]  # the centring's constant back in
    if not kept:
        return _without_noise(plain, t, w, sel, trend_coef, span, window)
    a, b = coef[trend.shape[1]::2], coef[trend.shape[1] + 1::2]
    k = np.asarray(kept, dtype=float)
    ok = np.isfinite(th)
    phase = np.outer(np.where(ok, th, 0.0), k)
    ripple = np.where(ok, np.cos(phase) @ a + np.sin(phase) @ b, np.nan)
    ripple_rate = np.where(ok, np.cos(phase) @ (k * b) - np.sin(phase) @ (k * a), 0.0)
    rest = w - ripple
    return _without_noise(smoothed_acceleration(t, rest, window), t, rest, sel, trend_coef, span,
                          window) + w * ripple_rate


#: share of the unexplained part's variance that the speed noise must reach for the part to be left
#: out of the acceleration (:func:`_without_noise`)
NOISE_SHARE = 0.5


def _without_noise(accel, t, speed, sel, trend_coef, span: float, window: int) -> np.ndarray:
    """``accel`` (the smoothed derivative of ``speed``, shaft-order ripple taken out) on the ``sel``
    samples (50 or more, over a time ``span`` > 0) without its part that the run's slow trend (Chebyshev coefficients ``trend_coef`` over
    the ``sel`` samples' time span ``span``) does not explain, where that part is mostly the speed
    sensor's noise: at least :data:`NOISE_SHARE` of its variance [rad/s²].

    The derivative of sampled speed carries the speed noise amplified by 1/Δt: at 1 kHz a speed noise
    of 0.3 rpm reads as ±4 rad/s² of acceleration, more than a dynamometer's own wobble, and J·α
    built on it is J times that noise, not the torque the rotor needs.  A fit of J (or of anything
    ∝ α) on such α is biased toward zero by var(true)/var(read) (regression dilution).  The part is
    left out whole or kept whole, never scaled: the fit regresses on shaft-angle cell means, where
    the noise averages down and a real part would not, so a scaled part would bias J the other way.
    The noise variance is the derivative filter's gain times the speed noise, read from second
    differences of consecutive samples about the trend (white noise; a real wobble's second
    differences are (ωΔt)² times smaller; a quantized speed, whose second differences are mostly 0,
    keeps its part).  The trend's own derivative is exact (a polynomial over the run)."""
    t_s = t[sel]
    u = 2.0 * (t_s - t_s.min()) / span - 1.0
    cheb = np.polynomial.chebyshev
    e = speed[sel] - cheb.chebval(u, trend_coef)
    slow = cheb.chebval(u, cheb.chebder(trend_coef)) * (2.0 / span)
    dt = float(np.median(np.diff(t)))  # the log's own sampling interval (sel may skip samples)
    d2 = np.diff(e, 2)[sel[2:] - sel[:-2] == 2]  # over consecutive samples only
    if d2.size < 20 or not dt > 0 or not np.all(np.isfinite(e)):
        return accel
    noise_var = float(np.median(np.abs(d2)) / 0.6745) ** 2 / 6.0  # robust; 6σ² for white noise
    gain = float(np.sum(_derivative_weights(odd_window(min(max(window, 5), t.size))) ** 2)) / dt**2
    part = accel[sel] - slow
    spread = float(np.mean(part**2))
    if not (np.isfinite(spread) and spread > 0) or noise_var * gain < NOISE_SHARE * spread:
        return accel
    out = np.asarray(accel, dtype=float).copy()
    out[sel] = slow
    return out
