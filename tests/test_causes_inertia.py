"""A wrong rotor inertia in the spec (issue 15), and standard errors that the runs' own scatter widens.

The spec's J is what turns with the rotor up to the torque flange; a coupling or a flange hub left
out makes the true J several times the data sheet's.  In steady runs it shows only where the shaft
speed ripples: the torque carries −J·α, and a wrong J leaves −ΔJ·α in the residual.  The campaign
``causes_inertia_error`` is simulated with the true J (4× the motor.toml's), not through the
mechanism's hook; its truth stays in synthetic_data/concealed/truths/.
"""

import dataclasses
import math

import numpy as np
import pytest

from conftest import REPO, concealed
from motorid import model
from motorid.identify.cell_fit import fit_cells
from motorid.identify.least_squares import fit_least_squares
from motorid.identify.pipeline import load_campaign
from motorid.identify.run_scatter import birge_ratio
from motorid.identify.types import FitOptions
from motorid.io.spec import load_motor_spec
from motorid.physics import registry as catalog

ROOT = REPO / "synthetic_data" / "concealed"
NAME = "causes_inertia_error"
BASE = {"Kv": 4000.0, "KF": 2e-3, "KFS": 1.2e-2, "TFc": 2.0, "Ks": 1.5,
        "KL0": 6e-14, "KL_a1": 0.2, "KL_b1": -0.1, "KAB": 3e-14}


def test_inertia_error_is_the_model_with_the_true_inertia():
    """The hook with ΔJ on a spec of J is the 1992 model on a spec of J + ΔJ (Eq. 17), sample by
    sample; the flows and the held torque at breakaway are untouched."""
    spec = model.MotorSpec(name="t", pistons=9, displacement=80e-6, inertia=0.004)
    true = dataclasses.replace(spec, inertia=0.004 + 0.011)
    rng = np.random.default_rng(3)
    n = 200
    s = model.make_samples(spec, rng.uniform(0, 2 * np.pi, n), rng.choice([-1, 1], n) * rng.uniform(1, 300, n),
                           rng.uniform(1e6, 2.5e7, n), rng.uniform(5e5, 2e6, n), np.full(n, 7e4),
                           rng.uniform(0.015, 0.05, n), acceleration=rng.normal(0.0, 40.0, n))
    mech = catalog.get("inertia_error")
    hooked = model.predict(model.as_jax({**BASE, "inertia_error.dJ": 0.011}), spec, s, (mech,))
    plain = model.predict(model.as_jax(BASE), true, s)
    for got, want in zip(hooked, plain):
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-12, atol=1e-12)
    without = model.predict(model.as_jax(BASE), spec, s)
    assert np.max(np.abs(np.asarray(hooked.torque) - np.asarray(without.torque))) > 0.1  # J·α is not nothing
    assert mech.unseen_in_table(None)  # a table of steady means holds no acceleration
    # what an export writes for the load: the measured J, never a negative one
    assert mech.fold_into_spec({"inertia_error.dJ": 0.011}, spec).inertia == pytest.approx(0.015, rel=1e-12)
    from motorid.errors import InputError

    with pytest.raises(InputError, match="not positive"):
        mech.fold_into_spec({"inertia_error.dJ": -0.005}, spec)
    words = mech.describe({"dJ": 0.011}, spec=spec)
    assert "0.015 kg·m²" in words and "+275 %" in words


@pytest.fixture(scope="module")
def campaign():
    spec, ds, base, truth = concealed(NAME)
    return spec, ds, base, truth["mechanisms"]["inertia_error"]["dJ"]


@pytest.mark.slow  # a minute of diagnose: `make test-all`, and `make bench` (bench_causes scores the campaign too)
def test_the_inertia_error_is_told_from_its_torque_rivals_and_recovered_within_its_error(campaign):
    """The inertia error and the catalog's other torque ripples fitted on the same data, noise and
    outliers held as the base fit's (as diagnose compares them): only ΔJ takes the residual away,
    and the fit with its own noise gives ΔJ within 3 σ of the truth (σ widened by the runs' scatter:
    the acceleration of the aliased fast runs carries errors of its own)."""
    spec, ds, base, dj = campaign
    noise = {c: base.noise_by_run[c] for c in base.noise_by_run}
    if base.noise.get("breakaway") is not None:
        noise["breakaway"] = np.asarray(base.sigma["breakaway"], dtype=float)
    held = FitOptions(fixed_noise=noise, fixed_inliers=dict(base.inliers))
    rivals = ("inertia_error", "sensor_lag_torque", "misalignment_ripple", "torque_meter_gain", "torque_offset")
    gain = {m: base.chi2 - fit_least_squares(ds, spec, [catalog.get(m)], held, initial=base.params_all).chi2
            for m in rivals}
    assert gain["inertia_error"] > 100.0
    assert gain["inertia_error"] > 5 * max(max(v for m, v in gain.items() if m != "inertia_error"), 1.0), gain
    fit = fit_least_squares(ds, spec, [catalog.get("inertia_error")])
    value, std = fit.values["inertia_error.dJ"], fit.std["inertia_error.dJ"]
    assert abs(value - dj) < 3 * std, (value, std, dj)
    assert abs(value - dj) < 0.1 * dj  # within 10 % whatever the widening
    assert std < 0.15 * dj  # and it still says something
    assert any("inertia_error.dJ" in w and "widened" in w for w in fit.warnings)


def test_runs_that_disagree_widen_a_parameter_and_runs_that_agree_do_not():
    """Birge's ratio of the runs' own estimates: a torque zero drawn anew for every run
    (``causes_per_run_offsets``, σ 0.25 N·m) fitted as one offset scatters far beyond the runs'
    errors, and its standard error is widened by that; a zero that is the same in every run
    (``causes_offsets_and_gain``, 0.4 N·m) is not."""
    out = {}
    for name in ("causes_per_run_offsets", "causes_offsets_and_gain"):
        spec = load_motor_spec(ROOT / name / "motor.toml")
        _, ds = load_campaign([ROOT / name / "campaign.csv.gz"], spec)
        fit = fit_least_squares(ds, spec, [catalog.get("torque_offset")])
        out[name] = (birge_ratio(fit, "torque_offset.T0", ds), fit)
    (r2_wander, runs), wander = out["causes_per_run_offsets"]
    narrow = wander.std["torque_offset.T0"] / math.sqrt(r2_wander)
    (r2_fixed, _), fixed = out["causes_offsets_and_gain"]
    assert r2_wander > 10.0 and runs >= 20
    assert r2_fixed < 2.0
    assert any("torque_offset.T0" in w and "widened" in w for w in wander.warnings)
    assert not any("torque_offset.T0" in w and "widened" in w for w in fixed.warnings)
    # the widened error is the narrow one times √R² (the covariance's row and column with it)
    i = wander.free.index("torque_offset.T0")
    assert math.isclose(wander.std["torque_offset.T0"], math.sqrt(wander.covariance[i, i]), rel_tol=1e-9)
    # the same on the path of long logs, reduced to shaft-angle cells as they are read (the runs'
    # estimates from the cells the fit solved on)
    name = "causes_per_run_offsets"
    spec = load_motor_spec(ROOT / name / "motor.toml")
    _, cells = load_campaign([ROOT / name / "campaign.csv.gz"], spec, cells=True)
    reduced = fit_cells(cells, spec, [catalog.get("torque_offset")])
    assert any("torque_offset.T0" in w and "widened" in w for w in reduced.warnings)
    assert reduced.std["torque_offset.T0"] > 5 * narrow
