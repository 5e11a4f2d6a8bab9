"""How far the model misses a table's points by structure, not by noise: the model error of its
predictions.

A table fit estimates each channel's noise from the scatter of the points about the model, so a
model that misses a real map (a leak law it does not hold, a loss growing faster than it allows)
shows no misfit in χ²/dof: the misfit is taken as noise.  The confidence band of a prediction
then says where the *model's* value lies, not the motor's, and misses the motor's true mean at
most points.

The structured part is told from the noise by neighbours: the residuals r_i = m(x_i) + e_i of two
points close in the operating space share the model error m (smooth over the grid) but not the
noise e (independent), so E[r_i r_j] = E[m²] over pairs of nearest neighbours, and 0 where the
model is right.  This is the nugget-and-sill reading of a variogram at its shortest lag
(Cressie, *Statistics for Spatial Data*, 1993, §2.3); replicated points (the same setting
measured twice) are neighbours at distance 0 and give it exactly.  The mean of the products is
taken as model error where a permutation test (the same mean over shuffled residuals) says the
neighbours share more than chance, else 0.
"""

from __future__ import annotations

import numpy as np

#: the neighbours' mean product must stand above this share of the same mean over shuffled residuals
#: (a permutation test: no assumption on the noise's shape, heavy tails and noise growing with the
#: reading included)
MODEL_ERROR_ALPHA = 0.01
#: shuffles of the permutation test
MODEL_ERROR_PERMUTATIONS = 400
#: neighbours of each point in the test's graph (more pairs than the nearest alone: more power)
MODEL_ERROR_NEIGHBOURS = 4
#: fewer points with a channel than this: no estimate
MODEL_ERROR_MIN_POINTS = 10
#: more points than this: the test and the size from a seeded subset of them (a dense interpolated map of
#: 50 000 points says as much with this many, at a tenth of the permutations' cost)
MODEL_ERROR_MAX_POINTS = 8000


def operating_axes(table) -> np.ndarray:
    """The points' axes in the operating space, unscaled [SI]: signed speed, signed ΔP, the mean port
    pressure above the case, log viscosity and (a variable unit) displacement."""
    cols = [np.asarray(table.speed, float), np.asarray(table.dp, float),
            0.5 * (np.asarray(table.p_a, float) + np.asarray(table.p_b, float)) - np.asarray(table.p_case, float),
            np.log(np.maximum(np.asarray(table.viscosity, float), 1e-300))]
    if getattr(table, "variable_displacement", False):
        cols.append(np.asarray(table.displacement, float))
    return np.column_stack(cols)


#: points turning the other way lie this far apart (in units of an axis's spread): friction changes sign
#: with the direction of rotation, so the model's error on one side of ω = 0 says nothing of the other's
DIRECTION_SEPARATION = 1e3


class AxisScaling:
    """Centre and spread of some points' axes (:func:`operating_axes`): ``scaling(axes)`` puts any points on
    the scale of those, each axis to unit spread, a missing value at the axis's median, an axis that does
    not vary there left out; and one more coordinate, the direction of rotation (sign of the speed, axis
    0) times :data:`DIRECTION_SEPARATION`, so that no neighbour and no correlation crosses ω = 0."""

    def __init__(self, axes: np.ndarray):
        finite = np.isfinite(axes)
        med = np.array([np.median(axes[finite[:, j], j]) if finite[:, j].any() else 0.0
                        for j in range(axes.shape[1])])
        axes = np.where(finite, axes, med)
        self.fill, self.mean, self.std = med, axes.mean(axis=0), axes.std(axis=0)
        self.keep = self.std > 1e-12 * np.maximum(np.abs(axes).max(axis=0, initial=0.0), 1e-300)

    def document(self) -> dict:
        """The scaling as JSON (result.json, for predictions at new points)."""
        return {"fill": self.fill.tolist(), "mean": self.mean.tolist(), "std": self.std.tolist(),
                "keep": [bool(k) for k in self.keep]}

    @classmethod
    def from_document(cls, doc: dict) -> "AxisScaling":
        new = cls.__new__(cls)
        new.fill, new.mean, new.std = (np.asarray(doc[k], float) for k in ("fill", "mean", "std"))
        new.keep = np.asarray(doc["keep"], bool)
        return new

    def __call__(self, axes: np.ndarray) -> np.ndarray:
        axes = np.asarray(axes, float)
        d = self.fill.size  # points with an axis the scaled ones lack (a displacement), or without one they had
        if axes.shape[1] != d:
            axes = (axes[:, :d] if axes.shape[1] > d else
                    np.column_stack([axes, np.full((axes.shape[0], d - axes.shape[1]), np.nan)]))
        axes = np.where(np.isfinite(axes), axes, self.fill)
        scaled = ((axes - self.mean) / np.where(self.keep, self.std, 1.0))[:, self.keep]
        return np.column_stack([scaled, DIRECTION_SEPARATION * np.sign(axes[:, 0])])


def operating_coordinates(table) -> np.ndarray:
    """The points in the operating space (:func:`operating_axes`), each axis scaled to unit spread;
    axes that do not vary are left out; the direction of rotation apart (:class:`AxisScaling`)."""
    axes = operating_axes(table)
    return AxisScaling(axes)(axes)


