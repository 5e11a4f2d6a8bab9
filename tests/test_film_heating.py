"""Viscous heating of the films (motorid/physics/film_heating.py, issue 20): its equation, and
the mechanism named by `diagnose` on a concealed simulated loss map (the truth stays in this
test; diagnose sees the table only), with the whole catalog as candidates.

Gradients, neutrality, jit/vmap of the mechanism are checked with every catalog mechanism
in tests/physics/test_registry.py."""

import math

import numpy as np
import pandas as pd

from motorid import model
from motorid.physics import registry as catalog
from motorid.io.spec import MotorSpec, OilSpec

SPEC = MotorSpec("map-9", 9, 80e-6, 0.005, oil=OilSpec(temp_C=50.0))
BASE = {"Kv": 4000.0, "KF": 2e-3, "KFS": 1.2e-2, "TFc": 2.0, "Ks": 1.5,
        "KL0": 6e-14, "KL_a1": 0.2, "KL_b1": -0.1, "KAB": 3e-14}
RPM = 2 * math.pi / 60


def test_film_heating_divides_the_viscous_loss_by_one_plus_the_nahme_number():
    """Eq. (2): the viscous loss K_v D μ ω becomes K_v D μ ω / (1 + c_N μ ω²), nothing else changes,
    and the loss still grows with speed (the torque change is below the viscous loss itself)."""
    mech = catalog.get("film_heating")
    c_n = 3e-5
    speed = np.array([-3000, -500, 0.0, 100, 1000, 3000, 6000]) * RPM
    mu = np.array([0.01, 0.04, 0.04, 0.08, 0.04, 0.02, 0.06])
    n = speed.size
    s = model.make_samples(SPEC, np.linspace(0, 6, n), speed, np.full(n, 2e7), np.full(n, 1e6), np.full(n, 5e4), mu)
    p = model.as_jax({**BASE, "film_heating.c_N": c_n})
    a, b = model.predict(p, SPEC, s, (mech,)), model.predict(p, SPEC, s, ())
    viscous = BASE["Kv"] * SPEC.displacement * mu * speed
    expect = viscous - viscous / (1 + c_n * mu * speed**2)  # the part of the loss the heated films do not cause
    # a difference of two torques of ~300 N·m: round-off of 1e-13 N·m
    np.testing.assert_allclose(np.asarray(a.torque) - np.asarray(b.torque), expect, rtol=1e-9, atol=1e-12)
    assert np.all(np.abs(expect) <= np.abs(viscous)) and np.all(np.sign(expect) == np.sign(speed))
    for c in ("q_a", "q_b", "q_case"):
        np.testing.assert_array_equal(np.asarray(getattr(a, c)), np.asarray(getattr(b, c)))
    # loss still monotonic in speed: d/dω [ω/(1+cμω²)] > 0 below ω = 1/√(cμ)
    w = np.linspace(1, 1 / math.sqrt(c_n * 0.04), 50)
    assert np.all(np.diff(w / (1 + c_n * 0.04 * w**2)) > 0)


def test_diagnose_names_film_heating_on_a_concealed_loss_map(tmp_path):
    """A 4-quadrant map at two oil temperatures whose viscous loss bends over at speed: the table
    diagnose names film_heating alone and recovers c_N within 4 σ.  Candidates: every catalog
    mechanism that acts on the running torque (those that could stand in for it; the flow and
    sensor-lag ones are left out to keep the test fast)."""
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.discrepancy.tables import diagnose_table
    from motorid.io.tables import read_table

    truth = {**BASE, "film_heating.c_N": 6e-5}
    grid = map_grid([100, 500, 1000, 2000, 3000, 4000], [20, 100, 200, 300], 4)
    noise = {"torque_Nm": 0.3, "q_a_lpm": 0.05, "q_b_lpm": 0.05, "q_case_lpm": 0.02}
    rng = np.random.default_rng(11)
    frames = [simulate_map(SPEC, truth, grid, temp_C=t, mechanisms=(catalog.get("film_heating"),),
                           noise=noise, rng=rng) for t in (35, 70)]
    frames[1]["point_id"] = [f"H{i:03d}" for i in range(len(frames[1]))]
    pd.concat(frames, ignore_index=True).to_csv(tmp_path / "map.csv", index=False)
    torque_laws = [m for m in catalog.all_mechanisms()
                   if m.channels == ("torque",) and not m.id.startswith("sensor_lag")]
    assert len(torque_laws) >= 6 and catalog.get("hydrodynamic_torque") in torque_laws
    dg = diagnose_table(read_table(tmp_path / "map.csv", SPEC), SPEC, max_mechanisms=2, candidates=torque_laws)
    assert [m.id for m in dg["mechanisms"]] == ["film_heating"], dg["steps"]
    ls = dg["fit"].ls
    k = "film_heating.c_N"
    assert abs(ls.values[k] - truth[k]) < 4 * ls.std[k] < truth[k], (ls.values[k], ls.std[k])
    assert abs(ls.values["Kv"] - truth["Kv"]) < 4 * ls.std["Kv"]


def test_the_concealed_campaign_holds_no_truth():
    """synthetic_data/concealed/film_heating (generate_maps.py; diagnose names it: bench_mapphysics and
    docs/mechanisms.md): the campaign and the motor only, the truth kept apart."""
    from conftest import REPO

    root = REPO / "synthetic_data" / "concealed"
    assert sorted(p.name for p in (root / "film_heating").iterdir()) == ["campaign.csv.gz", "motor.toml"]
    assert "film_heating" not in (root / "film_heating" / "motor.toml").read_text()
    assert "[mechanisms.film_heating]" in (root / "truths" / "film_heating.toml").read_text()
