"""Run protocols on the one model in time: the synthetic ISO 4392 bench.

Three kinds of run, all evaluated through :func:`motorid.model.predict` (and
:func:`motorid.model.predict_breakaway` for startability):

- *speed-held* (constant_speed, constant_pressure, ISO 4392-1): the dynamometer
  prescribes ω(t) = ω_set (1 + ripple), θ(t) is its exact integral and α(t) its
  derivative; the supply holds ΔP with a small fluctuation.  One vectorized
  model call per protocol.
- *startability* (ISO 4392-2): the shaft is held at a set angle by a constant
  load torque while the inlet pressure is ramped.  It stays stuck while the
  held load lies within the model's breakaway limits (Karnopp); the breakaway
  instant is where ``predict_breakaway`` reaches the load.  Afterwards the
  shaft moves under :mod:`motorid.bench.dynamics` up to a speed limiter.
- *flow-fed* (constant_flow, constant_torque, ISO 4392-3): a pump delivers a
  set flow into the inlet through a compressible line, the load is a constant
  torque, speed and pressure follow from :mod:`motorid.bench.dynamics`.

The oil temperature drifts within a run; viscosity follows from it through the
motor spec's oil.  Sensors (:mod:`motorid.bench.sensors`) then read every
channel.  Random numbers come from ``numpy.random.default_rng([seed, stream,
protocol index, run index])``: stream 0 for the process (angles, ripple phases,
temperature offsets), stream 1 for the sensors, so ideal and noisy sensors see
the same motion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from motorid.bench import dynamics
from motorid.bench.kernels import evaluate
from motorid.bench.protocols import Protocol, RunPlan, running_duration
from motorid.bench.truth import Truth
from motorid.errors import InputError
from motorid.units import FORMAT_COLUMNS, SI_COLUMNS
from motorid.model import MotorSpec

#: internal integration rate of the startability transient [Hz] (at least)
STARTABILITY_RATE = 2000.0
#: integration steps per flow-ripple period and per hydraulic-resonance period (ISO 4392-3 runs)
STEPS_PER_RIPPLE = 20
STEPS_PER_RESONANCE = 40
#: channels the simulator computes for each sample, canonical SI names
_TRUE = tuple(FORMAT_COLUMNS)


@dataclass
class RunRecord:
    """What one simulated run was: its id, protocol, plan, row count; for a
    startability run the true breakaway time [s] (``None``: no breakaway)."""

    run_id: str
    protocol: str
    procedure: str
    plan: RunPlan
    rows: int = 0
    breakaway_time: float | None = None


@dataclass
class Campaign:
    """A simulated campaign.

    frame : the log as the sensors read it, canonical SI columns (logs.SI_COLUMNS;
        ``viscosity_Pa_s`` NaN or absent where a protocol omits it)
    true_frame : the same samples, true values, with ``acceleration_rad_s2`` and
        ``moving`` (False while a startability shaft is stuck: there the
        transducer reads the held load, not a running-model torque)
    """

    frame: pd.DataFrame
    true_frame: pd.DataFrame
    runs: list
    seed: int
    warnings: list = field(default_factory=list)


def _rng(seed: int, stream: int, protocol_index: int, run_index: int) -> np.random.Generator:
    return np.random.default_rng([seed, stream, protocol_index, run_index])


def _ripple(t, terms):
    """Σ ε sin(a t + φ), its time integral from 0 and its derivative, for terms (ε, a [rad/s], φ)."""
    value, integral, derivative = (np.zeros_like(t) for _ in range(3))
    for eps, a, phase in terms:
        if eps == 0.0 or a == 0.0:
            continue
        value += eps * np.sin(a * t + phase)
        integral += eps * (np.cos(phase) - np.cos(a * t + phase)) / a
        derivative += eps * a * np.cos(a * t + phase)
    return value, integral, derivative


_SAMPLE_KEYS = ("theta_rad", "speed_rad_s", "acceleration_rad_s2", "p_a_Pa", "p_b_Pa", "p_case_Pa",
                "viscosity_Pa_s", "direction", "oil_temp_C", "time_s")


def _sample_columns(cols: dict) -> dict:
    return {k: cols[k] for k in _SAMPLE_KEYS if k in cols}


def _oil(truth: Truth, spec: MotorSpec, cols: dict) -> dict:
    """Add the viscosity of the oil at cols['oil_temp_C']."""
    cols.update(evaluate("viscosity", truth, spec, {"oil_temp_C": cols["oil_temp_C"]}))
    return cols


def _case_pressure(truth: Truth, spec: MotorSpec, cols: dict, drain_resistance: float) -> dict:
    """Raise cols['p_case_Pa'] (the no-flow case pressure) by the drain line's
    resistance times the case drain flow."""
    if drain_resistance > 0.0:
        q_case = evaluate("running", truth, spec, _sample_columns(cols))["q_case_m3_s"]
        cols["p_case_Pa"] = cols["p_case_Pa"] + drain_resistance * q_case
    return cols


def _running_channels(truth: Truth, spec: MotorSpec, cols: dict) -> dict:
    """Add the model's torque and flows at every sample of cols."""
    cols.update(evaluate("running", truth, spec, _sample_columns(cols)))
    return cols


