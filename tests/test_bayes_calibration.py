"""Issue 7: the breakaway noise level's uncertainty is carried into the
intervals (Student-t dof in least squares; σ_brk integrated out of the posterior)."""

import math

import numpy as np
import pytest

from conftest import DEMO_TRUTH, simulated
from motorid.identify.extract import extract
from motorid.identify.least_squares import fit_least_squares


@pytest.fixture(scope="module")
def fitted():
    frame, spec, params = simulated(pistons=9, truth_items=tuple(sorted(DEMO_TRUTH.items())))
    ds = extract(frame, spec)
    return fit_least_squares(ds, spec), spec


def test_interval_dof_rests_on_the_breakaway_events(fitted):
    from motorid.identify.results import interval_dof, interval_factor, result_document

    ls, spec = fitted
    dof = interval_dof(ls)
    # K_FS, K_s (and the variance model's shape) out of the events' dof
    n_brk = int(np.sum(ls.inliers["breakaway"])) - 2 - (ls.breakaway_noise_shape > 0)
    # breakaway-only parameters: about the events' dof (a little more: K_F, T_Fc come from running torque)
    for k in ("KFS", "Ks"):
        assert n_brk <= dof[k] < 3 * n_brk, (k, dof[k], n_brk)
    # parameters the running data determine: effectively infinite dof
    for k in ("Kv", "KL0", "KAB"):
        assert dof[k] > 1e4, (k, dof[k])
    assert interval_factor(math.inf) == pytest.approx(1.959964, abs=1e-5)
    assert interval_factor(28.0) == pytest.approx(2.0484, abs=1e-3)
    doc = result_document(ls, spec)
    e = doc["parameters"]["Ks"]
    half = 0.5 * (e["ci95"][1] - e["ci95"][0])
    assert half == pytest.approx(interval_factor(dof["Ks"]) * e["std"], rel=1e-9)


def test_posterior_integrates_the_breakaway_noise_out(fitted):
    from motorid.identify.bayes import sample_posterior

    ls, spec = fitted
    post = sample_posterior(ls, spec, seed=5, progress=False)
    fixed = sample_posterior(ls, spec, seed=5, progress=False, marginal_breakaway=False)
    assert post.breakaway_noise == "marginalized" and fixed.breakaway_noise == "fixed"
    # the exact sufficient-statistics likelihood carries the marginal too
    assert post.expansion_gap is not None and post.expansion_gap < 0.05
    assert post.converged
    # K_s, K_FS: posterior as wide as least squares or a little wider (heavier tails, ν ≈ 28),
    # never much narrower; the running-data parameters unchanged
    for k in ("KFS", "Ks"):
        assert 0.9 * ls.std[k] < post.std[k] < 1.35 * ls.std[k], (k, post.std[k], ls.std[k])
    for k in ("Kv", "KL0"):
        assert post.std[k] == pytest.approx(fixed.std[k], rel=0.15)
    from motorid.identify.results import result_document

    doc = result_document(ls, spec, bayes=post)
    assert doc["mcmc"]["breakaway_noise"].startswith("integrated out")
    assert result_document(ls, spec, bayes=fixed)["mcmc"]["breakaway_noise"].startswith("held")


def test_posterior_carries_the_smoothed_viscosity_error(fitted):
    """The viscosity's run-level error is in the least-squares covariance
    (covariance_viscosity) and the posterior is convolved with it: K_L0's
    posterior is as wide as its standard error, wider than the data alone give."""
    from motorid.identify.bayes import sample_posterior

    ls, spec = fitted
    i = ls.free.index("KL0")
    visc = ls.covariance_viscosity[i, i]
    data_only = math.sqrt(ls.covariance[i, i] - visc)
    assert visc > 0.3 * data_only**2
    post = sample_posterior(ls, spec, seed=6, progress=False)
    assert post.std["KL0"] == pytest.approx(ls.std["KL0"], rel=0.12)
    assert post.std["KL0"] > 1.15 * data_only


def test_result_json_names_the_viscosity_share(fitted):
    from motorid.identify.results import result_document

    ls, spec = fitted
    doc = result_document(ls, spec)
    e = doc["parameters"]["KL0"]
    i = ls.free.index("KL0")
    assert e["std_viscosity"] == pytest.approx(math.sqrt(ls.covariance_viscosity[i, i]))
    assert 0 < e["std_viscosity"] < e["std"]
    # the breakaway-only parameters do not see the viscosity
    assert "std_viscosity" not in doc["parameters"]["Ks"]
