"""The synthetic bench: logs that the one model reproduces, breakaway where the
breakaway torque says, sensors that match their model, reproducible bytes."""

from __future__ import annotations

import gzip
import io
import math
import tomllib

import numpy as np
import pandas as pd
import pytest

from motorid import model
from motorid.bench.protocols import parse_protocol
from motorid.bench.simulate import simulate_campaign
from motorid.bench.truth import Truth, parse_truth
from motorid.physics.base import Mechanism
from motorid.io.logs import FORMAT_COLUMNS, write_log
from motorid.model import ParameterInfo
from motorid.physics import torque as torque_physics
from motorid.physics.kinematics import port_a_sum
from motorid.model import MotorSpec, OilSpec

SPEC = MotorSpec("test-9", pistons=9, displacement=80e-6, inertia=0.005, oil=OilSpec())
TRUTH = parse_truth({"parameters": {"Kv": 5000.0, "KF": 0.003, "KFS": 0.015, "TFc": 3.0, "Ks": 1.0,
                                    "KL0": 5e-14, "KL_a1": 0.15, "KL_b1": 0.08, "KAB": 2e-14}}, "truth")
BAR, RPM, LPM = 1e5, math.pi / 30.0, 1e-3 / 60.0

PROTOCOLS = {
    "cs": """
[protocol]
procedure = "constant_speed"
standard = "ISO 4392-1"
[set_points]
pressure_difference_bar = [100.0, 250.0]
speed_rpm = [0.5, 20.0, 1500.0]
[timing]
sample_rate_Hz = [20.0, 100.0, 200.0]
duration_s = 1.0
revolutions = 1.0
""",
    "cp": """
[protocol]
procedure = "constant_pressure"
standard = "ISO 4392-1"
[set_points]
oil_temp_C = [40.0, 60.0]
pressure_difference_bar = [150.0]
speed_rpm = [300.0, 2000.0]
[timing]
sample_rate_Hz = 200.0
duration_s = 0.5
""",
    "st": """
[protocol]
procedure = "startability"
standard = "ISO 4392-2"
[set_points]
load_torque_Nm = [0.0, 60.0, 200.0]
shaft_angle_deg = [0.0, 7.0, 14.0, 21.0, 28.0, 35.0, 42.0]
[timing]
sample_rate_Hz = 50.0
ramp_rate_bar_s = 2.5
after_breakaway_s = 0.5
[dynamometer]
load_inertia_kg_m2 = 0.5
max_speed_rpm = 10.0
[supply]
pressure_ripple = 0.0002
""",
    "cf": """
[protocol]
procedure = "constant_flow"
standard = "ISO 4392-3"
[set_points]
flow_lpm = [30.0, 90.0]
load_torque_Nm = [80.0]
[timing]
sample_rate_Hz = 100.0
duration_s = 1.0
settle_s = 0.5
[dynamometer]
load_inertia_kg_m2 = 0.05
""",
    "ct": """
[protocol]
procedure = "constant_torque"
standard = "ISO 4392-3"
[set_points]
load_torque_Nm = [150.0]
flow_lpm = [15.0, 60.0]
[timing]
sample_rate_Hz = 100.0
duration_s = 1.0
settle_s = 0.5
[dynamometer]
load_inertia_kg_m2 = 0.05
""",
}


def protocol(key: str, extra: str = ""):
    return parse_protocol(tomllib.loads(PROTOCOLS[key] + extra), f"{key}.toml")


ALL = [protocol(k) for k in PROTOCOLS]


@pytest.fixture(scope="module")
def ideal():
    return simulate_campaign(ALL, SPEC, TRUTH, seed=3, ideal_sensors=True)


def read_back(path) -> pd.DataFrame:
    """A log file → canonical SI frame (the inverse of logs.FORMAT_COLUMNS)."""
    table = pd.read_csv(path)
    out = table[["run_id", "protocol"]].copy()
    for si, (col, factor) in FORMAT_COLUMNS.items():
        if col in table:
            out[si] = table[col].to_numpy(dtype=float) * factor
    return out


