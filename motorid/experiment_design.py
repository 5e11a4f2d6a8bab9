"""Experiment design: Fisher information, Cramér–Rao bounds, and the extra bench runs to plan.

The noise model of a campaign is Gaussian and independent per sample and
channel: the running channels (torque, port flows, case flow) with a standard
deviation σ per sample, and the held torque of each breakaway event with its
own σ.  The Fisher information of the parameters is then

    I(θ) = Σ_channels Σ_samples  J_i J_iᵀ / σ_i²,      J_i = ∂ prediction_i / ∂θ,

with J from JAX (forward mode through :func:`motorid.model.predict` and
:func:`motorid.model.predict_breakaway`, the same functions the fit uses), and
the Cramér–Rao bound is the diagonal of I⁻¹.  The sums are taken in chunks of
samples, so the memory does not grow with the campaign.

:func:`suggest_runs` uses the same information for experiment design: for each
candidate extra bench run (a constant-speed set point, a startability ramp) it
adds the run's information to the campaign's and ranks the runs by how much the
worst-determined parameter's relative standard error shrinks.  ``motorid plan``
puts that in front of a user.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import jax.numpy as jnp
import numpy as np

from motorid import model
from motorid.errors import InputError
from motorid.identify.problem import Ctx as _Ctx, bucket, normal_equations as _normal_equations, pad, pad_samples
from motorid.identify.types import RUNNING_CHANNELS
from motorid.model import Samples
from motorid.units import PA_PER_BAR, RAD_S_PER_RPM

CHUNK = 1 << 16  # samples per Jacobian block


# ----------------------------------------------------------------------------
# Fisher information and the Cramér–Rao bound


def _weights(sigma, n: int, measured=None) -> np.ndarray:
    """1/σ per sample; 0 where σ is not finite or not positive, or the channel has no reading."""
    s = np.broadcast_to(np.asarray(sigma, dtype=float), (n,))
    ok = np.isfinite(s) & (s > 0)
    if measured is not None:
        ok &= np.isfinite(np.asarray(measured, dtype=float))
    return np.where(ok, 1.0 / np.where(ok, s, 1.0), 0.0)


def _block(values: dict, held: dict, spec, mechanisms, running, events, weights: dict) -> np.ndarray:
    """JᵀWJ of one block of samples, through the fit's own normal equations (observed = 0)."""
    obs = {c: jnp.zeros_like(w) for c, w in weights.items()}
    ctx = _Ctx(spec=spec, mechanisms=tuple(mechanisms), free=tuple(values), positive=(), scales=jnp.zeros(0),
               held={k: jnp.asarray(v, dtype=jnp.float64) for k, v in held.items()},
               running=running, events=events, observed=obs, weights=weights)
    jtj, _, _ = _normal_equations({k: jnp.asarray(v, dtype=jnp.float64) for k, v in values.items()}, ctx)
    return np.asarray(jtj)


def fisher_information(params: dict, spec, dataset=None, sigma: dict | None = None, names: Sequence | None = None,
                       mechanisms: Sequence = (), running: Samples | None = None, events: Samples | None = None,
                       measured: dict | None = None) -> np.ndarray:
    """Fisher information of the parameters ``names`` at ``params`` (SI).

    params : every model parameter (a dict as :func:`motorid.model.predict` takes)
    spec : the motor; dataset : an extracted :class:`~motorid.identify.extract.Dataset`
        (its running samples, breakaway events and which channels have readings);
        or give ``running`` / ``events`` Samples (and optionally ``measured``) directly
    sigma : channel → σ per sample (or a scalar) of "torque", "q_a", "q_b",
        "q_case" (aligned with the running samples) and "breakaway" (aligned with
        the events) [SI].  A channel absent from ``sigma`` carries no information;
        a sample with σ = NaN/inf/0, or without a reading, neither.
    names : the parameters to differentiate (default: every key of ``params``)

    Returns the (p, p) matrix in the order of ``names``; I = Σ J Jᵀ/σ².
    """
    sigma = sigma or {}
    names = list(params) if names is None else list(names)
    values = {k: float(params[k]) for k in names}
    held = {k: float(v) for k, v in params.items() if k not in values}
    if dataset is not None:
        running = dataset.running if running is None else running
        events = dataset.events if events is None else events
        measured = dict(dataset.measured, breakaway=dataset.held_torque) if measured is None else measured
    measured = measured or {}
    info = np.zeros((len(names), len(names)))
    n_run = 0 if running is None else int(np.asarray(running.theta).size)
    run_ch = [c for c in RUNNING_CHANNELS if c in sigma]
    if n_run and run_ch:
        for lo in range(0, n_run, CHUNK):
            hi = min(lo + CHUNK, n_run)
            size = bucket(hi - lo)
            part = Samples(*[np.asarray(f)[lo:hi] for f in running])
            w = {}
            for c in RUNNING_CHANNELS:
                wc = np.zeros(hi - lo)
                if c in sigma:
                    s = np.broadcast_to(np.asarray(sigma[c], dtype=float), (n_run,))[lo:hi]
                    m = measured.get(c)
                    wc = _weights(s, hi - lo, None if m is None else np.asarray(m)[lo:hi])
                w[c] = jnp.asarray(pad(wc, size))
            info += _block(values, held, spec, mechanisms, pad_samples(part, size), None, w)
    n_ev = 0 if events is None else int(np.asarray(events.theta).size)
    if n_ev and "breakaway" in sigma:
        size = bucket(n_ev, 16)
        wb = _weights(sigma["breakaway"], n_ev, measured.get("breakaway"))
        info += _block(values, held, spec, mechanisms, None, pad_samples(events, size),
                       {"breakaway": jnp.asarray(pad(wb, size))})
    return 0.5 * (info + info.T)


