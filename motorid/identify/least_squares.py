"""Least-squares identification with optimistix (Levenberg-Marquardt).

All channels are fitted jointly — running torque, breakaway torque, port A and
B flows, case flow — each residual divided by a noise level estimated from the
data (per channel and run).  The Jacobian comes from JAX.  Isolated spikes are
rejected (|r| > ``outlier_sigma`` σ) and counted; the noise levels and the
outlier set are re-estimated until they settle.

Parameters the logs cannot determine are found twice over: by rules that say
which data each parameter needs (:func:`coverage_reasons`) and by the null
space of the weighted Jacobian.  They are held fixed and reported as not
identifiable, never given a number.
"""


from __future__ import annotations

from typing import Sequence

import numpy as np

from motorid import model
from motorid.identify.covariance import breakaway_sandwich, covariance_from_normal, viscosity_covariance
from motorid.identify.identifiability import at_bound_warning, coverage_reasons, tfc_carries_kf_warning
from motorid.identify.noise import correlation_threshold, correlation_times
from motorid.identify.noise import (breakaway_noise, floor_noise, initial_noise, residual_noise, shaft_locked,
                                    spikiness)
from motorid.identify.problem import Problem
from motorid.identify.run_scatter import widen_by_run_scatter
from motorid.identify.solver import backend_for, gauss_newton_start, solve
from motorid.identify.types import BREAKAWAY_ONLY, RUNNING_CHANNELS, FitOptions, FitResult
from motorid.robust import robust_std
from motorid.units import CHANNEL_WORDS


#: χ²/dof of a channel above which a fit warns that the model misses the logs (a clean fit: 1 ± a few %)
CHI2_WARN = 4.0


def start_values(spec, mechanisms, opt: FitOptions, initial: dict | None):
    """Every parameter's name and starting value: the spec's typical sizes, the mechanisms'
    initial values, then ``initial`` → (names, start)."""
    harmonics = spec.leak_harmonics if opt.harmonics is None else opt.harmonics
    names = model.parameter_names(harmonics)
    for mech in mechanisms:
        names += list(mech.parameters)
    start = model.default_parameters(spec)
    start = {k: start.get(k, 0.0) for k in model.parameter_names(harmonics)}
    for mech in mechanisms:
        start.update(mech.initial())
    if initial:
        start.update({k: float(v) for k, v in initial.items() if k in names and v is not None})
    return names, start