def model_channels(log: pd.DataFrame, acceleration, truth: Truth = TRUTH):
    s = model.make_samples(SPEC, log["theta_rad"], log["speed_rad_s"], log["p_a_Pa"], log["p_b_Pa"],
                           log["p_case_Pa"], log["viscosity_Pa_s"], acceleration)
    return model.predict(truth.params, SPEC, s, truth.mechanisms)


# ---------------------------------------------------------------- the model reproduces a noise-free log

def test_noise_free_log_reproduced_by_the_model_to_round_off(ideal, tmp_path):
    path = write_log(ideal.frame, tmp_path / "log.csv.gz", full_precision=True)
    log = read_back(path)
    true = ideal.true_frame
    assert len(log) == len(true) and (log["run_id"].to_numpy() == true["run_id"].to_numpy()).all()
    moving = true["moving"].to_numpy()
    assert 0.3 * len(log) < moving.sum() < len(log)
    ch = model_channels(log, true["acceleration_rad_s2"].to_numpy())
    scale_t = np.abs(log["torque_Nm"]).max()
    np.testing.assert_allclose(np.asarray(ch.torque)[moving], log["torque_Nm"][moving], rtol=1e-10,
                               atol=1e-11 * scale_t)
    for name, col in (("q_a", "q_a_m3_s"), ("q_b", "q_b_m3_s"), ("q_case", "q_case_m3_s")):
        np.testing.assert_allclose(np.asarray(getattr(ch, name)), log[col], rtol=1e-10,
                                   atol=1e-11 * np.abs(log[col]).max(), err_msg=name)
    np.testing.assert_allclose(np.asarray(SPEC.oil.viscosity(log["oil_temp_C"].to_numpy())),
                               log["viscosity_Pa_s"], rtol=1e-12)
    # mass balance, as logged
    np.testing.assert_allclose(log["q_a_m3_s"] + log["q_b_m3_s"], log["q_case_m3_s"], rtol=1e-9,
                               atol=1e-12)
    # while a startability shaft is stuck the transducer reads the held load, which is not the
    # running model's torque there (friction holds the difference)
    stuck = ~moving
    assert (log["speed_rad_s"][stuck] == 0.0).all()
    assert np.abs(np.asarray(ch.torque)[stuck] - log["torque_Nm"][stuck]).max() > 1.0


def test_speed_is_the_derivative_of_angle_and_acceleration_of_speed(ideal):
    true = ideal.true_frame
    for run_id, g in true[true["protocol"] == "constant_speed"].groupby("run_id"):
        if abs(g["speed_rad_s"].iloc[0]) > 30 * RPM:
            continue  # ripple near the DAQ rate: finite differences say nothing there
        t, th, w, a = (g[c].to_numpy() for c in ("time_s", "theta_rad", "speed_rad_s", "acceleration_rad_s2"))
        dtheta = np.diff(th)
        np.testing.assert_allclose(dtheta, 0.5 * (w[1:] + w[:-1]) * np.diff(t), rtol=1e-4, err_msg=run_id)
        # central differences of a 1.5 Hz ripple at 20 Hz are within (ωh)²/6 ≈ 4 %
        np.testing.assert_allclose(np.gradient(w, t)[1:-1], a[1:-1], atol=0.05 * np.abs(a).max(),
                                   err_msg=run_id)
        assert np.abs(a).max() > 0.0


def test_ports_and_directions(ideal):
    true = ideal.true_frame
    running = true[true["moving"]]
    fwd, bwd = running[running["speed_rad_s"] > 0], running[running["speed_rad_s"] < 0]
    assert len(fwd) and len(bwd)
    # forward: port A is the inlet; backward: port B (ΔP < 0), back pressure on the outlet
    assert (fwd["p_a_Pa"] > fwd["p_b_Pa"]).all() and (bwd["p_b_Pa"] > bwd["p_a_Pa"]).all()
    assert np.allclose(np.minimum(true["p_a_Pa"], true["p_b_Pa"]), 7e5)
    assert ((true["p_case_Pa"] > 0.7e5) & (true["p_case_Pa"] < 1.0e5)).all()
    # the torque delivered goes with the direction of motion in a motoring run
    speed_held = running[running["protocol"].isin(["constant_speed", "constant_pressure"])]
    assert (np.sign(speed_held["torque_Nm"]) == np.sign(speed_held["speed_rad_s"])).all()
    assert (true["q_case_m3_s"] > 0).all()


