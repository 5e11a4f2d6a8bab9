"""What a table diagnosis says where its points cannot tell, or where nothing in the catalog fits
(found by trying motorid as a new user would, 2026-11-26): a map with only the inlet flow, a map
whose case leakage follows another law (no meter is wrong), a friction with a hump in ΔP."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from conftest import DEMO_TRUTH, map_motor_toml

NOISE = {"torque_Nm": 0.1, "q_a_lpm": 0.02, "q_b_lpm": 0.02, "q_case_lpm": 0.005}


@pytest.fixture
def spec(tmp_path):
    from motorid.io.spec import load_motor_spec

    (tmp_path / "motor.toml").write_text(map_motor_toml(50.0))
    return load_motor_spec(tmp_path / "motor.toml")


def _map(spec, grid, rng, temps=(50.0,), **kw):
    from motorid.bench.maps import simulate_map

    parts = [simulate_map(spec, DEMO_TRUTH, grid, temp_C=t, noise=NOISE, rng=rng, **kw) for t in temps]
    return pd.concat(parts, ignore_index=True).assign(point_id=lambda d: [f"P{i}" for i in range(len(d))])


def _table(spec, df, path):
    from motorid.io.tables import read_table

    df.to_csv(path, index=False)
    return read_table(path, spec)


def test_a_map_of_the_inlet_flow_alone_fits_the_leakage_it_shows_and_predicts_that_flow(spec, tmp_path):
    """Port A's flow carries K_L0 (to the case) and K_AB (to port B): with no case meter K_L0 is
    not held by rule at a start value that has soaked up the port's leakage (K_AB then came out
    25 σ from the truth, 'identifiable'); both are fitted, each within 3 σ, and q_a is predicted."""
    from motorid.bench.maps import map_grid
    from motorid.identify.predict import predict_points
    from motorid.identify.tables import fit_table
    from motorid.identify.results import json_safe

    grid = map_grid([300, 1000, 2000, 3000], [30, 100, 200, 300], 4, p_low_bar=10.0)
    df = _map(spec, grid, np.random.default_rng(3), temps=(40.0, 60.0))
    df = df.drop(columns=["q_b_lpm", "q_case_lpm"])
    table = _table(spec, df, tmp_path / "qa.csv")
    tf = fit_table(table, spec)
    for k in ("KL0", "KAB"):
        assert tf.ls.identifiable[k], k
        assert abs(tf.ls.values[k] - DEMO_TRUTH[k]) < 3 * tf.ls.std[k], (k, tf.ls.values[k], tf.ls.std[k])
    doc = {"parameters": {k: {"value": tf.ls.values[k], "std": tf.ls.std[k], "identifiable": tf.ls.identifiable[k]}
                          for k in tf.ls.names},
           "correlation": {"names": tf.ls.free, "matrix": json_safe(np.asarray(tf.ls.correlation).tolist())},
           "fit": {"mechanisms": []}}
    pred = predict_points((doc, spec, ()), table)
    assert np.isfinite(pred["q_a_lpm"]).all()
    assert np.sqrt(np.mean((pred["q_a_lpm"] - df["q_a_lpm"]) ** 2)) < 3 * NOISE["q_a_lpm"]


def test_a_flow_meter_error_is_named_on_a_table_only_where_the_meters_mass_balance_shows_it(spec, tmp_path):
    """A constant case flow is a case-meter zero or the low port's leakage at one boost pressure and
    temperature: only the mass balance Q_A + Q_B − Q_case tells them apart.  Where it holds (no meter
    wrong) the meter's error is not tried; where the case meter reads 0.05 L/min high it is."""
    from motorid.bench.maps import map_grid
    from motorid.physics.registry import get

    grid = map_grid([300, 1000, 2000], [30, 100, 200, 300], 4, p_low_bar=20.0)
    df = _map(spec, grid, np.random.default_rng(4))
    offset, gain = get("flow_meter_offset_case"), get("flow_meter_gain_a")
    clean = _table(spec, df, tmp_path / "clean.csv")
    assert "mass balance" in offset.unseen_in_table(clean) and "mass balance" in gain.unseen_in_table(clean)
    # the torque transducer's gain at one back pressure is K_F's shape (and pump-mode friction's): not tried;
    # at two back pressures it is
    assert "one pressure" in get("torque_meter_gain").unseen_in_table(clean)
    second = _map(spec, map_grid([300, 1000, 2000], [30, 100, 200, 300], 4, p_low_bar=45.0), np.random.default_rng(5))
    both = _table(spec, pd.concat([df, second], ignore_index=True), tmp_path / "two_back_pressures.csv")
    assert get("torque_meter_gain").unseen_in_table(both) is None
    shifted = _table(spec, df.assign(q_case_lpm=df.q_case_lpm + 0.05), tmp_path / "shifted.csv")
    assert offset.unseen_in_table(shifted) is None
    scaled = _table(spec, df.assign(q_a_lpm=df.q_a_lpm * 1.01), tmp_path / "scaled.csv")
    assert gain.unseen_in_table(scaled) is None
    # the oil compressed between meters at different pressures (Q·|ΔP|/β, β = 15 000 bar): no meter is wrong
    squeeze = 1.0 - (df.p_a_bar - df.p_b_bar).abs() / 15000.0
    compressed = _table(spec, df.assign(q_a_lpm=df.q_a_lpm * squeeze, q_b_lpm=df.q_b_lpm * squeeze),
                        tmp_path / "compressed.csv")
    assert gain.unseen_in_table(compressed) is not None
    both = _table(spec, df.assign(q_a_lpm=df.q_a_lpm * squeeze * 1.01, q_b_lpm=df.q_b_lpm * squeeze),
                  tmp_path / "both.csv")
    assert gain.unseen_in_table(both) is None
    no_case = _table(spec, df.drop(columns=["q_case_lpm"]), tmp_path / "two.csv")
    assert "all three flows" in offset.unseen_in_table(no_case)