def _concat(pieces: list[dict]) -> tuple[dict, np.ndarray]:
    keys = pieces[0].keys()
    counts = np.array([len(p["time_s"]) for p in pieces])
    return {k: np.concatenate([np.broadcast_to(p[k], (n,)) for p, n in zip(pieces, counts)])
            for k in keys}, counts


def _split(cols: dict, counts) -> list[dict]:
    edges = np.concatenate([[0], np.cumsum(counts)])
    return [{k: v[a:b] for k, v in cols.items()} for a, b in zip(edges[:-1], edges[1:])]


# ---------------------------------------------------------------- speed-held runs (ISO 4392-1)

def _speed_held(protocol: Protocol, spec: MotorSpec, truth: Truth, rngs, warn) -> tuple[list, list]:
    cond, dyn, sup = protocol.conditions, protocol.dynamometer, protocol.supply
    pieces = []
    for plan, rng in zip(protocol.runs, rngs):
        theta0, temp_offset = rng.uniform(0.0, 2.0 * math.pi), rng.uniform(-1.0, 1.0) * cond.temp_tolerance
        ph = rng.uniform(0.0, 2.0 * math.pi, size=3)
        n = int(math.floor(running_duration(plan, protocol.timing) * plan.sample_rate + 1e-9)) + 1
        t = np.arange(n) / plan.sample_rate
        w_set = plan.direction * plan.speed
        r, r_int, r_der = _ripple(t, [(dyn.speed_ripple, 2.0 * math.pi * dyn.speed_ripple_freq, ph[0]),
                                      (dyn.speed_ripple_per_rev, plan.speed, ph[1])])
        dp = plan.pressure_difference * (1.0 + sup.pressure_ripple
                                         * np.sin(2.0 * math.pi * sup.pressure_ripple_freq * t + ph[2]))
        p_in = cond.back_pressure + dp
        temp = plan.oil_temp + temp_offset + cond.temp_drift * t
        a_in = (plan.direction > 0) != plan.pump  # pump mode: the high pressure where the shaft delivers
        pieces.append({
            "time_s": t, "theta_rad": theta0 + w_set * (t + r_int), "speed_rad_s": w_set * (1.0 + r),
            "acceleration_rad_s2": w_set * r_der,
            "p_a_Pa": p_in if a_in else np.full(n, cond.back_pressure),
            "p_b_Pa": np.full(n, cond.back_pressure) if a_in else p_in,
            "p_case_Pa": np.full(n, cond.case_pressure), "oil_temp_C": temp,
            "direction": np.full(n, float(plan.direction)), "moving": np.ones(n, bool),
        })
    cols, counts = _concat(pieces)
    cols = _case_pressure(truth, spec, _oil(truth, spec, cols), cond.case_drain_resistance)
    return _split(_running_channels(truth, spec, cols), counts), [None] * len(pieces)


