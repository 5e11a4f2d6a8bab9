"""Loss maps made by a law that is not motorid's (a second reader's, stop 38): the Schlösser /
McCandlish–Dorey shape of a real unit, written here in plain numpy, nothing of motorid's model in it.
Its cross-port leak has a turbulent √ΔP part, its churning goes as ω², a compressibility flow
∝ |ω|·|ΔP| passes between the ports, and its case leakage is exactly laminar.

Two wrong answers were given with exit 0 on such maps:

- diagnose named ``pressure_viscosity`` (and with a boost pressure a case-meter zero) as a stand-in
  for the turbulent cross-port leak, which bent the laminar case drain 16-45× away from the truth;
- predict's 95 % confidence band held the true value at 3-17 % of held-out points (the fit took the
  model's misfit as noise, so χ²/dof was 1 and nothing warned).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

MOTOR = """[motor]
name = "foreign law"
pistons = 9
displacement_cm3 = 80.0

[oil]
name = "ISO VG 46 mineral oil"
nu40_cSt = 46.0
nu100_cSt = 6.8
density15_kg_m3 = 875.0
temp_C = 50.0
"""
D_CM3, TEMP_C, P_CASE = 80.0, 50.0, 2.0


def _oil():
    """μ [Pa·s], ρ [kg/m³] of ISO VG 46 at TEMP_C (Walther, ASTM D341)."""
    T1, T2 = 313.15, 373.15
    y1, y2 = np.log10(np.log10(46.7)), np.log10(np.log10(7.5))
    B = (y1 - y2) / (np.log10(T2) - np.log10(T1))
    A = y1 + B * np.log10(T1)
    T = TEMP_C + 273.15
    rho = 875.0 * (1 - 0.00065 * (T - 288.15))
    return rho * (10 ** (10 ** (A - B * np.log10(T))) - 0.7) * 1e-6, rho


def law(speed_rpm, p_a_bar, p_b_bar, d_cm3=D_CM3, full_cm3=None, p_case=P_CASE) -> dict:
    """The foreign unit's true outputs (bench units); ``full_cm3``: a variable unit whose gaps, viscous,
    churning and compression losses keep the largest setting's size (they do not shrink with the swash
    angle), at setting ``d_cm3``."""
    mu, rho = _oil()
    d = np.asarray(d_cm3, float) * 1e-6 / (2 * np.pi)
    f = d if full_cm3 is None else full_cm3 * 1e-6 / (2 * np.pi)
    w = np.asarray(speed_rpm, float) * 2 * np.pi / 60
    pa, pb = np.asarray(p_a_bar, float) * 1e5, np.asarray(p_b_bar, float) * 1e5
    dp, pc = pa - pb, p_case * 1e5
    t_loss = 8.3e4 * mu * np.abs(w) * f + 0.035 * np.abs(dp) * d + 8.0 * rho * w**2 * f ** (5 / 3) + 1.57e5 * f
    q_la, q_lb = 1.4e-9 * f * (pa - pc) / mu, 1.4e-9 * f * (pb - pc) / mu
    q_ab = 2.9e-9 * f * dp / mu + 1.5e-4 * f ** (2 / 3) * np.sign(dp) * np.sqrt(2 * np.abs(dp) / rho)
    q_c = 3.1e-10 * np.abs(w) * np.abs(dp) * f
    return {"torque_Nm": d * dp - np.sign(w) * t_loss, "q_a_lpm": (d * w + q_la + q_ab + np.sign(dp) * q_c) * 6e4,
            "q_b_lpm": (-d * w + q_lb - q_ab - np.sign(dp) * q_c) * 6e4, "q_case_lpm": (q_la + q_lb) * 6e4}


NOISE = {"torque_Nm": 0.0015 * 80e-6 / (2 * np.pi) * 400e5, "q_a_lpm": 0.002 * 280.0, "q_b_lpm": 0.002 * 280.0,
         "q_case_lpm": 0.0004 * 280.0}


def _points(speeds, dps) -> pd.DataFrame:
    """Four quadrants: each speed and |ΔP| in motor and pump mode, both directions."""
    w, dp = np.meshgrid(speeds, dps)
    w, dp = w.ravel(), dp.ravel()
    w = np.concatenate([w, w, -w, -w])
    dp = np.concatenate([dp, -dp, dp, -dp])
    return pd.DataFrame({"speed_rpm": w, "p_a_bar": np.maximum(dp, 0.0), "p_b_bar": np.maximum(-dp, 0.0),
                         "p_case_bar": P_CASE, "oil_temp_C": TEMP_C})


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    d = tmp_path_factory.mktemp("foreign")
    (d / "motor.toml").write_text(MOTOR)
    rng = np.random.default_rng(0)
    grid = _points([50, 100, 200, 400, 700, 1000, 1500, 2000, 2500, 3000, 3500],
                   [10, 25, 50, 100, 150, 200, 250, 300, 350, 400])
    true = law(grid.speed_rpm, grid.p_a_bar, grid.p_b_bar)
    grid.assign(**{k: v + NOISE[k] * rng.standard_normal(v.size) for k, v in true.items()}).to_csv(d / "map.csv",
                                                                                                 index=False)
    # held-out points inside the fitted range, never on the grid
    n = 60
    held = pd.DataFrame({"point_id": [f"h{i}" for i in range(n)]})
    held = held.assign(**_points([0.0], [0.0]).iloc[[0] * n].reset_index(drop=True))
    w = rng.uniform(60, 3400, n) * rng.choice([-1, 1], n)
    dp = rng.uniform(15, 390, n) * rng.choice([-1, 1], n)
    held = held.assign(speed_rpm=w, p_a_bar=np.maximum(dp, 0.0), p_b_bar=np.maximum(-dp, 0.0))
    held.to_csv(d / "held.csv", index=False)
    return d, held.assign(**law(held.speed_rpm, held.p_a_bar, held.p_b_bar))


def test_predicts_confidence_band_holds_the_true_mean_where_the_model_misses_by_structure(foreign, capsys):
    from motorid.cli import main

    d, truth = foreign
    assert main(["fit", str(d / "map.csv"), "--motor", str(d / "motor.toml"), "--out", str(d / "fit"),
                 "--quiet", "--force"]) == 0
    printed = capsys.readouterr().out
    assert "misses the table's port A flow by structure" in printed
    assert "misses the table's case-drain flow" not in printed  # laminar: the model holds it
    assert main(["predict", str(d / "fit"), str(d / "held.csv"), "--out", str(d / "pred.csv")]) == 0
    pred = pd.read_csv(d / "pred.csv").set_index("point_id").loc[truth.point_id]
    for col in ("torque_Nm", "q_a_lpm", "q_b_lpm", "q_case_lpm"):
        t = truth[col].to_numpy()
        inside = (pred[col + "_lo95"].to_numpy() <= t) & (t <= pred[col + "_hi95"].to_numpy())
        assert inside.mean() >= 0.85, (col, inside.mean())  # was 3-17 % for the flows and torque
    # the case drain's band stays as narrow as the parameters make it (no model error found there)
    width = (pred["q_case_lpm_hi95"] - pred["q_case_lpm_lo95"]).median()
    assert width < 0.25 * (pred["q_a_lpm_hi95"] - pred["q_a_lpm_lo95"]).median()


def test_a_model_that_holds_the_map_adds_no_model_error():
    """On maps of motorid's own model (noise only), neighbouring points share nothing: the bands are
    the parameters' alone."""
    from conftest import DEMO_TRUTH, map_motor_toml
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.identify.lack_of_fit import structured_error
    from motorid.identify.tables import fit_table
    from motorid.io.spec import parse_stored_spec
    from motorid.io.tables import read_table

    spec = parse_stored_spec(map_motor_toml(50.0), "motor.toml")
    found = []
    for seed in range(4):
        df = simulate_map(spec, DEMO_TRUTH, map_grid([100, 300, 1000, 2000, 3000], [20, 50, 150, 250, 320], 4),
                          temp_C=50.0, noise={"torque_Nm": 0.3, "q_a_lpm": 0.05, "q_b_lpm": 0.05, "q_case_lpm": 0.02},
                          rng=np.random.default_rng(seed))
        table = read_table(_csv(df, seed), spec)
        fit = fit_table(table, spec)
        found += [e["sigma"] > 0 for e in structured_error(table, fit.table_residuals).values()]
        assert not any("by structure" in w for w in fit.ls.warnings)
    assert sum(found) <= 1, found  # 16 channel fits, one-sided 2σ test: at most a chance one


