"""Protocol and truth files, the `motorid simulate` command and the demo campaign."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from motorid.bench.protocols import load_protocol, parse_protocol
from motorid.bench.simulate import simulate_campaign
from motorid.bench.truth import load_truth, parse_truth
from motorid.physics.base import Mechanism
from motorid.errors import InputError
from motorid.io.logs import PROTOCOLS
from motorid.model import ParameterInfo
from motorid.io.spec import load_motor_spec

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "synthetic_data" / "demo"
PROTOCOL_DIR = ROOT / "protocols"

GOOD = """
[protocol]
procedure = "constant_speed"
standard = "ISO 4392-1"
[set_points]
pressure_difference_bar = [100.0]
speed_rpm = [1.0, 100.0]
[timing]
sample_rate_Hz = [5.0, 50.0]
duration_s = 1.0
"""


def parse(text: str, name: str = "plan.toml"):
    return parse_protocol(tomllib.loads(text), name)


# ---------------------------------------------------------------- protocols

def test_shipped_protocols_cover_every_procedure_and_cite_their_standard():
    protos = [load_protocol(p) for p in sorted(PROTOCOL_DIR.glob("*.toml"))]
    assert {p.procedure for p in protos} == set(PROTOCOLS)
    for p in protos:
        part = {"constant_speed": "4392-1", "constant_pressure": "4392-1", "startability": "4392-2",
                "constant_flow": "4392-3", "constant_torque": "4392-3"}[p.procedure]
        assert f"ISO {part}" in p.standard, p.name
        assert p.runs and {r.direction for r in p.runs} == {1, -1}, p.name
    cs = next(p for p in protos if p.procedure == "constant_speed")
    speeds = sorted({r.speed for r in cs.runs})
    assert speeds[0] < 0.5 * math.pi / 30 and speeds[-1] >= 2000 * math.pi / 30  # well below 1 rpm to rated
    assert len({r.pressure_difference for r in cs.runs}) >= 3 and cs.timing.revolutions >= 1.0
    st = next(p for p in protos if p.procedure == "startability")
    angles = sorted({r.shaft_angle for r in st.runs})
    assert angles[-1] - angles[0] >= 2 * math.pi / 9 and len({r.load_torque for r in st.runs}) >= 3
    assert st.timing.ramp_rate / st.runs[0].sample_rate <= 0.1e5  # breakaway pressure resolved to 0.1 bar


def test_a_user_plan_gives_the_grid_of_its_set_points():
    p = parse(GOOD)
    assert p.name == "plan" and p.procedure == "constant_speed" and len(p.runs) == 4
    first = p.runs[0]
    assert first.direction == 1 and first.speed == pytest.approx(math.pi / 30) and first.sample_rate == 5.0
    assert first.pressure_difference == 100e5 and first.oil_temp == 40.0
    assert [r.direction for r in p.runs] == [1, 1, -1, -1]
    assert p.timing.revolutions == 1.0  # constant speed: a full revolution unless told otherwise


@pytest.mark.parametrize("edit,key", [
    (("procedure = \"constant_speed\"", "procedure = \"fast\""), "procedure"),
    (("standard = \"ISO 4392-1\"\n", ""), "standard"),
    (("speed_rpm = [1.0, 100.0]", "speed_rpm = [-1.0, 100.0]"), "speed_rpm"),
    (("speed_rpm = [1.0, 100.0]", "speed_rpm = []"), "speed_rpm"),
    (("speed_rpm = [1.0, 100.0]", "speed_rpm = [1.0, \"fast\"]"), "speed_rpm"),
    (("sample_rate_Hz = [5.0, 50.0]", "sample_rate_Hz = [5.0]"), "sample_rate_Hz"),
    (("sample_rate_Hz = [5.0, 50.0]\n", ""), "sample_rate_Hz"),
    (("duration_s = 1.0", "duration_s = 1.0\nramp_rate_bar_s = 2.0"), "ramp_rate_bar_s"),
    (("duration_s = 1.0", "duratoin_s = 1.0"), "duratoin_s"),
    (("[set_points]", "[set_points]\ndirections = [\"up\"]"), "directions"),
    (("[set_points]", "[set_points]\nshaft_angle_deg = [0.0]"), "shaft_angle_deg"),
    (("[timing]", "[sensors.torque_Nm]\nnoise = -1.0\n[timing]"), "noise"),
    (("[timing]", "[sensors.torque]\nnoise = 1.0\n[timing]"), "torque"),
    (("[timing]", "[sensors]\nviscosity = \"yes\"\n[timing]"), "viscosity"),
    (("[timing]", "[conditions]\nback_pressure_bar = \"7\"\n[timing]"), "back_pressure_bar"),
    (("[timing]", "[dynamometer]\nspeed_ripple = 0.9\n[timing]"), "speed_ripple"),
    (("sample_rate_Hz = [5.0, 50.0]", "sample_rate_Hz = [5e5, 50.0]"), "sample_rate_Hz"),
])
def test_bad_plans_name_the_file_and_key(edit, key):
    old, new = edit
    assert old in GOOD
    with pytest.raises(InputError) as err:
        parse(GOOD.replace(old, new), "my_plan.toml")
    msg = str(err.value)
    assert "my_plan.toml" in msg and key in msg and "\n" not in msg


def test_unreadable_or_invalid_protocol_files(tmp_path):
    with pytest.raises(InputError, match="cannot read protocol"):
        load_protocol(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[protocol\n")
    with pytest.raises(InputError, match="bad.toml: not valid TOML"):
        load_protocol(bad)


def test_startability_plan_and_its_defaults():
    text = """
