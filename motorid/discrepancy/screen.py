"""Candidates scored on the reduced data: cell means of a coarse shaft-angle grid.

A candidate's evidence is how much it lowers χ², with the noise levels and the
outlier set of the base fit held so that the numbers compare.  χ² over samples
is χ² over cell means plus the scatter of the samples inside their cells; that
scatter is the same for every model that is nearly constant over a cell (one run,
one slice of the shaft angle), so Δχ² is read off the cells alone.  The cells
here are coarser than the fit's (``bins_per_pitch`` per piston pitch, default 8:
72 per revolution on a nine-piston motor, enough for every shaft order a
mechanism of the catalog shows), which makes a candidate's fit cost a few
thousand cells however long the logs, and none of the per-sample work (no
per-sample predictions, noise rounds or outlier tests: those are the base fit's).

The same cells give the held-out check: runs left out of a fit by zeroing their
cells' weights, their χ² then taken at the fitted values.
"""

from __future__ import annotations

import copy
import functools
import itertools
from dataclasses import dataclass, replace

import numpy as np

from motorid import model
from motorid.identify.identifiability import coverage_reasons
from motorid.identify.least_squares import start_values
from motorid.identify.problem import Problem, as_arrays, normal_equations, residual_jit
from motorid.identify.solver import backend_for, solve
from motorid.identify.types import CHANNELS, RUNNING_CHANNELS, FitOptions

#: shaft-angle cells per piston pitch of the screening grid
SCREEN_BINS_PER_PITCH = 8
#: rtol and atol of Levenberg-Marquardt from each screening start (the best start is then
#: solved to the fit's own tolerance)
SCREEN_START_TOLERANCE = 1e-4

_versions = itertools.count(1 << 20)  # cells versions of the reweighted problems (never reused)


@dataclass
class CellFit:
    """A model fitted on the screening cells.

    values : every parameter (fitted and held) [SI]; free : the fitted ones;
    chi2 : over the cells it was fitted on; problem : the cells and the model.
    """

    mechanisms: tuple
    values: dict
    free: list
    chi2: float
    problem: object

    @property
    def params_all(self) -> dict:
        return self.values

    @functools.cached_property
    def covariance(self) -> np.ndarray:
        """(JᵀJ)⁻¹ over ``free`` on its own cells (:meth:`Screen.covariance`), made once."""
        return Screen.covariance(Screen.information(self))


def gauss_newton_chi2(JtJ, Jtr, rr: float, x0, positive, hold=None, rcond: float = 1e-10) -> float:
    """min over δ of ‖r + J δ‖² = rr + 2 δ·Jᵀr + δᵀ JᵀJ δ, with x0 + δ ≥ 0 where ``positive``
    (active set: a parameter that would cross zero is held at zero and the rest solved
    again) and δ = 0 where ``hold``; directions JᵀJ cannot see (relative eigenvalue <
    ``rcond``) are left alone."""
    JtJ, Jtr, x0 = np.asarray(JtJ, float), np.asarray(Jtr, float), np.asarray(x0, float)
    if not (np.all(np.isfinite(JtJ)) and np.all(np.isfinite(Jtr)) and np.isfinite(rr)):
        return np.inf
    n = Jtr.size
    norms = np.sqrt(np.maximum(np.diag(JtJ), 0.0))
    norms[norms == 0] = 1.0
    A, g = JtJ / np.outer(norms, norms), Jtr / norms  # unit columns: the cut-off is scale-free
    lo = np.where(positive, -x0 * norms, -np.inf)  # δ (in unit columns) may not go below this
    held = np.zeros(n, bool) if hold is None else np.asarray(hold, bool)
    lo = np.where(held, 0.0, lo)
    fixed = held.copy()
    d = np.zeros(n)
    for _ in range(n + 1):
        f = ~fixed
        if not f.any():
            break
        d_fixed = np.where(fixed, lo, 0.0)
        rhs = -(g[f] + A[np.ix_(f, fixed)] @ d_fixed[fixed])
        d = d_fixed.copy()
        d[f] = np.linalg.lstsq(A[np.ix_(f, f)], rhs, rcond=rcond)[0]
        crossed = f & (d < lo)
        if not crossed.any():
            break
        fixed |= crossed
    return float(max(rr + 2.0 * d @ g + d @ A @ d, 0.0))


def thread_pool():
    """Threads that fit on the cells two at a time (candidates, folds, region splits: their compiled
    programs run outside Python's lock; each fit's numbers are the same whatever the order); one
    where the machine has one core, or as many as ``MOTORID_DIAGNOSE_THREADS`` says."""
    import os
    from concurrent.futures import ThreadPoolExecutor

    n = os.environ.get("MOTORID_DIAGNOSE_THREADS")
    workers = int(n) if n and n.isdigit() and int(n) > 0 else min(2, os.cpu_count() or 1)
    return ThreadPoolExecutor(max_workers=workers)


