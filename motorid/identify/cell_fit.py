"""The least-squares fit of a campaign reduced to cells as it was read (:mod:`motorid.identify.cells`).

The same fit as :func:`motorid.identify.least_squares.fit_least_squares`, on rows
that are cells: each cell mean weighs √count/σ and the outliers were left out
before the reduction.  Two solves:

1. with the model-free noise levels the reduction estimated per run and channel
   (within-cell scatter and first differences: upper bounds, since they also hold
   the operating point's change within a cell or between samples);
2. (twice, ``FitOptions.rounds``) with the noise levels of the last solve's residuals,
   per run and channel as the
   per-sample fit takes them, σ² = σ₀² + b²: a cell mean's residual has
   E[count·r̄²] = σ₀² + count·b², with σ₀ the sensor noise and b the model's misfit
   in the cell, so σ₀² is the smaller of the model-free level and Σ count·r̄²/cells,
   and b² = (Σ count·r̄² − cells·σ₀²)/Σ count (at one sample a cell this is the
   per-sample residual variance; with many it does not count the misfit once per
   sample of the cell), and the breakaway events' variance model
   (:func:`motorid.identify.noise.breakaway_noise`) from their residuals.

χ², the degrees of freedom and the residual counts are then those of the samples:
Σ over cells of count·(cell-mean residual)²/σ², plus the within-cell part at its
expected value (count − 1 per cell), so that the covariance is widened by
χ²/dof > 1 as for a per-sample fit.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import numpy as np

from motorid.identify.cells import give_back_free_memory
from motorid.identify.least_squares import fit_least_squares
from motorid.identify.noise import breakaway_noise, floor_noise
from motorid.identify.types import BREAKAWAY_ONLY, RUNNING_CHANNELS, FitOptions, FitResult
from motorid.robust import robust_std


def _breakaway_levels(res: np.ndarray, x2: np.ndarray, k: int, outlier_sigma: float, scale: float):
    """σ of each event from the residuals of a first solve → (σ [N·m], inliers, γ), with the
    events beyond ``outlier_sigma`` σ left out (two passes)."""
    finite = np.isfinite(res)
    sig = np.full(res.shape, robust_std(res[finite]) if finite.sum() >= 3 else 1.0)
    gamma = 0.0
    ok = finite
    for _ in range(2):
        ok = finite & (np.abs(np.where(finite, res, 0.0)) <= outlier_sigma * sig)
        if ok.sum() <= k + 1:
            break
        s0, gamma, ref = breakaway_noise(res[ok], x2[ok], k)
        sig = np.maximum(s0 * np.sqrt(1.0 + gamma * x2 / ref), 1e-9 * scale)
    return sig, ok, gamma


def _sample_statistics(ls: FitResult, data) -> None:
    """χ², dof, used and outliers of the samples behind the cells; the covariance widened by
    χ²/dof where that exceeds 1 (its viscosity share is not scaled), in place."""
    stats = data.cells
    chi2, used = 0.0, {}
    for c in ls.residuals:
        inl = ls.inliers[c]
        r, s = ls.residuals[c][inl], ls.sigma[c][inl]
        if c == "breakaway":
            used[c] = int(inl.sum())
            chi2 += float(np.sum((r / s) ** 2))
            continue
        n = stats.counts[c][inl]
        used[c] = int(round(n.sum()))
        chi2 += float(np.sum(n * r * r / (s * s)) + np.sum(np.maximum(n - 1.0, 0.0)))
        ls.outliers[c] = int(stats.outliers.get(c, 0))
    dof = max(sum(used.values()) - len(ls.free), 1)
    applied = max(ls.chi2 / max(ls.dof, 1), 1.0)  # what the fit of the cell rows widened by
    ls.chi2, ls.dof, ls.used = chi2, dof, used
    factor = max(chi2 / dof, 1.0) / applied
    if not ls.free or factor == 1.0:
        return
    visc = ls.covariance_viscosity if ls.covariance_viscosity is not None else 0.0
    ls.covariance = (ls.covariance - visc) * factor + visc
    if ls.covariance_breakaway is not None:
        ls.covariance_breakaway = ls.covariance_breakaway * factor
    std = np.sqrt(np.clip(np.diag(ls.covariance), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        ls.correlation = ls.covariance / np.outer(std, std)
    for i, k in enumerate(ls.free):
        ls.std[k] = float(std[i])


def _residual_noise(ls: FitResult, data, model_free: dict) -> dict:
    """channel → σ per run from the cell-mean residuals of a solve (the model-free level where a
    run has fewer than five cells of the channel) [SI]."""
    run_of = np.asarray(data.run_of_sample, dtype=int)
    out = {}
    for c, sig0 in model_free.items():
        inl = ls.inliers[c]
        r = np.where(inl, ls.residuals[c], 0.0)
        n = np.where(inl, data.cells.counts[c], 0.0)
        ss = np.bincount(run_of, weights=n * r * r, minlength=sig0.size)
        cells = np.bincount(run_of, weights=inl.astype(float), minlength=sig0.size)
        total = np.bincount(run_of, weights=n, minlength=sig0.size)
        with np.errstate(invalid="ignore", divide="ignore"):
            between = ss / np.maximum(cells, 1.0)  # E = σ² + n̄·b²: b the model's misfit in a cell
            s2 = np.fmin(sig0 ** 2, between)  # the sensor noise: the model-free level bounds it
            misfit = np.maximum(ss - cells * s2, 0.0) / np.maximum(total, 1.0)  # b², once per sample
            # runs with too few cells keep their model-free level; runs with none (startability) stay
            # NaN, so that they do not pull the median that floor_noise fills and floors with
            raw = np.asarray(data.cells.noise[c], dtype=float)
            sig = np.where(cells >= 5, np.sqrt(s2 + misfit), np.where(cells > 0, raw, np.nan))
        out[c] = floor_noise(sig, np.asarray(data.measured[c], dtype=float))
    return out


def fit_cells(data, spec, mechanisms: Sequence = (), options: FitOptions | None = None,
              initial: dict | None = None) -> FitResult:
    """Fit a :class:`~motorid.identify.types.Dataset` whose running rows are cells
    (``data.cells`` set, :func:`motorid.identify.extract.extract_cells`); see the module doc."""
    opt = options or FitOptions()
    stats = data.cells
    noise = {c: floor_noise(np.asarray(stats.noise[c], dtype=float), np.asarray(data.measured[c], dtype=float))
             for c in RUNNING_CHANNELS}
    inliers = {c: np.isfinite(np.asarray(data.measured[c], dtype=float)) & (stats.counts[c] > 0)
               for c in RUNNING_CHANNELS}
    held = np.asarray(data.held_torque, dtype=float)
    if held.size:
        inliers["breakaway"] = np.isfinite(held)
    ls = fit_least_squares(data, spec, mechanisms,  # the covariance's viscosity share: second solve only
                           replace(opt, fixed_noise=dict(noise), fixed_inliers=dict(inliers), viscosity_error=False),
                           initial)
    gamma = 0.0
    for round_ in range(max(opt.rounds, 1)):  # as the per-sample fit: the noise re-estimated, solved again
        fixed = _residual_noise(ls, data, noise)
        if held.size and "breakaway" in ls.residuals and np.isfinite(held).sum() >= 3:
            ev = data.events
            x2 = np.asarray(ev.p_a, dtype=float) ** 2 + np.asarray(ev.p_b, dtype=float) ** 2
            k = sum(1 for n in BREAKAWAY_ONLY if n in ls.free)
            scale = float(np.nanmax(np.abs(held)))
            fixed["breakaway"], inliers["breakaway"], gamma = _breakaway_levels(
                ls.residuals["breakaway"], x2, k, opt.outlier_sigma, scale)
        start = {k: v for k, v in ls.values.items() if v is not None}
        last = round_ == max(opt.rounds, 1) - 1
        ls = None  # the last solve's problem and expansion go before the next is built
        give_back_free_memory()
        ls = fit_least_squares(data, spec, mechanisms, replace(opt, fixed_noise=fixed, fixed_inliers=dict(inliers),
                                                               viscosity_error=opt.viscosity_error and last), start)
    ls.breakaway_noise_shape = gamma
    _sample_statistics(ls, data)
    return ls
