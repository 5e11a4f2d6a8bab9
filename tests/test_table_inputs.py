"""Tables as users bring them (found by trying motorid as a new user would, 2026-11-26): a
European CSV export, a signed ΔP column, a unit suffix motorid does not know, points at rest,
a single-speed sweep in the report, a partly filled temperature column, a table given twice."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from conftest import DEMO_TRUTH, map_motor_toml
from motorid.errors import InputError

MOTOR = map_motor_toml(50.0)
TRUTH = DEMO_TRUTH


@pytest.fixture
def made(tmp_path):
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.io.spec import load_motor_spec

    (tmp_path / "motor.toml").write_text(MOTOR)
    spec = load_motor_spec(tmp_path / "motor.toml")
    df = simulate_map(spec, TRUTH, map_grid([300, 1000, 2000], [50, 150, 250], 4), temp_C=50.0,
                      noise={"torque_Nm": 0.1, "q_a_lpm": 0.02, "q_b_lpm": 0.02, "q_case_lpm": 0.01},
                      rng=np.random.default_rng(5)).drop(columns=["oil_temp_C"])
    return tmp_path, spec, df


def test_a_semicolon_export_with_decimal_commas_reads_as_the_plain_csv(made):
    """'100,0;20,0;…' under 'speed_rpm;p_a_bar;…': more commas than semicolons in the data line, yet
    the header says ';' (it was read as comma-separated and refused: '100,0' is not a number)."""
    from motorid.io.tables import read_tables

    d, spec, df = made
    numeric = df[["speed_rpm", "p_a_bar", "p_b_bar", "torque_Nm"]]
    numeric.to_csv(d / "plain.csv", index=False)
    numeric.to_csv(d / "excel.csv", sep=";", decimal=",", index=False)
    a, b = read_tables([d / "plain.csv"], spec), read_tables([d / "excel.csv"], spec)
    np.testing.assert_allclose(b.speed, a.speed, rtol=1e-15)
    np.testing.assert_allclose(b.measured["torque"], a.measured["torque"], rtol=1e-12)


def test_a_signed_dp_column_puts_the_pressure_on_the_high_port_and_vacuum_is_refused(made):
    from motorid.io.tables import read_table

    d, spec, df = made
    df.assign(dp_bar=df.p_a_bar - df.p_b_bar).drop(columns=["p_a_bar", "p_b_bar"]).to_csv(d / "dp.csv", index=False)
    df.to_csv(d / "ports.csv", index=False)
    a, b = read_table(d / "ports.csv", spec), read_table(d / "dp.csv", spec)
    np.testing.assert_allclose(b.p_a, a.p_a)
    np.testing.assert_allclose(b.p_b, a.p_b)
    assert (b.p_a >= 0).all() and (b.p_b >= 0).all() and (b.p_b > 0).any()
    df.assign(p_b_bar=-0.9).to_csv(d / "suction.csv", index=False)  # a suction port: below atmosphere, above vacuum
    assert np.allclose(read_table(d / "suction.csv", spec).p_b, -0.9e5)
    df.assign(p_b_bar=-5.0).to_csv(d / "vacuum.csv", index=False)
    with pytest.raises(InputError, match=r"vacuum.csv: column 'p_b_bar', line 2: a gauge pressure below vacuum"):
        read_table(d / "vacuum.csv", spec)


def test_an_output_in_a_unit_motorid_does_not_know_is_named_not_dropped(made):
    from motorid.io.tables import read_table

    d, spec, df = made
    df.rename(columns={"q_case_lpm": "q_case_cc_s"}).to_csv(d / "cc.csv", index=False)
    with pytest.raises(InputError, match=r"cc.csv: column 'q_case_cc_s' seems to be the .*unit suffix"):
        read_table(d / "cc.csv", spec)
    # a qualified channel in a known unit is a column of its own, kept and ignored
    df.drop(columns=["torque_Nm"]).assign(torque_setpoint_Nm=1.0, q_b_set_lpm=2.0).to_csv(d / "set.csv", index=False)
    assert np.isnan(read_table(d / "set.csv", spec).measured["torque"]).all()
    df.rename(columns={"torque_Nm": "torque"}).to_csv(d / "bare.csv", index=False)
    with pytest.raises(InputError, match=r"column 'torque' seems to be the shaft torque"):
        read_table(d / "bare.csv", spec)


def test_torque_at_rest_is_set_aside_with_words_and_its_flows_kept(made):
    from motorid.identify.tables import fit_table
    from motorid.io.tables import read_table

    d, spec, df = made
    rest = df.iloc[:3].assign(speed_rpm=0.0, point_id=["R1", "R2", "R3"])
    pd.concat([df, rest]).to_csv(d / "rest.csv", index=False)
    t = read_table(d / "rest.csv", spec)
    at_rest = np.abs(t.speed) < 1e-3
    assert at_rest.sum() == 3 and np.isnan(t.measured["torque"][at_rest]).all()
    assert np.isfinite(t.measured["q_case"][at_rest]).all()
    assert any("zero speed" in n for n in t.notes)
    fit = fit_table(t, spec)
    assert any("zero speed" in w for w in fit.ls.warnings)


def test_the_efficiency_maps_of_a_single_speed_sweep_are_drawn_not_a_traceback(made):
    """One speed: no triangulation exists (qhull refused the points); the maps fall back to points."""
    from motorid.identify.tables import fit_table
    from motorid.io.tables import read_table
    from motorid.report.maps import plot_efficiency_maps

    d, spec, df = made
    df[df.speed_rpm == 1000].to_csv(d / "one_speed.csv", index=False)
    t = read_table(d / "one_speed.csv", spec)
    fit = fit_table(t, spec)
    plot = plot_efficiency_maps(t, fit.table_prediction)
    assert plot is not None and plot.facts and all(f["points"] >= 4 for f in plot.facts.values())


def test_recording_temperatures_only_where_no_point_has_one_and_empty_cells_are_no_recording(made):
    """With some temperatures recorded, K_v and K_L0 are pinned and the recordings' mean cannot stand for
    the assumed temperature: not offered (it gave 8 K for a 4 K difference). An empty recording cell is
    a point of no named recording."""
    from motorid.io.tables import read_table
    from motorid.physics.recording_temperature import RecordingTemperature

    d, spec, df = made
    days = np.array(["a", "b", "c"])[np.arange(len(df)) % 3]
    df.assign(recording=days).to_csv(d / "rec.csv", index=False)
    assert RecordingTemperature.for_table(read_table(d / "rec.csv", spec)) is not None
    temps = np.where(np.arange(len(df)) % 2 == 0, 50.0, np.nan)
    df.assign(recording=days, oil_temp_C=temps).to_csv(d / "partial.csv", index=False)
    assert RecordingTemperature.for_table(read_table(d / "partial.csv", spec)) is None
    blank = np.where(np.arange(len(df)) < 5, "", days)
    df.assign(recording=blank).to_csv(d / "blank.csv", index=False)
    t = read_table(d / "blank.csv", spec)
    mech = RecordingTemperature.for_table(t)
    assert "" not in (mech.reference_recording,) + mech.labels
    assert (mech.index[:5] == len(mech.labels) + 1).all()  # taken at the assumed temperature
    tiny = np.where(np.arange(len(df)) < 2, "z", days)  # a recording of two points: named, not fitted
    df.assign(recording=tiny).to_csv(d / "tiny.csv", index=False)
    t = read_table(d / "tiny.csv", spec)
    assert "z" not in RecordingTemperature.for_table(t).labels and RecordingTemperature.too_small(t) == ["z"]


def test_a_table_given_twice_is_refused(made):
    from motorid.io.tables import read_tables

    d, spec, df = made
    df.to_csv(d / "map.csv", index=False)
    with pytest.raises(InputError, match="table given twice"):
        read_tables([d / "map.csv", d / ".." / d.name / "map.csv"], spec)


def test_report_re_reads_a_mapped_table_from_any_folder(made, monkeypatch, capsys):
    """`motorid report DIR` of a fit read through --channels refused ('read it with a channel map'), and
    a fit given a relative path could not be reported from another folder: result.json now keeps
    the tables' absolute paths and the map they were read through."""
    from motorid.cli import main

    d, spec, df = made
    df.rename(columns={"speed_rpm": "n", "p_a_bar": "pA", "p_b_bar": "pB", "torque_Nm": "M"})[
        ["n", "pA", "pB", "M"]].to_csv(d / "maker.csv", index=False)
    (d / "bench.toml").write_text('[channels]\nspeed_rpm = {name = "n", unit = "rpm"}\n'
                                  'p_a_bar = {name = "pA", unit = "bar"}\np_b_bar = {name = "pB", unit = "bar"}\n'
                                  'torque_Nm = {name = "M", unit = "N*m"}\n')
    monkeypatch.chdir(d)
    assert main(["fit", "maker.csv", "--channels", "bench.toml", "--motor", "motor.toml", "--out", "fit",
                 "--quiet"]) == 0
    elsewhere = d / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    capsys.readouterr()
    assert main(["report", str(d / "fit")]) == 0, capsys.readouterr().err
    assert (d / "fit" / "report.html").stat().st_size > 10_000