class Screen:
    """The reduced data of a campaign, with the base fit's noise and inliers held."""

    def __init__(self, dataset, spec, base, bins_per_pitch: int = SCREEN_BINS_PER_PITCH):
        self.dataset, self.spec = dataset, spec
        self.options = FitOptions(bins_per_pitch=bins_per_pitch, uncertainty=False, viscosity_error=False)
        self.template = Problem(dataset, spec, [], {}, (), bins_per_pitch)
        noise_runs = {c: np.asarray(base.noise_by_run[c], dtype=float) for c in RUNNING_CHANNELS
                      if c in base.noise_by_run}
        sigma_brk = np.asarray(base.sigma["breakaway"], dtype=float) if "breakaway" in base.sigma else None
        self.template.set_cells(dict(base.inliers), noise_runs, sigma_brk)
        obs, w = self.template.cells
        # inlier samples per cell (events: 1), in the order of the concatenated residual
        self.counts = {}
        for c in obs:
            if c == "breakaway":
                self.counts[c] = np.ones_like(w[c])
            else:
                cnt = np.bincount(self.template.cell_of, weights=np.asarray(base.inliers[c], dtype=float),
                                  minlength=self.template.n_cells)
                self.counts[c] = np.concatenate([cnt, np.zeros(w[c].size - cnt.size)])
        self._run = self.template.entry_runs(dataset)
        self._coverage: dict = {}  # parameter names → what the data cannot see (coverage_reasons)
        self._expansions: dict = {}  # Screen._expansion_key → None: the model is not quadratic

    @property
    def n_cells(self) -> int:
        return self.template.n_cells

    @staticmethod
    def _expansion_key(prob) -> tuple:
        """What the quadratic expansion of a problem's cell predictions depends on: the model, the
        free parameters and the held ones with their values."""
        return (tuple(m.id for m in prob.mechanisms), tuple(prob.free),
                tuple(sorted((k, float(v)) for k, v in prob.held.items())))

    def _remember_expansion(self, prob) -> None:
        """Keep what a solve learnt of ``prob``'s model: that it is not quadratic in its free parameters
        (no expansion), so that the next problem of the same model, free and held parameters does not try
        again (each try evaluates Hessians on sampled cells; many screening fits share one model).  A
        built expansion is not kept: its exactness was checked near its own start, and it holds every
        cell's terms."""
        if prob.expansion_key == tuple(prob.free) and prob.expansion is None:
            self._expansions[self._expansion_key(prob)] = None

    def _problem(self, mechanisms, free, held, weights=None) -> Problem:
        prob = copy.copy(self.template)
        prob.free, prob.held, prob.mechanisms = list(free), dict(held), tuple(mechanisms)
        prob.expansion = prob.expansion_key = prob.compressed = None
        key = self._expansion_key(prob)
        if key in self._expansions:  # known not to be quadratic: the full problem at once
            prob.expansion, prob.expansion_key = None, tuple(prob.free)
        if weights is not None:
            prob.cells = (self.template.cells[0], weights)
            prob.cells_version = next(_versions)
        return prob

    def _parameters(self, mechanisms, initial: dict, hold=()) -> tuple:
        """(start, free, held, reasons) of the base model plus ``mechanisms`` from ``initial``:
        what the data cannot see is held (``coverage_reasons``, asked once per set of base parameters;
        ``reasons`` is a fresh dict, which the solver may add to), and ``hold`` at ``initial``."""
        names, start = start_values(self.spec, mechanisms, self.options, initial)
        # what the data cannot see is asked of the 1992 model's parameters alone (a mechanism's,
        # "id.name", are never among coverage_reasons' answers): once for every candidate
        key = tuple(k for k in names if "." not in k)
        if key not in self._coverage:
            self._coverage[key] = coverage_reasons(self.dataset, self.spec, key)
        reasons = dict(self._coverage[key])
        held = {k: start[k] for k in names if k in reasons or k in hold}
        return start, [k for k in names if k not in held], held, reasons

    def fit(self, mechanisms, initial: dict, tolerance: float | None = None, weights=None, hold=()) -> CellFit:
        """Fit the base model plus ``mechanisms`` on the cells, from ``initial`` (``tolerance``:
        a looser rtol and atol of Levenberg-Marquardt, for screening starts; the compiled
        program is the same; ``hold``: parameters kept at ``initial``)."""
        opt = self.options if tolerance is None else replace(self.options, rtol=tolerance, atol=tolerance)
        start, free, held, reasons = self._parameters(mechanisms, initial, hold)
        prob = self._problem(mechanisms, free, held, weights)
        values = {k: float(start[k]) for k in free}
        values, _, _, free, _ = solve(prob, values, free, reasons, opt, first=True)
        self._remember_expansion(prob)
        chi2 = backend_for(prob, values, free, opt).chi2(values) if free else self._chi2(prob, values)
        if not np.isfinite(chi2):
            chi2 = np.inf
        return CellFit(tuple(mechanisms), {**prob.held, **{k: float(v) for k, v in values.items()}},
                       list(free), float(chi2), prob)

    def predicted_chi2(self, mechanisms, starts: list) -> float:
        """The lowest of :meth:`predicted_chi2_by_start` (see there)."""
        return float(min(self.predicted_chi2_by_start(mechanisms, starts), default=np.inf))

    def predicted_chi2_by_start(self, mechanisms, starts: list) -> list:
        """χ² after fitting the base model plus ``mechanisms``, predicted without fitting: from
        each start one Gauss-Newton update on the cells' sufficient statistics (JᵀJ, Jᵀr, rᵀr:
        one evaluation of the normal equations), positive parameters held at ≥ 0 by an active
        set; the lowest over the starts.  Exact where the candidate is linear in its parameters
        given the base fit (gains, offsets, amplitudes of a fixed shape).  For a nonlinear one
        (a characteristic speed, a time constant) the update is also taken with the candidate's
        own parameters held at each start, which is its χ² there, the rest refitted: a profile
        over the starts.  It ranks, it does not measure: the candidates it ranks highest are
        then fitted (:meth:`fit_best_start`) → one χ² per start (∞ where nothing is free)."""
        out = []
        added = {k for m in mechanisms[-1:] for k in m.parameters}
        for initial in starts:
            start, free, held, _ = self._parameters(mechanisms, initial)
            if not free:
                out.append(np.inf)
                continue
            prob = self._problem(mechanisms, free, held)
            values = as_arrays({k: start[k] for k in free})
            JtJ, Jtr, rr = (np.asarray(x) for x in normal_equations(values, prob.ctx()))
            x0 = np.array([start[k] for k in free], dtype=float)
            positive = np.array([bool(model.parameter_info(k, mechanisms).positive) for k in free])
            own = np.array([k in added for k in free])
            out.append(min(gauss_newton_chi2(JtJ, Jtr, float(rr), x0, positive),
                           gauss_newton_chi2(JtJ, Jtr, float(rr), x0, positive, hold=own)))
        return out

    @staticmethod
    def _chi2(prob, values) -> float:
        r = np.asarray(residual_jit(as_arrays(values), prob.ctx()))
        return float(r @ r)

    def fit_best_start(self, mechanisms, starts: list) -> CellFit:
        """Screen ``starts`` with a loose Levenberg-Marquardt solve each (rtol = atol =
        :data:`SCREEN_START_TOLERANCE`), finish the best; one start: fitted at once."""
        if len(starts) == 1:
            return self.fit(mechanisms, starts[0])
        best = None
        for start in starts:
            fit = self.fit(mechanisms, start, tolerance=SCREEN_START_TOLERANCE)
            if np.isfinite(fit.chi2) and (best is None or fit.chi2 < best.chi2):
                best = fit
        if best is None:
            return fit
        final = self.fit(mechanisms, best.values)
        return final if final.chi2 <= best.chi2 else best

    def _out(self, runs) -> dict:
        """Per channel: which cells (events) belong to ``runs`` (run indices)."""
        return {c: np.isin(self._run[c], runs) for c in self.template.cells[0]}

    def fit_without(self, mechanisms, initial: dict, runs, hold=()) -> CellFit:
        """The base model plus ``mechanisms`` fitted on the cells of every run but ``runs`` (``hold``:
        parameters kept at ``initial``)."""
        obs, w = self.template.cells
        out = self._out(runs)
        return self.fit(mechanisms, initial, weights={c: np.where(out[c], 0.0, w[c]) for c in obs}, hold=hold)

    def _on_runs(self, fit: CellFit, runs) -> Problem:
        """``fit``'s model and values on the cells of ``runs`` alone."""
        obs, w = self.template.cells
        out = self._out(runs)
        return self._problem(fit.mechanisms, fit.free, {k: v for k, v in fit.values.items() if k not in fit.free},
                             weights={c: np.where(out[c], w[c], 0.0) for c in obs})

    def chi2_of(self, fit: CellFit, runs) -> float:
        """χ² of the cells of ``runs`` at ``fit``'s values (a cell's share capped at 25 per sample:
        a held-out spike counts like an outlier)."""
        obs = self.template.cells[0]
        order = [c for c in CHANNELS if c in obs]
        prob = self._on_runs(fit, runs)
        r = np.asarray(residual_jit(as_arrays({k: fit.values[k] for k in fit.free}), prob.ctx()))
        cap = 25.0 * np.concatenate([np.maximum(self.counts[c], 1.0) for c in order])
        return float(np.sum(np.minimum(np.where(np.isfinite(r), r * r, 0.0), cap)))

    def chi2_by_run(self, fit: CellFit) -> np.ndarray:
        """χ² of ``fit`` on every cell, summed per run (events with their run) → [runs]."""
        obs, w = self.template.cells
        order = [c for c in CHANNELS if c in obs]
        prob = self._problem(fit.mechanisms, fit.free, {k: v for k, v in fit.values.items() if k not in fit.free})
        r = np.asarray(residual_jit(as_arrays({k: fit.values[k] for k in fit.free}), prob.ctx()))
        runs = np.concatenate([self._run[c] for c in order])
        ok = (runs >= 0) & np.isfinite(r)
        n_runs = len(self.dataset.runs)
        return np.bincount(runs[ok], r[ok] ** 2, minlength=n_runs)[:n_runs]

    def scatter_of(self, runs) -> float:
        """The χ² the samples of ``runs`` add about their cell means where the noise model holds
        (n − 1 per cell of n samples): what a χ² over the cells lacks against one over samples."""
        return float(sum(np.sum(np.maximum(self.counts[c] - 1.0, 0.0)[m]) for c, m in self._out(runs).items()))

    @staticmethod
    def information(fit: CellFit, prob: Problem | None = None) -> np.ndarray:
        """JᵀJ over ``fit.free`` at its values, on ``fit``'s own cells or those of ``prob`` (the
        noise held at the base fit's: the Fisher information of the free parameters)."""
        prob = fit.problem if prob is None else prob
        return np.asarray(normal_equations(as_arrays({k: fit.values[k] for k in fit.free}), prob.ctx())[0])

    @staticmethod
    def covariance(information: np.ndarray) -> np.ndarray:
        """(JᵀJ)⁻¹, inverted in unit columns (a scale-free cut-off); ∞ on the diagonal of a
        parameter JᵀJ does not see; NaN everywhere where JᵀJ is not finite."""
        F = np.asarray(information, dtype=float)
        if not np.all(np.isfinite(F)):
            return np.full(F.shape, np.nan)
        d = np.sqrt(np.maximum(np.diag(F), 0.0))
        seen = d > 0
        cov = np.zeros(F.shape)
        cov[~seen, ~seen] = np.inf
        if seen.any():
            ds = d[seen]
            cov[np.ix_(seen, seen)] = np.linalg.pinv(F[np.ix_(seen, seen)] / np.outer(ds, ds), rcond=1e-12,
                                                     hermitian=True) / np.outer(ds, ds)
        return cov

    def parameter_std(self, fit: CellFit) -> dict:
        """Standard errors of ``fit``'s free parameters on its own cells → {name: std} (∞: not seen)."""
        if not fit.free:
            return {}
        cov = fit.covariance
        return {k: float(np.sqrt(max(cov[i, i], 0.0))) for i, k in enumerate(fit.free)}

    def expected_excess(self, fit: CellFit, runs) -> float:
        """The χ² by which ``fit`` (on a training part of the cells) should predict the cells of
        ``runs`` worse than a fit that saw them, were its model right: its parameters'
        uncertainty carried to those cells, tr(C_train · F_runs); ∞ where the training part does
        not see a parameter those runs depend on."""
        if not fit.free:
            return 0.0
        cov = fit.covariance
        F = self.information(fit, self._on_runs(fit, runs))
        if not np.all(np.isfinite(F)) or np.any(np.isnan(cov)):
            return np.inf
        if np.any(np.isinf(np.diag(cov)) & (np.diag(F) > 0)):
            return np.inf
        return float(np.sum(np.where(np.isinf(cov), 0.0, cov) * F))

    def held_out_chi2(self, mechanisms, initial: dict, folds: list) -> float:
        """χ² of each fold's runs predicted by a fit on the other runs, summed over the folds
        (:meth:`chi2_of`); the folds fitted two at a time (:func:`thread_pool`)."""
        with thread_pool() as pool:
            return sum(pool.map(lambda fold: self.chi2_of(self.fit_without(mechanisms, initial, fold), fold), folds))
