"""Bench logs without a shaft angle: fitted as their operating points (motorid/identify/log_points.py)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

REPO = Path(__file__).resolve().parent.parent
DEMO = REPO / "synthetic_data" / "demo"
MBARI = REPO / "real_data" / "mbari_f11"


def _motorid(*args, cwd=None, env=None):
    return subprocess.run([sys.executable, "-m", "motorid", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, env=env)


@pytest.fixture(scope="module")
def angle_free_demo(tmp_path_factory):
    """The demo campaign as a bench without a shaft encoder writes it: no shaft-angle column."""
    folder = tmp_path_factory.mktemp("noangle")
    frame = pd.read_csv(DEMO / "campaign.csv.gz").drop(columns=["shaft_angle_deg"])
    path = folder / "campaign.csv"
    frame.to_csv(path, index=False)
    return path


def test_a_log_without_shaft_angle_recovers_every_angle_free_parameter_within_its_uncertainty(angle_free_demo,
                                                                                                tmp_path):
    """Before, such a log identified nothing (every running run left out for its missing angle),
    and a log without the column was refused.  The angle-averaged model holds K_v, K_F, T_Fc, K_L0
    and K_AB, and the breakaways (taken at the pressure torque's mean over the angle) K_FS and K_s:
    each recovered within 3 std of the demo's truth; the harmonics are not identifiable, for a
    reason that names the missing angle."""
    import tomllib

    out = tmp_path / "fit"
    scratch = tmp_path / "scratch"  # the command's temporary folder: the points' copy is gone when it ends
    scratch.mkdir()
    proc = _motorid("fit", angle_free_demo, "--motor", DEMO / "motor.toml", "--out", out,
                    env={**os.environ, "TMPDIR": str(scratch)})
    assert proc.returncode == 0, proc.stderr
    assert not list(scratch.glob("motorid-points-*"))
    doc = json.loads((out / "result.json").read_text())
    truth = tomllib.loads((DEMO / "truth.toml").read_text())["parameters"]
    par = doc["parameters"]
    for k in ("Kv", "KF", "TFc", "KL0", "KAB", "KFS", "Ks"):
        assert par[k]["identifiable"], k
        assert abs(par[k]["value"] - truth[k]) < 3 * par[k]["std"], (k, par[k]["value"], par[k]["std"], truth[k])
    for k in ("KL_a1", "KL_b1"):
        assert not par[k]["identifiable"]
    assert "no shaft angle" in par["KL_a1"]["reason"]
    # the points alone would give K_v within 1 %: the aliased runs are weighted by what their sampling leaves
    assert par["Kv"]["std"] < 0.01 * truth["Kv"]
    # the points go with the result, named in its inputs, with the logs they came from
    points = out / "points_from_logs.csv"
    assert doc["inputs"]["tables"] == [str(points.resolve())]
    assert doc["inputs"]["reduced_logs"] == [str(angle_free_demo)]
    assert "startability" in doc["fit"]["warnings"][0]
    assert "no shaft angle in these logs" in doc["fit"]["warnings"][0]
    # one point per steady running run of the campaign (126), none from its startability runs
    table = pd.read_csv(points)
    runs = pd.read_csv(angle_free_demo)
    running = runs.loc[runs["protocol"] != "startability", "run_id"].nunique()
    assert len(table) == running and (table["source"] == "steady run").all()
    # and predict takes the folder
    pred = tmp_path / "pred.csv"
    proc = _motorid("predict", out, points, "--out", pred)
    assert proc.returncode == 0, proc.stderr
    p = pd.read_csv(pred)
    # the points are the model's own means: its prediction lies within 1 % of the torque span of each
    span = np.ptp(table["torque_Nm"])
    assert np.max(np.abs(p["torque_Nm"] - table["torque_Nm"])) < 0.01 * span


def test_an_empty_shaft_angle_column_reads_as_no_angle_too(tmp_path):
    from motorid.identify.log_points import logs_lack_shaft_angle

    frame = pd.read_csv(DEMO / "campaign.csv.gz", nrows=3000)
    with_angle = tmp_path / "a.csv"
    frame.to_csv(with_angle, index=False)
    empty = tmp_path / "b.csv"
    frame.assign(shaft_angle_deg=np.nan).to_csv(empty, index=False)
    assert not logs_lack_shaft_angle([with_angle])
    assert logs_lack_shaft_angle([empty])
    assert not logs_lack_shaft_angle([with_angle, empty])  # one log with an angle: the log fit


def _recording_of_motion(seconds=120.0, rate=200.0, seed=3):
    """A continuous motion as a test machine drives it (no steady stretch): speed a slow sine,
    ΔP another; torque and port flow linear in the inputs, with noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate)
    w = 150.0 * np.sin(2 * np.pi * t / 30.0)  # rad/s
    dp = 1e7 * (1.2 + np.sin(2 * np.pi * t / 17.0))  # Pa
    torque = 1.5e-6 * dp - 0.01 * w + rng.normal(0, 0.2, t.size)
    q_a = 1e-5 * w / (2 * np.pi) + 1e-12 * dp + rng.normal(0, 1e-6, t.size)
    return pd.DataFrame({
        "time_s": t, "run": "motion", "protocol": "constant_flow", "file": "m.csv", "speed_rad_s": w,
        "p_a_Pa": dp + 1e6, "p_b_Pa": np.full(t.size, 1e6), "p_case_Pa": np.zeros(t.size), "torque_Nm": torque,
        "q_a_m3_s": q_a, "oil_temp_C": np.full(t.size, 40.0), "viscosity_Pa_s": np.full(t.size, 0.03),
        "theta_rad": np.full(t.size, np.nan)})