class _Noise:
    """The noise levels and inliers of a fit, as the rounds re-estimate them.

    runs : channel → σ per run (running channels) [SI]; breakaway : σ of the events
    (a number, or one per event once the variance model is fitted) [N·m]; gamma : the
    events' variance-model shape (:func:`~motorid.identify.noise.breakaway_noise`);
    inliers : channel → bool per sample.
    """

    def __init__(self, problem: Problem, data, opt: FitOptions):
        obs, run_of = problem.observed(), problem.run_of
        self.n_runs = int(run_of.max()) + 1 if run_of.size else 0
        # model-free start of the noise levels: first differences within each run
        self.runs = {c: floor_noise(initial_noise(obs[c], run_of, self.n_runs), obs[c])
                     for c in RUNNING_CHANNELS if c in obs}
        self.breakaway, self.gamma, self.x2 = None, 0.0, None
        if "breakaway" in obs:
            self.breakaway = max(robust_std(np.diff(obs["breakaway"])) / np.sqrt(2)
                                 if obs["breakaway"].size > 2 else 1.0, 1e-6)
            ev = data.events
            self.x2 = np.asarray(ev.p_a, dtype=float) ** 2 + np.asarray(ev.p_b, dtype=float) ** 2
        self.inliers = {c: np.isfinite(v) for c, v in obs.items()}
        self.theta = np.asarray(data.running.theta, dtype=float) if problem.has_running else np.zeros(0)
        self.pistons = int(getattr(problem.spec, "pistons", 1) or 1)
        if opt.fixed_noise is not None:
            self.runs = {c: np.asarray(opt.fixed_noise[c], dtype=float) for c in self.runs}
            self.breakaway = opt.fixed_noise.get("breakaway", self.breakaway)
            if self.breakaway is not None and "breakaway" in obs:
                self.breakaway = np.broadcast_to(np.asarray(self.breakaway, dtype=float),
                                                 obs["breakaway"].shape).copy()
        if opt.fixed_inliers is not None:
            self.inliers = {c: np.asarray(opt.fixed_inliers[c], dtype=bool) & np.isfinite(obs[c]) for c in obs}

    def update(self, obs: dict, res: dict, run_of, free: list, opt: FitOptions, first: bool) -> bool:
        """Re-estimate the noise from the residuals of a round, then reject outliers against it
        → whether the inliers stayed as they were."""
        new_inliers = {}
        for c in obs:
            r = np.where(self.inliers[c], res[c], np.nan)
            if opt.fixed_noise is not None:
                new_inliers[c] = np.isfinite(obs[c]) & (np.abs(spikiness(res[c], run_of, c)) <= opt.outlier_sigma * (
                    self.breakaway if c == "breakaway" else self.runs[c][run_of]))
            elif c == "breakaway":
                self._update_breakaway(obs[c], r, free, first)
                new_inliers[c] = np.isfinite(obs[c]) & (np.abs(res[c]) <= opt.outlier_sigma * self.breakaway)
            else:
                self.runs[c] = floor_noise(residual_noise(r, run_of, self.n_runs, robust=first), obs[c])
                new_inliers[c] = np.isfinite(obs[c]) & (
                    np.abs(spikiness(res[c], run_of, c)) <= opt.outlier_sigma * self.runs[c][run_of])
            if c != "breakaway":  # rejections crowded at one shaft angle are structure, not spikes
                new_inliers[c] |= shaft_locked(np.isfinite(obs[c]) & ~new_inliers[c], self.theta, self.pistons)
        stable = all(np.array_equal(new_inliers[c], self.inliers[c]) for c in obs)
        self.inliers = new_inliers
        return stable

    def _update_breakaway(self, observed, r, free: list, first: bool) -> None:
        """One level for all events; after the first round the RMS of the inliers with the
        breakaway-only parameters (K_FS, K_s) taken out of the degrees of freedom — with a
        few dozen events the MAD would scatter by a fifth from campaign to campaign."""
        finite = r[np.isfinite(r)]
        k = sum(1 for n in ("KFS", "Ks") if n in free)
        scale = np.nanmax(np.abs(observed)) if np.any(np.isfinite(observed)) else 1.0
        if first and finite.size >= 8:
            est = robust_std(finite)
            self.breakaway = float(max(est, 1e-9 * scale)) if np.isfinite(est) else 1.0
        elif finite.size > k + 1:
            # one level, or a level growing with the port pressures (breakaway_noise)
            use = np.isfinite(r)
            s0, self.gamma, ref = breakaway_noise(r[use], self.x2[use], k)
            self.breakaway = np.maximum(s0 * np.sqrt(1.0 + self.gamma * self.x2 / ref), 1e-9 * scale)
        else:
            self.breakaway = 1.0

    def per_sample(self, obs: dict, run_of) -> dict:
        """channel → σ of each sample (each event) [SI]."""
        sig = {c: self.runs[c][run_of] for c in self.runs}
        if "breakaway" in obs:
            sig["breakaway"] = np.broadcast_to(np.asarray(self.breakaway, dtype=float), obs["breakaway"].shape).copy()
        return sig

    def pooled(self, obs: dict, sig: dict, run_of) -> dict:
        """channel → one σ: the median over the runs with data (over the events) [SI]."""
        noise = {}
        for c in obs:
            has = np.isfinite(obs[c])
            if not has.any():
                noise[c] = None
            elif c == "breakaway":
                noise[c] = float(np.median(sig["breakaway"][has]))  # the events' median σ
            else:
                noise[c] = float(np.median(self.runs[c][np.unique(run_of[has])]))
        return noise


def _uncertainty(problem: Problem, values: dict, free: list, opt: FitOptions, residuals: dict, sig: dict,
                 inliers: dict, chi2: float, dof: int):
    """Covariance of the free parameters in natural units from the weighted Jacobian of the
    cells at the optimum, widened by the breakaway sandwich and by χ²/dof > 1, plus the
    smoothed viscosity's share → (cov, corr, std, cov_visc, visc_run_var, cov_brk, visc_shifts)."""
    JtJ = np.zeros((0, 0))
    if not opt.uncertainty:
        n = len(free)
        return np.zeros((n, n)), np.eye(n), np.zeros(n), None, {}, None, None
    if free:
        JtJ = backend_for(problem, values, free, opt).normal(values)[0]
    cov = covariance_from_normal(JtJ) if free else np.zeros((0, 0))
    cov_visc, visc_run_var, visc_shifts = (viscosity_covariance(problem, values, cov)
                                           if (free and opt.viscosity_error) else (None, {}, None))
    cov_brk = breakaway_sandwich(problem, values, cov, residuals.get("breakaway"), sig.get("breakaway"),
                                 inliers.get("breakaway")) if free and "breakaway" in residuals else None
    if cov_brk is not None:
        cov = cov + cov_brk
    if chi2 / dof > 1.0:
        cov = cov * (chi2 / dof)  # noise underestimated: widen, never narrow
        cov_brk = None if cov_brk is None else cov_brk * (chi2 / dof)
    if cov_visc is not None:
        cov = cov + cov_visc
    std = np.sqrt(np.clip(np.diag(cov), 0, None)) if free else np.zeros(0)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std) if free else cov
    return cov, corr, std, cov_visc, visc_run_var, cov_brk, visc_shifts