def _csv(df, seed):
    import tempfile
    from pathlib import Path

    path = Path(tempfile.mkdtemp()) / f"m{seed}.csv"
    df.to_csv(path, index=False)
    return path


def test_diagnose_refuses_a_law_that_fits_one_channel_worse_for_the_others(foreign):
    """The pressure-viscosity law lowers the BIC (it bends the port flows toward the √ΔP leak) by
    fitting the laminar case drain worse: refused as a stand-in; what the map holds is named."""
    from motorid.discrepancy.tables import diagnose_table
    from motorid.io.spec import load_motor_spec
    from motorid.io.tables import read_table
    from motorid.physics.registry import get

    d, _ = foreign
    spec = load_motor_spec(d / "motor.toml")
    ids = ("pressure_viscosity", "flow_meter_offset_case", "compressibility_flow", "hydrodynamic_torque")
    dg = diagnose_table(read_table(d / "map.csv", spec), spec, candidates=[get(i) for i in ids])
    assert [m.id for m in dg["mechanisms"]] == ["compressibility_flow", "hydrodynamic_torque"]
    refused = {s["id"]: s["refused"] for s in dg["steps"] if "refused" in s}
    assert "fits the case-drain flow worse" in refused.get("pressure_viscosity", ""), dg["steps"]