def test_a_recording_in_motion_gives_quasi_steady_cells_whose_means_keep_the_law():
    """A run with no steady stretch is binned by speed and ΔP where it barely accelerates: each
    cell's mean torque and flow follow the same (linear) law of its mean inputs, and no cell holds
    samples that accelerate faster than the campaign's speed per ACCEL_TIME_S."""
    from motorid.identify.log_points import MIN_CELL_SAMPLES, operating_points

    frame = _recording_of_motion()
    points, notes = operating_points(frame)
    assert len(points) >= 10 and (points["source"] == "quasi-steady cell").all()
    assert (points["n_samples"] >= MIN_CELL_SAMPLES).all()
    dp = (points["p_a_bar"] - points["p_b_bar"]) * 1e5
    w = points["speed_rpm"] * math.pi / 30
    law = 1.5e-6 * dp - 0.01 * w
    assert np.max(np.abs(points["torque_Nm"] - law)) < 0.1  # 0.2 N·m noise over ≥ 100 samples: under 5 std errors
    q_law = (1e-5 * w / (2 * np.pi) + 1e-12 * dp) * 6e4
    assert np.max(np.abs(points["q_a_lpm"] - q_law)) < 0.03  # 0.06 L/min noise: under 5 std errors
    # the acceleration test: no cell of the fast turning-points (|dω/dt| > speed/ACCEL_TIME_S) sneaks in
    assert (points["speed_rpm"].abs() > 0.05 * 150.0 * 30 / math.pi).all()
    assert not notes


def test_a_point_that_breaks_the_first_law_is_left_out_with_a_note():
    from motorid.identify.log_points import operating_points

    frame = _recording_of_motion()
    # a shaft that delivers torque (T·ω > 0) while the ports also give power out (ΔP·Q_A < 0)
    frame["torque_Nm"] = 5.0 * np.sign(frame["speed_rad_s"])
    frame["q_a_m3_s"] = -1e-4
    points, notes = operating_points(frame)
    assert points.empty
    assert any("first law" in n for n in notes)


def test_the_mbari_recordings_fit_as_they_were_written_and_predict_held_out_points_like_the_classical_models(
        tmp_path):
    """The real F11-5 recordings (no shaft angle, no case sensors, continuous wave-like motion) go
    straight into `motorid fit` through their channel map: the motion is reduced to quasi-steady
    cells, and motorid's 5-fold held-out torque error is within 10 % of the best classical model's,
    while it extrapolates in ΔP better than every one of them (numbers in benchmarks/results.md)."""
    out = tmp_path / "mbari"
    proc = _motorid("fit", MBARI, "--motor", MBARI / "motor.toml", "--out", out)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((out / "result.json").read_text())
    for k in ("Kv", "KF", "TFc"):
        assert doc["parameters"][k]["identifiable"]
    assert any("no case pressure" in w for w in doc["fit"]["warnings"])
    # no startability run among the recordings: said in the logs' words, not a table's
    assert doc["parameters"]["KFS"]["reason"].startswith("these logs hold no startability run")
    models = doc["comparison"]["models"]
    others = {k: v for k, v in models.items() if not k.startswith("motorid")}  # the classical models
    ours = models["motorid"]
    best = min(v["kfold"]["torque"]["rms"] for v in others.values())
    assert ours["kfold"]["torque"]["rms"] <= 1.1 * best
    assert ours["extrapolate_pressure"]["torque"]["rms"] < min(
        v["extrapolate_pressure"]["torque"]["rms"] for v in others.values())
    assert doc["inputs"]["reduced_logs"] and len(pd.read_csv(out / "points_from_logs.csv")) >= 40