def test_predict_says_where_it_cannot_or_where_it_extrapolates(made, monkeypatch):
    """At rest the torque is not predicted (it lies within static friction: it had a zero-width band);
    where power flows in at both the shaft and the ports no efficiency is given (it printed −2.2);
    a point outside the fitted |ΔP| is noted as extrapolated."""
    from motorid.cli import main
    from motorid.identify.predict import predict_points
    from motorid.io.tables import read_tables

    d, spec, df = made
    df.to_csv(d / "map.csv", index=False)
    monkeypatch.chdir(d)
    assert main(["fit", "map.csv", "--motor", "motor.toml", "--out", "fit", "--quiet"]) == 0
    pd.DataFrame({"point_id": ["rest", "idle", "inside", "high"], "speed_rpm": [0.0, 2000.0, 1000.0, 1000.0],
                  "p_a_bar": [150.0, 1.0, 150.0, 600.0], "p_b_bar": [0.0] * 4}).to_csv(d / "pts.csv", index=False)
    pred = predict_points(d / "fit", read_tables([d / "pts.csv"], spec, require_outputs=False)).set_index("point_id")
    assert np.isnan(pred.loc["rest", "torque_Nm"]) and "at rest" in pred.loc["rest", "note"]
    assert np.isfinite(pred.loc["rest", "q_case_lpm"])
    assert pred.loc["idle", "torque_Nm"] < 0  # friction above the ideal torque at 1 bar
    assert np.isnan(pred.loc["idle", "overall_efficiency"])
    assert "not that of a motor or a pump" in pred.loc["idle", "note"]
    assert pred.loc["inside", "note"] == "" and 0 < pred.loc["inside", "overall_efficiency"] < 1
    assert "extrapolated: |ΔP| 600 bar outside the fitted 50-250 bar" in pred.loc["high", "note"]
    # and it says what its bands there cannot know: how the model error grows outside the range
    assert pred.loc["high", "note"].endswith("its bands take the model error at its size inside the fitted range")


