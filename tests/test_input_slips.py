"""A new user's slips that gave a wrong answer with exit 0 (a second reader playing a pump maker's
and another lab's engineer, stop 37): each is now refused in one line or told in a warning.

- a table of as many points as the parameters a channel determines: its noise, and so every
  standard error, came out 0 (Kv 12 % off at 5·10⁸ σ);
- an oil temperature under a bench's own name (``T_oil_C``, ``Temperature [°C]``) was dropped in
  silence and the spec's temperature taken (Kv 11 % off);
- °F values under a °C name (122 "°C": Kv 7× off);
- a pump's efficiency data sheet in the pump's own signs read as a motor's (nothing to check it by);
- the report drew a "predicted" η_v where the fit does not predict the flow (K_L0 and K_AB apart);
- a log's channel map with a forgotten sign or a unit 60× off (refused on tables, fitted on logs).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from conftest import DEMO_TRUTH, REPO, map_motor_toml
from motorid.errors import InputError


@pytest.fixture
def made(tmp_path):
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.io.spec import load_motor_spec

    (tmp_path / "motor.toml").write_text(map_motor_toml(50.0))
    spec = load_motor_spec(tmp_path / "motor.toml")
    df = simulate_map(spec, DEMO_TRUTH, map_grid([300, 1000, 2000], [50, 150, 250], 4), temp_C=50.0,
                      noise={"torque_Nm": 0.1, "q_a_lpm": 0.02, "q_b_lpm": 0.02, "q_case_lpm": 0.01},
                      rng=np.random.default_rng(5))
    return tmp_path, spec, df


def test_a_channel_with_no_points_left_for_its_noise_is_refused_and_a_few_more_are_rough(made):
    from motorid.identify.tables import fit_table
    from motorid.io.tables import read_table

    d, spec, df = made
    motor = df[(df.speed_rpm > 0) & (df.p_a_bar > df.p_b_bar)]
    spread = motor[(motor.speed_rpm == 300) & (motor.p_a_bar - motor.p_b_bar == 50) |
                   (motor.speed_rpm == 1000) & (motor.p_a_bar - motor.p_b_bar == 150) |
                   (motor.speed_rpm == 2000) & (motor.p_a_bar - motor.p_b_bar == 250)]
    assert len(spread) == 3
    spread.to_csv(d / "three.csv", index=False)
    with pytest.raises(InputError, match=r"three\.csv: 3 points with torque for the 3 parameters it determines "
                                         r"\(Kv, KF, TFc\).*at least 4 points with torque"):
        fit_table(read_table(d / "three.csv", spec), spec)
    pd.concat([spread, motor[~motor.index.isin(spread.index)].iloc[:2]]).to_csv(d / "five.csv", index=False)
    fit = fit_table(read_table(d / "five.csv", spec), spec)
    assert any("torque noise rests on 2 degrees of freedom" in w for w in fit.ls.warnings), fit.ls.warnings
    assert all(fit.ls.std[k] > 0 for k in ("Kv", "KF", "TFc"))
    whole = fit_table(read_table(_csv(d, df, "all.csv"), spec), spec)  # 36 points: no such word
    assert not any("degrees of freedom" in w for w in whole.ls.warnings)
    # two points: nothing to identify — refused, not a result.json of "not identifiable" rows (the
    # reasons saying how many readings there are, not that the column is missing)
    with pytest.raises(InputError, match=r"two\.csv: 2 points: too few to identify any parameter"):
        fit_table(read_table(_csv(d, spread.iloc[:2], "two.csv"), spec), spec)
    from motorid.identify.tables import table_coverage_reasons

    words = table_coverage_reasons(read_table(d / "two.csv", spec), spec, ["Kv", "KL0"])
    assert words["Kv"].startswith("the table has only 2 torque readings") and "fewer than 3 points" in words["KL0"]


def _csv(d, df, name):
    df.to_csv(d / name, index=False)
    return d / name


def test_an_oil_temperature_under_a_benchs_own_name_is_read_and_one_without_unit_refused(made):
    from motorid.io.tables import read_table

    d, spec, df = made
    hot = df.assign(oil_temp_C=np.where(np.arange(len(df)) % 2, 40.0, 60.0))
    want = read_table(_csv(d, hot, "own.csv"), spec).temperature
    for name in ("T_oil_C", "Temperature [°C]", "temp_C"):
        t = read_table(_csv(d, hot.rename(columns={"oil_temp_C": name}), "alias.csv"), spec)
        np.testing.assert_allclose(t.temperature, want)
    # the format's own column wins over another name of it (an ambient reading, say)
    t = read_table(_csv(d, hot.assign(temp_C=20.0), "both.csv"), spec)
    np.testing.assert_allclose(t.temperature, want)
    twice = _csv(d, pd.concat([hot, hot[["oil_temp_C"]]], axis=1), "twice.csv")  # the format's own, twice
    assert (d / "twice.csv").read_text().splitlines()[0].count("oil_temp_C") == 2
    with pytest.raises(InputError, match=r"columns 'oil_temp_C' and 'oil_temp_C' give the same quantity"):
        read_table(twice, spec)
    with pytest.raises(InputError, match=r"column 'T_oil' seems to be the oil temperature, but its unit suffix"):
        read_table(_csv(d, hot.rename(columns={"oil_temp_C": "T_oil"}), "nounit.csv"), spec)
    with pytest.raises(InputError, match=r"column 'p_a_bara' is an absolute pressure; the columns are gauge: "
                                         r"read the file through a channel map"):
        read_table(_csv(d, hot.rename(columns={"p_a_bar": "p_a_bara"}), "abs.csv"), spec)
    f = hot.assign(oil_temp_C=hot.oil_temp_C * 9 / 5 + 32)  # °F under a °C name: K_v 7× off, refused
    with pytest.raises(InputError, match=r"f\.csv: column 'oil_temp_C': oil at 122 °C in the median.*oil_temp_F"):
        read_table(_csv(d, f, "f.csv"), spec)
    # oil that truly runs this hot is read where its viscosity is given; the same column as °F reads as °C
    mu = read_table(d / "own.csv", spec).viscosity
    assert np.median(read_table(_csv(d, f.assign(viscosity_mPas=1e3 * mu), "hot.csv"), spec).temperature) > 110
    np.testing.assert_allclose(read_table(_csv(d, f.rename(columns={"oil_temp_C": "oil_temp_F"}), "fahrenheit.csv"),
                                          spec).temperature, want)


def test_a_logs_oil_temperature_in_fahrenheit_under_a_celsius_name_is_refused(tmp_path):
    """The same slip on a bench log (read through a channel map, as a DAQ file is): refused in one line
    naming the file, where the viscosity is to come from the temperature."""
    from motorid.io.logs import read_logs
    from motorid.io.spec import load_motor_spec

    df = pd.read_csv(REPO / "synthetic_data" / "demo" / "campaign.csv.gz", nrows=2000)
    df = df.drop(columns=["viscosity_mPas"]).assign(oil_temp_C=lambda f: (f.oil_temp_C + 20) * 9 / 5 + 32)
    df.to_csv(tmp_path / "log.csv", index=False)
    spec = load_motor_spec(REPO / "synthetic_data" / "demo" / "motor.toml")
    with pytest.raises(InputError, match=r"log\.csv: column 'oil_temp_C': oil at 1\d\d °C in the median"):
        read_logs([tmp_path / "log.csv"], spec)


def test_an_efficiency_sheet_in_motor_mode_alone_says_it_cannot_check_the_signs(made):
    from motorid.io.tables import read_table
    from motorid.physics.efficiency import efficiencies

    d, spec, df = made
    ref = read_table(_csv(d, df, "map.csv"), spec)
    ev, ehm, _ = efficiencies(ref.measured["torque"], ref.measured["q_a"], ref.measured["q_b"], ref.speed,
                              ref.p_a, ref.p_b, ref.displacement)
    sheet = df[["speed_rpm", "p_a_bar", "p_b_bar", "oil_temp_C"]].assign(eta_v_pct=100 * ev, eta_hm_pct=100 * ehm)
    words = "every point read in motor mode"
    assert not any(words in n for n in read_table(_csv(d, sheet, "four.csv"), spec).notes)  # both modes
    motor = sheet[(sheet.speed_rpm > 0) & (sheet.p_a_bar > sheet.p_b_bar)]
    assert any(words in n and 'convention = "pump"' in n for n in read_table(_csv(d, motor, "m.csv"), spec).notes)
    with_torque = df[(df.speed_rpm > 0) & (df.p_a_bar > df.p_b_bar)]  # readings carry their sign
    assert not any(words in n for n in read_table(_csv(d, with_torque, "t.csv"), spec).notes)


def test_an_efficiency_sheet_over_dp_alone_predicts_its_own_efficiency_through_the_sum_of_the_leaks(made,
                                                                                                      monkeypatch):
    """A sheet of η_v and η_hm over ΔP alone holds the inlet flow with its outlet at the case's
    pressure, which sees only K_L0 + K_AB: the two were both dropped and predict left the flows and
    η_v, the sheet's own quantity, empty at every point (a second reader, stop 38).  K_AB is held at 0
    and K_L0 carries the sum: the inlet flow and η_v are predicted where the outlet is at the case's
    pressure; the case drain, the outlet flow, and the inlet where the outlet is above it stay empty."""
    from motorid.cli import main
    from motorid.identify.predict import predict_points
    from motorid.io.tables import read_table, read_tables
    from motorid.physics.efficiency import efficiencies

    d, spec, df = made
    motor = df[(df.speed_rpm > 0) & (df.p_a_bar > df.p_b_bar)]
    ref = read_table(_csv(d, motor, "map.csv"), spec)
    ev, ehm, _ = efficiencies(ref.measured["torque"], ref.measured["q_a"], ref.measured["q_b"], ref.speed,
                              ref.p_a, ref.p_b, ref.displacement)
    pd.DataFrame({"speed_rpm": motor.speed_rpm, "dp_bar": motor.p_a_bar - motor.p_b_bar, "oil_temp_C": 50.0,
                  "eta_v_pct": 100 * ev, "eta_hm_pct": 100 * ehm}).to_csv(d / "sheet.csv", index=False)
    monkeypatch.chdir(d)
    assert main(["fit", "sheet.csv", "--motor", "motor.toml", "--out", "fit", "--quiet"]) == 0
    doc = __import__("json").loads((d / "fit" / "result.json").read_text())
    assert doc["parameters"]["KL0"]["identifiable"] and not doc["parameters"]["KAB"]["identifiable"]
    assert "K_L0 carries K_AB" in doc["parameters"]["KAB"]["reason"]
    # the sum is the truth's: K_L0 + K_AB of the map that made the sheet, within its error
    total = DEMO_TRUTH["KL0"] + DEMO_TRUTH["KAB"]
    assert abs(doc["parameters"]["KL0"]["value"] - total) < 3 * doc["parameters"]["KL0"]["std"] + 0.01 * total
    pd.DataFrame({"point_id": ["sheet", "boost"], "speed_rpm": [700.0, 700.0], "p_a_bar": [120.0, 140.0],
                  "p_b_bar": [0.0, 20.0], "p_case_bar": [0.0, 0.0], "oil_temp_C": [50.0, 50.0]}).to_csv(
        d / "pts.csv", index=False)
    pred = predict_points(d / "fit", read_tables([d / "pts.csv"], spec, require_outputs=False)).set_index("point_id")
    assert np.isfinite(pred.loc["sheet", "q_a_lpm"]) and np.isfinite(pred.loc["sheet", "volumetric_efficiency"])
    assert np.isnan(pred.loc["sheet", "q_case_lpm"]) and np.isnan(pred.loc["sheet", "q_b_lpm"])
    assert np.isnan(pred.loc["boost", "q_a_lpm"]) and "share their sum here" in pred.loc["boost", "note"]
    from motorid.bench.maps import simulate_map

    true = simulate_map(spec, DEMO_TRUTH, np.array([[700.0, 120.0, 0.0]]), temp_C=50.0)
    q_true = float(true.q_a_lpm.iloc[0])
    assert pred.loc["sheet", "q_a_lpm_lo95"] <= q_true <= pred.loc["sheet", "q_a_lpm_hi95"]
    assert main(["report", "fit"]) == 0
    html = (d / "fit" / "report.html").read_text()
    assert "volumetric: RMS residual" in html and "Not predicted: q_a" not in html


def test_a_logs_channel_map_with_a_forgotten_sign_or_a_wrong_unit_is_refused(tmp_path):
    """The ideal machine's checks of a table, on the logs' steady samples: flows negated (a pump
    bench's signs, no convention = "pump"), a flow 60× off (l/s mapped as L/min)."""
    from motorid.identify.pipeline import load_campaign
    from motorid.io.spec import load_motor_spec

    demo = REPO / "synthetic_data" / "demo"
    spec = load_motor_spec(demo / "motor.toml")
    frame = pd.read_csv(demo / "campaign.csv.gz")
    frame = frame[frame.protocol != "startability"].iloc[:20000]
    frame.to_csv(tmp_path / "good.csv", index=False)
    load_campaign([tmp_path / "good.csv"], spec)  # the logs as written pass
    frame.assign(q_a_lpm=-frame.q_a_lpm, q_b_lpm=-frame.q_b_lpm).to_csv(tmp_path / "signs.csv", index=False)
    with pytest.raises(InputError, match=r"signs\.csv: the steady samples' port A flow is -1× the swept flow.*"
                                         r"its sign runs against the ideal machine's"):
        load_campaign([tmp_path / "signs.csv"], spec)
    frame.assign(q_a_lpm=frame.q_a_lpm / 60, q_b_lpm=frame.q_b_lpm / 60).to_csv(tmp_path / "unit.csv", index=False)
    with pytest.raises(InputError, match=r"unit\.csv: the steady samples' port A flow is 0\.01\d*× the swept flow"):
        load_campaign([tmp_path / "unit.csv"], spec)


def test_an_encoder_counting_the_other_way_is_said_where_the_user_reads_it(tmp_path, capsys):
    """An encoder mounted the other way round: the fit notes it (the K_L(θ) harmonics' phase comes out
    mirrored), but the note stayed in result.json's data.notes and `motorid fit` printed nothing."""
    from motorid.cli import main

    demo = REPO / "synthetic_data" / "demo"
    frame = pd.read_csv(demo / "campaign.csv.gz")
    frame = frame[frame.protocol != "startability"].iloc[:20000]
    frame.assign(shaft_angle_deg=(-frame.shaft_angle_deg) % 360).to_csv(tmp_path / "reversed.csv", index=False)
    assert main(["fit", str(tmp_path / "reversed.csv"), "--motor", str(demo / "motor.toml"),
                 "--out", str(tmp_path / "fit"), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "note: the shaft angle runs against the logged speed" in printed
    frame.to_csv(tmp_path / "right.csv", index=False)
    assert main(["fit", str(tmp_path / "right.csv"), "--motor", str(demo / "motor.toml"),
                 "--out", str(tmp_path / "fit2"), "--quiet"]) == 0
    assert "runs against the logged speed" not in capsys.readouterr().out


def test_a_point_below_the_slowest_fitted_speed_is_noted_as_extrapolated(tmp_path):
    """A map fitted from 30 rpm up to 2 000 rpm: a point at 5 rpm (where the losses change fastest)
    was inside the old slack (2 % of the range, 40 rpm) and came without a word."""
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.cli import main
    from motorid.identify.predict import predict_points
    from motorid.io.spec import load_motor_spec
    from motorid.io.tables import read_tables

    (tmp_path / "motor.toml").write_text(map_motor_toml(50.0))
    spec = load_motor_spec(tmp_path / "motor.toml")
    simulate_map(spec, DEMO_TRUTH, map_grid([30, 1000, 2000], [50, 150, 250], 4), temp_C=50.0,
                 noise={"torque_Nm": 0.1, "q_a_lpm": 0.02, "q_b_lpm": 0.02, "q_case_lpm": 0.01},
                 rng=np.random.default_rng(5)).to_csv(tmp_path / "map.csv", index=False)
    assert main(["fit", str(tmp_path / "map.csv"), "--motor", str(tmp_path / "motor.toml"),
                 "--out", str(tmp_path / "fit"), "--quiet"]) == 0
    pd.DataFrame({"point_id": ["slow", "low_dp", "inside"], "speed_rpm": [5.0, 1000.0, 500.0],
                  "p_a_bar": [150.0, 45.0, 150.0], "p_b_bar": [0.0] * 3}).to_csv(tmp_path / "pts.csv", index=False)
    pred = predict_points(tmp_path / "fit", read_tables([tmp_path / "pts.csv"], spec, require_outputs=False))
    pred = pred.set_index("point_id")
    assert "extrapolated: speed 5 rpm outside the fitted 30-2000 rpm" in pred.loc["slow", "note"]
    assert "|ΔP| 45 bar outside the fitted 50-250 bar" in pred.loc["low_dp", "note"]  # 10 % below: outside
    assert pred.loc["inside", "note"] == ""


def test_predict_with_an_unidentified_parameter_at_a_point_at_rest_or_at_zero_pressure_difference(made,
                                                                                                 monkeypatch):
    """A fit of flows alone (K_v, K_F, T_Fc not identified) predicted at a point at rest and one at
    ΔP = 0, where the efficiencies are not defined: the per-point blanking of stop 38 raised KeyError
    'Kv' there (a second reader's review); the torque column is empty with its note, the flows given."""
    from motorid.cli import main
    from motorid.identify.predict import predict_points
    from motorid.io.tables import read_tables

    d, spec, df = made
    df.drop(columns=["torque_Nm"]).to_csv(d / "flows.csv", index=False)
    monkeypatch.chdir(d)
    assert main(["fit", "flows.csv", "--motor", "motor.toml", "--out", "fit", "--quiet"]) == 0
    pd.DataFrame({"point_id": ["run", "rest", "level"], "speed_rpm": [1000.0, 0.0, 1000.0],
                  "p_a_bar": [150.0, 150.0, 100.0], "p_b_bar": [0.0, 0.0, 100.0]}).to_csv(d / "pts.csv", index=False)
    pred = predict_points(d / "fit", read_tables([d / "pts.csv"], spec, require_outputs=False)).set_index("point_id")
    assert pred["torque_Nm"].isna().all() and np.isfinite(pred["q_a_lpm"]).all()
    assert all("torque_Nm empty: it depends on" in n for n in pred["note"])