def test_low_speed_set_points_cover_a_revolution_and_the_temperature_drifts(ideal):
    true = ideal.true_frame
    cs = true[true["protocol"] == "constant_speed"]
    for run_id, g in cs.groupby("run_id"):
        turned = abs(g["theta_rad"].iloc[-1] - g["theta_rad"].iloc[0])
        assert turned >= 2 * math.pi * 0.999, run_id
        temp = g["oil_temp_C"].to_numpy()
        assert abs(temp[0] - 40.0) <= 0.5 and np.all(np.diff(temp) > 0)  # +0.2 °C/min default


def test_flow_fed_runs_hold_flow_and_load(ideal):
    true = ideal.true_frame
    for proc in ("constant_flow", "constant_torque"):
        runs = true[true["protocol"] == proc]
        for run_id, g in runs.groupby("run_id"):
            d = np.sign(g["speed_rad_s"].iloc[0])
            inlet = g["q_a_m3_s"] if d > 0 else g["q_b_m3_s"]
            plan = next(r.plan for r in ideal.runs if r.run_id == run_id)
            assert inlet.mean() == pytest.approx(plan.flow, rel=5e-3), run_id
            assert d * g["torque_Nm"].mean() == pytest.approx(plan.load_torque, rel=5e-3), run_id
            assert (np.sign(g["speed_rad_s"]) == d).all()
            # the shaft turns slower than the ideal motor by the leakage
            ideal_speed = plan.flow * 2 * math.pi / SPEC.displacement
            assert 0.85 * ideal_speed < abs(g["speed_rad_s"].mean()) < ideal_speed


# ---------------------------------------------------------------- startability (ISO 4392-2)

def breakaway_pressure(theta, load, p_out):
    """|ΔP| where the pressure torque exceeds the load by the static friction limit (base model)."""
    p, D, n = TRUTH.params, SPEC.displacement, SPEC.pistons
    s = float(port_a_sum(theta, n))
    kfs = p["KF"] + p["KFS"]
    return (load + 2 * D * p_out * kfs + p["TFc"] * (1 + p["Ks"])) / (D * s / (2 * n) - D * kfs)


def test_startability_breaks_away_at_the_predicted_pressure_without_creep(ideal):
    true = ideal.true_frame
    runs = [r for r in ideal.runs if r.procedure == "startability"]
    assert len(runs) == 42
    angles = {round(math.degrees(r.plan.shaft_angle), 6) for r in runs}
    assert max(angles) - min(angles) >= 360.0 / SPEC.pistons  # at least one piston pitch
    for r in runs:
        g = true[true["run_id"] == r.run_id]
        d, load = r.plan.direction, r.plan.load_torque
        moving = g["moving"].to_numpy()
        k = int(np.argmax(moving))
        assert moving[k] and moving[k:].all() and not moving[:k].any(), r.run_id
        assert k > 10, r.run_id
        # no creep: angle and speed exactly still before breakaway, the transducer reads the load
        before = g.iloc[:k]
        assert (before["theta_rad"] == r.plan.shaft_angle).all() and (before["speed_rad_s"] == 0).all()
        assert (before["torque_Nm"] == d * load).all()
        # breakaway between the last stuck and the first moving sample, by the model's limit
        pa, pb = g["p_a_Pa"].to_numpy(), g["p_b_Pa"].to_numpy()
        tp = np.asarray(torque_physics.pressure_torque(r.plan.shaft_angle, pa, pb, SPEC.displacement,
                                                       SPEC.pistons))
        limit = np.asarray(model.static_friction_limit(TRUTH.params, SPEC, pa, pb))
        excess = d * tp - load - limit
        assert (np.abs(d * tp[:k] - load) < limit[:k]).all(), r.run_id
        assert excess[k] >= 0.0, r.run_id
        # and at the pressure the breakaway torque predicts, to better than 0.1 bar
        dp = np.abs(pa - pb)
        expected = breakaway_pressure(r.plan.shaft_angle, load, 7e5)
        assert dp[k - 1] <= expected + 0.05 * BAR and dp[k] >= expected - 0.05 * BAR, r.run_id
        assert abs(0.5 * (dp[k - 1] + dp[k]) - expected) < 0.1 * BAR, r.run_id
        assert r.breakaway_time == pytest.approx(g["time_s"].iloc[k], abs=1 / 50.0)
        # after breakaway: the shaft speeds up in the run's direction to the limiter; the
        # transducer reads the load plus the load inertia's share
        after = g.iloc[k:]
        w = d * after["speed_rad_s"].to_numpy()
        assert (w > 0).all() and (np.diff(w) >= -1e-12).all() and w.max() == pytest.approx(10 * RPM)
        alpha = after["acceleration_rad_s2"].to_numpy()
        reading = d * load + 0.5 * alpha
        at_limit = w >= 10 * RPM * (1 - 1e-12)
        np.testing.assert_allclose(after["torque_Nm"][~at_limit], reading[~at_limit], rtol=1e-9)
        assert (d * after["torque_Nm"][at_limit] >= load).all()