@pytest.mark.parametrize("edit,words", [
    (lambda df: df.assign(speed_rpm=df.speed_rpm * 2 * np.pi / 60), r"port A flow is 9.5\d× the swept flow"),
    (lambda df: df.assign(q_a_lpm=df.q_a_lpm / 3.785411784, q_b_lpm=df.q_b_lpm / 3.785411784),
     r"port A flow is 0.26\d× the swept flow .*gpm read as L/min"),
    (lambda df: df.assign(p_a_bar=df.p_a_bar * 14.5038, p_b_bar=df.p_b_bar * 14.5038),
     r"torque is 0.06\d+× the ideal torque D·ΔP/2π .* psi read as bar"),
    (lambda df: df.assign(torque_Nm=-df.torque_Nm, q_a_lpm=-df.q_a_lpm, q_b_lpm=-df.q_b_lpm),
     r"port A flow is -1[.0-9]*× the swept flow .* sign convention"),
    # a pump's data in its own signs: speed positive, flow out of A positive, torque into the shaft
    # positive; it reads as a motor giving out more than it takes in (flow and torque ratios pass)
    (lambda df: df[(df.speed_rpm < 0) & (df.p_a_bar > df.p_b_bar)].assign(
        speed_rpm=lambda d: -d.speed_rpm, q_a_lpm=lambda d: -d.q_a_lpm, q_b_lpm=lambda d: -d.q_b_lpm),
     r"its motor-mode points give out more power than they take in .* its speed takes sign = -1"),
    (lambda df: df.assign(q_b_lpm=-df.q_b_lpm), r"port B flow is -1[.0-9]*× .* negative where the oil leaves"),
])
def test_a_unit_or_sign_the_ideal_machine_contradicts_is_refused_in_one_line(edit, words, made):
    """A map in rad/s under speed_rpm, in gpm under _lpm, in psi under _bar, or in pump signs with the
    motor's speed was fitted with exit 0: K_v 9.5× too high, K_L0 3.8× too low, K_F 100× (a probe's
    maps, 2026-11-26).  The port flow against D·ω/2π and the torque against D·ΔP/2π refuse them."""
    from motorid.io.tables import read_tables

    d, spec, df = made
    df.to_csv(d / "good.csv", index=False)
    read_tables([d / "good.csv"], spec)  # the map itself passes
    edit(df).to_csv(d / "bad.csv", index=False)
    with pytest.raises(InputError, match=r"^bad.csv: " + words):
        read_tables([d / "bad.csv"], spec)
    assert len(read_tables([d / "bad.csv"], spec, require_outputs=False)) == len(edit(df))  # predict's points pass


