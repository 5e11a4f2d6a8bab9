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
