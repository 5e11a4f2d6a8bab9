"""motorid.identify.problem: samples reduced to cells, their weights, padding; the residual core."""

import numpy as np
import pandas as pd
import pytest

from motorid.identify.problem import Problem, bucket, pad
from motorid.identify.types import Dataset
from motorid.model import make_samples
from motorid.model import MotorSpec, OilSpec

SPEC = MotorSpec("test-2", pistons=2, displacement=80e-6, inertia=0.005, oil=OilSpec())


def _dataset():
    """Two runs of three samples: run 0 twice in the first θ bin, once in another; run 1 once in
    the first bin (a cell is one run's samples in one bin, never two runs')."""
    theta = np.array([0.001, 0.002, 3.0, 0.0015])
    mu = np.array([0.02, 0.04, 0.03, 0.03])
    s = make_samples(SPEC, theta, np.full(4, 5.0), np.full(4, 100e5), np.full(4, 5e5), 1e5, mu)
    measured = {"torque": np.array([10.0, 12.0, 20.0, 30.0]), "q_a": np.full(4, np.nan),
                "q_b": np.full(4, np.nan), "q_case": np.full(4, 1e-5)}
    empty = make_samples(SPEC, np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), 1e5, np.zeros(0))
    return Dataset(running=s, measured=measured, run_of_sample=np.array([0, 0, 0, 1]), frame_index=np.arange(4),
                   runs=pd.DataFrame({"run": ["A", "B"]}), events=empty, held_torque=np.zeros(0), event_runs=[],
                   run_of_event=np.zeros(0, int), onset_time=np.zeros(0))


def test_cells_are_one_runs_samples_in_one_shaft_angle_bin():
    p = Problem(_dataset(), SPEC, ["Kv"], {}, (), bins_per_pitch=4)
    assert p.n_cells == 3 and p.has_running and not p.has_events
    np.testing.assert_array_equal(p.cell_of, [0, 0, 1, 2])
    np.testing.assert_array_equal(p.cell_run, [0, 0, 1])
    # the cell's viscosity is the harmonic mean of its samples' (the leakage goes as 1/μ)
    assert float(np.asarray(p.cell_samples.viscosity)[0]) == pytest.approx(2 / (1 / 0.02 + 1 / 0.04))
    assert float(np.asarray(p.cell_samples.theta)[0]) == pytest.approx(0.0015)
    assert np.asarray(p.cell_samples.theta).size == bucket(3) == 64  # padded to a power of two


def test_cell_means_and_weights_over_the_inliers():
    p = Problem(_dataset(), SPEC, ["Kv"], {}, (), bins_per_pitch=4)
    inliers = {"torque": np.array([True, True, True, False]), "q_a": np.zeros(4, bool),
               "q_b": np.zeros(4, bool), "q_case": np.ones(4, bool)}
    sigma = {c: np.array([2.0, 4.0]) for c in inliers}
    p.set_cells(inliers, sigma, None)
    obs, w = p.cells
    np.testing.assert_allclose(obs["torque"][:3], [11.0, 20.0, 0.0])
    # √(inliers in the cell)/σ of its run: the cell mean's weight; 0 where no inlier
    np.testing.assert_allclose(w["torque"][:3], [np.sqrt(2) / 2, 1 / 2, 0.0])
    assert not np.any(w["torque"][3:]) and p.cells_version == 1
    ctx = p.ctx()
    assert ctx.free == ("Kv",) and ctx.events is None and ctx.positive == (True,)


def test_bucket_and_pad():
    assert [bucket(n) for n in (1, 64, 65, 1000)] == [64, 64, 128, 1024]
    assert bucket(3, minimum=16) == 16
    np.testing.assert_array_equal(pad(np.array([1.0, 2.0]), 4, value=9.0), [1.0, 2.0, 9.0, 9.0])