# ---------------------------------------------------------------- load-driven runs (shared)

def _drive(protocol: Protocol, plans, rngs) -> tuple[dict, np.ndarray]:
    """Per-run drive arrays (dynamics.DRIVE_FIELDS) and the process random draws."""
    cond, dyn, sup, tim = protocol.conditions, protocol.dynamometer, protocol.supply, protocol.timing
    R = len(plans)
    draws = np.array([[rng.uniform(0.0, 2.0 * math.pi), rng.uniform(-1.0, 1.0), *rng.uniform(0.0, 2.0 * math.pi, 2)]
                      for rng in rngs]).reshape(R, 4)
    d = np.array([p.direction for p in plans], dtype=float)
    flow_fed = protocol.procedure in ("constant_flow", "constant_torque")
    drive = {
        "direction": d,
        "load_torque": d * np.array([p.load_torque for p in plans]),
        "load_inertia": np.full(R, dyn.load_inertia),
        "max_speed": np.full(R, np.inf if flow_fed else dyn.max_speed),
        "p_out": np.full(R, cond.back_pressure),
        "p_case": np.full(R, cond.case_pressure),
        "temp0": np.array([p.oil_temp for p in plans]) + draws[:, 1] * cond.temp_tolerance,
        "temp_rate": np.full(R, cond.temp_drift),
        "is_flow": np.full(R, 1.0 if flow_fed else 0.0),
        "dp_start": np.zeros(R),
        "ramp_rate": np.full(R, 0.0 if flow_fed else tim.ramp_rate),
        "hold": np.full(R, tim.hold),
        "p_ripple": np.zeros(R),
        "p_ripple_w": np.full(R, 2.0 * math.pi * sup.pressure_ripple_freq),
        "p_ripple_phase": draws[:, 2],
        "q_set": np.array([p.flow or 0.0 for p in plans]),
        "q_ripple": np.full(R, sup.flow_ripple),
        "q_ripple_w": np.full(R, 2.0 * math.pi * sup.flow_ripple_freq),
        "q_ripple_phase": draws[:, 3],
        "stiffness": np.full(R, sup.bulk_modulus / sup.volume),
    }
    return drive, draws


def _per_sample(drive: dict, counts) -> dict:
    return {k: np.repeat(v, counts) for k, v in drive.items()}


def _held_load(truth: Truth, spec: MotorSpec, drive: dict, theta, dp, t, direction, drain_resistance: float):
    """predict_breakaway: the load torque held at breakaway in ``direction`` [N·m],
    at shaft angle theta [rad], ΔP magnitude dp [Pa] and time t [s] of each sample
    (the case pressure rises with the standstill case drain flow, as logged)."""
    t = np.broadcast_to(t, np.shape(theta))
    p_a, p_b = dynamics.port_pressures(drive["direction"], drive["p_out"] + dp, drive["p_out"], xp=np)
    cols = {"theta_rad": theta, "speed_rad_s": 0.0, "p_a_Pa": p_a, "p_b_Pa": p_b, "p_case_Pa": drive["p_case"],
            "direction": direction, "oil_temp_C": dynamics.oil_temperature(drive, t), "time_s": t}
    cols = _case_pressure(truth, spec, _oil(truth, spec, cols), drain_resistance)
    return evaluate("held", truth, spec, _sample_columns(cols))["held_Nm"]