def test_a_case_leakage_of_another_law_is_left_unexplained_not_blamed_on_a_meter(spec, tmp_path):
    """Case leakage from the high-pressure port alone (∝ |ΔP|/μ, Wilson's form; the 1992 model also
    leaks from the low port at its 20 bar boost): the mass balance holds, so no flow meter is named,
    and the misfit is reported as unexplained in the case-drain flow."""
    from motorid.bench.maps import map_grid
    from motorid.discrepancy.tables import diagnose_table
    from motorid.physics.registry import get

    grid = map_grid([300, 1000, 2000], [30, 100, 200, 300], 4, p_low_bar=20.0)
    df = _map(spec, grid, np.random.default_rng(5))
    mu = float(spec.oil.viscosity(50.0))
    low_is_a = (df.p_a_bar < df.p_b_bar).to_numpy()
    p_low = np.minimum(df.p_a_bar, df.p_b_bar).to_numpy() * 1e5
    low_leak = DEMO_TRUTH["KL0"] * p_low / mu * 6e4  # [L/min] the low port's leakage to the case
    # taken away from the low port's meter and from the case drain alike: the mass balance still holds
    df["q_a_lpm"] -= np.where(low_is_a, low_leak, 0.0)
    df["q_b_lpm"] -= np.where(low_is_a, 0.0, low_leak)
    df["q_case_lpm"] -= low_leak
    table = _table(spec, df, tmp_path / "wilson.csv")
    cands = [get(i) for i in ("flow_meter_offset_case", "flow_meter_gain_case", "flow_meter_offset_a",
                              "turbulent_leakage", "hydrodynamic_torque")]
    dg = diagnose_table(table, spec, candidates=cands)
    named = {m.id for m in dg["mechanisms"]}
    assert not any(i.startswith("flow_meter") for i in named), named
    assert any(u["channel"] == "q_case" for u in dg["unexplained"]), dg["unexplained"]
    skipped = {s["id"] for s in dg["steps"] if "skipped" in s}
    assert {"flow_meter_offset_case", "flow_meter_gain_case", "flow_meter_offset_a"} <= skipped


def test_a_friction_with_a_hump_in_pressure_is_reported_even_without_a_formula(spec, tmp_path):
    """An extra friction that rises and falls with ΔP (peak at 200 bar) in a four-quadrant map: it
    changes sign with the rotation, so the residual averaged over both directions cancels; taken in
    the sense of rotation it is a structure along ΔP.  A clean map of the same grid shows none."""
    from motorid.bench.maps import map_grid
    from motorid.discrepancy.table_structure import table_structures
    from motorid.identify.tables import fit_table

    grid = map_grid([300, 1000, 2000, 3000], [20, 100, 200, 300, 400], 4)
    df = _map(spec, grid, np.random.default_rng(8))
    clean = fit_table(_table(spec, df, tmp_path / "clean.csv"), spec)
    assert table_structures(clean) == []
    dp = np.abs(df.p_a_bar - df.p_b_bar).to_numpy()
    hump = 1.0 * np.exp(-(((dp - 200.0) / 60.0) ** 2))
    humped = fit_table(_table(spec, df.assign(torque_Nm=df.torque_Nm - np.sign(df.speed_rpm) * hump),
                              tmp_path / "hump.csv"), spec)
    found = table_structures(humped)
    top = [s for s in found if s["channel"] == "torque"]
    along = {}  # per variable its strongest (at zero boost P_A + P_B = |ΔP|: the same grouping)
    for s in sorted(top, key=lambda s: s["p_value"]):
        along.setdefault(s["variable"], s)
    assert "pressure difference" in along, found
    assert "sense of rotation" in along["pressure difference"]["where"]