def test_breakaway_varies_with_angle_and_load_as_the_ripple_says(ideal):
    """Breakaway ΔP differs across the angles by the pressure-torque ripple, rises with load."""
    runs = [r for r in ideal.runs if r.procedure == "startability" and r.plan.direction > 0]
    true = ideal.true_frame
    by_load: dict = {}
    for r in runs:
        g = true[true["run_id"] == r.run_id]
        k = int(np.argmax(g["moving"].to_numpy()))
        by_load.setdefault(r.plan.load_torque, []).append(
            (r.plan.shaft_angle, abs(g["p_a_Pa"].iloc[k] - g["p_b_Pa"].iloc[k])))
    means = [np.mean([p for _, p in by_load[L]]) for L in sorted(by_load)]
    assert np.all(np.diff(means) > 5 * BAR)
    theta, dp = np.array(by_load[max(by_load)]).T  # at 200 N·m the ripple moves ΔP by ±2.5 bar
    s = np.asarray(port_a_sum(theta, SPEC.pistons))
    assert dp.max() - dp.min() > 2 * BAR
    assert np.corrcoef(s, dp)[0, 1] < -0.99  # more pressure needed where S(θ) is low


# ---------------------------------------------------------------- sensors

SENSORS = """
[sensors.torque_Nm]
noise = 0.05
resolution = 0.01
offset = 0.5
[sensors.p_a_bar]
noise = 0.03
resolution = 0.01
offset = -0.2
[sensors.q_a_lpm]
noise = 0.01
relative_noise = 0.002
resolution = 0.001
"""


def test_noise_matches_the_sensor_model():
    protos = [protocol("cs", SENSORS), protocol("cp", SENSORS)]
    noisy = simulate_campaign(protos, SPEC, TRUTH, seed=5)
    clean = simulate_campaign(protos, SPEC, TRUTH, seed=5, ideal_sensors=True)
    assert len(noisy.frame) > 10000
    sensors = protos[0].sensors.channels
    for col, s in sensors.items():
        x, y = clean.frame[col].to_numpy(), noisy.frame[col].to_numpy()
        resid = y - x
        if s.resolution > 0:  # every reading sits on the quantization grid
            steps = y / s.resolution
            assert np.abs(steps - np.round(steps)).max() < 1e-6, col
        sigma = np.sqrt(s.std(x) ** 2 + s.resolution**2 / 12.0)
        z = (resid - s.offset) / sigma
        assert abs(z.mean()) < 0.05, col
        assert z.std() == pytest.approx(1.0, abs=0.06), col
    assert np.mean(noisy.frame["torque_Nm"] - clean.frame["torque_Nm"]) == pytest.approx(0.5, abs=0.005)
    assert np.mean(noisy.frame["p_a_Pa"] - clean.frame["p_a_Pa"]) == pytest.approx(-0.2 * BAR, abs=0.01 * BAR)
    # the relative part of the flow noise grows with the reading
    q = clean.frame["q_a_m3_s"].abs().to_numpy()
    r = (noisy.frame["q_a_m3_s"] - clean.frame["q_a_m3_s"]).to_numpy()
    big, small = q > 100 * LPM, q < 10 * LPM
    assert r[big].std() > 5 * r[small].std()


