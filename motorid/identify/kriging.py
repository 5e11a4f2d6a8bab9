"""The model error of a table fit, interpolated: simple kriging of the residuals over the operating space.

A physical model that misses a real map by structure (:mod:`motorid.identify.lack_of_fit`) leaves
residuals that neighbouring points share.  Between measured points that shared part can be
predicted: the residual at a new point is estimated from those of its neighbours, weighted by how
much a model error at that distance is shared (the best linear unbiased predictor of a zero-mean
field: simple kriging, Cressie, *Statistics for Spatial Data*, 1993, §3.2; the model plus a
discrepancy field as in Kennedy & O'Hagan, J. R. Stat. Soc. B 63 (2001) 425).  Far from every
measured point the estimate falls back to zero: outside the map the physical model predicts
alone, so extrapolation keeps what the physics knows.

The field: a Matérn-3/2 covariance σ_m² (1 + √3 h/ℓ) e^{−√3 h/ℓ} in the scaled operating
coordinates of :func:`~motorid.identify.lack_of_fit.operating_axes` (scaled by the training points'
spread, :class:`~motorid.identify.lack_of_fit.AxisScaling`), plus independent noise σ_e².  σ_m² is the neighbours' estimate of
:func:`~motorid.identify.lack_of_fit.structured_error`;
ℓ and the ratio σ_e²/σ_m² those of the lowest leave-one-out error.  Each prediction uses its
:data:`NEIGHBOURS` nearest training points (local kriging: tens of thousands of points cost
seconds).  Where the neighbours show no model error, nothing is added.
"""

from __future__ import annotations

import numpy as np

#: training points each prediction is kriged from
NEIGHBOURS = 16
#: correlation lengths tried, in units of the training points' spread along each axis
LENGTHS = (0.03, 0.06, 0.12, 0.25, 0.5, 1.0)
#: leave-one-out points used to choose the length (a seeded subsample of larger tables)
LOO_POINTS = 600
#: training points a field keeps (a seeded subsample of denser maps: an interpolated grid of 50 000 points
#: is carried by 20 000 of them, and result.json stays a few MB)
FIELD_POINTS = 20000


def _matern32(h, length):
    a = np.sqrt(3.0) * h / length
    return (1.0 + a) * np.exp(-a)


class ResidualKriging:
    """The kriged model error of one channel: ``predict(X)`` → (mean, variance) at scaled coordinates X."""

    def __init__(self, X: np.ndarray, r: np.ndarray, sigma_m: float, sigma_e: float, length: float,
                 variance_factor: float = 1.0):
        from scipy.spatial import cKDTree

        self.X, self.r = np.asarray(X, float), np.asarray(r, float)
        self.sigma_m, self.sigma_e, self.length = float(sigma_m), float(sigma_e), float(length)
        self.variance_factor = float(variance_factor)  # ≥ 1: the leave-one-out errors' own calibration
        self.tree = cKDTree(self.X)

    def _weights(self, Xq, idx):
        """Kriging weights of the neighbours ``idx`` (n × k) of the points Xq → (weights, c_q·weights)."""
        s2, e2 = self.sigma_m**2, self.sigma_e**2
        N = self.X[idx]  # n × k × d
        dNN = np.linalg.norm(N[:, :, None, :] - N[:, None, :, :], axis=-1)
        K = s2 * _matern32(dNN, self.length) + e2 * np.eye(idx.shape[1])
        kq = s2 * _matern32(np.linalg.norm(N - Xq[:, None, :], axis=-1), self.length)
        w = np.linalg.solve(K, kq[..., None])[..., 0]
        return w, np.sum(w * kq, axis=1)

    def document(self) -> dict:
        """The field as JSON: its training points (scaled coordinates), residuals [SI] and constants."""
        return {"sigma": self.sigma_m, "noise": self.sigma_e, "length": self.length,
                "variance_factor": self.variance_factor,
                "points": np.round(self.X, 6).tolist(),  # scaled coordinates: 10⁻⁶ of a spread
                "residuals": [float(f"{v:.7g}") for v in self.r]}

    @classmethod
    def from_document(cls, doc: dict) -> "ResidualKriging":
        return cls(np.asarray(doc["points"], float).reshape(len(doc["residuals"]), -1),
                   np.asarray(doc["residuals"], float), doc["sigma"], doc["noise"], doc["length"],
                   doc.get("variance_factor", 1.0))

    def predict(self, Xq: np.ndarray, chunk: int = 4096):
        """(mean, variance of the model error) at the points Xq [SI of the channel, its square]."""
        Xq = np.asarray(Xq, float)
        k = min(NEIGHBOURS, len(self.X))
        mean, var = np.zeros(len(Xq)), np.full(len(Xq), self.sigma_m**2)
        for a in range(0, len(Xq), chunk):
            q = Xq[a:a + chunk]
            _, idx = self.tree.query(q, k=k)
            idx = idx.reshape(len(q), k)
            w, explained = self._weights(q, idx)
            mean[a:a + chunk] = np.sum(w * self.r[idx], axis=1)
            var[a:a + chunk] = self.variance_factor * np.maximum(self.sigma_m**2 - explained, 0.0)
        return mean, var