def test_a_wrong_displacement_in_the_spec_is_refused_and_a_kf_at_zero_gives_a_readable_warning(made):
    from motorid.identify.identifiability import one_back_pressure_warning
    from motorid.io.spec import load_motor_spec
    from motorid.io.tables import read_tables

    d, spec, df = made
    df.to_csv(d / "map.csv", index=False)
    (d / "in3.toml").write_text(MOTOR.replace("displacement_cm3 = 80.0", "displacement_cm3 = 4.88"))
    with pytest.raises(InputError, match=r"port A flow is 16.\d× the swept flow D·ω/2π of D = 4.88 cm³/rev"):
        read_tables([d / "map.csv"], load_motor_spec(d / "in3.toml"))
    words = one_back_pressure_warning(np.full(10, 5e5), 1e-25)
    assert "more than this fit's whole K_F" in words and "e+" not in words


def test_a_kinematic_viscosity_without_a_temperature_converts_at_its_own_temperature(made):
    """cSt and no temperature column: the density was taken at the spec's temperature (or 40 °C),
    μ 2.7 % high at 80 °C and K_L0 11σ off on a probe's 500 cm³ maps.  The temperature at which the
    oil has that ν (Walther inverted) gives the density; the same μ as with the temperature given."""
    from motorid.physics.oil import kinematic_viscosity, temperature_of_viscosity
    from motorid.io.tables import read_table

    d, spec, df = made
    o = spec.oil
    temps = np.array([20.0, 40.0, 63.0, 80.0, 110.0])
    nu = np.asarray(kinematic_viscosity(temps, o.nu40_cSt, o.nu100_cSt, xp=np)) * 1e6
    np.testing.assert_allclose(temperature_of_viscosity(nu, o.nu40_cSt, o.nu100_cSt, xp=np), temps, atol=1e-9)
    t_pt = np.resize(temps, len(df))
    nu_pt = np.asarray(kinematic_viscosity(t_pt, o.nu40_cSt, o.nu100_cSt, xp=np)) * 1e6
    df.assign(viscosity_cSt=nu_pt, oil_temp_C=t_pt).to_csv(d / "with_t.csv", index=False)
    df.assign(viscosity_cSt=nu_pt).to_csv(d / "without_t.csv", index=False)
    a, b = read_table(d / "with_t.csv", spec), read_table(d / "without_t.csv", spec)
    np.testing.assert_allclose(b.viscosity, a.viscosity, rtol=1e-12)