def _load_driven_channels(truth: Truth, spec: MotorSpec, drive_s: dict, cols: dict, drain_resistance: float):
    """Channels of load-driven samples: α from the model and the load, the
    transducer reading T(α) = T_load + J_load α while moving, T_load while stuck.
    cols holds time_s, theta_rad, speed_rad_s, p_in (inlet pressure) and moving."""
    p_a, p_b = dynamics.port_pressures(drive_s["direction"], cols.pop("p_in"), drive_s["p_out"], xp=np)
    cols.update(oil_temp_C=dynamics.oil_temperature(drive_s, cols["time_s"]), p_a_Pa=p_a, p_b_Pa=p_b,
                p_case_Pa=drive_s["p_case"], direction=drive_s["direction"],
                acceleration_rad_s2=np.zeros_like(cols["time_s"]))
    cols = _case_pressure(truth, spec, _oil(truth, spec, cols), drain_resistance)
    alpha = evaluate("acceleration", truth, spec, {**_sample_columns(cols), "load_torque": drive_s["load_torque"],
                                                   "load_inertia": drive_s["load_inertia"]})["acceleration_rad_s2"]
    d, speed = drive_s["direction"], cols["speed_rad_s"]
    at_limit = (d * speed >= drive_s["max_speed"] * (1.0 - 1e-12)) & (d * alpha > 0.0)
    cols["moving"] = cols["moving"] & (speed != 0.0)  # at rest (stalled after breakaway): held by friction
    cols["acceleration_rad_s2"] = np.where(at_limit | ~cols["moving"], 0.0, alpha)
    cols = _running_channels(truth, spec, cols)
    cols["torque_Nm"] = np.where(cols["moving"], cols["torque_Nm"], drive_s["load_torque"])
    return cols


# ---------------------------------------------------------------- startability (ISO 4392-2)

def _first_crossing(values, counts):
    """Index (within each run's block) of the first value >= 0, or -1."""
    out = []
    for block in _split({"v": values}, counts):
        hits = np.flatnonzero(block["v"] >= 0.0)
        out.append(int(hits[0]) if hits.size else -1)
    return np.array(out)