def _pairs(idx: np.ndarray, k: int) -> np.ndarray:
    """The pairs (i < j) of the ``k``-nearest-neighbour graph, from the neighbour indices ``idx`` of each
    point (column 0: the point itself or a replicate at distance 0)."""
    i = np.repeat(np.arange(len(idx)), k)
    pairs = np.unique(np.sort(np.column_stack([i, idx[:, 1:k + 1].ravel()]), axis=1), axis=0)
    return pairs[pairs[:, 0] != pairs[:, 1]]


def structured_error(table, residuals: dict, seed: int = 0, sigma: dict | None = None) -> dict:
    """channel → {"sigma": the model error's RMS [SI], "share": its share of the residuals' mean
    square, "pairs": neighbour pairs used, "p_value": of the permutation test}; sigma 0 where the
    neighbours show none.

    Found where the mean product of the residuals of neighbouring points (the
    :data:`MODEL_ERROR_NEIGHBOURS`-nearest graph) exceeds that of shuffled residuals at the
    :data:`MODEL_ERROR_ALPHA` level; its size is the nearest pairs' mean product (the graph's where
    that is not positive), at most the residuals' mean square.  ``sigma`` (channel → each point's
    noise σ, where it differs from point to point: table_noise.py) makes the test's products those of
    the standardized residuals r/σ (a quiet region's structure is not drowned by a noisy one's), and
    where the plain products give no positive size, the size is their mean weighted by
    1/(σ_i σ_j)²."""
    from scipy.spatial import cKDTree

    X = operating_coordinates(table)
    rng = np.random.default_rng(seed)
    point_sigma = dict(sigma or {})
    out = {}
    for c, r in residuals.items():
        r = np.asarray(r, float)
        ok = np.flatnonzero(np.isfinite(r))
        if ok.size < MODEL_ERROR_MIN_POINTS or X.shape[1] <= 1:  # the direction alone: no axis varies
            continue
        if ok.size > MODEL_ERROR_MAX_POINTS:
            ok = np.sort(rng.choice(ok, MODEL_ERROR_MAX_POINTS, replace=False))
        x, y = X[ok], r[ok]
        s = None if point_sigma.get(c) is None else np.asarray(point_sigma[c], float)[ok]
        u = y if s is None else y / s
        k = min(MODEL_ERROR_NEIGHBOURS, len(x) - 1)
        idx = np.asarray(cKDTree(x).query(x, k=k + 1)[1]).reshape(len(x), k + 1)
        graph, nearest = _pairs(idx, k), _pairs(idx, 1)
        if len(nearest) < MODEL_ERROR_MIN_POINTS // 2:
            continue
        stat = float(np.mean(u[graph[:, 0]] * u[graph[:, 1]]))
        null = np.empty(MODEL_ERROR_PERMUTATIONS)
        for b in range(MODEL_ERROR_PERMUTATIONS):
            z = rng.permutation(u)
            null[b] = np.mean(z[graph[:, 0]] * z[graph[:, 1]])
        p = float((1 + np.sum(null >= stat)) / (1 + MODEL_ERROR_PERMUTATIONS))
        ms = float(np.mean(y**2))
        size = float(np.mean(y[nearest[:, 0]] * y[nearest[:, 1]]))
        size = size if size > 0 else float(np.mean(y[graph[:, 0]] * y[graph[:, 1]]))
        if not size > 0 and s is not None:
            w = 1.0 / (s[graph[:, 0]] * s[graph[:, 1]]) ** 2
            size = float(np.sum(w * y[graph[:, 0]] * y[graph[:, 1]]) / np.sum(w))
        sigma = float(np.sqrt(min(size, ms))) if p < MODEL_ERROR_ALPHA and size > 0 else 0.0
        out[c] = {"sigma": sigma, "share": (sigma**2 / ms) if ms > 0 else 0.0, "pairs": int(len(graph)),
                  "p_value": p}
    return out


#: a model error of this share of a channel's residual mean square or more is told in the fit's warnings
MODEL_ERROR_WARN_SHARE = 0.2


def model_error_warnings(errors: dict) -> list:
    """The fit's words for each channel the model misses by structure (:func:`structured_error`)."""
    from motorid.units import CHANNEL_WORDS, LPM_PER_M3S

    out = []
    for c, e in errors.items():
        if e["sigma"] > 0 and e["share"] >= MODEL_ERROR_WARN_SHARE and c in CHANNEL_WORDS:
            words = CHANNEL_WORDS[c]
            unit, f = ("N·m", 1.0) if c == "torque" else ("L/min", LPM_PER_M3S)
            out.append(f"the model misses the table's {words} by structure, not noise: neighbouring points share "
                       f"{e['sigma'] * f:.3g} {unit} RMS of their residuals ({100 * e['share']:.0f} % of the scatter "
                       "about the model); the fitted values carry it, predict's confidence bands include it within the "
                       "fitted range (where predict extrapolates, at its size there: it may grow outside), and "
                       "`motorid diagnose` looks for what the model lacks")
    return out