def test_a_decimal_comma_export_with_thousands_points_reads_as_the_plain_csv(made):
    """'1.002,5' (a German Excel export): the thousands point left the column text, and the table was
    refused ('498,0000' is not a number, on the first row, which has none)."""
    from motorid.io.tables import read_tables

    d, spec, df = made
    cols = ["speed_rpm", "p_a_bar", "p_b_bar", "torque_Nm", "q_a_lpm"]
    de = lambda x: f"{x:,.4f}".replace(",", "_").replace(".", ",").replace("_", ".")  # noqa: E731
    lines = [";".join(cols)] + [";".join(de(v) for v in row) for row in df[cols].to_numpy()]
    assert any("." in line for line in lines[1:])  # some speeds above 999
    (d / "de.csv").write_text("\n".join(lines) + "\n")
    df[cols].to_csv(d / "plain.csv", index=False)
    a, b = read_tables([d / "plain.csv"], spec), read_tables([d / "de.csv"], spec)
    np.testing.assert_allclose(b.speed, a.speed, rtol=1e-6)
    np.testing.assert_allclose(b.measured["q_a"], a.measured["q_a"], rtol=1e-4, atol=1e-9)


def test_a_units_row_is_named_as_such_in_the_refusal(made):
    from motorid.io.tables import read_tables

    d, spec, df = made
    cols = ["speed_rpm", "p_a_bar", "p_b_bar", "torque_Nm"]
    text = df[cols].to_csv(index=False).splitlines()
    (d / "units.csv").write_text("\n".join([text[0], "[rpm],bar,bar,Nm"] + text[1:]) + "\n")
    with pytest.raises(InputError, match=r"line 2: '\[rpm\]' is not a number \(a units row under the header\? "
                                         r"a channel map with \[file\] skip_rows = 1"):
        read_tables([d / "units.csv"], spec)
    (d / "bad.csv").write_text("\n".join(text[:3] + ["300,x,0,1"] + text[3:]) + "\n")
    with pytest.raises(InputError, match=r"line 4: 'x' is not a number$"):
        read_tables([d / "bad.csv"], spec)