def _startability(protocol: Protocol, spec: MotorSpec, truth: Truth, rngs, warn) -> tuple[list, list]:
    plans, tim = protocol.runs, protocol.timing
    R = len(plans)
    drive, _ = _drive(protocol, plans, rngs)
    drain = protocol.conditions.case_drain_resistance
    d, load = drive["direction"], np.abs(drive["load_torque"])
    theta_set = np.array([p.shaft_angle for p in plans])
    fs = plans[0].sample_rate
    sup = protocol.supply

    # start pressure: where the pressure torque alone holds the load (friction holds nothing)
    grid = np.linspace(0.0, tim.max_pressure, 401)
    counts_g = np.full(R, grid.size)
    dg = _per_sample(drive, counts_g)
    dp_g, th_g = np.tile(grid, R), np.repeat(theta_set, grid.size)
    fwd = _held_load(truth, spec, dg, th_g, dp_g, 0.0, dg["direction"], drain)
    bwd = _held_load(truth, spec, dg, th_g, dp_g, 0.0, -dg["direction"], drain)
    balance = dg["direction"] * 0.5 * (fwd + bwd) - np.repeat(load, grid.size)
    start = np.empty(R)
    for r, (j, block) in enumerate(zip(_first_crossing(balance, counts_g), _split({"b": balance}, counts_g))):
        b = block["b"]
        start[r] = grid[0] if j == 0 else (grid[-1] if j < 0 else
                                          np.interp(0.0, [b[j - 1], b[j]], [grid[j - 1], grid[j]]))
    if tim.start_pressure is not None:
        held_back = d * _held_load(truth, spec, drive, theta_set, np.full(R, tim.start_pressure), 0.0, -d, drain)
        slips = held_back < load
        for r in np.flatnonzero(slips):
            warn(f"run {protocol.name}-{r + 1:03d}: the load overhauls the motor at start_pressure_bar; "
                 "the ramp starts where the pressure torque holds the load instead")
        start = np.where(slips, start, tim.start_pressure)
    drive["dp_start"] = start
    drive["p_ripple"] = sup.pressure_ripple * start

    # stuck phase: breakaway where predict_breakaway reaches the load (first DAQ sample, then refined)
    t_end = tim.hold + np.maximum(tim.max_pressure - start, 0.0) / tim.ramp_rate
    counts = np.floor(t_end * fs + 1e-9).astype(int) + 1
    t_daq = np.concatenate([np.arange(n) / fs for n in counts])
    ds = _per_sample(drive, counts)
    cond = ds["direction"] * _held_load(truth, spec, ds, np.repeat(theta_set, counts),
                                        dynamics.ramp_pressure(ds, t_daq, xp=np), t_daq, ds["direction"], drain) \
        - np.repeat(load, counts)
    first = _first_crossing(cond, counts)
    t_break = np.full(R, np.nan)
    t_break[first == 0] = 0.0
    refine = np.flatnonzero(first > 0)
    if refine.size:
        sub = 65
        lo = (first[refine] - 1) / fs
        t_sub = (lo[:, None] + np.linspace(0.0, 1.0 / fs, sub)[None, :]).ravel()
        dr = _per_sample({k: v[refine] for k, v in drive.items()}, np.full(refine.size, sub))
        c = (dr["direction"] * _held_load(truth, spec, dr, np.repeat(theta_set[refine], sub),
                                          dynamics.ramp_pressure(dr, t_sub, xp=np), t_sub, dr["direction"], drain)
             - np.repeat(load[refine], sub)).reshape(-1, sub)
        t_sub = t_sub.reshape(-1, sub)
        for i, r in enumerate(refine):
            hits = np.flatnonzero(c[i] >= 0.0)
            k = int(hits[0]) if hits.size else sub - 1  # (the bracket's end crossed on the DAQ grid)
            t_break[r] = t_sub[i, k] if k == 0 else np.interp(0.0, [c[i, k - 1], c[i, k]],
                                                             [t_sub[i, k - 1], t_sub[i, k]])
    for r in np.flatnonzero(first == 0):
        warn(f"run {protocol.name}-{r + 1:03d}: the shaft breaks away at the start of the ramp")
    for r in np.flatnonzero(first < 0):
        warn(f"run {protocol.name}-{r + 1:03d}: no breakaway up to max_pressure_bar")

    # after breakaway: Karnopp, load-driven, up to the speed limiter
    broke = np.isfinite(t_break)
    substeps = max(1, math.ceil(STARTABILITY_RATE / fs))
    dt = 1.0 / (fs * substeps)
    steps = math.ceil(tim.after_breakaway / dt) + 2
    if broke.any():
        db = {k: v[broke] for k, v in drive.items()}
        nb = int(broke.sum())
        times, th, om, _ = dynamics.integrate(truth.params, spec, truth.mechanisms, db, theta_set[broke],
                                              np.zeros(nb), np.zeros(nb), t_break[broke], np.full(nb, dt), steps)
    pieces, b = [], 0
    for r in range(R):
        if broke[r]:
            n = int(math.floor((t_break[r] + tim.after_breakaway) * fs + 1e-9)) + 1
        else:
            n = counts[r]
        t = np.arange(n) / fs
        moving = t > t_break[r] if broke[r] else np.zeros(n, bool)  # stuck up to the breakaway instant
        theta, speed = np.full(n, theta_set[r]), np.zeros(n)
        if broke[r]:
            theta[moving] = np.interp(t[moving], times[:, b], th[:, b])
            speed[moving] = np.interp(t[moving], times[:, b], om[:, b])
            b += 1
        pieces.append({"time_s": t, "theta_rad": theta, "speed_rad_s": speed, "moving": moving})
    cols, counts = _concat(pieces)
    ds = _per_sample(drive, counts)
    cols["p_in"] = ds["p_out"] + dynamics.ramp_pressure(ds, cols["time_s"], xp=np)
    cols = _load_driven_channels(truth, spec, ds, cols, drain)
    return _split(cols, counts), [None if not broke[r] else float(t_break[r]) for r in range(R)]