def test_a_variable_unit_whose_losses_keep_the_largest_size_gets_no_displacement_error(tmp_path):
    """Four settings (25-100 % of 250 cm³/rev), the displacement column exact, but the gaps, viscous,
    churning and compression losses keep the largest setting's size: diagnose named a displacement
    error of +0.25 % "at every setting alike" (a second reader's v7).  Fitted on the small settings it
    predicts the large ones worse than the model without it: refused as a stand-in."""
    from motorid.discrepancy.tables import diagnose_table
    from motorid.io.spec import load_motor_spec
    from motorid.io.tables import read_table
    from motorid.physics.registry import get

    (tmp_path / "motor.toml").write_text(MOTOR.replace("80.0", "250.0"))
    spec = load_motor_spec(tmp_path / "motor.toml")
    rng = np.random.default_rng(7)
    parts = []
    for x in (0.25, 0.5, 0.75, 1.0):
        w, dp = np.meshgrid([100, 300, 600, 1000, 1500, 2000], [25, 50, 100, 200, 300, 400])
        pts = pd.DataFrame({"speed_rpm": w.ravel(), "p_a_bar": dp.ravel() + 1.0, "p_b_bar": 1.0, "p_case_bar": 1.0,
                            "oil_temp_C": TEMP_C, "displacement_cm3": 250.0 * x})
        true = law(pts.speed_rpm, pts.p_a_bar, pts.p_b_bar, pts.displacement_cm3, full_cm3=250.0, p_case=1.0)
        noise = {"torque_Nm": 0.0015 * 250e-6 / (2 * np.pi) * 400e5, "q_a_lpm": 0.002 * 500.0,
                 "q_b_lpm": 0.002 * 500.0, "q_case_lpm": 0.0004 * 500.0}
        parts.append(pts.assign(**{k: v + noise[k] * rng.standard_normal(len(pts)) for k, v in true.items()}))
    pd.concat(parts).to_csv(tmp_path / "map.csv", index=False)
    ids = ("hydrodynamic_torque", "compressibility_flow", "displacement_error")
    dg = diagnose_table(read_table(tmp_path / "map.csv", spec), spec, candidates=[get(i) for i in ids])
    assert "displacement_error" not in [m.id for m in dg["mechanisms"]]
    refused = {s["id"]: s["refused"] for s in dg["steps"] if "refused" in s}
    assert "predicts the larger settings from the smaller worse" in refused.get("displacement_error", ""), dg["steps"]


def _tiny_law(speed_rpm, p_a_bar, p_b_bar, p_case=0.5):
    """A second reader's 0.8 cm³/rev unit (stop 39, his own law): constant seal friction, churning ∝ ω²,
    a turbulent √ΔP cross-port leak, laminar case leakage; the displacement exact."""
    mu, rho = _oil()
    d = 0.8e-6 / (2 * np.pi)
    w = np.asarray(speed_rpm, float) * np.pi / 30
    pa, pb, pc = np.asarray(p_a_bar, float) * 1e5, np.asarray(p_b_bar, float) * 1e5, p_case * 1e5
    dp = pa - pb
    t_loss = 0.03 + 0.03 * d * np.abs(dp) + 3e4 * mu * np.abs(w) * d + 15.0 * rho * w * w * d ** (5 / 3)
    la, lb = 2.2e-9 * d * (pa - pc) / mu, 2.2e-9 * d * (pb - pc) / mu
    x = 1.5e-9 * d * dp / mu + 4e-4 * d ** (2 / 3) * np.sign(dp) * np.sqrt(2 * np.abs(dp) / rho)
    return {"torque_Nm": d * dp - np.sign(w) * t_loss, "q_a_lpm": (d * w + la + x) * 6e4,
            "q_b_lpm": (-d * w + lb - x) * 6e4, "q_case_lpm": (la + lb) * 6e4}