def cramer_rao(info: np.ndarray, names: Sequence, rtol: float = 1e-10):
    """Cramér–Rao bound from a Fisher information matrix → (std dict, covariance).

    The inverse is taken on unit-diagonal scaling; a parameter with a component
    in a direction the information cannot see (relative eigenvalue below
    ``rtol``) gets std = inf, and its covariance row NaN.
    """
    names = list(names)
    p = len(names)
    info = np.asarray(info, dtype=float)
    d = np.sqrt(np.clip(np.diag(info), 0.0, None))
    seen = d > 0
    cov = np.full((p, p), np.nan)
    std = {k: math.inf for k in names}
    idx = np.flatnonzero(seen)
    if idx.size:
        sub = info[np.ix_(idx, idx)] / np.outer(d[idx], d[idx])
        w, v = np.linalg.eigh(sub)
        weak = w < rtol * max(w.max(), 1e-300)
        inv = np.where(weak, 0.0, 1.0 / np.where(weak, 1.0, w))
        c = (v * inv) @ v.T / np.outer(d[idx], d[idx])
        blind = np.abs(v[:, weak]).max(axis=1) > 1e-6 if weak.any() else np.zeros(idx.size, bool)
        for j, i in enumerate(idx):
            if not blind[j]:
                std[names[i]] = float(math.sqrt(max(c[j, j], 0.0)))
        good = idx[~blind]
        keep = np.flatnonzero(~blind)
        cov[np.ix_(good, good)] = c[np.ix_(keep, keep)]
    return std, cov


# ----------------------------------------------------------------------------
# candidate runs


@dataclass
class Candidate:
    """One extra bench run: its protocol, set point in words and the operating
    point of its samples (running) or its breakaway event (startability)."""

    protocol: str
    set_point: str
    running: Samples | None = None
    events: Samples | None = None
    setting: dict = field(default_factory=dict)


@dataclass
class Suggestion:
    candidate: Candidate
    parameter: str  # the worst-determined parameter now
    std_now: float
    std_after: float
    rel_now: float
    rel_after: float
    worst_after: str  # the worst-determined parameter with the run added
    all_after: dict  # every parameter's std with the run added

    @property
    def gain(self) -> float:
        """Relative shrinking of the worst parameter's relative standard error [-]."""
        return 1.0 - self.rel_after / self.rel_now if self.rel_now > 0 else 0.0

    def as_dict(self) -> dict:
        return {"protocol": self.candidate.protocol, "set_point": self.candidate.set_point,
                "setting": self.candidate.setting, "parameter": self.parameter, "std_now": self.std_now,
                "std_after": self.std_after, "improvement_percent": 100.0 * self.gain,
                "worst_after": self.worst_after, "std_after_all": self.all_after}


def _viscosity(spec, temp_c: float) -> float:
    if spec.oil is None:
        return 0.04
    return float(np.asarray(spec.oil.viscosity(np.array([temp_c])))[0])


def _ports(direction: int, dp: float, back: float):
    p_in = back + dp
    return (p_in, back) if direction > 0 else (back, p_in)


