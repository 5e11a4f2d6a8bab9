"""Regenerate the concealed-cause campaigns (issue 15): spec errors, transducer errors, physics in no catalog.

    python synthetic_data/concealed/generate_causes.py [NAME ...]

Each campaign folder ``causes_<NAME>/`` holds only what the tool reads
(``campaign.csv.gz``, ``motor.toml``); the truth stays in
``truths/causes_<NAME>.toml`` (never given to the tool).  Protocols: the light
plans in ``causes_protocols/`` (64 runs, about 15 k rows).

How the causes are made, independently of motorid's own mechanism hooks:

- physics (a displacement error, a leakage phase, catalog mechanisms) runs
  through the simulator from the truth file, like any motor;
- transducer errors are applied here to the true signals the simulator logs
  (ideal sensors), then the protocol's sensor noise and quantization are added:
  a gain multiplies a column; a per-run zero offset adds a constant to a run; a
  lag is a first-order filter τ dy/dt + y = x run in time on a signal simulated
  at 40 samples per ripple period or more (exact for a signal linear between
  samples), then decimated to the protocol's sample rate;
- effects in no catalog (``EXTRA``) are added to the true running channels
  from the simulated operating point, by formulas written here only.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import tomllib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
PROTOCOLS = HERE / "causes_protocols"
sys.path.insert(0, str(HERE))
from generate import EVEN, MOTOR_8, MOTOR_9, ODD, truth_text  # noqa: E402

#: channel → log SI column
COLUMN = {"torque": "torque_Nm", "q_a": "q_a_m3_s", "q_b": "q_b_m3_s", "q_case": "q_case_m3_s"}


def _friction_inverse_viscosity(f, c):
    """Coulomb friction growing as the oil thins (boundary friction; no catalog law has it):
    T −= sgn ω · c/μ [N·m], c [N·m·Pa·s], μ from the oil temperature."""
    return {"torque": -np.sign(f["speed_rad_s"]) * c / f["viscosity_Pa_s"]}


def _case_leak_pa_pb(f, c):
    """A port-to-case leakage ∝ P_A·P_B, split between the ports by their pressures [m³/s]."""
    pa, pb = f["p_a_Pa"], f["p_b_Pa"]
    q = c * pa * pb
    return {"q_case": q, "q_a": q * pa / (pa + pb), "q_b": q * pb / (pa + pb)}


def _torque_order3_dp(f, c):
    """A torque ripple at the 3rd shaft order growing with ΔP: c·ΔP·cos(3θ + 0.7) [N·m]."""
    return {"torque": c * (f["p_a_Pa"] - f["p_b_Pa"]) * np.cos(3.0 * f["theta_rad"] + 0.7)}


def _torque_cubic_speed(f, c):
    """A torque loss ∝ ω³, growing faster than the churning law ∝ ω|ω| (a drag no catalog law has):
    T −= c·ω³ [N·m], c [N·m·s³]."""
    return {"torque": -c * f["speed_rad_s"] ** 3}


EXTRA = {"friction_inverse_viscosity": _friction_inverse_viscosity, "case_leak_pa_pb": _case_leak_pa_pb,
         "torque_order3_dp": _torque_order3_dp, "torque_cubic_speed": _torque_cubic_speed}

# name: (pistons, seed, physics {mechanism: {parameter: value}}, transducers, extra {effect: size}
#        [, protocol folder: default causes_protocols])
#   transducers: {"gain": {channel: g}, "lag": {channel: τ [s]}, "offset": {channel: constant zero [SI]},
#                 "offset_sd": {channel: σ of a zero drawn per run [SI]},
#                 "inertia": {"factor": true rotor inertia / the motor.toml's (the spec given to the tool)}}
CASES = {
    "displacement_error": (9, 201, {"displacement_error": {"eps": -0.02}}, {}, {}),
    "displacement_error_8": (8, 202, {"displacement_error": {"eps": 0.015}}, {}, {}),
    "flow_meter_gain_a": (9, 203, {}, {"gain": {"q_a": 0.01}}, {}),
    "flow_meter_gain_case": (8, 204, {}, {"gain": {"q_case": -0.04}}, {}),
    "torque_meter_gain": (9, 205, {}, {"gain": {"torque": 0.01}}, {}, "causes_protocols_back_pressure"),
    "sensor_lag_torque": (9, 206, {}, {"lag": {"torque": 2e-3}}, {}),
    "sensor_lag_q_a": (8, 207, {}, {"lag": {"q_a": 1e-3}}, {}),
    "leak_phase": (9, 208, {"leak_phase": {"dphi": 0.12}}, {}, {}),
    "displacement_and_stribeck": (9, 209, {"displacement_error": {"eps": 0.02},
                                           "stribeck_friction": {"T_s": 2.0, "K_p": 0.002, "w_s": 0.5}}, {}, {}),
    "flow_gain_b_and_turbulent": (9, 210, {"turbulent_leakage": {"C_t": 4e-10}},
                                  {"gain": {"q_b": -0.015}}, {}),
    "extra_friction_inverse_viscosity": (9, 211, {}, {}, {"friction_inverse_viscosity": 0.02}),
    "extra_case_leak_pa_pb": (9, 212, {}, {}, {"case_leak_pa_pb": 5e-20}),
    "extra_torque_order3_dp": (9, 213, {}, {}, {"torque_order3_dp": 2e-8}),
    "clean_9_seed214": (9, 214, {}, {}, {}),
    "extra_torque_cubic_speed": (8, 221, {}, {}, {"torque_cubic_speed": 1e-7}),
    # transducer zeros that differ run to run (σ of the offset per channel, SI), alone and with small gains
    "per_run_offsets": (9, 215, {}, {"offset_sd": {"torque": 0.25, "q_a": 1e-6, "q_b": 1e-6}}, {}),
    "gains_and_offsets": (8, 216, {}, {"gain": {"torque": 0.004, "q_a": -0.005, "q_case": 0.01},
                                       "offset_sd": {"torque": 0.15, "q_a": 6e-7, "q_b": 6e-7,
                                                     "q_case": 3e-8}}, {}),
    # constant zero offsets of a flow meter (the same in every run), alone and with a gain and a torque zero
    "flow_meter_offset_a": (9, 217, {}, {"offset": {"q_a": 5e-7}}, {}),
    "flow_meter_offset_case": (8, 218, {}, {"offset": {"q_case": -1.5e-7}}, {}),
    "offsets_and_gain": (9, 219, {}, {"gain": {"q_a": 0.006}, "offset": {"q_b": -6e-7, "torque": 0.4}}, {}),
    # the spec's rotor inertia leaves out what turns with the rotor up to the torque flange (a coupling,
    # the flange's hub): the true J is 4× the motor.toml's; simulated with the true J, not with the hook
    "inertia_error": (9, 220, {}, {"inertia": {"factor": 4.0}}, {}),
}


def _spec_inertia(pistons: int) -> float:
    """The rotor inertia of the motor.toml a case of ``pistons`` is given [kg·m²]."""
    text = MOTOR_9.read_text() if pistons == 9 else MOTOR_8
    return float(tomllib.loads(text)["motor"]["inertia_kg_m2"])


def truth_document(pistons: int, physics: dict, sensors: dict, extra: dict) -> str:
    """The truth file: [parameters], [mechanisms.<id>] for every named cause (physics and transducers,
    with the catalog's parameter names), [extra.<effect>] for the effects in no catalog."""
    mechs = dict(physics)
    if "inertia" in sensors:  # a spec error made by simulating with the true J (see make)
        mechs["inertia_error"] = {"dJ": _spec_inertia(pistons) * (sensors["inertia"]["factor"] - 1.0)}
    for ch, g in sensors.get("gain", {}).items():
        mechs[{"torque": "torque_meter_gain"}.get(ch, f"flow_meter_gain_{ch[2:]}")] = {"g": g}
    for ch, tau in sensors.get("lag", {}).items():
        mechs[f"sensor_lag_{ch}"] = {"tau": tau}
    for ch, c in sensors.get("offset", {}).items():
        if ch == "torque":
            mechs["torque_offset"] = {"T0": c}
        else:
            mechs[f"flow_meter_offset_{ch[2:]}"] = {"c": c}
    text = truth_text(pistons, mechs)
    for ch, sd in sensors.get("offset_sd", {}).items():
        text += f"\n[per_run_offset.{ch}]\nsd = {sd!r}\n"
    for effect, size in extra.items():
        doc = " ".join(EXTRA[effect].__doc__.split())
        text += f"\n[extra.{effect}]\nc = {size!r}\n# {doc}\n"
    return text


def first_order_lag(x, dt: float, tau: float):
    """τ dy/dt + y = x for x linear between samples spaced dt, started at rest (y₀ = x₀)."""
    from scipy.signal import lfilter

    a = math.exp(-dt / tau)
    b0 = 1.0 - tau * (1.0 - a) / dt
    b = [b0, 1.0 - a - b0]
    zi = np.array([x[0] * (1.0 - b[0])])  # steady state: y = x
    return lfilter(b, [1.0, -a], x, zi=zi)[0]


def _oversampled(protocols, pistons: int):
    """Protocols at ≥ 40 samples per ripple period (2n orders per revolution), and the factor per run."""
    out, factors = [], []
    for p in protocols:
        runs, fac = [], []
        for r in p.runs:
            rate_needed = 40.0 * 2 * pistons * (r.speed or 0.0) / (2 * math.pi)
            k = max(1, math.ceil(rate_needed / r.sample_rate))
            runs.append(dataclasses.replace(r, sample_rate=r.sample_rate * k))
            fac.append(k)
        out.append(dataclasses.replace(p, runs=tuple(runs)))
        factors.append(fac)
    return out, factors


def simulate_case(spec, truth, protocols, seed: int, sensors: dict, extra: dict):
    """The campaign frame (SI columns) as the bench would log it."""
    import pandas as pd

    from motorid.bench.simulate import run_ids, simulate_campaign

    lagging = bool(sensors.get("lag"))
    sim_protocols, factors = _oversampled(protocols, spec.pistons) if lagging else (
        protocols, [[1] * len(p.runs) for p in protocols])
    camp = simulate_campaign(sim_protocols, spec, truth, seed=seed, ideal_sensors=True)
    frame, true = camp.frame, camp.true_frame
    rng = np.random.default_rng([seed, 99])
    pieces = []
    ids = run_ids(protocols)
    for pi, p in enumerate(protocols):
        for r, rid in zip(p.runs, ids[pi]):
            sel = (frame["run_id"] == rid).to_numpy()
            f = {k: frame[k].to_numpy()[sel].copy() for k in frame.columns}
            moving = true["moving"].to_numpy()[sel] & (p.procedure != "startability")
            for effect, size in extra.items():
                for ch, dq in EXTRA[effect](f, size).items():
                    f[COLUMN[ch]] = f[COLUMN[ch]] + np.where(moving, dq, 0.0)
            for ch, tau in sensors.get("lag", {}).items():
                f[COLUMN[ch]] = first_order_lag(f[COLUMN[ch]], 1.0 / (r.sample_rate * factors[pi][r.index]), tau)
            k = factors[pi][r.index]
            f = {c: v[::k] for c, v in f.items()}
            for ch, g in sensors.get("gain", {}).items():
                f[COLUMN[ch]] = f[COLUMN[ch]] * (1.0 + g)
            for ch, c in sensors.get("offset", {}).items():
                f[COLUMN[ch]] = f[COLUMN[ch]] + c
            for ch, sd in sensors.get("offset_sd", {}).items():
                f[COLUMN[ch]] = f[COLUMN[ch]] + rng.normal(0.0, sd)
            read = p.sensors.read({c: v for c, v in f.items() if c not in ("run_id", "protocol", "time_s")},
                                  np.random.default_rng([seed, 1, pi, r.index]))
            pieces.append(pd.DataFrame({"run_id": f["run_id"], "protocol": f["protocol"], "time_s": f["time_s"],
                                        **read}, columns=frame.columns))
    return pd.concat(pieces, ignore_index=True)


def make(name: str, dest_root: Path = HERE, truths: Path = HERE / "truths") -> Path:
    """Simulate case ``name`` into ``dest_root/causes_<name>/`` and its truth into ``truths/``."""
    from motorid.bench.protocols import load_protocol
    from motorid.bench.truth import parse_truth
    from motorid.io.logs import write_log
    from motorid.io.spec import load_motor_spec

    pistons, seed, physics, sensors, extra = CASES[name][:5]
    folder = HERE / (CASES[name][5] if len(CASES[name]) > 5 else "causes_protocols")
    truths.mkdir(parents=True, exist_ok=True)
    text = truth_document(pistons, physics, sensors, extra)
    (truths / f"causes_{name}.toml").write_text(text)
    dest = dest_root / f"causes_{name}"
    dest.mkdir(parents=True, exist_ok=True)
    motor = dest / "motor.toml"
    motor.write_text(MOTOR_9.read_text() if pistons == 9 else MOTOR_8)
    spec = load_motor_spec(motor)
    table = tomllib.loads(text)
    truth = parse_truth({"parameters": table["parameters"], "mechanisms": {k: v for k, v in table.get(
        "mechanisms", {}).items() if k in physics}}, f"causes_{name}")
    protocols = [load_protocol(p) for p in sorted(folder.glob("*.toml"))]
    if "inertia" in sensors:  # the rotor the bench turns, not the one the motor.toml describes
        spec = dataclasses.replace(spec, inertia=spec.inertia * sensors["inertia"]["factor"])
    frame = simulate_case(spec, truth, protocols, seed, sensors, extra)
    write_log(frame, dest / "campaign.csv.gz")
    return dest


def main(argv=None) -> int:
    names = (argv if argv else None) or list(CASES)
    for name in names:
        print(f"causes_{name}: {make(name)}")
    return 0


assert ODD and EVEN  # the base parameters shared with generate.py


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
