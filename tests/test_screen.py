"""Candidates screened on the reduced data (issue 16): the cells' Δχ² is the samples' Δχ²."""

from pathlib import Path

import jax
import numpy as np
import pytest

from motorid.discrepancy.screen import Screen
from motorid.discrepancy.select import _fixed, _starts
from motorid.identify import compress
from motorid.identify.least_squares import fit_least_squares, start_values
from motorid.identify.pipeline import load_campaign
from motorid.identify.types import FitOptions
from motorid.io.spec import load_motor_spec
from motorid.physics.registry import get

CASE = Path(__file__).resolve().parent.parent / "synthetic_data" / "concealed" / "stribeck_friction"


@pytest.fixture(scope="module")
def campaign():
    spec = load_motor_spec(CASE / "motor.toml")
    _, data = load_campaign([CASE / "campaign.csv.gz"], spec)
    base = fit_least_squares(data, spec)
    return spec, data, base


def test_cells_give_the_samples_delta_chi2(campaign):
    """Δχ² of the concealed mechanism and of a wrong one, on the coarse cells and on every
    sample with the same noise and inliers held: the first large and equal within 1 %, the
    second small on both."""
    spec, data, base = campaign
    screen = Screen(data, spec, base)
    assert screen.n_cells < data.n_running / 3  # the reduction is real
    current = screen.fit([], base.params_all)
    noise, inliers = _fixed(base)
    held = FitOptions(fixed_noise=noise, fixed_inliers=inliers)
    reference = fit_least_squares(data, spec, [], held, initial=base.params_all)  # the base model, alike
    for mech_id in ("stribeck_friction", "turbulent_leakage"):
        mech = get(mech_id)
        cells = screen.fit_best_start([mech], _starts(current.params_all, mech))
        full = fit_least_squares(data, spec, [mech], held, initial=cells.params_all)
        d_cells, d_full = current.chi2 - cells.chi2, reference.chi2 - full.chi2
        if mech_id == "stribeck_friction":
            assert d_full > 1e4
            assert abs(d_cells - d_full) < 0.01 * d_full
        else:
            assert abs(d_cells) < 50 and abs(d_full) < 50


def test_held_out_runs_favour_the_true_mechanism(campaign):
    spec, data, base = campaign
    screen = Screen(data, spec, base)
    folds = [np.arange(i, len(data.runs), 3) for i in range(3)]
    without = screen.held_out_chi2([], base.params_all, folds)
    with_it = screen.held_out_chi2([get("stribeck_friction")], base.params_all, folds)
    assert with_it < 0.5 * without


def test_forward_hessian_matches_jax_hessian(campaign):
    """The pairwise forward-over-forward Hessian of compress equals jax.hessian (on a few cells)."""
    spec, data, base = campaign
    mech = get("stribeck_friction")
    names, start = start_values(spec, [mech], FitOptions(), base.params_all)
    screen = Screen(data, spec, base)
    prob = screen._problem([mech], names, {})
    small = compress._sample_ctx(prob.ctx(), np.arange(0, screen.n_cells, max(screen.n_cells // 20, 1)))
    order = ("torque", "q_a")
    v = np.array([start[k] for k in names])
    ours = np.asarray(compress._hessian(v, tuple(names), small, order))
    ref = np.asarray(jax.hessian(lambda x: compress._flat_predictions(x, tuple(names), small, order))(v))
    scale = np.max(np.abs(ref), axis=0, keepdims=True) + 1e-300
    assert ours.shape == ref.shape
    assert np.max(np.abs(ours - ref) / scale) < 1e-9