def constant_speed_candidate(spec, speed_rpm: float, dp_bar: float, direction: int, oil_temp: float = 40.0,
                             back_bar: float = 7.0, case_bar: float = 0.7, duration_s: float = 2.0,
                             revolutions: float = 1.05, sample_rate_hz: float | None = None) -> Candidate:
    """An ISO 4392-1 constant-speed run: at least ``duration_s`` and ``revolutions``
    shaft turns (a slow run then covers every piston pitch), sampled like the
    repo's protocol (10 Hz at 0.3 rpm … 100 Hz from 30 rpm)."""
    if sample_rate_hz is None:
        sample_rate_hz = 10.0 if speed_rpm <= 0.5 else 20.0 if speed_rpm <= 2 else 50.0 if speed_rpm <= 20 else 100.0
    w = speed_rpm * RAD_S_PER_RPM
    t_run = max(duration_s, revolutions * 2 * math.pi / w)
    n = int(t_run * sample_rate_hz) + 1
    t = np.arange(n) / sample_rate_hz
    p_a, p_b = _ports(direction, dp_bar * PA_PER_BAR, back_bar * PA_PER_BAR)
    s = model.make_samples(spec, direction * w * t, direction * w, p_a, p_b, case_bar * PA_PER_BAR,
                           _viscosity(spec, oil_temp), direction=float(direction), temperature=oil_temp, time=t)
    dirw = "+" if direction > 0 else "−"
    return Candidate("ISO 4392-1 constant speed", f"{speed_rpm:g} rpm, ΔP {dp_bar:g} bar, dir {dirw}, {n} samples",
                     running=s, setting={"speed_rpm": speed_rpm, "pressure_difference_bar": dp_bar,
                                         "direction": direction, "samples": n})


def startability_candidate(spec, params: dict, load_nm: float, direction: int, angles_deg: Sequence[float],
                           oil_temp: float = 40.0, back_bar: float = 7.0, case_bar: float = 0.7) -> Candidate | None:
    """ISO 4392-2 startability ramps at one load torque and several shaft angles:
    one breakaway event each, at the ΔP where :func:`predict_breakaway` reaches
    the load (the model is linear in ΔP at a fixed angle).  None if no ΔP below
    600 bar breaks the shaft away."""
    th = np.deg2rad(np.asarray(angles_deg, dtype=float))
    mu = _viscosity(spec, oil_temp)

    def held(dp):
        p_a, p_b = _ports(direction, dp, back_bar * PA_PER_BAR)
        ev = model.make_samples(spec, th, 0.0, p_a, p_b, case_bar * PA_PER_BAR, mu, direction=float(direction),
                                temperature=oil_temp)
        return np.asarray(model.predict_breakaway(model.as_jax(params), spec, ev)), ev

    h0, _ = held(0.0)
    h1, _ = held(100 * PA_PER_BAR)
    slope = (h1 - h0) / (100 * PA_PER_BAR)
    with np.errstate(divide="ignore", invalid="ignore"):
        dp = (direction * load_nm - h0) / slope
    ok = np.isfinite(dp) & (dp > 0) & (dp < 600 * PA_PER_BAR)
    if not ok.any():
        return None
    p_a, p_b = _ports(direction, dp[ok], back_bar * PA_PER_BAR)
    ev = model.make_samples(spec, th[ok], 0.0, p_a, p_b, case_bar * PA_PER_BAR, mu, direction=float(direction),
                            temperature=oil_temp)
    dirw = "+" if direction > 0 else "−"
    return Candidate("ISO 4392-2 startability",
                     f"load {load_nm:g} N·m, dir {dirw}, {int(ok.sum())} angles {min(angles_deg):g}-{max(angles_deg):g}°",
                     events=ev, setting={"load_torque_Nm": load_nm, "direction": direction,
                                         "shaft_angles_deg": [float(a) for a in np.asarray(angles_deg)[ok]]})


def default_candidates(spec, params: dict) -> list[Candidate]:
    """The grid of candidate runs: constant speed 0.3-2500 rpm × ΔP 50/150/250 bar ×
    both directions; startability at 40-400 N·m × both directions over one pitch
    of shaft angle."""
    out = []
    for rpm in (0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0, 2500.0):
        for dp in (50.0, 150.0, 250.0):
            for d in (1, -1):
                out.append(constant_speed_candidate(spec, rpm, dp, d))
    pitch = 360.0 / spec.pistons
    angles = list(np.linspace(0.0, pitch, 9))
    for load in (40.0, 120.0, 240.0, 400.0):
        for d in (1, -1):
            c = startability_candidate(spec, params, load, d, angles)
            if c is not None:
                out.append(c)
    return out