# ---------------------------------------------------------------- flow-fed runs (ISO 4392-3)

def _steady_state(truth: Truth, spec: MotorSpec, drive: dict, theta0, iterations: int = 12):
    """Mean steady speed magnitude [rad/s] and ΔP magnitude [Pa] of flow-fed runs,
    by fixed-point iteration on the model averaged over one piston pitch."""
    R = len(theta0)
    G = 32
    th = (theta0[:, None] + np.arange(G)[None, :] * 2.0 * math.pi / (spec.pistons * G)).ravel()
    dg = _per_sample(drive, np.full(R, G))
    gain = 2.0 * math.pi / spec.displacement  # ideal motor: [rad/m³] from flow, [Pa/N·m] from torque
    speed = drive["q_set"] * gain
    dp = np.abs(drive["load_torque"]) * gain
    cols = _oil(truth, spec, {"theta_rad": th, "acceleration_rad_s2": 0.0, "p_case_Pa": dg["p_case"],
                              "direction": dg["direction"], "oil_temp_C": dg["temp0"], "time_s": 0.0})
    for _ in range(iterations):
        p_a, p_b = dynamics.port_pressures(dg["direction"], dg["p_out"] + np.repeat(dp, G), dg["p_out"], xp=np)
        ch = evaluate("running", truth, spec, {**cols, "speed_rad_s": np.repeat(drive["direction"] * speed, G),
                                               "p_a_Pa": p_a, "p_b_Pa": p_b})
        q_in = np.where(dg["direction"] > 0, ch["q_a_m3_s"], ch["q_b_m3_s"]).reshape(R, G).mean(axis=1)
        torque = (dg["direction"] * ch["torque_Nm"]).reshape(R, G).mean(axis=1)
        speed = np.maximum(speed + (drive["q_set"] - q_in) * gain, 1e-3 * drive["q_set"] * gain)
        dp = np.maximum(dp + (np.abs(drive["load_torque"]) - torque) * gain, 0.0)
    return speed, dp


def _flow_fed(protocol: Protocol, spec: MotorSpec, truth: Truth, rngs, warn) -> tuple[list, list]:
    plans, tim = protocol.runs, protocol.timing
    R = len(plans)
    drive, draws = _drive(protocol, plans, rngs)
    theta0 = draws[:, 0]
    speed, dp = _steady_state(truth, spec, drive, theta0)
    durations = np.array([running_duration(p, tim, speed=s) for p, s in zip(plans, speed)])
    span = tim.settle + durations
    ripple_hz = 2.0 * spec.pistons * speed / (2.0 * math.pi)  # flow ripple frequency (odd n: 2n per rev)
    dm = spec.displacement / (2.0 * math.pi)
    f_h = np.sqrt(drive["stiffness"] * dm**2 / (spec.inertia + drive["load_inertia"])) / (2.0 * math.pi)
    rates = np.array([p.sample_rate for p in plans])
    dt_req = 1.0 / np.maximum.reduce([STEPS_PER_RIPPLE * ripple_hz, STEPS_PER_RESONANCE * f_h, 2.0 * rates])
    steps = int(np.max(np.ceil(span / dt_req))) + 1
    dt = span / (steps - 1)
    times, th, om, p_in = dynamics.integrate(truth.params, spec, truth.mechanisms, drive, theta0,
                                             drive["direction"] * speed, drive["p_out"] + dp,
                                             np.full(R, -tim.settle), dt, steps)
    pieces = []
    for r, plan in enumerate(plans):
        t = np.arange(int(math.floor(durations[r] * plan.sample_rate + 1e-9)) + 1) / plan.sample_rate
        th_r, om_r, p_r = (np.interp(t, times[:, r], x[:, r]) for x in (th, om, p_in))
        if np.any(om_r == 0.0):
            warn(f"run {protocol.name}-{r + 1:03d}: the shaft stalls (stick-slip is not simulated in "
                 f"{protocol.procedure} runs); raise the flow or lower the load")
        pieces.append({"time_s": t, "theta_rad": th_r, "speed_rad_s": om_r, "p_in": p_r,
                       "moving": np.ones(t.size, bool)})
    cols, counts = _concat(pieces)
    cols = _load_driven_channels(truth, spec, _per_sample(drive, counts), cols,
                                 protocol.conditions.case_drain_resistance)
    return _split(cols, counts), [None] * R