def test_a_flow_between_the_ports_that_follows_the_sign_of_the_pressure_difference_is_found(spec, tmp_path):
    """A cross-port leak ∝ ΔP|ΔP| in a four-quadrant map: it changes sign with ΔP, so its residual
    cancels in a mean over both signs of ΔP at one |ΔP| (and over the directions too, since pump mode
    puts the high pressure on the other port); taken in the sense of the pressure difference it is a
    structure along |ΔP| in both port flows.  A clean map of the same grid shows none."""
    from motorid.bench.maps import map_grid
    from motorid.discrepancy.table_structure import table_structures
    from motorid.identify.tables import fit_table

    grid = map_grid([300, 1000, 2000, 3000], [20, 100, 200, 300], 4)
    df = _map(spec, grid, np.random.default_rng(12))
    assert table_structures(fit_table(_table(spec, df, tmp_path / "clean.csv"), spec)) == []
    dp = (df.p_a_bar - df.p_b_bar).to_numpy()
    extra = 0.1 * dp * np.abs(dp) / 300.0**2  # L/min: into the high-pressure port, out of the low one
    leaky = fit_table(_table(spec, df.assign(q_a_lpm=df.q_a_lpm + extra, q_b_lpm=df.q_b_lpm - extra),
                             tmp_path / "leak.csv"), spec)
    found = table_structures(leaky)
    for c in ("q_a", "q_b"):
        mine = [s for s in found if s["channel"] == c]
        assert mine, found
        assert "sense of the pressure difference" in mine[0]["where"], mine[0]["where"]
    # no test twice under two names (by operating mode the sense of ΔP is the sense of rotation)
    keys = [(s["channel"], s["variable"], round(s["statistic"], 6)) for s in found]
    assert len(keys) == len(set(keys)), keys
    # a motor-only map of both directions: sgn ΔP = sgn ω at every point, so no sense of ΔP is added
    four = map_grid([300, 1000, 2000, 3000], [20, 100, 200, 300], 4)
    motor_mode = four[np.sign(four[:, 1] - four[:, 2]) == np.sign(four[:, 0])]
    motor = _map(spec, motor_mode, np.random.default_rng(13))
    dp = (motor.p_a_bar - motor.p_b_bar).to_numpy()
    assert np.all(np.sign(dp) == np.sign(motor.speed_rpm)) and len(set(np.sign(dp))) == 2
    extra = 0.4 * dp * np.abs(dp) / 300.0**2
    one = table_structures(fit_table(_table(spec, motor.assign(q_a_lpm=motor.q_a_lpm + extra,
                                                               q_b_lpm=motor.q_b_lpm - extra),
                                            tmp_path / "motor.csv"), spec))
    assert one and not any("pressure difference)" in s["where"] for s in one), [s["where"] for s in one]
    keys = [(s["channel"], s["variable"], round(s["statistic"], 6)) for s in one]
    assert len(keys) == len(set(keys)), keys


def test_a_one_quadrant_map_of_the_inlet_flow_cannot_tell_the_two_leakages_apart(spec, tmp_path):
    """Motor mode only, the low port at the case pressure: port A's leakage is (K_L0 + K_AB)·P_A/μ,
    so neither is identifiable alone (never carried as wild values): K_AB is held at 0 and said so,
    and K_L0 carries their sum, which the inlet flow does determine (stop 38: both had been dropped,
    and the flow and η_v of such a map went unpredicted)."""
    from motorid.bench.maps import map_grid
    from motorid.identify.tables import fit_table

    df = _map(spec, map_grid([300, 1000, 2000], [50, 150, 250], 1), np.random.default_rng(9))
    tf = fit_table(_table(spec, df.drop(columns=["q_b_lpm", "q_case_lpm"]), tmp_path / "one.csv"), spec)
    assert not tf.ls.identifiable["KAB"] and tf.ls.values["KAB"] is None
    assert "cannot be told from K_L0" in tf.ls.reasons["KAB"] and "K_L0 carries K_AB" in tf.ls.reasons["KAB"]
    total = DEMO_TRUTH["KL0"] + DEMO_TRUTH["KAB"]
    assert tf.ls.identifiable["KL0"] and abs(tf.ls.values["KL0"] - total) < 3 * tf.ls.std["KL0"]
    assert any("K_L0 is the leakage the inlet flows see" in w for w in tf.ls.warnings)


def test_clean_maps_of_many_shapes_show_no_structure(spec, tmp_path):
    """The structure test's false alarms (α = 10⁻³ over its tests): none on 12 clean maps of four grids
    (one, two and four quadrants; boost 0-20 bar; one or two oil temperatures).  (Run on 40 such maps
    with three times the noise, 0.3 N·m and 0.05 / 0.02 L/min: none either.)"""
    from motorid.bench.maps import map_grid
    from motorid.discrepancy.table_structure import table_structures
    from motorid.identify.tables import fit_table

    grids = [([300, 1000, 2000, 3000], [20, 100, 200, 300], 4, 0.0),
             ([200, 800, 1500], [50, 150, 250, 350], 2, 15.0),
             ([100, 500, 1000, 2000, 3000], [30, 100, 200], 1, 20.0),
             ([500, 1500, 2500], [20, 60, 120, 240, 400], 4, 10.0)]
    rng = np.random.default_rng(11)
    found = []
    for i in range(12):
        speeds, dps, quadrants, low = grids[i % 4]
        df = _map(spec, map_grid(speeds, dps, quadrants, p_low_bar=low), rng,
                  temps=(40.0, 70.0) if i % 3 == 0 else (50.0,))
        found += table_structures(fit_table(_table(spec, df, tmp_path / f"clean{i}.csv"), spec))
    assert found == []