def _correlated_noise(problem: Problem, noise, residuals, sig, inliers, run_of, warnings) -> dict:
    """Widen the cells' weights by the residuals' correlation time where the noise is not white.

    Each channel with τ above :func:`~motorid.identify.noise.correlation_threshold` (per-sample residuals
    only: a campaign reduced to cells as it was read keeps none) has its run noise levels times √τ
    in the problem's cells, so the covariance and the sampler count n/τ independent readings per
    run; a warning names the channel.  χ², the noise levels and the fixed noise diagnose gives its
    candidates stay per sample.  → channel → τ."""
    if problem.row_counts is not None or not problem.has_running:
        return {}
    taus = {c: t for c, (t, n) in correlation_times(residuals, sig, inliers, run_of).items()
            if t > correlation_threshold(n)}
    if not taus:
        return {}
    # the problem's weights only (covariance, sampler); the noise levels, χ² and what diagnose compares
    # with them stay those of single samples
    problem.set_cells(noise.inliers, {c: (v * np.sqrt(taus[c]) if c in taus else v) for c, v in noise.runs.items()},
                      noise.breakaway)
    warnings.append("the residuals are correlated in time (" + ", ".join(
        f"{CHANNEL_WORDS.get(c, c)}: τ = {t:.3g} samples" for c, t in taus.items()) + "), as band-limited noise or a "
        "sample rate above the sensors' bandwidth gives: each run holds about n/τ independent readings, and "
        "the standard errors are widened by √τ")
    return taus


def _reported(names, free, fixed, values, std, reasons, start, mechanisms, warnings):
    """Value, standard error and identifiability of every parameter (None where not
    identifiable), with a warning for each fitted one at its bound or barely constrained."""
    out_values, out_std, ident = {}, {}, {}
    for k in names:
        if k in free:
            i = free.index(k)
            out_values[k], out_std[k], ident[k] = float(values[k]), float(std[i]), True
        elif k in fixed:
            out_values[k], out_std[k], ident[k] = float(fixed[k]), 0.0, True
            reasons.pop(k, None)
        else:
            out_values[k], out_std[k], ident[k] = None, None, False
    for k in free:
        info = model.parameter_info(k, mechanisms)
        if info.positive and out_values[k] < 1e-4 * abs(start.get(k) or info.typical):
            warnings.append(at_bound_warning(k))
        elif info.positive and out_std[k] > abs(out_values[k]):
            warnings.append(f"{k}: standard error exceeds the value; the logs barely constrain it")
    return out_values, out_std, ident


