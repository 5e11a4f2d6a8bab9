"""A table's noise that grows with the reading (identify/table_noise.py), the model error's neighbours on
one side of ω = 0 (identify/lack_of_fit.py), and the kriged model error in `motorid predict`."""

import json
import subprocess
import sys
import tomllib

import numpy as np
import pandas as pd
import pytest

from motorid.identify.table_noise import READING_NOISE_LR, channel_noise

SPEC = "synthetic_data/demo/motor.toml"


def _truth():
    return tomllib.loads(open("synthetic_data/demo/truth.toml").read())["parameters"]


def test_noise_growing_with_the_reading_is_taken_only_where_the_likelihood_says_so():
    """Residuals of σ_i = 0.02 + 0.01·|y_i|: the shape growing with the reading is chosen and its share
    recovered within 25 %; residuals of one σ: one σ is kept in at least 48 of 50 draws (the test is at
    χ²₁'s 0.1 % point, so a draw or two may pass by chance)."""
    rng = np.random.default_rng(0)
    y = np.linspace(0.5, 400.0, 120)
    grown = [channel_noise(rng.normal(size=y.size) * np.sqrt(0.02**2 + (0.01 * y) ** 2), y, None, 1.0, 1.0, 1e-12)
             for _ in range(5)]
    assert all(g.reading_share is not None for g in grown)
    assert all(abs(g.reading_share / 0.01 - 1) < 0.25 for g in grown)
    flat = [channel_noise(0.7 * rng.normal(size=y.size), y, None, 1.0, 1.0, 1e-12) for _ in range(50)]
    assert sum(f.reading_share is not None for f in flat) <= 2
    assert all(abs(f.scale / 0.7 - 1) < 0.2 for f in flat if f.reading_share is None)
    assert READING_NOISE_LR > 10  # one parameter more, at the 0.1 % level


def _map_with_reading_noise(tmp_path, rng, share=0.004):
    """A map of the demo motor whose noise is a share of each reading (a transducer's accuracy class),
    speeds from 5 to 2500 rpm so the readings span three decades."""
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.io.spec import load_motor_spec

    spec = load_motor_spec(SPEC)
    grid = map_grid(np.geomspace(5, 2500, 12), np.linspace(20, 300, 8), quadrants=1)
    frame = simulate_map(spec, _truth(), grid, rng=rng)
    for col, floor in (("torque_Nm", 0.01), ("q_a_lpm", 0.002), ("q_b_lpm", 0.002), ("q_case_lpm", 0.001)):
        v = frame[col].to_numpy()
        frame[col] = v + rng.standard_normal(len(v)) * np.sqrt(floor**2 + (share * v) ** 2)
    return spec, frame


def test_a_map_with_noise_growing_with_the_reading_gets_bands_that_hold_at_both_ends(tmp_path):
    """Fitted on a map whose noise is 0.4 % of each reading, the fit says so (result.json
    ``reading_share`` within 30 % of 0.4 %), and the prediction bands of new readings hold 95 % of them
    at the low readings as at the high ones (at least 85 % in each half of new draws at the 96 points;
    torque reads with ΔP, the inlet flow with speed); one σ for all would miss most high readings and
    be far too wide at the low ones."""
    from motorid.identify.predict import predict_points
    from motorid.identify.table_pipeline import identify_tables, table_result_document
    from motorid.io.tables import read_table

    rng = np.random.default_rng(3)
    spec, frame = _map_with_reading_noise(tmp_path, rng)
    frame.to_csv(tmp_path / "map.csv", index=False)
    tf = identify_tables([], [tmp_path / "map.csv"], spec)
    doc = table_result_document(tf, spec, {})
    noise = doc["table"]["noise"]
    assert noise["q_a"].get("reading_share") is not None
    assert abs(noise["q_a"]["reading_share"] / 0.004 - 1) < 0.3
    assert abs(noise["torque"]["reading_share"] / 0.004 - 1) < 0.3
    # new readings at the same points: the noise-free model plus fresh noise
    _, fresh = _map_with_reading_noise(tmp_path, np.random.default_rng(4))
    pts = frame[["point_id", "speed_rpm", "p_a_bar", "p_b_bar", "p_case_bar", "oil_temp_C"]]
    pts.to_csv(tmp_path / "pts.csv", index=False)
    pred = predict_points((doc, spec, ()), read_table(tmp_path / "pts.csv", spec, require_outputs=False))
    # torque reads ∝ ΔP, the inlet flow ∝ speed: each channel's low and high readings
    dp = (frame["p_a_bar"] - frame["p_b_bar"]).to_numpy()
    for col, axis, ratio in (("torque_Nm", dp, 3), ("q_a_lpm", frame["speed_rpm"].to_numpy(), 5)):
        low = axis < np.median(axis)
        inside = (fresh[col] >= pred[col + "_pi_lo95"]) & (fresh[col] <= pred[col + "_pi_hi95"])
        assert inside[low].mean() >= 0.85 and inside[~low].mean() >= 0.85, (col, inside[low].mean(),
                                                                            inside[~low].mean())
        width = (pred[col + "_pi_hi95"] - pred[col + "_pi_lo95"]).to_numpy()
        assert np.median(width[~low]) > ratio * np.median(width[low])  # the bands follow the reading