def test_a_data_sheet_of_efficiencies_gives_back_the_torque_and_the_high_pressure_flow(made):
    """Makers publish η_v and η_hm (in %) more often than torque and flow: such a sheet was refused
    ('no output column').  The ISO 4409 definitions, inverted per mode, give back the torque and the
    flow into the high-pressure port of every point, in all four quadrants."""
    from motorid.io.tables import read_tables
    from motorid.physics.efficiency import efficiencies

    d, spec, df = made
    df.to_csv(d / "map.csv", index=False)
    ref = read_tables([d / "map.csv"], spec)
    eta_v, eta_hm, eta = efficiencies(ref.measured["torque"], ref.measured["q_a"], ref.measured["q_b"], ref.speed,
                                      ref.p_a, ref.p_b, ref.displacement)
    sheet = df[["speed_rpm", "p_a_bar", "p_b_bar"]].assign(vol_eff_pct=100 * eta_v, eta_t_pct=100 * eta)
    sheet.to_csv(d / "sheet.csv", index=False)
    got = read_tables([d / "sheet.csv"], spec)
    hp_a = ref.dp >= 0
    power = ref.dp * ref.speed != 0
    assert np.isin(["motor", "pump"], np.where(ref.dp * ref.speed > 0, "motor", "pump")).all()
    np.testing.assert_allclose(got.measured["torque"][power], ref.measured["torque"][power], rtol=1e-9)
    np.testing.assert_allclose(got.measured["q_a"][power & hp_a], ref.measured["q_a"][power & hp_a], rtol=1e-9)
    np.testing.assert_allclose(got.measured["q_b"][power & ~hp_a], ref.measured["q_b"][power & ~hp_a], rtol=1e-9)
    assert np.isnan(got.measured["q_case"]).all() and np.isnan(got.measured["q_b"][hp_a]).all()
    assert any("derived from the volumetric, overall efficiency" in n for n in got.notes)
    sheet[["speed_rpm", "p_a_bar", "p_b_bar", "eta_t_pct"]].to_csv(d / "overall.csv", index=False)
    with pytest.raises(InputError, match=r"an overall efficiency alone cannot be split"):
        read_tables([d / "overall.csv"], spec)


def test_predict_says_where_a_point_lies_in_a_quadrant_the_fit_never_saw(made, monkeypatch):
    """A motor-mode map predicted in pump mode or in reverse said nothing (a probe's points): the
    quadrants the fit saw are in result.json (ranges.quadrants), and a point outside them is noted."""
    import json

    from motorid.cli import main
    from motorid.identify.predict import predict_points
    from motorid.io.tables import read_tables

    d, spec, df = made
    df[(df.speed_rpm > 0) & (df.p_a_bar > df.p_b_bar)].to_csv(d / "motor_only.csv", index=False)
    monkeypatch.chdir(d)
    assert main(["fit", "motor_only.csv", "--motor", "motor.toml", "--out", "fit", "--quiet"]) == 0
    assert json.loads((d / "fit" / "result.json").read_text())["table"]["ranges"]["quadrants"] == ["motor, forward"]
    pd.DataFrame({"point_id": ["inside", "pump", "reverse"], "speed_rpm": [1000.0, -1000.0, -1000.0],
                  "p_a_bar": [150.0, 150.0, 0.0], "p_b_bar": [0.0, 0.0, 150.0]}).to_csv(d / "pts.csv", index=False)
    pred = predict_points(d / "fit", read_tables([d / "pts.csv"], spec, require_outputs=False)).set_index("point_id")
    assert pred.loc["inside", "note"] == ""
    assert "pump, reverse, a quadrant the fit never saw (it saw motor, forward)" in pred.loc["pump", "note"]
    assert "motor, reverse, a quadrant the fit never saw" in pred.loc["reverse", "note"]


def test_a_row_without_any_output_reading_is_set_aside_not_counted(made):
    from motorid.io.tables import read_tables

    d, spec, df = made
    cols = ["speed_rpm", "p_a_bar", "p_b_bar", "torque_Nm", "q_a_lpm"]
    holes = df[cols].copy()
    holes.loc[holes.index[[3, 7]], ["torque_Nm", "q_a_lpm"]] = np.nan
    holes.to_csv(d / "holes.csv", index=False)
    got = read_tables([d / "holes.csv"], spec)
    assert len(got) == len(df) - 2 and any("2 row(s) with no output reading (line 5 first)" in n for n in got.notes)
    assert len(read_tables([d / "holes.csv"], spec, require_outputs=False)) == len(df)  # predict's points
    holes.assign(torque_Nm=np.nan, q_a_lpm=np.nan).to_csv(d / "none.csv", index=False)
    with pytest.raises(InputError, match=r"none.csv: no row holds an output reading"):
        read_tables([d / "none.csv"], spec)


