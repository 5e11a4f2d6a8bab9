"""Leakage gaps that open under pressure (motorid.physics.leakage.GapDeformation): the h³ law against its
equation, and the mechanism found and named by `diagnose` on a concealed loss map, not the
pressure-viscosity law that bends the other way nor an orifice leak; a clean map names nothing."""

import math

import numpy as np
import pandas as pd
import pytest

from motorid import model
from motorid.io.spec import MotorSpec, OilSpec
from motorid.physics import registry as catalog

SPEC = MotorSpec(name="t", pistons=9, displacement=80e-6, inertia=0.004)
BASE = {"Kv": 4000.0, "KF": 2e-3, "KFS": 1.2e-2, "TFc": 2.0, "Ks": 1.5,
        "KL0": 6e-14, "KL_a1": 0.0, "KL_b1": 0.0, "KAB": 3e-14}
RPM = 2 * math.pi / 60
BAR = 1e5


def test_each_laminar_leak_grows_as_the_cube_of_its_opened_gap_and_the_mass_balance_holds():
    """With h = h₀(1 + c|Δp|): the case drain is K_L0 Σ (P − P_c)(1 + c(P − P_c))³/μ, the cross-port
    leak K_AB ΔP(1 + c|ΔP|)³/μ, port flows change by what leaves them; c = 0 changes nothing."""
    mech = catalog.get("gap_deformation")
    c = 3e-9
    n = 12
    p_a = np.linspace(10, 300, n) * BAR
    p_b = np.full(n, 5 * BAR)
    p_c = np.full(n, 1 * BAR)
    mu = 0.03
    s = model.make_samples(SPEC, np.zeros(n), np.full(n, 100 * RPM), p_a, p_b, p_c, np.full(n, mu))
    with_ = model.predict(model.as_jax({**BASE, "gap_deformation.c": c}), SPEC, s, (mech,))
    base = model.predict(model.as_jax({**BASE, "gap_deformation.c": 0.0}), SPEC, s, (mech,))
    plain = model.predict(model.as_jax(BASE), SPEC, s, ())
    for ch in ("torque", "q_a", "q_b", "q_case"):
        np.testing.assert_allclose(np.asarray(getattr(base, ch)), np.asarray(getattr(plain, ch)), rtol=0, atol=1e-18)
    case = BASE["KL0"] * ((p_a - p_c) * (1 + c * (p_a - p_c)) ** 3 + (p_b - p_c) * (1 + c * (p_b - p_c)) ** 3) / mu
    np.testing.assert_allclose(np.asarray(with_.q_case), case, rtol=1e-9)
    cross = BASE["KAB"] * (p_a - p_b) * ((1 + c * np.abs(p_a - p_b)) ** 3 - 1) / mu
    d_a = np.asarray(with_.q_a) - np.asarray(plain.q_a)
    d_b = np.asarray(with_.q_b) - np.asarray(plain.q_b)
    d_la = BASE["KL0"] * (p_a - p_c) * ((1 + c * (p_a - p_c)) ** 3 - 1) / mu
    d_lb = BASE["KL0"] * (p_b - p_c) * ((1 + c * (p_b - p_c)) ** 3 - 1) / mu
    np.testing.assert_allclose(d_a, d_la + cross, rtol=1e-9)
    np.testing.assert_allclose(d_b, d_lb - cross, rtol=1e-9)
    np.testing.assert_allclose(d_a + d_b, np.asarray(with_.q_case) - np.asarray(plain.q_case), rtol=1e-9)
    np.testing.assert_allclose(np.asarray(with_.torque), np.asarray(plain.torque), rtol=0, atol=1e-12)


def _map(tmp_path, truth, mechanisms, seed):
    from motorid.bench.maps import map_grid, simulate_map

    spec = MotorSpec("map-9", 9, 80e-6, 0.005, oil=OilSpec(temp_C=50.0))
    grid = map_grid([50, 300, 1000, 2000, 3000], [20, 80, 160, 240, 320], 4)
    noise = {"torque_Nm": 0.3, "q_a_lpm": 0.05, "q_b_lpm": 0.05, "q_case_lpm": 0.01}
    frames = [simulate_map(spec, truth, grid, temp_C=t, mechanisms=mechanisms, noise=noise,
                           rng=np.random.default_rng(seed + k)) for k, t in enumerate((40, 70))]
    frames[1]["point_id"] = [f"Q{i:03d}" for i in range(len(frames[1]))]
    pd.concat(frames, ignore_index=True).to_csv(tmp_path / "map.csv", index=False)
    return spec


@pytest.mark.parametrize("seed", [3])
def test_diagnose_names_gaps_opening_under_pressure_on_a_loss_map(tmp_path, seed):
    """A four-quadrant map at two oil temperatures whose leaks grow 30 % above proportional at 320 bar
    (c = 8e-10 /Pa): the whole catalog as candidates, `gap_deformation` is named, c recovered within
    four standard errors; neither pressure_viscosity nor turbulent_leakage is named."""
    from motorid.discrepancy.tables import diagnose_table
    from motorid.io.tables import read_table

    truth = {**BASE, "gap_deformation.c": 8e-10}
    spec = _map(tmp_path, truth, (catalog.get("gap_deformation"),), seed)
    dg = diagnose_table(read_table(tmp_path / "map.csv", spec), spec, max_mechanisms=2)
    named = [m.id for m in dg["mechanisms"]]
    assert named == ["gap_deformation"], dg["steps"]
    ls = dg["fit"].ls
    k = "gap_deformation.c"
    assert abs(ls.values[k] - truth[k]) < 4 * ls.std[k], (ls.values[k], ls.std[k])
