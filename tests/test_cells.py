"""A campaign reduced to cells as it is read (identify/cells.py, identify/cell_fit.py): the same cells
as the per-sample problem where each cell holds one sample, and a fit whose values lie within the
per-sample fit's standard errors, with standard errors of the same size."""

import numpy as np
import pytest

from conftest import DEMO_TRUTH, REPO
from motorid.identify.extract import extract
from motorid.identify.least_squares import fit_least_squares
from motorid.identify.pipeline import identify, load_campaign
from motorid.identify.problem import Problem
from motorid.identify.types import RUNNING_CHANNELS, CellStatistics, FitOptions
from motorid.io.logs import read_logs
from motorid.io.spec import load_motor_spec

DEMO = REPO / "synthetic_data" / "demo"
LOG = DEMO / "campaign.csv.gz"
SPEC = load_motor_spec(DEMO / "motor.toml")


@pytest.fixture(scope="module")
def fits():
    exact = identify([LOG], SPEC)
    _, data = load_campaign([LOG], SPEC, cells=True)
    reduced = identify([LOG], SPEC, dataset=data)
    return exact, reduced


def test_one_sample_cells_weigh_as_the_samples():
    """Rows that are cells of one sample each (n = 1, within-scatter 0) give the per-sample problem's
    cell means and weights: the count weighting is an identity there."""
    data = extract(read_logs([LOG], SPEC), SPEC)
    n = data.n_running
    ones = np.ones(n)
    stats = CellStatistics(n=ones, counts={c: np.isfinite(data.measured[c]).astype(float) for c in RUNNING_CHANNELS},
                           within={c: np.zeros(n) for c in RUNNING_CHANNELS},
                           noise={c: np.ones(len(data.runs)) for c in RUNNING_CHANNELS},
                           viscosity_basis=np.zeros((n, 6)), outliers={})
    from dataclasses import replace

    free, held = ["Kv", "KF"], {}
    plain, counted = (Problem(d, SPEC, free, held, ()) for d in (data, replace(data, cells=stats)))
    inliers = {c: np.isfinite(data.measured[c]) for c in RUNNING_CHANNELS}
    inliers["breakaway"] = np.isfinite(data.held_torque)
    sigma = {c: np.linspace(1.0, 2.0, len(data.runs)) for c in RUNNING_CHANNELS}
    for p in (plain, counted):
        p.set_cells(inliers, sigma, 0.1)
    assert counted.n_cells == plain.n_cells
    for a, b in zip(plain.cell_samples, counted.cell_samples):
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=0)
    for c in RUNNING_CHANNELS:
        np.testing.assert_allclose(counted.cells[0][c], plain.cells[0][c], rtol=1e-12, atol=0)
        np.testing.assert_allclose(counted.cells[1][c], plain.cells[1][c], rtol=1e-12, atol=0)


def test_reduced_fit_agrees_with_the_per_sample_fit_within_its_errors(fits):
    exact, reduced = fits
    assert reduced.dataset.cells is not None and exact.dataset.cells is None
    assert reduced.frame is None
    # the samples behind the cells: every steady sample of the per-sample extraction
    assert reduced.dataset.cells.n.sum() == exact.dataset.n_running
    assert reduced.dataset.n_running < exact.dataset.n_running
    a, b = exact.ls, reduced.ls
    assert set(a.free) == set(b.free)
    for k in a.free:
        assert abs(b.values[k] - a.values[k]) < a.std[k], k
        # honest standard errors: the size the per-sample fit gives (noise from the cells' residuals)
        assert 0.9 < b.std[k] / a.std[k] < 1.1, (k, b.std[k] / a.std[k])
        # and both cover the truth as a per-sample fit does
        assert abs(b.values[k] - DEMO_TRUTH[k]) < 4 * b.std[k], k


def test_reduced_fit_counts_samples_not_cells(fits):
    exact, reduced = fits
    a, b = exact.ls, reduced.ls
    for c in RUNNING_CHANNELS:
        # every inlier sample counted once: the same count as the per-sample fit, up to the spikes
        # each one calls outliers (model-free here, against the model there)
        assert abs(b.used[c] - a.used[c]) <= max(a.outliers[c], b.outliers[c]) + 5, c
        assert b.noise[c] == pytest.approx(a.noise[c], rel=0.05), c
    assert b.dof == pytest.approx(a.dof, rel=1e-3)
    assert 0.95 < b.chi2 / b.dof < 1.05


def test_the_threshold_picks_the_path(monkeypatch, tmp_path):
    from motorid.errors import InputError
    from motorid.identify import pipeline

    monkeypatch.setenv("MOTORID_CELL_ROWS", "1000")
    assert pipeline.cell_rows() == 1000
    monkeypatch.setenv("MOTORID_CELL_ROWS", "many")
    with pytest.raises(InputError, match="MOTORID_CELL_ROWS"):
        pipeline.cell_rows()
    monkeypatch.delenv("MOTORID_CELL_ROWS")
    assert pipeline.cell_rows() == pipeline.CELL_ROWS
    assert FitOptions().bins_per_pitch == 192  # the cells of the reduction are the fit's
