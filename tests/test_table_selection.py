"""Diagnose on a big table: mechanisms chosen on points spread over the operating range, the chosen
model fitted and compared on every point (motorid/discrepancy/tables.py ``selection_points``)."""

from __future__ import annotations

import numpy as np

from motorid.bench.maps import map_grid, simulate_map
from motorid.model import MotorSpec, OilSpec

TRUTH = {"Kv": 5000.0, "KF": 3e-3, "KFS": 1.5e-2, "TFc": 3.0, "Ks": 1.0, "KL0": 5e-14, "KL_a1": 0.15,
         "KL_b1": 0.08, "KAB": 2e-14}
NOISE = {"torque_Nm": 0.3, "q_a_lpm": 0.05, "q_b_lpm": 0.05, "q_case_lpm": 0.02}
SPEC = MotorSpec("map-9", 9, 80e-6, 0.005, oil=OilSpec(temp_C=50.0))


def _table(tmp_path, speeds, dps, quadrants=4, mechanisms=(), truth=TRUTH, name="t.csv", recording=None):
    from motorid.io.tables import read_table

    df = simulate_map(SPEC, truth, map_grid(speeds, dps, quadrants), mechanisms=mechanisms, noise=NOISE,
                      rng=np.random.default_rng(7))
    if recording is not None:
        df["recording"] = recording(len(df))
    path = tmp_path / name
    df.to_csv(path, index=False)
    return read_table(path, SPEC)


def test_points_spread_over_the_range_one_per_cell(tmp_path):
    from motorid.discrepancy.tables import selection_points

    speeds = np.linspace(50, 3000, 40)
    dps = np.linspace(10, 300, 15)
    t = _table(tmp_path, speeds, dps)  # 4 quadrants: 2 400 points
    assert selection_points(t, len(t)) is None  # no more points than asked: every point
    idx = selection_points(t, 300)
    assert 200 < idx.size <= 300 and np.all(np.diff(idx) > 0)
    np.testing.assert_array_equal(idx, selection_points(t, 300))  # nothing random
    s, dp = t.speed[idx], t.dp[idx]
    for full, part in ((t.speed, s), (t.dp, dp)):  # both signs, and the edges to within a cell
        span = np.ptp(full)
        assert part.min() - full.min() < 0.07 * span and full.max() - part.max() < 0.07 * span
    # the four quadrants keep a quarter each
    quarters = [np.sum((np.sign(s) == a) & (np.sign(dp) == b)) for a in (1, -1) for b in (1, -1)]
    assert max(quarters) - min(quarters) <= 0.1 * idx.size
    # repeated operating points and crowded cells keep n points, not one per occupied cell
    repeated = t.subset(np.repeat(np.arange(3), 1000))
    assert selection_points(repeated, 300).size == 300
    crowded = t.subset(np.r_[np.repeat(np.flatnonzero(np.abs(t.speed) < 200), 100), np.argmax(t.speed)])
    assert selection_points(crowded, 300).size >= 290
    # two recordings (say two temperatures) keep their share each
    r = _table(tmp_path, speeds, dps, name="r.csv", recording=lambda n: np.where(np.arange(n) % 3, "hot", "cold"))
    idx = selection_points(r, 300)
    rec = r.recordings()[idx]
    assert abs(np.sum(rec == "hot") - np.sum(rec == "cold")) <= 0.1 * idx.size


