"""Per-run statistics without a loop over runs (motorid.discrepancy.run_segments) against the loop."""

import numpy as np
import pytest

from motorid.discrepancy.locate import _lag1, _run_table
from motorid.discrepancy.run_segments import RunIndex


@pytest.fixture()
def runs():
    """Five runs interleaved in time (as a campaign's samples are not, but a run index must not care),
    one empty, one of three samples, with a mask that drops a fifth of the samples."""
    rng = np.random.default_rng(3)
    sizes = [400, 0, 3, 250, 31]
    run_of = np.concatenate([np.full(n, r) for r, n in enumerate(sizes)])
    order = rng.permutation(run_of.size)
    run_of = run_of[order]
    n = run_of.size
    x = rng.normal(size=n) + run_of  # a level per run
    z = np.cumsum(rng.normal(size=n)) * 0.1 + rng.normal(size=n)  # autocorrelated
    t = np.cumsum(rng.uniform(0.5, 1.5, n)) * 1e-3
    theta = np.cumsum(rng.uniform(0.0, 0.9, n))  # unwrapped angle ...
    wrapped = np.mod(theta, 2 * np.pi)  # ... as the log has it
    mask = rng.uniform(size=n) > 0.2
    return run_of, len(sizes), x, z, t, theta, wrapped, mask


def _loop(run_of, n_runs, mask, f):
    out = np.full(n_runs, np.nan)
    for r in range(n_runs):
        sel = np.flatnonzero((run_of == r) & mask)
        if sel.size:
            out[r] = f(sel)
    return out


def test_sums_means_medians_ranges_match_a_loop_over_runs(runs):
    run_of, n_runs, x, z, t, theta, wrapped, mask = runs
    seg = RunIndex(run_of, n_runs).kept(mask)
    assert list(seg.n) == [int(np.sum((run_of == r) & mask)) for r in range(n_runs)]
    xs = seg.take(x)
    np.testing.assert_allclose(seg.sum(xs), np.nan_to_num(_loop(run_of, n_runs, mask, lambda s: x[s].sum())),
                               rtol=1e-12)
    np.testing.assert_allclose(seg.mean(xs), _loop(run_of, n_runs, mask, lambda s: x[s].mean()), rtol=1e-12)
    np.testing.assert_array_equal(seg.median(xs), _loop(run_of, n_runs, mask, lambda s: np.median(x[s])))
    np.testing.assert_allclose(seg.ptp(xs), _loop(run_of, n_runs, mask, lambda s: np.ptp(x[s])), rtol=1e-12)
    np.testing.assert_array_equal(
        seg.pair_median(seg.take(t)),
        _loop(run_of, n_runs, mask, lambda s: np.median(np.diff(t[s])) if s.size > 1 else np.nan))
    np.testing.assert_allclose(seg.unwrapped_ptp(seg.take(wrapped)),
                               _loop(run_of, n_runs, mask, lambda s: np.ptp(np.unwrap(wrapped[s]))), rtol=1e-9)
    assert seg.unwrapped_ptp(seg.take(wrapped))[0] > 10 * 2 * np.pi  # unwrapped, not the wrapped range
    two = seg.sum(np.column_stack([xs, 2 * xs]))
    np.testing.assert_allclose(two[:, 1], 2 * two[:, 0], rtol=1e-12)


def test_lag_one_and_run_table_match_a_loop_over_runs(runs):
    run_of, n_runs, x, z, t, theta, wrapped, mask = runs
    seg = RunIndex(run_of, n_runs).kept(mask)
    want = np.nan_to_num(_loop(run_of, n_runs, mask, lambda s: _lag1(z[s])))
    np.testing.assert_allclose(seg.lag1(seg.take(z)), want, rtol=1e-10, atol=1e-14)
    assert want[0] > 0.1  # the series is autocorrelated: the test is not of zeros
    zz = np.where(mask, z, np.nan)
    mean, se = _run_table(zz, run_of, n_runs)
    for r in range(n_runs):
        v = zz[run_of == r]
        v = v[np.isfinite(v)]
        if v.size < 5:
            assert np.isnan(mean[r]) and np.isnan(se[r])
            continue
        rho = _lag1(v)
        n_eff = v.size * (1 - rho) / (1 + rho)
        assert mean[r] == pytest.approx(v.mean(), rel=1e-12)
        assert se[r] == pytest.approx(max(np.std(v), 1.0) / np.sqrt(max(n_eff, 1.0)), rel=1e-10)


def test_a_nan_stays_in_its_own_run(runs):
    """np.median's NaN for a run that holds one; an angle's NaN does not spread to the runs after it;
    run numbers outside the index are in no run."""
    run_of, n_runs, x, z, t, theta, wrapped, mask = runs
    x, wrapped = x.copy(), wrapped.copy()
    first = np.flatnonzero(run_of == 0)[7]
    x[first] = np.nan
    wrapped[first] = np.nan
    seg = RunIndex(run_of, n_runs).kept()
    med = seg.median(seg.take(x))
    assert np.isnan(med[0]) and np.all(np.isfinite(med[[2, 3, 4]]))
    span = seg.unwrapped_ptp(seg.take(wrapped))
    want = _loop(run_of, n_runs, np.ones_like(mask), lambda s: np.ptp(np.unwrap(wrapped[s])))
    np.testing.assert_allclose(span[[2, 3, 4]], want[[2, 3, 4]], rtol=1e-9)
    stray = np.concatenate([run_of, [-1, n_runs]])
    seg2 = RunIndex(stray, n_runs).kept()
    assert list(seg2.n) == list(seg.n) and seg2.idx.size == seg.idx.size