def _loo(X, r, sigma_m, sigma_e, length, rows):
    """Leave-one-out at ``rows`` (each kriged from its neighbours but itself) → (errors, their variance
    as the field says, σ_m² − c·w + σ_e²)."""
    krig = ResidualKriging(X, r, sigma_m, sigma_e, length)
    k = min(NEIGHBOURS + 1, len(X))
    _, idx = krig.tree.query(X[rows], k=k)
    idx = idx.reshape(len(rows), k)
    # itself out (a replicated point at distance 0 may come first or second)
    others = np.array([[j for j in row if j != i][: k - 1] for i, row in zip(rows, idx)])
    w, explained = krig._weights(X[rows], others)
    return r[rows] - np.sum(w * r[others], axis=1), np.maximum(sigma_m**2 - explained, 0.0) + sigma_e**2


def _loo_error(X, r, sigma_m, sigma_e, length, rows) -> float:
    """Mean squared leave-one-out error at ``rows``."""
    return float(np.mean(_loo(X, r, sigma_m, sigma_e, length, rows)[0] ** 2))


#: noise-to-field variance ratios σ_e²/σ_m² tried beside the one the neighbours give
NUGGET_RATIOS = (0.01, 0.03, 0.1, 0.3, 1.0, 3.0)


def fit_residual_kriging(X: np.ndarray, r: np.ndarray, sigma_m: float, seed: int = 0):
    """The kriged model error of residuals ``r`` at scaled coordinates ``X`` (NaN: left out), with the
    neighbours' model error ``sigma_m`` [SI]; None where there is none or too few points, or where no
    length predicts left-out points better than zero does.  The length and the noise-to-field ratio
    (that of the residuals' mean square beyond σ_m², or one of :data:`NUGGET_RATIOS`) are those of the
    lowest leave-one-out error (a coordinate search: lengths, then ratios, then lengths again); the field's
    variance stays σ_m², its kriging variance widened where the left-out residuals miss by more than it
    says (their mean squared error over the mean variance claimed); a table of more than :data:`FIELD_POINTS` points is
    kriged from a seeded subset."""
    r = np.asarray(r, float)
    ok = np.isfinite(r) & np.all(np.isfinite(X), axis=1)
    X, r = np.asarray(X, float)[ok], r[ok]
    if sigma_m <= 0 or len(r) < 10 or X.shape[1] <= 1:  # the direction alone: no axis varies
        return None
    rng = np.random.default_rng(seed)
    if len(r) > FIELD_POINTS:  # a dense map: a spread subset carries its field
        keep = np.sort(rng.choice(len(r), FIELD_POINTS, replace=False))
        X, r = X[keep], r[keep]
    ms = float(np.mean(r**2))
    neighbours_ratio = max(ms / sigma_m**2 - 1.0, 1e-3)
    rows = np.arange(len(r)) if len(r) <= LOO_POINTS else np.sort(rng.choice(len(r), LOO_POINTS, replace=False))
    best, choice = float(np.mean(r[rows] ** 2)), None  # zero (the physics alone) to beat
    tried: dict = {}

    def consider(length, ratio):
        nonlocal best, choice
        if (length, ratio) not in tried:
            tried[length, ratio] = _loo_error(X, r, sigma_m, sigma_m * np.sqrt(ratio), length, rows)
            if tried[length, ratio] < best:
                best, choice = tried[length, ratio], (length, ratio)

    # coordinate search: the lengths at the neighbours' ratio, the ratios at the best length, the lengths again
    for length in LENGTHS:
        consider(length, neighbours_ratio)
    at = choice[0] if choice else LENGTHS[len(LENGTHS) // 2]
    for ratio in sorted({neighbours_ratio, *NUGGET_RATIOS}):
        consider(at, ratio)
    if choice is not None:
        for length in LENGTHS:
            consider(length, choice[1])
    if choice is None:
        return None
    sigma_e = sigma_m * np.sqrt(choice[1])
    # the band the field gives must hold its own left-out residuals: where their mean squared error exceeds
    # the mean variance it claims for them (σ_m² − c·w + σ_e²), its variance is widened by that ratio
    err, var = _loo(X, r, sigma_m, sigma_e, choice[0], rows)
    factor = max(1.0, float(np.mean(err**2) / max(np.mean(var), 1e-300)))
    return ResidualKriging(X, r, sigma_m, sigma_e, choice[0], factor)


def model_error_fields(table, residuals: dict, sigma: dict | None = None, errors: dict | None = None) -> tuple:
    """(scaling, {channel: ResidualKriging}) of the residuals of a fit on ``table`` (channels where the
    neighbours show a model error, :func:`~motorid.identify.lack_of_fit.structured_error` with each
    point's noise ``sigma`` where given, or ``errors`` where the fit has it already, and kriging predicts
    left-out points better than nothing)."""
    from motorid.identify.lack_of_fit import AxisScaling, operating_axes, structured_error

    axes = operating_axes(table)
    scaling = AxisScaling(axes)
    X = scaling(axes)
    fields = {}
    for c, e in (structured_error(table, residuals, sigma=sigma) if errors is None else errors).items():
        if e["sigma"] > 0:
            krig = fit_residual_kriging(X, residuals[c], e["sigma"])
            if krig is not None:
                fields[c] = krig
    return scaling, fields


#: what result.json says of the field
FIELD_METHOD = ("simple kriging of the fit's residuals over the scaled operating space (Matérn-3/2, "
                f"{NEIGHBOURS} nearest training points, length and noise by leave-one-out; Cressie 1993 §3.2, "
                "Kennedy & O'Hagan 2001): the model error between measured points, added by `motorid predict` "
                "unless --physics-only; zero far from them")


def field_document(scaling, fields: dict) -> dict | None:
    """result.json's ``table.model_error_field`` (None where no channel has one)."""
    if not fields:
        return None
    return {"method": FIELD_METHOD, "scaling": scaling.document(),
            "channels": {c: k.document() for c, k in fields.items()}}


def fields_from_document(doc: dict | None) -> tuple:
    """(scaling, {channel: ResidualKriging}) from result.json's ``table.model_error_field``; (None, {})
    where it has none."""
    from motorid.identify.lack_of_fit import AxisScaling

    if not doc or not doc.get("channels"):
        return None, {}
    return (AxisScaling.from_document(doc["scaling"]),
            {c: ResidualKriging.from_document(d) for c, d in doc["channels"].items()})