def test_same_seed_same_bytes_other_seed_other_noise(tmp_path):
    protos = [protocol("cp"), protocol("st")]
    a = simulate_campaign(protos, SPEC, TRUTH, seed=11)
    b = simulate_campaign(protos, SPEC, TRUTH, seed=11)
    c = simulate_campaign(protos, SPEC, TRUTH, seed=12)
    pa, pb, pc = (write_log(x.frame, tmp_path / f"{n}.csv.gz") for n, x in zip("abc", (a, b, c)))
    assert pa.read_bytes() == pb.read_bytes()
    assert pa.read_bytes() != pc.read_bytes()
    diff = (a.frame["torque_Nm"] - c.frame["torque_Nm"]).abs()
    assert len(a.frame) != len(c.frame) or (diff > 0).mean() > 0.5


def test_log_carries_every_required_column(tmp_path):
    camp = simulate_campaign(ALL, SPEC, TRUTH, seed=1)
    path = write_log(camp.frame, tmp_path / "log.csv.gz")
    with gzip.open(path, "rt") as fh:
        table = pd.read_csv(fh)
    required = {"time_s", "run_id", "protocol", "shaft_angle_deg", "speed_rpm", "torque_Nm", "p_a_bar",
                "p_b_bar", "p_case_bar", "q_a_lpm", "q_b_lpm", "q_case_lpm", "oil_temp_C"}
    assert required <= set(table.columns) and "viscosity_mPas" in table.columns
    assert not table[sorted(required)].isna().any().any()
    assert set(table["protocol"]) == {"constant_speed", "constant_pressure", "startability",
                                      "constant_flow", "constant_torque"}
    assert table["shaft_angle_deg"].between(0.0, 360.0, inclusive="left").all()
    for run_id, g in table.groupby("run_id", sort=False):
        assert (np.diff(g["time_s"]) > 0).all() and g["time_s"].iloc[0] == 0.0
    # run ids are unique: one run, one contiguous block
    blocks = (table["run_id"] != table["run_id"].shift()).sum()
    assert blocks == table["run_id"].nunique() == len(camp.runs)


def test_viscosity_column_can_be_omitted(tmp_path):
    off = protocol("cp", "[sensors]\nviscosity = false\n")
    camp = simulate_campaign([off], SPEC, TRUTH, seed=1)
    head = write_log(camp.frame, tmp_path / "a.csv").read_text().splitlines()[0]
    assert "viscosity_mPas" not in head and "oil_temp_C" in head
    mixed = simulate_campaign([off, protocol("ct")], SPEC, TRUTH, seed=1)
    table = pd.read_csv(io.StringIO(write_log(mixed.frame, tmp_path / "b.csv").read_text()))
    is_cp = table["protocol"] == "constant_pressure"
    assert table.loc[is_cp, "viscosity_mPas"].isna().all() and table.loc[~is_cp, "viscosity_mPas"].notna().all()
    camp = simulate_campaign([protocol("ct")], SPEC, TRUTH, seed=1, omit_viscosity=True)
    assert "viscosity_Pa_s" not in camp.frame


# ---------------------------------------------------------------- extra physics through the same model

class Drag(Mechanism):
    """A test mechanism: extra viscous-like drag c·ω and a larger static limit."""

    id = "drag"
    channels = ("torque", "breakaway")
    parameters = {"drag.c": ParameterInfo("N·m·s/rad", "drag", True, 1.0),
                  "drag.extra": ParameterInfo("N·m", "extra static friction", True, 1.0)}

    def running(self, params, spec, samples, ch):
        return ch._replace(torque=ch.torque - params["drag.c"] * samples.speed)

    def static_limit(self, params, spec, events, limit):
        return limit + params["drag.extra"]