def test_a_slow_map_where_leakage_dominates_passes_the_ideal_machine_check(made):
    """At 5-20 rpm and up to 350 bar the leakage is several times the swept flow: the plain ratio read
    4.2 and refused a good map; the swept flow's coefficient beside the ports' leakage is near 1."""
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.io.tables import read_tables

    d, spec, _ = made
    slow = simulate_map(spec, TRUTH, map_grid([5, 10, 20], [100, 200, 350], 1), temp_C=50.0,
                        noise={"torque_Nm": 0.1, "q_a_lpm": 0.002, "q_b_lpm": 0.002, "q_case_lpm": 0.001},
                        rng=np.random.default_rng(2))
    q_ratio = slow.q_a_lpm / (spec.displacement * 1e3 * slow.speed_rpm)
    assert q_ratio.max() > 2.5  # leakage dominates the slowest points
    slow.to_csv(d / "slow.csv", index=False)
    assert len(read_tables([d / "slow.csv"], spec)) == len(slow)


def test_efficiencies_in_per_cent_under_a_fraction_header_are_named(made):
    from motorid.io.tables import read_tables

    d, spec, df = made
    df[["speed_rpm", "p_a_bar", "p_b_bar"]].assign(volumetric_efficiency=95.0, hydromechanical_efficiency=90.0) \
        .to_csv(d / "pct.csv", index=False)
    with pytest.raises(InputError, match=r"column 'volumetric_efficiency': efficiencies of 95 .* per cent\?"):
        read_tables([d / "pct.csv"], spec)


def test_a_workbook_with_a_sheet_per_temperature_reads_in_one_go(made):
    """A maker's .xlsx with an info sheet and one sheet per oil temperature: '[file] sheet: expected
    text' for a list, and the default sheet's refusal named neither it nor the others."""
    from motorid.io.tables import read_tables

    d, spec, df = made
    cols = ["speed_rpm", "p_a_bar", "p_b_bar", "torque_Nm", "q_a_lpm"]
    half = len(df) // 2
    with pd.ExcelWriter(d / "maker.xlsx", engine="openpyxl") as xw:
        pd.DataFrame({"note": ["test report 17"]}).to_excel(xw, sheet_name="Info", index=False)
        df[cols].iloc[:half].rename(columns={"speed_rpm": "n"}).to_excel(xw, sheet_name="50C", index=False)
        df[cols].iloc[half:].rename(columns={"speed_rpm": "n"}).to_excel(xw, sheet_name="50C bis", index=False)
    channels = "\n".join(f'{c} = {{name = "{c}", unit = "{u}"}}' for c, u in
                         (("p_a_bar", "bar"), ("p_b_bar", "bar"), ("torque_Nm", "N*m"), ("q_a_lpm", "l/min")))
    body = f'[channels]\nspeed_rpm = {{name = "n", unit = "rpm"}}\n{channels}\n[constants]\noil_temp_C = 50.0\n'
    (d / "map.toml").write_text('[file]\nsheet = ["50C", "50C bis"]\n' + body + '[extra]\nrecording = "sheet"\n')
    got = read_tables([d / "maker.xlsx"], spec, channels=d / "map.toml")
    np.testing.assert_allclose(got.speed, read_tables([_csv(d, df)], spec).speed)
    assert list(np.unique(got.recording)) == ["50C", "50C bis"]
    (d / "first.toml").write_text(body)  # the first sheet: the info sheet
    with pytest.raises(InputError, match=r"no channel 'n' .*\(sheet Info; the workbook's sheets: Info, 50C, 50C bis\)"):
        read_tables([d / "maker.xlsx"], spec, channels=d / "first.toml")


def _csv(d, df):
    df.to_csv(d / "map.csv", index=False)
    return d / "map.csv"