def test_a_big_table_is_diagnosed_on_its_spread_and_fitted_on_every_point(tmp_path, monkeypatch):
    """Churning torque (ω²) concealed in a map of 512 points; the selection takes 64 of them; the same
    name; the churning coefficient and the held-out comparison from every point."""
    import motorid.discrepancy.tables as dt
    from motorid.discrepancy.tables import diagnose_table, diagnosis_table_document
    from motorid.physics.registry import get

    hydro = get("hydrodynamic_torque")
    truth = dict(TRUTH, **{"hydrodynamic_torque.C_h": 1e-4})
    t = _table(tmp_path, np.linspace(100, 3000, 16), np.linspace(20, 300, 8), mechanisms=(hydro,), truth=truth)
    import motorid.comparators.evaluate as ev

    monkeypatch.setattr(dt, "SELECTION_POINTS", 64)
    compared, compare = [], ev.compare
    monkeypatch.setattr(ev, "compare", lambda table, *a, **k: compared.append(len(table)) or compare(table, *a, **k))
    seen = []
    cands = [get("turbulent_leakage"), hydro]
    dg = diagnose_table(t, SPEC, candidates=cands, max_mechanisms=2, progress=seen.append)
    assert [m.id for m in dg["mechanisms"]] == ["hydrodynamic_torque"]
    assert any("of the 512 points" in m for m in seen)
    assert 32 < dg["selection_points"]["points"] <= 64 and dg["selection_points"]["of"] == 512
    assert len(dg["fit"].table) == 512 and len(dg["base_fit"].table) == 512  # fitted on every point
    assert compared == [512] and "motorid + hydrodynamic_torque" in dg["comparison"]["models"]
    ls = dg["fit"].ls
    k = "hydrodynamic_torque.C_h"
    assert abs(ls.values[k] - 1e-4) < 3 * ls.std[k]
    # its std is every point's: smaller than a fit of the 64 alone would give
    from motorid.identify.tables import fit_table

    small = fit_table(t.subset(dt.selection_points(t, 64)), SPEC, [hydro])
    assert ls.std[k] < 0.5 * small.ls.std[k]
    doc = diagnosis_table_document(dg, SPEC)
    assert doc["selection"]["points"] == dg["selection_points"]["points"] and doc["selection"]["of_points"] == 512
    assert "fitted and compared on every point" in doc["selection"]["points_note"]
    # a table no bigger than the limit: every point, no note
    monkeypatch.setattr(dt, "SELECTION_POINTS", 2000)
    assert diagnosis_table_document({**dg, "selection_points": {"points": 512, "of": 512}}, SPEC)[
        "selection"].get("points_note") is None


def test_on_a_pump_map_alone_a_law_that_differs_between_the_modes_is_not_tried(tmp_path):
    """A pump's own map (every point in pump mode, as the V32HL56 map of docs/maps.md): a friction that
    differs in pump mode is K_F itself in other words (it was named there with ΔK_F < 0 and K_F at 0).
    Not tried, with the reason; a map with both modes tries it.  A displacement error on a variable
    unit's table is told relative to the table's displacement column."""
    from motorid.discrepancy.tables import diagnose_table, diagnosis_table_document
    from motorid.physics.registry import get

    pmf = get("pump_mode_friction")
    both = _table(tmp_path, [500, 1500, 3000], [50, 150, 300], quadrants=2, name="both.csv")
    assert pmf.unseen_in_table(both) is None
    pump = both.subset(np.sign(both.speed) * both.dp < 0)
    assert len(pump) == 9
    why = pmf.unseen_in_table(pump)
    assert "9 pump-mode and 0 motor-mode points" in why and "K_F in other words" in why
    dg = diagnose_table(pump, SPEC, candidates=[pmf], max_mechanisms=1)
    assert not dg["mechanisms"] and {"id": "pump_mode_friction", "skipped": why} in dg["steps"]

    eps = get("displacement_error")
    variable = _table(tmp_path, [500, 1500, 3000], [50, 150, 300], name="var.csv")
    variable.variable_displacement = True
    variable.displacement = np.where(np.arange(len(variable)) % 2, 40e-6, 80e-6)
    words = eps.describe_per_point({"displacement_error.eps": -0.01}, variable.displacement)
    assert "-1 % from the table's displacement column" in words and "40 → 39.6" in words and "80 → 79.2" in words
    fake = {"mechanisms": [eps], "fit": dg["fit"], "base_fit": dg["base_fit"], "steps": [], "comparison": None,
            "unexplained": []}
    fake["fit"].ls.params_all["displacement_error.eps"] = -0.01
    fake["fit"].table = variable
    doc = diagnosis_table_document(fake, SPEC)
    assert "table's displacement column" in doc["mechanisms"][0]["description"]