# ----------------------------------------------------------------------------
# experiment design


_WANTS = {
    "Kv": "constant-speed runs (ISO 4392-1) at several speeds, e.g. 10, 100 and 1000 rpm",
    "KF": "running runs at ≥ 2 port-pressure levels, e.g. constant speed at ΔP 50 and 250 bar",
    "TFc": "running runs at ≥ 2 port-pressure levels, e.g. constant speed at ΔP 50 and 250 bar",
    "KFS": "ISO 4392-2 startability runs at ≥ 2 load levels (better 3, e.g. 40, 120, 240 N·m), both directions",
    "Ks": "ISO 4392-2 startability runs at ≥ 2 load levels (better 3, e.g. 40, 120, 240 N·m), both directions",
    "KL0": "runs that log the case-drain flow (or both port flows)",
    "KAB": "runs that log the port flows at several ΔP",
}


def wanted_runs(name: str, reason: str = "") -> str:
    """The runs that would make a parameter identifiable, in words."""
    if name.startswith("KL_"):
        return ("add slow constant-speed runs (ISO 4392-1, ≤ 3 rpm, ≥ 1.05 revolutions) logging the case-drain "
                "flow over a whole piston pitch")
    if name in ("KFS", "Ks") and "no startability" in reason:
        return "no startability runs: add " + _WANTS[name]
    return "add " + _WANTS.get(name, "runs that excite this parameter")


def _relative(name: str, value: float, std: float, mechanisms=()) -> float:
    info = model.parameter_info(name, mechanisms)
    floor = 0.1 * info.typical if not info.positive else 0.0
    return std / max(abs(value), floor, 1e-300)


def campaign_information(ls, dataset, spec, names=None) -> np.ndarray:
    """Fisher information of a fitted campaign at the fitted values, with the
    fit's own per-sample noise levels and inliers (``ls.sigma``, ``ls.inliers``)."""
    names = list(ls.free) if names is None else list(names)
    return fisher_information(ls.params_all, spec, dataset, _fit_sigma(ls), names=names, mechanisms=ls.mechanisms)


def _fit_sigma(ls) -> dict:
    """The fit's per-sample σ of each channel, NaN where it rejected the sample."""
    sigma = {}
    for c, s in ls.sigma.items():
        ok = np.asarray(ls.inliers.get(c, np.ones(np.shape(s), bool)), dtype=bool)
        sigma[c] = np.where(ok, np.asarray(s, dtype=float), np.nan)
    return sigma