def test_ripple_coverage_tells_a_run_sampled_in_step_with_the_pitch_frequency():
    """9 pistons at 1000 rpm: pitch frequency 150 Hz.  Sampled at 50 Hz every sample sees one phase of
    the ripple (coverage 1); at 47 Hz over 2 s the phases spread and the ripple averages out."""
    from motorid.identify.log_points import ripple_coverage

    w = 1000 * math.pi / 30
    for rate, low in ((50.0, False), (47.0, True)):
        t = np.arange(0, 2.0, 1 / rate)
        d = ripple_coverage(t, np.full(t.size, w), 9)
        assert (d < 0.3) if low else (d > 0.95), (rate, d)


def test_the_points_of_a_log_without_angle_agree_with_the_model_within_their_standard_errors():
    """The demo's steady runs reduced to points, against the θ-averaged model at the demo's true
    parameters: each output within 4 of the point's standard errors (spread/√n, widened by what the
    sampling leaves of the ripple), and about one in the RMS.  Without the widening, runs sampled in
    step with the pitch frequency lie tens of standard errors off (diagnose then named physics on a
    clean motor)."""
    import tomllib

    from motorid.identify.log_points import operating_points
    from motorid.identify.tables import point_channels, table_samples
    from motorid.io.logs import read_logs
    from motorid.io.spec import load_motor_spec
    from motorid.io.tables import read_table

    spec = load_motor_spec(DEMO / "motor.toml")
    frame = read_logs([DEMO / "campaign.csv.gz"], spec)
    frame["theta_rad"] = np.nan
    points, _ = operating_points(frame, spec)
    path = Path(__import__("tempfile").mkdtemp()) / "p.csv"
    points.to_csv(path, index=False)
    table = read_table(path, spec)
    truth = tomllib.loads((DEMO / "truth.toml").read_text())["parameters"]
    model = point_channels(truth, spec, table_samples(spec, table))
    for c, v, col, unit in zip(("torque", "q_a", "q_b", "q_case"), model,
                               ("torque_std_Nm", "q_a_std_lpm", "q_b_std_lpm", "q_case_std_lpm"),
                               (1.0, 1 / 6e4, 1 / 6e4, 1 / 6e4)):
        se = points[col].to_numpy() * unit / np.sqrt(points["n_samples"].to_numpy())
        z = (table.measured[c] - np.asarray(v)) / se
        assert np.max(np.abs(z)) < 4 and np.sqrt(np.mean(z ** 2)) < 1.5, (c, np.max(np.abs(z)))


@pytest.mark.slow
@pytest.mark.parametrize("campaign,named", [("clean_9_seed101", []), ("mixed_lubrication", ["mixed_lubrication"])])
def test_diagnose_on_logs_without_angle_names_what_is_there_and_nothing_on_a_clean_motor(campaign, named,
                                                                                      tmp_path):
    folder = REPO / "synthetic_data" / "concealed" / campaign
    log = tmp_path / "log.csv"
    pd.read_csv(folder / "campaign.csv.gz").drop(columns=["shaft_angle_deg"]).to_csv(log, index=False)
    out = tmp_path / "dg"
    proc = _motorid("diagnose", log, "--motor", folder / "motor.toml", "--out", out)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((out / "diagnosis.json").read_text())
    assert [m["id"] for m in doc["mechanisms"]] == named
    assert (out / "points_from_logs.csv").exists() and (out / "result.json").exists()


