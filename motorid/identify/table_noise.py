"""The noise of an operating-point table's channels, estimated from the residuals about the model.

A table has no first differences to estimate its noise from beforehand, so each channel's σ comes
from the scatter of its points about the fit, in one of three shapes:

- **weighted by the table** (``*_std_*`` / ``n_samples`` columns, :class:`motorid.io.tables.PointTable`):
  σ_i² = σ_floor² + (s · r_i)², r_i the point's relative σ from its columns; the floor is what
  averaging does not lower (calibration, drift, an unrecorded temperature, what the model leaves out);
- **growing with the reading** (no such columns): σ_i² = σ_floor² + (s · |ŷ_i| / ȳ)², ŷ_i the model's
  value at the point and ȳ the RMS of ŷ over the points, as the accuracy of a torque transducer or a
  flow meter is stated (a share of the reading above a floor, e.g. ISO 4409's classes of
  measurement accuracy).  Taken only where the likelihood says so against one σ for every point
  (a likelihood-ratio test at :data:`READING_NOISE_LR`); a map spanning 2 to 1000 rpm then gives its
  slow points their own small σ instead of one that their fast neighbours set;
- **one level** otherwise: σ_i = s.

Both levels are estimated by maximum likelihood (:func:`noise_floor_and_scale`), the squared
residuals inflated by n/dof for the parameters fitted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: 2Δ log L a noise growing with the reading must gain over one σ to be taken (χ²₁ at 0.1 %: one
#: parameter more)
READING_NOISE_LR = 10.83
#: fewer points with a channel than this: one σ (two levels from fewer points are too rough)
READING_NOISE_MIN_POINTS = 20
#: the floor of a noise growing with the reading is at least this share of its level at the RMS reading
#: (a point reading 0 would otherwise weigh without bound)
READING_NOISE_LEAST_FLOOR = 0.01
#: a table's own weights give two levels from this many points
WEIGHTED_MIN_POINTS = 10


@dataclass
class ChannelNoise:
    """σ_i = √(floor² + (scale · relative_i)²) [SI] at each point, relative_i the table's own relative σ
    of the point, or where ``reading_share`` [1] is set, σ(y)² = floor² + (reading_share · y)² at the
    model's value y (any point's, a new one's too)."""

    floor: float
    scale: float
    reading_share: float | None = None

    def sigma(self, relative: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """σ [SI] of points with the table's ``relative`` σ and the model's ``predicted`` values."""
        if self.reading_share is not None:
            return np.sqrt(self.floor ** 2 + (self.reading_share * np.asarray(predicted, float)) ** 2)
        return np.sqrt(self.floor ** 2 + (self.scale * np.asarray(relative, float)) ** 2)


def noise_floor_and_scale(residuals, relative, dof_factor: float = 1.0, start: float | None = None):
    """(σ_floor, s) [unit of the residuals] maximizing the Gaussian likelihood of ``residuals``
    with σ_i² = σ_floor² + (s · relative_i)²; ``dof_factor`` (n/dof ≥ 1) inflates the squared
    residuals for the parameters fitted.  A floor below 10⁻⁶ of s is returned as 0."""
    r2 = np.asarray(residuals, float) ** 2 * dof_factor
    q2 = np.asarray(relative, float) ** 2
    s0 = float(np.sqrt(np.mean(r2 / np.maximum(q2, 1e-300)))) if start is None else float(start)
    s0 = max(s0, 1e-300)
    r2s = r2 / (s0 * s0)

    def nll(th):  # th = log(σ_floor / s0), log(s / s0)
        return _neg2_log_likelihood(r2s, np.exp(2 * th[0]) + np.exp(2 * th[1]) * q2)

    def derivatives(th):  # its gradient and Hessian in the two logs (a Newton step needs a pass over the points)
        a, b = np.exp(2 * th[0]), np.exp(2 * th[1]) * q2
        v = a + b
        g = 1.0 / v - r2s / v ** 2  # ∂/∂v
        h = -1.0 / v ** 2 + 2.0 * r2s / v ** 3  # ∂²/∂v²
        grad = np.array([np.sum(g * 2 * a), np.sum(g * 2 * b)])
        hess = np.array([[np.sum(h * 4 * a * a + g * 4 * a), np.sum(h * 4 * a * b)],
                         [np.sum(h * 4 * a * b), np.sum(h * 4 * b * b + g * 4 * b)]])
        return grad, hess

    # a damped Newton descent from the best of three starts (floor-led, scale-led, both): the likelihood is
    # smooth in the two logs, and its exact derivatives take it there in a few passes over the points
    th = np.asarray(min(([-3.0, 0.0], [0.0, -3.0], [-1.0, -1.0]), key=nll), dtype=float)
    f, damping = nll(th), 1e-3
    for _ in range(200):
        grad, hess = derivatives(th)
        while True:
            step = np.linalg.solve(hess + damping * (np.abs(np.diag(hess)).max() + 1.0) * np.eye(2), -grad) \
                if np.all(np.isfinite(hess)) else -grad
            trial = th + np.clip(step, -2.0, 2.0)  # at most a factor e² in σ_floor or s a step
            f_trial = nll(trial)
            if np.isfinite(f_trial) and f_trial <= f:
                break
            damping *= 10.0
            if damping > 1e12:
                break
        if not (np.isfinite(f_trial) and f_trial <= f):
            break
        # settled: the likelihood no longer falls (a floor or scale sliding to 0 changes it by nothing)
        done = f - f_trial <= 1e-10 * max(abs(f), 1.0)
        th, f, damping = trial, f_trial, max(damping / 10.0, 1e-9)
        if done:
            break
    floor, scale = s0 * math.exp(th[0]), s0 * math.exp(th[1])
    return (0.0 if floor < 1e-6 * scale else floor), scale


def _neg2_log_likelihood(r2: np.ndarray, var: np.ndarray) -> float:
    return float(np.sum(np.log(var) + r2 / var))


def initial_sigma(y: np.ndarray) -> float:
    """A first σ [unit of y] for a channel before any fit: 10⁻³ of its span."""
    y = y[np.isfinite(y)]
    if y.size == 0:
        return 1.0
    return float(max(1e-3 * (np.max(y) - np.min(y)), 1e-6 * np.max(np.abs(y)), 1e-300))


def channel_noise(residuals: np.ndarray, predicted: np.ndarray, table_relative: np.ndarray | None,
                  dof_factor: float, start: float, tiny: float) -> ChannelNoise:
    """The noise of one channel from its ``residuals`` (measured − model) at the points fitted.

    predicted : the model's value there [SI] (the reading a noise growing with it follows)
    table_relative : each point's relative σ from the table's own columns, None where it has none
    dof_factor : n/dof of the channel; start : the σ of the round before; tiny : the least σ."""
    r = np.asarray(residuals, float)
    k = r.size
    if table_relative is not None and k >= WEIGHTED_MIN_POINTS:
        rel = np.asarray(table_relative, float)
        floor, scale = noise_floor_and_scale(r, rel, dof_factor, start)
        return ChannelNoise(floor, float(max(scale, tiny)))
    if table_relative is not None:
        rel = np.asarray(table_relative, float)
        return ChannelNoise(0.0, float(max(np.sqrt(np.sum((r / rel) ** 2) * dof_factor / k), tiny)))
    one = float(max(np.sqrt(np.mean(r ** 2) * dof_factor), tiny))
    flat = ChannelNoise(0.0, one)
    y = np.abs(np.asarray(predicted, float))
    norm = float(np.sqrt(np.mean(y ** 2)))
    if k < READING_NOISE_MIN_POINTS or not norm > 0 or not np.all(np.isfinite(y)):
        return flat
    rel = y / norm
    floor, scale = noise_floor_and_scale(r, rel, dof_factor, one)
    scale = float(max(scale, tiny))
    floor = float(max(floor, READING_NOISE_LEAST_FLOOR * scale, tiny))  # a reading of 0 is not exact
    r2 = r ** 2 * dof_factor
    gain = _neg2_log_likelihood(r2, np.full(k, one ** 2)) - \
        _neg2_log_likelihood(r2, floor ** 2 + (scale * rel) ** 2)
    if not gain > READING_NOISE_LR:
        return flat
    return ChannelNoise(floor, scale, reading_share=scale / norm)