def suggest_runs(ls, dataset, spec, candidates: Sequence[Candidate] | None = None, top: int = 5,
                 parameter: str | None = None):
    """Rank candidate extra runs by how much they shrink the relative standard
    error of the worst-determined identifiable parameter (or of ``parameter``).

    ls : the least-squares fit of the campaign (values, noise levels per channel)
    dataset : its extracted data; spec : the motor
    candidates : :class:`Candidate` runs (default :func:`default_candidates`)

    The noise of a candidate's samples is the fitted pooled level of each channel
    (``ls.noise``; the breakaway channel's is ``ls.noise['breakaway']``, or the
    torque's when the campaign has no breakaway).  The share of the covariance
    that the campaign's smoothed viscosity carries (``ls.covariance_viscosity``)
    is kept, shrinking as the added run sharpens the rest (a new run's own
    viscosity error is left out).  Returns a dict:
    ``suggestions`` (the best ``top`` :class:`Suggestion`), ``worst`` (the
    parameter), ``std_now``, and ``unidentified``: for each parameter the logs
    cannot identify, the runs that would, and the best candidate that makes it
    identifiable (with the std it would reach).
    """
    params = dict(ls.params_all)
    names = list(ls.free)
    if candidates is None:
        candidates = default_candidates(spec, params)
    noise = {c: v for c, v in ls.noise.items() if v is not None}
    cand_sigma = {c: noise[c] for c in RUNNING_CHANNELS if c in noise}
    cand_sigma["breakaway"] = noise.get("breakaway", noise.get("torque", 1.0))

    out = {"suggestions": [], "worst": None, "std_now": {}, "unidentified": {}, "target": parameter is not None}
    cand_info_all = []
    all_names = list(ls.names)
    for cand in candidates:
        cand_info_all.append(fisher_information(params, spec, None, cand_sigma, names=all_names,
                                                mechanisms=ls.mechanisms, running=cand.running,
                                                events=cand.events))
    if names:
        base = campaign_information(ls, dataset, spec, names)
        # the smoothed viscosity's run-level error (ls.covariance_viscosity = C M C with C
        # the data's covariance): more data shrink C and with it that share, C' M C'
        visc = getattr(ls, "covariance_viscosity", None)
        shared = base @ visc @ base if visc is not None and visc.shape == base.shape else None

        def bound(info):
            std, cov = cramer_rao(info, names)
            if shared is None:
                return std
            total = np.diag(cov + cov @ shared @ cov)
            return {k: (float(math.sqrt(max(total[i], 0.0))) if math.isfinite(std[k]) else math.inf)
                    for i, k in enumerate(names)}

        std_now = bound(base)
        rel_now = {k: _relative(k, params[k], std_now[k], ls.mechanisms) for k in names}
        if parameter is not None and parameter not in names:
            raise InputError(f"parameter '{parameter}' is not identified by these logs "
                             f"(identified: {', '.join(names)})")
        worst = parameter or max(names, key=lambda k: rel_now[k])
        out.update(worst=worst, std_now=std_now)
        sel = [all_names.index(k) for k in names]
        sugg = []
        for cand, ci in zip(candidates, cand_info_all):
            std_after = bound(base + ci[np.ix_(sel, sel)])
            rel_after = {k: _relative(k, params[k], std_after[k], ls.mechanisms) for k in names}
            sugg.append(Suggestion(cand, worst, std_now[worst], std_after[worst], rel_now[worst],
                                   rel_after[worst], max(names, key=lambda k: rel_after[k]), std_after))
        sugg.sort(key=lambda s: (-s.gain, s.candidate.running is not None and
                                 int(np.asarray(s.candidate.running.theta).size)))
        out["suggestions"] = sugg[:top]
    missing = [k for k in all_names if not ls.identifiable.get(k, True)]
    if missing:
        # information over every parameter, the unidentified ones at their start values
        base_all = campaign_information(ls, dataset, spec, all_names)
        for k in missing:
            best = None
            for cand, ci in zip(candidates, cand_info_all):
                std_after, _ = cramer_rao(base_all + ci, all_names)
                if math.isfinite(std_after[k]) and (best is None or std_after[k] < best[1]):
                    best = (cand, std_after[k])
            reason = ls.reasons.get(k, "")
            out["unidentified"][k] = {
                "reason": reason, "add": wanted_runs(k, reason),
                "best_single_run": None if best is None else {"protocol": best[0].protocol,
                                                              "set_point": best[0].set_point,
                                                              "std_after": best[1]}}
    return out


# ----------------------------------------------------------------------------
# the plan in words (what `motorid plan` prints)


def format_plan(plan: dict, ls) -> str:
    lines = []
    sugg = plan["suggestions"]
    if plan["worst"] is not None:
        w = plan["worst"]
        unit = model.parameter_info(w, ls.mechanisms).unit
        lines.append(f"{'target' if plan.get('target') else 'worst-determined'} parameter: {w} = {ls.values[w]:.5g} ± {plan['std_now'][w]:.3g} {unit}")
        lines.append("")
        head = f"{'#':>2}  {'protocol':<26} {'set point':<44} {'parameter':<9} {'std now → after':<24} {'gain':>6}"
        lines.append(head)
        for i, s in enumerate(sugg, 1):
            lines.append(f"{i:>2}  {s.candidate.protocol:<26} {s.candidate.set_point:<44} {s.parameter:<9} "
                         f"{s.std_now:.3g} → {s.std_after:.3g}".ljust(len(head) - 7)
                         + f" {100 * s.gain:>5.1f}%")
    for k, u in plan["unidentified"].items():
        lines.append(f"{k}: not identifiable ({u['reason']}) — {u['add']}")
        b = u["best_single_run"]
        if b is not None:
            lines.append(f"    a single {b['protocol']} run ({b['set_point']}) would give std {b['std_after']:.3g}")
    return "\n".join(lines)


__all__ = ["fisher_information", "cramer_rao", "suggest_runs", "Candidate", "Suggestion", "default_candidates",
           "constant_speed_candidate", "startability_candidate", "campaign_information", "wanted_runs", "format_plan"]