def test_a_parquet_log_without_angle_takes_the_points_path_and_a_mixed_campaign_warns(tmp_path):
    """The cheap test reads CSV headers only: a Parquet log without the angle column is found out
    from the extracted runs (every running run left out for its missing angle) and fitted as its
    points, where it gave exit 0 with nothing identified.  A campaign where some logs hold an angle
    and others none: the second become points, fitted jointly with the first (their runs were left
    out), every parameter within 3 std of the truth, the harmonics from the logs with an angle."""
    import tomllib

    import motorid

    frame = pd.read_csv(DEMO / "campaign.csv.gz")
    pq = tmp_path / "c.parquet"
    frame.drop(columns=["shaft_angle_deg"]).to_parquet(pq)
    fit = motorid.fit([pq], DEMO / "motor.toml")
    assert fit.log_points is not None and fit.document["parameters"]["Kv"]["identifiable"]
    fit.save(tmp_path / "out")
    assert (tmp_path / "out" / "points_from_logs.csv").exists()
    runs = frame["run_id"].unique()
    half = set(runs[::2])
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    frame[frame["run_id"].isin(half)].to_csv(a, index=False)
    frame[~frame["run_id"].isin(half)].assign(shaft_angle_deg=np.nan).to_csv(b, index=False)
    mixed = motorid.fit([a, b], DEMO / "motor.toml")
    assert mixed.log_points is not None and mixed.log_points.sources == (str(b),)
    assert "no shaft angle in 1 of the 2 logs (b.csv)" in mixed.warnings[0]
    truth = tomllib.loads((DEMO / "truth.toml").read_text())["parameters"]
    par = mixed.document["parameters"]
    for k, v in truth.items():
        assert par[k]["identifiable"] and abs(par[k]["value"] - v) < 3 * par[k]["std"], (k, par[k], v)


def test_a_refusal_of_the_points_names_the_logs_not_a_temporary_file(tmp_path):
    """A pump-sign log read as a motor's: the ideal-machine check refuses the points, naming the log."""
    frame = pd.read_csv(DEMO / "campaign.csv.gz").drop(columns=["shaft_angle_deg"])
    frame["torque_Nm"] = -frame["torque_Nm"]
    log = tmp_path / "pumpsign.csv"
    frame.to_csv(log, index=False)
    proc = _motorid("fit", log, "--motor", DEMO / "motor.toml", "--out", tmp_path / "o")
    assert proc.returncode == 2
    line = proc.stderr.strip().splitlines()[-1]
    assert "pumpsign.csv" in line and "motorid-points-" not in line, line
    assert not (tmp_path / "o").exists()


def test_the_inertia_torque_of_a_cells_mean_acceleration_is_taken_out_where_the_spec_gives_j():
    """A recording in motion whose torque carries −J·α (Eq. 17): with the spec's J the cells keep the
    steady law; the cells accelerate, so without J their torque is off by J·ᾱ."""
    from motorid.identify.log_points import operating_points
    from motorid.model import MotorSpec

    frame = _recording_of_motion(seconds=240.0)
    t, w = frame["time_s"].to_numpy(), frame["speed_rad_s"].to_numpy()
    alpha = np.gradient(w, t)
    J = 0.5  # kg·m², large enough that J·α (up to 16 N·m) dwarfs the noise
    frame["torque_Nm"] = frame["torque_Nm"] - J * alpha
    spec = MotorSpec("probe", 9, 80e-6, J)
    points, _ = operating_points(frame, spec)
    dp = (points["p_a_bar"] - points["p_b_bar"]) * 1e5
    law = 1.5e-6 * dp - 0.01 * points["speed_rpm"] * math.pi / 30
    assert np.max(np.abs(points["torque_Nm"] - law)) < 0.15
    bare, _ = operating_points(frame, MotorSpec("probe", 9, 80e-6, 0.0))
    assert np.max(np.abs(bare["torque_Nm"] - law)) > 1.0
    assert np.isfinite(points["accel_rpm_s"]).all()


def test_a_log_without_run_ids_is_refused_with_the_way_to_read_it(tmp_path):
    """Runs logged one after another with no run column: the refusal says how a channel map reads them."""
    frame = pd.read_csv(DEMO / "campaign.csv.gz", nrows=2000).drop(columns=["run_id"])
    log = tmp_path / "norun.csv"
    frame.to_csv(log, index=False)
    proc = _motorid("fit", log, "--motor", DEMO / "motor.toml", "--out", tmp_path / "o")
    assert proc.returncode == 2
    line = proc.stderr.strip().splitlines()[-1]
    assert "missing required column 'run_id'" in line and "channel map without run_id" in line