def test_the_efficiency_maps_of_a_dense_grid_show_their_colours(tmp_path):
    """A dense map (24 000 points, as a lab's meshgrid file holds tens of thousands): the points are
    not marked (their markers covered every colour: 44 % of the picture was black)."""
    import base64
    import io
    import re

    from PIL import Image

    from motorid.bench.maps import map_grid, simulate_map
    from motorid.identify.tables import fit_table
    from motorid.io.tables import read_table
    from motorid.model import MotorSpec, OilSpec
    from motorid.report.maps import plot_efficiency_maps

    spec = MotorSpec("dense", 9, 80e-6, 0.005, oil=OilSpec(temp_C=50.0))
    truth = {"Kv": 5000.0, "KF": 3e-3, "KFS": 1.5e-2, "TFc": 3.0, "Ks": 1.0, "KL0": 5e-14, "KL_a1": 0.0,
             "KL_b1": 0.0, "KAB": 2e-14}
    grid = map_grid(np.linspace(50, 3000, 100), np.linspace(5, 300, 60), 4)
    df = simulate_map(spec, truth, grid, noise={"torque_Nm": 0.3, "q_a_lpm": 0.05, "q_b_lpm": 0.05,
                                                "q_case_lpm": 0.02}, rng=np.random.default_rng(3))
    df.to_csv(tmp_path / "dense.csv", index=False)
    t = read_table(tmp_path / "dense.csv", spec)
    plot = plot_efficiency_maps(t, fit_table(t, spec).table_prediction)
    png = base64.b64decode(re.search(r'base64,([^"]+)"', plot.img).group(1))
    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=int)
    dark = np.all(rgb < 40, axis=2).mean()
    assert dark < 0.10, f"{dark:.0%} of the picture is black"


def test_a_variable_units_maps_are_drawn_setting_by_setting(tmp_path):
    """Points of several displacement settings at one (ΔP, ω) were contoured across settings (the
    V32HL56 pump's five settings gave jagged nonsense): each setting now has its own maps, the
    largest first; displacements a lab derived point by point (within 5 %) are one setting."""
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.identify.tables import fit_table
    from motorid.io.tables import read_table
    from motorid.model import MotorSpec, OilSpec
    from motorid.report.maps import MAX_SETTINGS, displacement_settings, render_map_report

    spec = MotorSpec("var", 9, 80e-6, 0.005, oil=OilSpec(temp_C=50.0))
    truth = {"Kv": 5000.0, "KF": 3e-3, "KFS": 1.5e-2, "TFc": 3.0, "Ks": 1.0, "KL0": 5e-14, "KL_a1": 0.0,
             "KL_b1": 0.0, "KAB": 2e-14}
    grid = map_grid([500, 1000, 2000, 3000], [50, 150, 250], 1)
    grid = np.concatenate([grid, grid, grid])
    disp = np.repeat([80.0, 60.0, 40.0], len(grid) // 3) * (1 + 0.01 * np.sin(np.arange(len(grid))))
    df = simulate_map(spec, truth, grid, noise={"torque_Nm": 0.2, "q_a_lpm": 0.05, "q_b_lpm": 0.05,
                                                "q_case_lpm": 0.02}, rng=np.random.default_rng(2),
                      displacement_cm3=disp)
    df.to_csv(tmp_path / "var.csv", index=False)
    t = read_table(tmp_path / "var.csv", spec)
    groups = displacement_settings(t)
    assert [len(g) for g in groups] == [12, 12, 12]
    assert [round(float(np.median(t.displacement[g])) * 1e6) for g in groups] == [80, 60, 40]
    tf = fit_table(t, spec)
    page = render_map_report({"motor": {"name": "var"}, "table": {"points": len(t), "files": []},
                              "parameters": {}}, tf)
    assert page.count("<img") == 3 <= MAX_SETTINGS
    at = [page.index(f"D ≈ {d}") for d in ("80", "60", "40")]
    assert at == sorted(at)
    fixed = t.subset(groups[0])
    fixed.variable_displacement = False
    assert len(displacement_settings(fixed)) == 1