def test_a_model_error_that_changes_sign_with_the_direction_of_rotation_is_found():
    """A friction the model lacks, +e at forward and −e at reverse rotation, on a map whose slowest speeds
    (±5 rpm) lie closer to each other across ω = 0 than to their neighbours in ΔP: the neighbours of one
    direction share it, and it is found (it was missed while pairs across ω = 0 cancelled)."""
    from motorid.identify.lack_of_fit import structured_error
    from motorid.io.tables import PointTable

    speeds = np.array([5.0, 10, 40, 100, 200]) * 2 * np.pi / 60
    dps = np.linspace(20e5, 300e5, 8)
    w = np.concatenate([s * speeds for s in (1, -1)])
    W, P = np.meshgrid(w, dps, indexing="ij")
    W, P = W.ravel(), P.ravel()
    n = W.size
    ones = np.ones(n)
    t = PointTable(np.array([f"P{i}" for i in range(n)], dtype=object), W, P, 0 * P, 0 * P, 50 * ones, 0.03 * ones,
                   ones * 1e-4, {c: np.full(n, np.nan) for c in ("torque", "q_a", "q_b", "q_case")},
                   {c: ones for c in ("torque", "q_a", "q_b", "q_case")}, np.array(["x"] * n, dtype=object),
                   np.arange(n), True, {}, False)
    rng = np.random.default_rng(5)
    field = np.sign(W) * 3.0 * np.exp(-np.abs(W) / 3.0) * (P / 300e5)  # crawl-speed friction, grows with ΔP
    found = structured_error(t, {"torque": field + 0.3 * rng.normal(size=n)})["torque"]
    assert found["sigma"] > 0 and found["p_value"] < 0.01


