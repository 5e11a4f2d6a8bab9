"""Transducer zeros that change from run to run, told from physics (issue 15).

The flow meters' mass balance Q_A + Q_B = Q_case holds for the motor whatever its
parameters: its per-run means show the meters' gains (as differences) and their per-run
zeros with nothing fitted.  For any channel, runs at one operating point in the two
directions share the physics left in a residual, not per-run zeros.  Campaigns from
synthetic_data/concealed/ (truths in truths/, never given to the tool).
"""

import tomllib

import numpy as np
import pytest

from conftest import REPO
from motorid.discrepancy.locate import locate
from motorid.discrepancy.run_offsets import between_run_variance, flow_balance, run_spread
from motorid.discrepancy.unexplained import unexplained_entries
from motorid.identify.least_squares import fit_least_squares
from motorid.identify.pipeline import load_campaign
from motorid.io.spec import load_motor_spec

ROOT = REPO / "synthetic_data" / "concealed"


def _load(name):
    spec = load_motor_spec(ROOT / name / "motor.toml")
    _, ds = load_campaign([ROOT / name / "campaign.csv.gz"], spec)
    return spec, ds


def _truth(name):
    return tomllib.loads((ROOT / "truths" / f"{name}.toml").read_text())


@pytest.fixture(scope="module")
def offsets():
    spec, ds = _load("causes_per_run_offsets")
    return spec, ds, fit_least_squares(ds, spec)


def test_between_run_variance_recovers_a_known_spread_and_stays_zero_without_one():
    rng = np.random.default_rng(3)
    k = 400
    se = rng.uniform(0.05, 0.3, k)
    with_spread = between_run_variance(rng.normal(0, 0.2, k) + se * rng.standard_normal(k), se)
    assert abs(with_spread["tau"] - 0.2) < 0.03 and with_spread["p_value"] < 1e-6
    without = between_run_variance(1.0 + se * rng.standard_normal(k), se)
    assert without["tau"] < 0.03 and without["p_value"] > 1e-3


def test_the_mass_balance_tells_meter_gains_from_per_run_zeros():
    # a +1 % gain on the port-A meter: the balance follows Q_A by g_A − g_case = 0.01, no per-run zeros
    g = _truth("causes_flow_meter_gain_a")["mechanisms"]["flow_meter_gain_a"]["g"]
    fb = flow_balance(_load("causes_flow_meter_gain_a")[1])
    d, s = fb["gain_differences"], fb["gain_differences_std"]
    assert abs(d["g_A − g_case"] - g) < 4 * s["g_A − g_case"] and abs(d["g_B − g_case"]) < 4 * s["g_B − g_case"]
    assert fb["offsets"] is False
    # per-run zeros on the two port meters (σ 1e-6 m³/s each): the balance scatters from run to run
    fb = flow_balance(_load("causes_per_run_offsets")[1])
    assert fb["offsets"] is True and fb["p_value"] < 1e-6
    assert 0.4e-6 < fb["offset_spread"] < 2.5e-6
    assert "zero offsets that change between runs" in fb["words"]
    # a clean bench keeps the balance
    assert flow_balance(_load("causes_clean_9_seed214")[1])["offsets"] is False


def test_per_run_torque_zeros_are_told_from_a_friction_law(offsets):
    spec, ds, base = offsets
    sd = _truth("causes_per_run_offsets")["per_run_offset"]["torque"]["sd"]
    spread = run_spread(base.residuals["torque"], base.inliers["torque"], ds)
    assert spread["offset_like"] and abs(spread["tau"] - sd) < 0.3 * sd, spread
    # friction ∝ sgn ω/μ (in no catalog) leaves a run-to-run residual too, but twin runs share it
    spec2, ds2 = _load("causes_extra_friction_inverse_viscosity")
    fit2 = fit_least_squares(ds2, spec2)
    law = run_spread(fit2.residuals["torque"], fit2.inliers["torque"], ds2)
    assert law["p_value"] < 1e-6 and not law["offset_like"] and abs(law["twin_correlation"]) > 0.9, law


def test_per_run_zeros_are_said_as_such_without_a_smooth_law(offsets):
    spec, ds, base = offsets
    loc = locate(base, ds, spec)
    entries = {e["channel"]: e for e in unexplained_entries(loc.significant, base, ds, spec)}
    torque = entries["torque"]
    assert torque["run_spread"]["offset_like"] and "zero offset that changes between runs" in torque["description"]
    assert torque["empirical_term"] is None
    flows = [e for c, e in entries.items() if c in ("q_a", "q_b")]
    assert flows and all(e["flow_balance"]["offsets"] for e in flows)