[protocol]
procedure = "startability"
standard = "ISO 4392-2"
[set_points]
directions = [-1]
load_torque_Nm = [10.0, 20.0]
shaft_angle_deg = [0.0, 20.0, 40.0]
[timing]
sample_rate_Hz = 100.0
ramp_rate_bar_s = 1.0
"""
    p = parse(text)
    assert len(p.runs) == 6 and all(r.direction == -1 for r in p.runs)
    assert p.timing.ramp_rate == 1e5 and p.timing.after_breakaway == 1.0 and p.timing.start_pressure is None
    with pytest.raises(InputError, match="sample_rate_Hz.*one number"):
        parse(text.replace("sample_rate_Hz = 100.0", "sample_rate_Hz = [100.0, 50.0]"))
    with pytest.raises(InputError, match="start_pressure_bar"):
        parse(text.replace("ramp_rate_bar_s = 1.0", "ramp_rate_bar_s = 1.0\nstart_pressure_bar = 500.0"))


# ---------------------------------------------------------------- truth

BASE = {"Kv": 5000.0, "KF": 0.003, "KFS": 0.015, "TFc": 3.0, "Ks": 1.0, "KL0": 5e-14, "KAB": 2e-14}


def test_truth_file_and_its_errors():
    t = load_truth(DEMO / "truth.toml")
    assert t.params["KL_a1"] == 0.15 and t.harmonics == 1 and t.mechanisms == ()
    assert parse_truth({"parameters": {**BASE, "KL_b2": 0.01}}).params["KL_a2"] == 0.0
    for data, key in [({"parameters": {k: v for k, v in BASE.items() if k != "KF"}}, "KF"),
                      ({"parameters": {**BASE, "Kq": 1.0}}, "Kq"),
                      ({"parameters": {**BASE, "KL0": -1e-14}}, "KL0"),
                      ({"parameters": {**BASE, "TFc": "3"}}, "TFc"),
                      ({"params": BASE}, "params")]:
        with pytest.raises(InputError, match=key):
            parse_truth(data, "t.toml")


class Tilt(Mechanism):
    id = "tilt"
    parameters = {"tilt.k": ParameterInfo("N·m", "test", True, 1.0)}


def test_mechanisms_resolve_through_the_registry(monkeypatch):
    from motorid.physics import registry

    data = {"parameters": BASE, "mechanisms": {"tilt": {"k": 2.0}}}
    with pytest.raises(InputError, match="unknown mechanism 'tilt'; known: stribeck_friction"):
        parse_truth(data, "t.toml")
    monkeypatch.setitem(registry.CATALOG, "tilt", Tilt())
    t = parse_truth(data, "t.toml")
    assert isinstance(t.mechanisms[0], Tilt) and t.params["tilt.k"] == 2.0
    with pytest.raises(InputError, match=r"t.toml \[mechanisms.nope\]: unknown mechanism 'nope'"):
        parse_truth({"parameters": BASE, "mechanisms": {"nope": {}}}, "t.toml")
    with pytest.raises(InputError, match="unknown parameter 'q'.*takes: k"):
        parse_truth({"parameters": BASE, "mechanisms": {"tilt": {"q": 1.0}}}, "t.toml")
    with pytest.raises(InputError, match="missing key 'k'"):
        parse_truth({"parameters": BASE, "mechanisms": {"tilt": {}}}, "t.toml")


# ---------------------------------------------------------------- the command

def motorid(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "motorid", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd)


def test_simulate_command_writes_a_campaign_and_refuses_to_overwrite(tmp_path):
    plan = tmp_path / "plan.toml"
    plan.write_text(GOOD)
    out = tmp_path / "out"
    args = ["simulate", "--protocol", plan, PROTOCOL_DIR / "iso4392-3_constant_torque.toml",
            "--motor", DEMO / "motor.toml", "--truth", DEMO / "truth.toml", "--out", out, "--seed", 4]
    run = motorid(*args)
    assert run.returncode == 0, run.stderr
    assert "rows" in run.stdout
    for name in ("campaign.csv.gz", "truth.toml", "motor.toml", "manifest.json", "protocols/plan.toml",
                 "protocols/iso4392-3_constant_torque.toml"):
        assert (out / name).is_file(), name
    assert (out / "truth.toml").read_bytes() == (DEMO / "truth.toml").read_bytes()
    manifest = json.loads((out / "manifest.json").read_text())
    table = pd.read_csv(out / "campaign.csv.gz")
    assert manifest["seed"] == 4 and manifest["rows"] == len(table) == sum(r["rows"] for r in manifest["runs"])
    assert [r["run_id"] for r in manifest["runs"]] == list(dict.fromkeys(table["run_id"]))
    before = (out / "campaign.csv.gz").read_bytes()
    again = motorid(*args)
    assert again.returncode == 2 and "--force" in again.stderr and "Traceback" not in again.stderr
    assert len(again.stderr.strip().splitlines()) == 1
    forced = motorid(*args, "--force", "--omit-viscosity")
    assert forced.returncode == 0, forced.stderr
    assert (out / "campaign.csv.gz").read_bytes() != before
    assert "viscosity_mPas" not in pd.read_csv(out / "campaign.csv.gz", nrows=1).columns


def test_simulate_command_reports_bad_input_in_one_line(tmp_path):
    plan = tmp_path / "plan.toml"
    plan.write_text(GOOD.replace("duration_s = 1.0", "duration_s = -1.0"))
    run = motorid("simulate", "--protocol", plan, "--motor", DEMO / "motor.toml", "--truth",
                  DEMO / "truth.toml", "--out", tmp_path / "o")
    assert run.returncode == 2 and "plan.toml [timing]" in run.stderr and "duration_s" in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


# ---------------------------------------------------------------- the demo campaign

@pytest.fixture(scope="module")
def demo_log():
    return pd.read_csv(DEMO / "campaign.csv.gz")


def test_demo_is_small_complete_and_documented(demo_log):
    files = [p for p in DEMO.rglob("*") if p.is_file()]
    assert sum(p.stat().st_size for p in files) < 2.5e6
    for name in ("campaign.csv.gz", "truth.toml", "motor.toml", "manifest.json", "README.md"):
        assert (DEMO / name).is_file(), name
    manifest = json.loads((DEMO / "manifest.json").read_text())
    assert manifest["rows"] == len(demo_log) and 50_000 <= len(demo_log) <= 150_000
    assert set(demo_log["protocol"]) == set(PROTOCOLS)
    assert "motorid simulate" in (DEMO / "README.md").read_text()


def test_demo_motor_is_realistic(demo_log):
    """Efficiencies as a bench engineer would read them off the demo log."""
    spec = load_motor_spec(DEMO / "motor.toml")
    assert spec.pistons == 9 and spec.displacement == pytest.approx(80e-6)
    log = demo_log
    dp = (log["p_a_bar"] - log["p_b_bar"]) * 1e5
    ideal_torque = spec.displacement * dp / (2 * math.pi)
    cp = log[(log["protocol"] == "constant_pressure") & (dp.abs() > 200e5)]
    eta_m = (cp["torque_Nm"] / ideal_torque[cp.index]).groupby(cp["run_id"]).mean()
    assert eta_m.between(0.92, 0.975).all()
    assert cp["q_case_lpm"].between(1.0, 6.0).all()  # a few L/min at rated pressure
    # starting torque efficiency: held load over the ideal torque at breakaway
    st = log[log["protocol"] == "startability"]
    etas = []
    for run_id, g in st.groupby("run_id"):
        k = int(np.argmax(g["speed_rpm"].abs().to_numpy() > 1.0))
        last_stuck = g.iloc[k - 1]
        ideal = spec.displacement * abs(last_stuck["p_a_bar"] - last_stuck["p_b_bar"]) * 1e5 / (2 * math.pi)
        if ideal > 100:
            etas.append(abs(last_stuck["torque_Nm"]) / ideal)
    assert len(etas) > 20 and 0.80 <= min(etas) and max(etas) <= 0.90


def test_demo_regenerates_in_seconds(demo_log, tmp_path):
    spec = load_motor_spec(DEMO / "motor.toml")
    truth = load_truth(DEMO / "truth.toml")
    protos = [load_protocol(p) for p in sorted(PROTOCOL_DIR.glob("*.toml"))]
    start = time.perf_counter()
    camp = simulate_campaign(protos, spec, truth, seed=json.loads((DEMO / "manifest.json").read_text())["seed"])
    elapsed = time.perf_counter() - start
    assert elapsed < 30.0
    from motorid.io.logs import write_log

    fresh = pd.read_csv(write_log(camp.frame, tmp_path / "fresh.csv.gz"))
    assert list(fresh.columns) == list(demo_log.columns) and len(fresh) == len(demo_log)
    assert (fresh["run_id"] == demo_log["run_id"]).all()
    numeric = fresh.select_dtypes("number").columns
    differ = ~np.isclose(fresh[numeric].to_numpy(), demo_log[numeric].to_numpy(), rtol=1e-9, atol=0.0)
    assert differ.mean() < 1e-4  # the committed demo is what the code makes (to a rare last digit)
