"""motorid.robust: medians, MAD spreads, running medians, the Hampel test, robust lines."""

import numpy as np
import pytest

from motorid.robust import (MAD_TO_STD, hampel_spikes, mad_std, median, median3, median_of_five, moving_median,
                            nanmedian, robust_polyfit, robust_std, theil_sen_line, window_median)


def test_median_of_five_network():
    rng = np.random.default_rng(3)
    x = rng.standard_normal((5, 10000))
    x[:, :3000] = np.round(x[:, :3000])  # ties
    np.testing.assert_array_equal(median_of_five(*x), np.median(x, axis=0))


@pytest.mark.parametrize("n", [1, 2, 5, 20, 21, 22, 300])
@pytest.mark.parametrize("window", [1, 3, 5, 21])
def test_moving_median_matches_pandas_rolling_median(n, window):
    import pandas as pd

    rng = np.random.default_rng(n * 100 + window)
    x = rng.standard_normal(n)
    k = min(window, n) if min(window, n) % 2 else min(window, n) - 1
    for xx in (x, np.where(rng.random(n) < 0.2, np.nan, x)):
        want = pd.Series(xx).rolling(k, center=True, min_periods=1).median().to_numpy()
        np.testing.assert_allclose(moving_median(xx, k), want, equal_nan=True, rtol=0, atol=1e-15)


def test_input_spikes_leave_ripple_quantization_and_noise_alone():
    rng = np.random.default_rng(0)
    t = np.arange(3000) / 50.0
    assert not hampel_spikes(100 + 5 * np.sin(2 * np.pi * 7 * t) + 0.01 * rng.standard_normal(t.size)).any()
    assert not hampel_spikes(np.round(100 + 0.3 * rng.standard_normal(t.size))).any()
    assert sum(hampel_spikes(rng.standard_normal(500)).sum() for _ in range(200)) == 0
    x = rng.standard_normal(500)
    x[[0, 10, 11, 200, 499]] += 30.0
    assert list(np.flatnonzero(hampel_spikes(x))) == [0, 10, 11, 200, 499]


def test_medians_of_hand_made_arrays():
    assert median(np.array([3.0, 1.0, 2.0])) == 2.0
    assert median(np.array([4.0, 1.0, 3.0, 2.0])) == 2.5
    rng = np.random.default_rng(1)
    for n in (1, 2, 7, 100, 101):
        x = rng.standard_normal(n)
        assert median(x) == np.median(x)  # the partial sort gives np.median to the bit
    assert nanmedian(np.array([np.nan, 1.0, 3.0])) == 2.0
    assert np.isnan(nanmedian(np.array([np.nan, np.nan])))
    assert np.isnan(nanmedian(np.zeros(0)))


def test_mad_std_ignores_a_spike_and_scales_to_a_normal_sigma():
    from statistics import NormalDist

    assert MAD_TO_STD == pytest.approx(1.0 / NormalDist().inv_cdf(0.75), rel=1e-4)
    # |x − 3| = 2, 1, 0, 1, 97: MAD 1, whatever the spike's size
    assert mad_std(np.array([1.0, 2.0, 3.0, 4.0, 100.0])) == pytest.approx(MAD_TO_STD)
    assert mad_std(np.array([1.0, 2.0, 3.0, 4.0, 1e9])) == pytest.approx(MAD_TO_STD)
    assert mad_std(np.array([1.0, 2.0, 3.0]), centre=1.0) == pytest.approx(MAD_TO_STD * 1.0)
    x = np.random.default_rng(2).normal(0.0, 0.5, 40000)
    assert robust_std(x) == pytest.approx(0.5, rel=0.02)
    # NaN are skipped; fewer than two values give NaN
    assert robust_std(np.array([np.nan, 1.0, 2.0, 3.0, 4.0, 100.0])) == pytest.approx(MAD_TO_STD)
    assert np.isnan(robust_std(np.array([np.nan, 1.0])))


def test_running_medians_remove_isolated_spikes_and_keep_monotone_runs():
    np.testing.assert_array_equal(median3(np.array([0.0, 0.0, 9.0, 0.0, 0.0])), np.zeros(5))
    ramp = np.arange(6.0)
    np.testing.assert_array_equal(median3(ramp), ramp)
    rows = np.array([[1.0, 5.0, 3.0], [np.nan, 2.0, 4.0], [np.nan, np.nan, np.nan]])
    np.testing.assert_array_equal(window_median(rows), [3.0, 3.0, np.nan])


def test_robust_line_and_theil_sen_recover_a_line_through_outliers():
    x = np.linspace(0.0, 10.0, 21)
    y = 2.0 * x + 1.0
    y_bad = y.copy()
    y_bad[[3, 15]] += [40.0, -25.0]
    coef, sigma = robust_polyfit(x, y_bad, 1)
    np.testing.assert_allclose(coef, [2.0, 1.0], atol=1e-9)
    assert sigma == pytest.approx(0.0, abs=1e-9)
    # points at three x only, one of them far off: the pairwise slopes' median holds
    xs = np.repeat([0.0, 1.0, 2.0], 5)
    ys = 3.0 * xs - 1.0 + np.tile([0.0, 0.01, -0.01, 0.02, -0.02], 3)
    ys[7] = 50.0
    np.testing.assert_allclose(theil_sen_line(xs, ys), [3.0, -1.0], atol=0.02)