def test_a_stand_in_that_fails_the_operating_region_it_was_not_fitted_on_is_refused(tmp_path):
    """The tiny unit's map (noise growing with the reading, as a maker's): diagnose had named a
    displacement error of +1.89 % (exact in truth), a filling loss and a pressure-viscosity law.  The
    displacement error, fitted on the slow points, predicts the fast ones worse than the model without
    it, and the other way round: refused; the √ΔP leak is left unexplained with its own law as the
    empirical term."""
    from motorid.discrepancy.tables import diagnose_table
    from motorid.io.spec import load_motor_spec
    from motorid.io.tables import read_table
    from motorid.physics.registry import get

    (tmp_path / "motor.toml").write_text(MOTOR.replace("80.0", "0.8").replace("pistons = 9", "pistons = 7"))
    spec = load_motor_spec(tmp_path / "motor.toml")
    rng = np.random.default_rng(3)
    w, dp = np.meshgrid([200, 500, 1000, 1500, 2000, 3000, 4000, 5000, 6000], [20, 50, 80, 110, 140, 170, 210])
    sg = np.repeat([1.0, -1.0], w.size)
    w, dp = np.tile(w.ravel(), 2) * sg, np.tile(dp.ravel(), 2) * sg
    pts = pd.DataFrame({"speed_rpm": w, "p_a_bar": np.where(dp > 0, 5 + dp, 5.0), "p_b_bar": np.where(dp > 0, 5.0, 5 - dp),
                        "p_case_bar": 0.5, "oil_temp_C": TEMP_C})
    true = _tiny_law(pts.speed_rpm, pts.p_a_bar, pts.p_b_bar)
    scale = {"torque_Nm": 0.8 / 6.283 * 210 * 5e-4, "q_a_lpm": 4.8 * 5e-4, "q_b_lpm": 4.8 * 5e-4, "q_case_lpm": 5e-4}
    rel = {"torque_Nm": 0.002, "q_a_lpm": 0.003, "q_b_lpm": 0.003, "q_case_lpm": 0.02}
    pts = pts.assign(**{k: v + rng.standard_normal(v.size) * np.sqrt((rel[k] * v) ** 2 + scale[k] ** 2)
                        for k, v in true.items()})
    pts.to_csv(tmp_path / "map.csv", index=False)
    ids = ("displacement_error", "filling_loss", "pressure_viscosity", "hydrodynamic_torque")
    dg = diagnose_table(read_table(tmp_path / "map.csv", spec), spec, candidates=[get(i) for i in ids])
    named = [m.id for m in dg["mechanisms"]]
    assert not {"displacement_error", "filling_loss", "pressure_viscosity"} & set(named), dg["steps"]
    refused = {s["id"]: s["refused"] for s in dg["steps"] if "refused" in s}
    assert "fails where it was not fitted" in refused.get("displacement_error", ""), dg["steps"]
    terms = {u["channel"]: (u.get("empirical_term") or {}).get("formula", "") for u in dg["unexplained"]}
    assert "√|ΔP|" in terms.get("q_a", ""), dg["unexplained"]


def test_the_model_error_test_holds_for_noise_that_grows_with_the_reading():
    """Neighbours' residual products under a permutation test: a smooth model error under noise that
    grows tenfold over the map is found; the same noise alone is not (in 20 draws, at most one)."""
    import types

    from motorid.identify.lack_of_fit import structured_error

    w, dp = np.meshgrid(np.linspace(1, 150, 12), np.linspace(20, 300, 10))
    w, dp = w.ravel(), dp.ravel()
    table = types.SimpleNamespace(speed=w, dp=dp, p_a=dp, p_b=np.zeros_like(dp), p_case=np.zeros_like(dp),
                                  viscosity=np.full(dp.size, 0.03))
    scale = 0.5 + 5.0 * dp / 300  # 0.5 … 5.5
    field = 8.0 * np.sin(w / 40) * (dp / 300)
    found = []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        noise = scale * rng.standard_t(4, dp.size) / np.sqrt(2)
        found.append(structured_error(table, {"torque": noise}, seed=seed)["torque"]["sigma"] > 0)
        if seed < 5:
            assert structured_error(table, {"torque": noise + field}, seed=seed)["torque"]["sigma"] > 0
    assert sum(found) <= 1, found
