"""motorid.identify.viscosity: the viscometer's readings of a run smoothed, and the error the curve keeps."""

import numpy as np
import pytest

from motorid.identify.types import ViscositySmoothing
from motorid.identify.viscosity import smooth_viscosity


def _slow_curve(t):
    # 40 mPa·s oil warming slowly: viscosity falls about 2 % over the run, not a polynomial
    return 0.04 * np.exp(-0.02 * (t - t[0]) / np.ptp(t)) * (1 + 0.002 * np.sin(1.3 * t / np.ptp(t)))


def test_smoothed_viscosity_error_matches_its_stated_covariance():
    """Over many noise draws the smoothed curve's error at every sample has the
    variance its factor states (z² averages to 1), and is 1/√n-ish of the
    reading noise: the run-level error, not the readings' 0.3 %."""
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 20.0, 400)
    true = _slow_curve(t)
    z2, ratio = [], []
    for _ in range(200):
        mu = true * (1 + 0.003 * rng.standard_normal(t.size))
        smooth, degree, sigma, factor, center, half = smooth_viscosity(t, mu)
        assert degree >= 0
        err = smooth - true
        var = np.sum(ViscositySmoothing(np.array([center]), np.array([half]), factor[None]).modes(
            np.zeros(t.size, int), t) ** 2, axis=1)
        z2.append(np.mean(err**2 / var))
        ratio.append(np.std(err / true) / 0.003)
    assert 0.8 < np.mean(z2) < 1.25
    assert np.mean(ratio) < 0.2  # the readings' scatter is gone, only the curve's error is left


def test_spikes_do_not_move_the_curve():
    rng = np.random.default_rng(4)
    t = np.linspace(0.0, 10.0, 300)
    true = np.full(t.size, 0.03)
    mu = true * (1 + 0.003 * rng.standard_normal(t.size))
    mu[[50, 51, 200]] = 0.06
    smooth, degree, *_ = smooth_viscosity(t, mu)
    assert degree >= 0
    assert np.max(np.abs(smooth / true - 1)) < 0.002


@pytest.mark.parametrize("case", ["step", "held", "short"])
def test_readings_that_are_not_a_slow_curve_plus_white_noise_are_used_as_read(case):
    rng = np.random.default_rng(5)
    t = np.linspace(0.0, 10.0, 300)
    if case == "step":  # oil temperature steps halfway: no low-degree polynomial follows it
        mu = np.where(t < 5.0, 0.04, 0.036) * (1 + 0.003 * rng.standard_normal(t.size))
    elif case == "held":  # a bench that logs one held value
        mu = np.full(t.size, 0.04)
    else:
        t, mu = t[:15], 0.04 * (1 + 0.003 * rng.standard_normal(15))
    smooth, degree, sigma, factor, *_ = smooth_viscosity(t, mu)
    assert degree == -1
    np.testing.assert_array_equal(smooth, mu)
    assert not np.any(factor)