def test_mechanisms_enter_through_the_model(tmp_path):
    truth = Truth({**TRUTH.params, "drag.c": 0.05, "drag.extra": 4.0}, (Drag(),))
    camp = simulate_campaign([protocol("cp"), protocol("st"), protocol("ct")], SPEC, truth, seed=2,
                             ideal_sensors=True)
    log = read_back(write_log(camp.frame, tmp_path / "m.csv", full_precision=True))
    true = camp.true_frame
    moving = true["moving"].to_numpy()
    alpha = true["acceleration_rad_s2"].to_numpy()
    with_mech = np.asarray(model_channels(log, alpha, truth).torque)
    without = np.asarray(model_channels(log, alpha, Truth(truth.params)).torque)
    np.testing.assert_allclose(with_mech[moving], log["torque_Nm"][moving], rtol=1e-10, atol=1e-9)
    cp = (log["protocol"] == "constant_pressure").to_numpy()
    np.testing.assert_allclose(without[cp] - log["torque_Nm"][cp], 0.05 * log["speed_rad_s"][cp], rtol=1e-8)
    # breakaway moves up by the mechanism's extra static friction: predict_breakaway holds the load there
    for r in (r for r in camp.runs if r.procedure == "startability"):
        g = true[true["run_id"] == r.run_id]
        k = int(np.argmax(g["moving"].to_numpy()))
        d = r.plan.direction
        ev = model.make_samples(SPEC, r.plan.shaft_angle, 0.0, g["p_a_Pa"].iloc[k - 1:k + 1],
                                g["p_b_Pa"].iloc[k - 1:k + 1], 0.7e5, 0.04, direction=d)
        held = d * np.asarray(model.predict_breakaway(truth.params, SPEC, ev, truth.mechanisms))
        assert held[0] < r.plan.load_torque <= held[1], r.run_id
        dp = abs(g["p_a_Pa"].iloc[k] - g["p_b_Pa"].iloc[k])
        assert dp > breakaway_pressure(r.plan.shaft_angle, r.plan.load_torque, 7e5) + 2.0 * BAR


def test_every_registered_mechanism_round_trips_through_a_truth_file():
    from motorid.physics import registry

    protos = [protocol("cp"), parse_protocol(tomllib.loads(PROTOCOLS["st"].replace(
        "load_torque_Nm = [0.0, 60.0, 200.0]", "load_torque_Nm = [60.0]").replace(
        "[0.0, 7.0, 14.0, 21.0, 28.0, 35.0, 42.0]", "[0.0, 21.0]")), "st.toml"), protocol("ct")]
    for mech in registry.all_mechanisms():
        table = {name.split(".", 1)[1]: info.typical for name, info in mech.parameters.items()}
        truth = parse_truth({"parameters": TRUTH.params, "mechanisms": {mech.id: table}}, "truth.toml")
        assert [m.id for m in truth.mechanisms] == [mech.id]
        camp = simulate_campaign(protos, SPEC, truth, seed=2, ideal_sensors=True)
        true = camp.true_frame
        moving = true["moving"].to_numpy()
        ch = model_channels(true, true["acceleration_rad_s2"].to_numpy(), truth)
        for name, col in (("torque", "torque_Nm"), ("q_a", "q_a_m3_s"), ("q_case", "q_case_m3_s")):
            np.testing.assert_allclose(np.asarray(getattr(ch, name))[moving], true[col][moving], rtol=1e-9,
                                       atol=1e-11 * np.abs(true[col]).max(), err_msg=f"{mech.id} {name}")
        for r in (r for r in camp.runs if r.procedure == "startability"):
            g = true[true["run_id"] == r.run_id]
            k = int(np.argmax(g["moving"].to_numpy()))
            ev = model.make_samples(SPEC, r.plan.shaft_angle, 0.0, g["p_a_Pa"].iloc[k - 1:k + 1],
                                    g["p_b_Pa"].iloc[k - 1:k + 1], g["p_case_Pa"].iloc[k - 1:k + 1],
                                    g["viscosity_Pa_s"].iloc[k - 1:k + 1], direction=r.plan.direction,
                                    temperature=g["oil_temp_C"].iloc[k - 1:k + 1],
                                    time=g["time_s"].iloc[k - 1:k + 1])
            held = r.plan.direction * np.asarray(model.predict_breakaway(truth.params, SPEC, ev, truth.mechanisms))
            assert held[0] < r.plan.load_torque <= held[1] + 1e-9, (mech.id, r.run_id)