# ---------------------------------------------------------------- the campaign

_PROCEDURES = {"constant_speed": _speed_held, "constant_pressure": _speed_held,
               "startability": _startability, "constant_flow": _flow_fed, "constant_torque": _flow_fed}


def protocol_names(protocols) -> list[str]:
    """Protocol names unique within a campaign (a repeated name gets a ``~k`` suffix)."""
    seen: dict[str, int] = {}
    out = []
    for p in protocols:
        seen[p.name] = seen.get(p.name, 0) + 1
        out.append(p.name if seen[p.name] == 1 else f"{p.name}~{seen[p.name]}")
    return out


def run_ids(protocols) -> list[list[str]]:
    """Run ids, unique within a campaign: ``<protocol name>-<NNN>``."""
    return [[f"{name}-{r.index + 1:03d}" for r in p.runs] for p, name in zip(protocols, protocol_names(protocols))]


def simulate_campaign(protocols, spec: MotorSpec, truth: Truth, seed: int = 0, *,
                      ideal_sensors: bool = False, omit_viscosity: bool = False) -> Campaign:
    """Simulate every run of ``protocols`` on the motor ``spec`` with the true
    parameters and mechanisms of ``truth``.

    seed : non-negative integer; the same seed gives the same campaign, bit for bit.
    ideal_sensors : read true values (no offsets, noise or quantization).
    omit_viscosity : leave the viscosity column out whatever the protocols say.
    """
    if spec.oil is None:
        raise InputError(f"motor spec '{spec.name}': the simulator needs its [oil] table (viscosity)")
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed must be a non-negative integer, got {seed!r}")
    warnings: list[str] = []
    frames, true_frames, records = [], [], []
    for pi, (protocol, ids) in enumerate(zip(protocols, run_ids(protocols))):
        if not protocol.runs:
            continue
        process = [_rng(seed, 0, pi, r.index) for r in protocol.runs]
        runs, breakaways = _PROCEDURES[protocol.procedure](protocol, spec, truth, process, warnings.append)
        sensors = protocol.sensors.ideal() if ideal_sensors else protocol.sensors
        with_visc = sensors.viscosity and not omit_viscosity
        for plan, run_id, cols, t_b in zip(protocol.runs, ids, runs, breakaways):
            n = cols["time_s"].size
            true = {k: cols[k] for k in _TRUE}
            read = sensors.read(true, _rng(seed, 1, pi, plan.index))
            meta = {"run_id": np.full(n, run_id, dtype=object),
                    "protocol": np.full(n, protocol.procedure, dtype=object), "time_s": cols["time_s"]}
            measured = {**meta, **read}
            measured["viscosity_Pa_s"] = read["viscosity_Pa_s"] if with_visc else np.full(n, np.nan)
            frames.append(pd.DataFrame(measured, columns=SI_COLUMNS))
            true_frames.append(pd.DataFrame({**meta, **{k: true[k] for k in _TRUE[1:]},
                                             "acceleration_rad_s2": cols["acceleration_rad_s2"],
                                             "moving": cols["moving"]}))
            records.append(RunRecord(run_id, protocol.name, protocol.procedure, plan, n, t_b))
    if not frames:
        raise InputError("the protocols name no runs")
    frame = pd.concat(frames, ignore_index=True)
    if frame["viscosity_Pa_s"].isna().all():
        frame = frame.drop(columns="viscosity_Pa_s")
    return Campaign(frame, pd.concat(true_frames, ignore_index=True), records, int(seed), warnings)
