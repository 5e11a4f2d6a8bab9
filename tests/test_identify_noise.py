"""motorid.identify.noise: per-run noise levels, the residual spike test, the breakaway variance model."""

import numpy as np
import pytest

from motorid.identify.noise import (breakaway_noise, floor_noise, initial_noise, residual_noise, spikiness)


def test_spikiness_matches_running_median_within_runs():
    rng = np.random.default_rng(4)
    run_of = np.repeat([0, 1, 2], [7, 50, 3])
    res = rng.standard_normal(run_of.size)
    got = spikiness(res, run_of, "torque")
    want = np.empty_like(res)
    for r in np.unique(run_of):
        idx = np.flatnonzero(run_of == r)
        for k, i in enumerate(idx):
            window = idx[np.clip(np.arange(k - 2, k + 3), 0, idx.size - 1)]
            want[i] = res[i] - np.median(res[window])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)


def test_per_run_noise_vectorized_equals_loop():
    rng = np.random.default_rng(5)
    run_of = np.repeat(np.arange(6), [10, 3, 40, 5, 8, 20])
    res = rng.standard_normal(run_of.size) * (1 + run_of)
    res[7] = np.nan
    got = residual_noise(res, run_of, 6, robust=False)
    for r in range(6):
        v = res[run_of == r]
        v = v[np.isfinite(v)]
        want = np.std(v, ddof=1) if v.size >= 5 else np.nan
        np.testing.assert_allclose(got[r], want, rtol=1e-12)


def test_breakaway_noise_grows_with_the_port_pressures_where_the_events_show_it():
    rng = np.random.default_rng(11)
    p = np.repeat([60e5, 130e5, 235e5], 100)
    x2 = p**2 + (7e5) ** 2
    ref = np.median(x2)
    s = 0.02 * np.sqrt(1.0 + 1.0 * x2 / ref)
    s0, gamma, ref_out = breakaway_noise(s * rng.standard_normal(p.size), x2, k=2)
    assert ref_out == pytest.approx(ref)
    assert 0.5 < gamma < 2.0 and s0 == pytest.approx(0.02, rel=0.15)
    # even scatter: the shape comes out near nothing
    s0, gamma, _ = breakaway_noise(0.03 * rng.standard_normal(p.size), x2, k=2)
    assert gamma < 0.15 and s0 == pytest.approx(0.03, rel=0.1)
    # too few events to tell: one level
    assert breakaway_noise(np.array([0.01, -0.02, 0.03]), x2[:3], k=2)[1] == 0.0


def test_initial_noise_from_first_differences_within_each_run():
    run_of = np.array([0, 0, 0, 0, 1, 1, 2])
    v = np.array([1.0, 3.0, 1.0, 3.0, 10.0, 10.0, 5.0])
    # run 0: differences ±2 → RMS 2, over √2; run 1: one difference only; run 2: none
    got = initial_noise(v, run_of, 3)
    assert got[0] == pytest.approx(2.0 / np.sqrt(2.0))
    assert np.isnan(got[1]) and np.isnan(got[2])
    # a jump between runs is no difference of either
    assert initial_noise(np.array([0.0, 1.0, 0.0, 100.0, 101.0, 100.0]), np.repeat([0, 1], 3), 2)[1] == \
        pytest.approx(1.0 / np.sqrt(2.0))


def test_floor_noise_fills_missing_runs_with_the_pooled_level_and_floors_short_ones():
    sig = np.array([1.0, np.nan, 3.0, 0.01, 0.0])
    got = floor_noise(sig, np.array([5.0, -7.0]))
    pooled = np.median([1.0, 3.0, 0.01])  # the runs with an estimate above zero
    np.testing.assert_allclose(got, [1.0, pooled, 3.0, 0.1 * pooled, pooled])