@pytest.fixture(scope="module")
def missed_map(tmp_path_factory):
    """A map the model misses (a torque bump over speed and pressure, a case drain growing with the port
    pressure sum squared), fitted by `motorid fit`; every fourth point held out with its true mean."""
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.io.spec import load_motor_spec

    d = tmp_path_factory.mktemp("missed")
    spec = load_motor_spec(SPEC)
    grid = map_grid(np.linspace(100, 2500, 10), np.linspace(20, 300, 9), quadrants=2)
    truth = simulate_map(spec, _truth(), grid, rng=np.random.default_rng(6))
    w = truth["speed_rpm"].to_numpy() / 2500.0
    dp = (truth["p_a_bar"] - truth["p_b_bar"]).to_numpy() / 300.0
    truth["torque_Nm"] += 3.0 * np.exp(-((w - 0.5) ** 2 + (np.abs(dp) - 0.5) ** 2) / 0.08) * np.sign(dp)
    truth["q_case_lpm"] *= 1 + ((truth["p_a_bar"] + truth["p_b_bar"]) / 300.0) ** 2
    rng = np.random.default_rng(7)
    meas = truth.copy()
    for col, s in (("torque_Nm", 0.05), ("q_a_lpm", 0.02), ("q_b_lpm", 0.02), ("q_case_lpm", 0.005)):
        meas[col] = truth[col] + s * rng.standard_normal(len(meas))
    held = np.arange(len(meas)) % 4 == 1
    meas[~held].to_csv(d / "map.csv", index=False)
    truth[held].to_csv(d / "truth.csv", index=False)
    truth.loc[held, ["point_id", "speed_rpm", "p_a_bar", "p_b_bar", "p_case_bar", "oil_temp_C"]].to_csv(
        d / "pts.csv", index=False)
    cmd = [sys.executable, "-m", "motorid"]
    run = subprocess.run(cmd + ["fit", str(d / "map.csv"), "--motor", SPEC, "--out", str(d / "fit"), "--quiet"],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    for extra, name in (([], "pred.csv"), (["--physics-only"], "physics.csv")):
        run = subprocess.run(cmd + ["predict", str(d / "fit"), str(d / "pts.csv"), "--out", str(d / name)] + extra,
                             capture_output=True, text=True)
        assert run.returncode == 0, run.stderr
    return d


def test_predict_adds_the_kriged_model_error_and_its_held_out_error_falls(missed_map):
    """`motorid predict` adds the fit's kriged model error (result.json ``table.model_error_field``; its
    ``_model_error`` columns say by how much): at held-out points its torque and case-drain errors
    against the true means are well below those of --physics-only, and its confidence bands still hold
    the true means at 90 % or more of the points."""
    d = missed_map
    doc = json.loads((d / "fit" / "result.json").read_text())
    assert {"torque", "q_case"} <= set(doc["table"]["model_error_field"]["channels"])
    truth = pd.read_csv(d / "truth.csv").set_index("point_id")
    kriged = pd.read_csv(d / "pred.csv").set_index("point_id").loc[truth.index]
    physics = pd.read_csv(d / "physics.csv").set_index("point_id").loc[truth.index]
    assert "torque_Nm_model_error" in kriged and "torque_Nm_model_error" not in physics
    assert np.allclose(kriged["torque_Nm"] - kriged["torque_Nm_model_error"], physics["torque_Nm"], atol=1e-6)
    for col in ("torque_Nm", "q_case_lpm"):
        e_k = np.sqrt(np.mean((kriged[col] - truth[col]) ** 2))
        e_p = np.sqrt(np.mean((physics[col] - truth[col]) ** 2))
        assert e_k < 0.6 * e_p, (col, e_k, e_p)
        inside = (truth[col] >= kriged[col + "_lo95"]) & (truth[col] <= kriged[col + "_hi95"])
        assert inside.mean() >= 0.9, (col, inside.mean())


def test_the_kriged_model_error_is_a_row_of_the_fits_comparison_and_adds_nothing_far_away(missed_map):
    """result.json's comparison holds "motorid + kriged model error" beside motorid (on the same fold
    fits), with a lower K-fold torque error; at a point far outside the map the correction is nil and
    the band is the physics' band widened by the whole model error σ_m."""
    from motorid.identify.predict import load_result, predict_points
    from motorid.io.tables import read_table

    d = missed_map
    doc = json.loads((d / "fit" / "result.json").read_text())
    rows = doc["comparison"]["models"]
    assert rows["motorid + kriged model error"]["kfold"]["torque"]["rms"] < 0.7 * rows["motorid"]["kfold"]["torque"]["rms"]
    far = pd.DataFrame({"speed_rpm": [20000.0], "p_a_bar": [300.0], "p_b_bar": [0.0], "oil_temp_C": [50.0]})
    far.to_csv(d / "far.csv", index=False)
    result = load_result(d / "fit")
    pred = predict_points(result, read_table(d / "far.csv", result[1], require_outputs=False))
    assert abs(pred["torque_Nm_model_error"].iloc[0]) < 1e-6 * doc["table"]["noise"]["torque"]["model_error"]


def test_the_kriged_field_takes_points_with_an_axis_more_or_less_than_its_fit_had():
    """A field fitted on fixed-displacement points reads points that carry a displacement (the axis it
    did not have is dropped), and one fitted on a variable unit reads points without one (at the fit's
    median): no broadcasting error, the same coordinates on the axes both have."""
    from motorid.identify.lack_of_fit import AxisScaling

    rng = np.random.default_rng(0)
    four, five = rng.normal(size=(30, 4)), rng.normal(size=(30, 5))
    s4, s5 = AxisScaling(four), AxisScaling(five)
    assert np.allclose(s4(np.column_stack([four, rng.normal(size=30)])), s4(four))
    short = s5(five[:, :4])
    assert short.shape == s5(five).shape and np.all(np.isfinite(short))
