"""One steady run's viscometer readings replaced by a slow curve in time, with the curve's error."""

from __future__ import annotations

import math

import numpy as np

from motorid.identify.types import VISCOSITY_MODES
from motorid.robust import mad_std


def smooth_viscosity(time, viscosity, max_degree: int = 5):
    """One steady run's viscometer readings as a slow curve → (smoothed, degree, σ, factor, center, half_span).

    time [s], viscosity [Pa·s] of the run's steady samples (finite).  The curve
    is a Chebyshev polynomial in time, fitted by least squares with readings
    beyond 4 robust deviations left out (spikes); its degree is the lowest
    after which one more degree no longer lowers the residual sum of squares
    by more than max(log n, 10) residual variances.  It replaces the readings
    only where what is left is white noise: the residuals' lag-one
    autocorrelation, in time order, must be below 3/√n (a change the curve
    cannot follow, such as a temperature step, leaves it near one).  Otherwise,
    where the run is shorter than 20 samples, or the readings do not scatter at
    all (a held viscosity), the readings are returned as read, with degree −1
    and a zero factor.  σ is the readings' deviation about the curve [Pa·s]; factor
    (VISCOSITY_MODES, VISCOSITY_MODES) is a square root L (L Lᵀ) of the curve's
    coefficient covariance σ²(XᵀX)⁻¹ (see :class:`ViscositySmoothing`).
    """
    t = np.asarray(time, dtype=float)
    mu = np.asarray(viscosity, dtype=float)
    n = t.size
    center = 0.5 * (t.min() + t.max()) if n else 0.0
    half = 0.5 * float(np.ptp(t)) if n else 0.0
    as_read = (mu.copy(), -1, math.nan, np.zeros((VISCOSITY_MODES, VISCOSITY_MODES)), center, max(half, 1.0))
    if n < 20 or half <= 0 or not np.all(np.isfinite(mu)) or not np.all(np.isfinite(t)):
        return as_read
    order = np.argsort(t, kind="stable")
    d = np.diff(mu[order])
    noise_diff = mad_std(d) / math.sqrt(2.0)
    if not noise_diff > 0:
        return as_read
    u = (t - center) / half
    X_all = np.polynomial.chebyshev.chebvander(u, min(max_degree, VISCOSITY_MODES - 1))
    top = X_all.shape[1] - 1
    # spikes: readings beyond 4 robust deviations of the highest-degree curve (a spike is
    # one at any degree), found once
    keep = np.ones(n, bool)
    for _ in range(4):
        coef = np.linalg.lstsq(X_all[keep], mu[keep], rcond=None)[0]
        r = mu - X_all @ coef
        sigma = mad_std(r[keep])
        new = np.abs(r) <= max(4.0 * sigma, 1e-300)
        if new.sum() < top + 10 or np.array_equal(new, keep):
            break
        keep = new
    # every degree from one QR of the kept rows: the first d + 1 columns of Q span degree d
    Q, R = np.linalg.qr(X_all[keep])
    qy = Q.T @ mu[keep]
    rss_all = float(mu[keep] @ mu[keep]) - np.cumsum(qy**2)  # residual sum of squares by degree
    m = int(keep.sum())
    penalty = max(math.log(n), 10.0)
    degree = 0
    while degree < top and m > degree + 12:
        var = max(rss_all[degree + 1], 0.0) / max(m - degree - 2, 1)
        if rss_all[degree] - rss_all[degree + 1] <= penalty * var:
            break
        degree += 1
    Rd = R[: degree + 1, : degree + 1]
    try:
        coef = np.linalg.solve(Rd, qy[: degree + 1])
    except np.linalg.LinAlgError:
        return as_read
    smooth = X_all[:, : degree + 1] @ coef
    # what is left must be white: lag-one autocorrelation of the (clipped) residuals in
    # time order within 3/√n of zero (a curve the polynomial misses leaves it positive)
    sigma = mad_std((mu - smooth)[keep])
    rr = np.clip((mu - smooth)[order], -4.0 * sigma, 4.0 * sigma)
    power = float(rr @ rr)
    if not (power > 0 and float(rr[:-1] @ rr[1:]) / power <= 3.0 / math.sqrt(n)):
        return as_read
    sigma_ls = math.sqrt(max(rss_all[degree], 0.0) / max(m - degree - 1, 1))
    # covariance σ²(XᵀX)⁻¹ = σ² R⁻¹R⁻ᵀ: σR⁻¹ is a square root of it
    factor = np.zeros((VISCOSITY_MODES, VISCOSITY_MODES))
    factor[: degree + 1, : degree + 1] = sigma_ls * np.linalg.inv(Rd)
    return smooth, degree, sigma_ls, factor, center, half