def fit_least_squares(data, spec, mechanisms: Sequence = (), options: FitOptions | None = None,
                      initial: dict | None = None) -> FitResult:
    """Fit the model (plus ``mechanisms``) to extracted bench data.

    data : an :class:`motorid.identify.types.Dataset` (running samples and their
        measured channels, breakaway events and their held torques)
    spec : :class:`motorid.model.MotorSpec`
    mechanisms : extra physics (physics registry) whose parameters are fitted too
    initial : starting values (defaults: typical sizes, then a Gauss-Newton start)
    """
    opt = options or FitOptions()
    names, start = start_values(spec, mechanisms, opt, initial)
    reasons = coverage_reasons(data, spec, names)
    fixed = {k: float(v) for k, v in opt.fixed.items()}
    held = {k: start[k] for k in names if k in reasons}
    held.update(fixed)
    free = [k for k in names if k not in held]
    warnings: list[str] = []

    problem = Problem(data, spec, free, held, mechanisms, opt.bins_per_pitch)
    obs = problem.observed()
    run_of = problem.run_of
    noise = _Noise(problem, data, opt)
    values = {k: float(start[k]) for k in free}

    # rounds: solve, then re-estimate the noise levels and outliers from the residuals
    steps_total, converged = 0, True
    rounds = 0 if (opt.fixed_noise is not None and opt.fixed_inliers is not None) else opt.rounds
    if opt.solve not in ("levenberg-marquardt", "gauss-newton") or (opt.solve == "gauss-newton" and rounds):
        raise ValueError(f"FitOptions(solve={opt.solve!r}): 'levenberg-marquardt', or 'gauss-newton' with "
                         "fixed_noise and fixed_inliers")
    first_round = 0
    if opt.start_residuals is not None and rounds and opt.fixed_noise is None and opt.fixed_inliers is None:
        # the first round's work done by an earlier fit: its robust noise estimate and outlier test
        res0 = {c: np.asarray(opt.start_residuals[c], dtype=float) for c in obs}
        noise.update(obs, res0, run_of, free, opt, first=True)
        first_round = 1
    for round_ in range(first_round, rounds):
        problem.set_cells(noise.inliers, noise.runs, noise.breakaway)
        values, steps, converged, free, reasons = solve(problem, values, free, reasons, opt,
                                                        first=(round_ == first_round))
        steps_total += steps
        pred = problem.predictions(values)
        stable = noise.update(obs, {c: obs[c] - pred[c] for c in obs}, run_of, free, opt, first=round_ == 0)
        if stable and round_ >= 1:
            break
    # final solve with the settled noise and inliers
    problem.set_cells(noise.inliers, noise.runs, noise.breakaway)
    if opt.solve == "gauss-newton":
        values, free = gauss_newton_start(problem, values, free, reasons, opt)
    else:
        values, steps, converged, free, reasons = solve(problem, values, free, reasons, opt, first=rounds == 0)
        steps_total += steps
    if not converged:
        warnings.append("Levenberg-Marquardt stopped at max_steps before converging; raise FitOptions.max_steps")
    effective = tfc_carries_kf_warning(reasons, free, "logs", "runs")
    if effective:
        warnings.append(effective)

    inliers = noise.inliers
    pred = problem.predictions(values)
    residuals = {c: obs[c] - pred[c] for c in obs}
    sig = noise.per_sample(obs, run_of)
    used = {c: int(np.sum(inliers[c])) for c in obs}
    chi2 = float(sum(np.sum((residuals[c][inliers[c]] / sig[c][inliers[c]]) ** 2) for c in obs))
    dof = max(sum(used.values()) - len(free), 1)
    per_channel = {c: float(np.sum((residuals[c][inliers[c]] / sig[c][inliers[c]]) ** 2)) / used[c]
                   for c in obs if used[c] > 10}
    missed = {c: r for c, r in per_channel.items() if r > CHI2_WARN}
    if missed:
        warnings.append("χ²/dof = " + ", ".join(f"{r:.3g} in the {CHANNEL_WORDS.get(c, c)}"
                                                 for c, r in missed.items())
                        + ": the model misses these logs far beyond their noise, and the values above carry "
                        "what it misses (physics the model lacks, a sensor's error, a parameter the logs cannot "
                        "determine): `motorid diagnose` locates it")
    # fits with the noise held (diagnose's comparisons of candidates) keep per-sample weights
    taus = {} if opt.fixed_noise is not None else _correlated_noise(problem, noise, residuals, sig, inliers,
                                                                      run_of, warnings)
    cov, corr, std, cov_visc, visc_run_var, cov_brk, visc_shifts = _uncertainty(
        problem, values, free, opt, residuals, sig, inliers, chi2, dof)
    all_params = {**{k: float(v) for k, v in problem.held.items()}, **{k: float(v) for k, v in values.items()}}
    out_values, out_std, ident = _reported(names, free, fixed, values, std, reasons, start, mechanisms, warnings)
    result = FitResult(
        names=names, free=free, values=out_values, std=out_std, covariance=cov, correlation=corr,
        identifiable=ident, reasons=reasons, noise=noise.pooled(obs, sig, run_of), noise_by_run=dict(noise.runs),
        outliers={c: int(np.sum(np.isfinite(obs[c]) & ~inliers[c])) for c in obs},
        used=used, chi2=chi2, dof=dof, steps=steps_total, converged=bool(converged), warnings=warnings,
        residuals=residuals, sigma=sig, inliers=inliers, params_all=all_params, mechanisms=tuple(mechanisms),
        problem=problem, covariance_viscosity=cov_visc, viscosity_run_variance=visc_run_var, viscosity_shifts=visc_shifts,
        breakaway_noise_shape=noise.gamma, covariance_breakaway=cov_brk, noise_correlation=taus,
    )
    if opt.uncertainty and free:
        # a parameter whose runs disagree (a law that holds on average, an input with errors of its own such
        # as the acceleration behind an inertia error, a transducer's gain or zero): its standard error
        # widened; K_FS and K_s not where the breakaway sandwich already widened them for the events'
        # scatter (the same excess, counted once)
        checked = [k for i, k in enumerate(free)
                   if not (k in BREAKAWAY_ONLY and cov_brk is not None and cov_brk[i, i] > 0)]
        result.warnings.extend(widen_by_run_scatter(result, checked, data))
    return result
