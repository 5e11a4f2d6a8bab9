"""motorid.identify.acceleration: the speed's derivative, with a shaft-locked ripple resolved even when aliased."""

import numpy as np
import pytest

from motorid.identify.acceleration import aliased_cycles, running_acceleration, smoothed_acceleration


@pytest.mark.parametrize("jitter", [0.0, 2e-4])
def test_even_sampling_derivative_equals_the_local_fit(jitter):
    rng = np.random.default_rng(8)
    t = np.arange(300) * 0.01 + 5.0
    t = t + jitter * 0.01 * rng.uniform(-1, 1, t.size)  # time stamps rounded to a few digits
    w = np.sin(3 * t) + 0.01 * rng.standard_normal(t.size)
    fast = smoothed_acceleration(t, w)
    # the general path: every window's own quadratic (what uneven sampling gets)
    k, n = 9, t.size
    first = np.clip(np.arange(n) - k // 2, 0, n - k)
    slow = np.empty(n)
    for i in range(n):
        sl = slice(first[i], first[i] + k)
        slow[i] = np.polyfit(t[sl] - t[i], w[sl], 2)[1]
    tol = 1e-9 if jitter == 0 else 0.02
    np.testing.assert_allclose(fast, slow, rtol=0, atol=tol * np.max(np.abs(slow)))


def test_smoothed_acceleration_follows_a_known_derivative():
    t = np.arange(0.0, 2.0, 0.002)
    w = 3.0 + 2.0 * t ** 2
    np.testing.assert_allclose(smoothed_acceleration(t, w)[5:-5], 4.0 * t[5:-5], rtol=1e-6, atol=1e-6)
    jittered = np.sort(t + np.random.default_rng(0).uniform(0, 0.0015, t.size))
    acc = smoothed_acceleration(jittered, 3.0 + 2.0 * jittered ** 2)
    np.testing.assert_allclose(acc[5:-5], 4.0 * jittered[5:-5], atol=0.05)
    assert np.all(smoothed_acceleration(t[:3], w[:3]) == 0.0)


def test_shaft_locked_speed_ripple_gives_its_true_acceleration_even_when_aliased():
    """2500 rpm sampled at 50 Hz: a once-per-revolution speed wobble aliases; its
    acceleration comes from θ, the plain derivative of sampled speed is wrong."""
    rng = np.random.default_rng(11)
    w0, amp, rate = 2500 * 2 * np.pi / 60, 0.4, 50.0
    t = np.arange(400) / rate
    theta = w0 * t + 0.3  # the wobble hardly moves θ: first order is enough for the truth
    speed = w0 + amp * np.cos(theta) + 0.002 * rng.standard_normal(t.size)
    true_acc = -amp * np.sin(theta) * w0
    steady = np.ones(t.size, bool)
    got = running_acceleration(t, speed, np.mod(theta, 2 * np.pi), steady)
    plain = smoothed_acceleration(t, speed)
    inner = slice(5, -5)
    assert np.sqrt(np.mean((got - true_acc)[inner] ** 2)) < 0.02 * np.sqrt(np.mean(true_acc**2))
    assert np.sqrt(np.mean((plain - true_acc)[inner] ** 2)) > 0.5 * np.sqrt(np.mean(true_acc**2))
    # no ripple: the same as the plain derivative up to the fitted noise
    flat = w0 + 0.002 * rng.standard_normal(t.size)
    a = running_acceleration(t, flat, np.mod(theta, 2 * np.pi), steady)
    assert np.max(np.abs(a - smoothed_acceleration(t, flat))) < 0.05 * w0 * 0.002 * 10
    # less than two revolutions (θ held here, so the speed is constant): no ripple is fitted, and the
    # plain derivative's noise is left out for the run's smooth trend, never amplified
    short = running_acceleration(t[:40], speed[:40], np.full(40, 0.1), steady[:40])
    assert np.sqrt(np.mean(short**2)) <= np.sqrt(np.mean(smoothed_acceleration(t[:40], speed[:40]) ** 2))


def test_shaft_ripple_where_two_orders_alias_onto_one_frequency():
    """1000 rpm at 50 Hz: θ steps 120° a sample, so cos 2θ and cos θ read alike; the
    first order is kept and the second, folded onto it, left out (the fit of both is
    singular; it used to fall back to the plain derivative, off by the whole ripple)."""
    rng = np.random.default_rng(2)
    w0, amp, rate = 1000 * 2 * np.pi / 60, 0.3, 50.0
    t = np.arange(300) / rate
    theta = w0 * t + 0.4
    speed = w0 + amp * np.cos(theta) + 0.005 * rng.standard_normal(t.size)
    true_acc = -amp * np.sin(theta) * w0
    got = running_acceleration(t, speed, np.mod(theta, 2 * np.pi), np.ones(t.size, bool))
    rms = np.sqrt(np.mean(true_acc**2))
    inner = slice(5, -5)
    assert np.sqrt(np.mean((got - true_acc)[inner] ** 2)) < 0.05 * rms
    assert np.sqrt(np.mean((smoothed_acceleration(t, speed) - true_acc)[inner] ** 2)) > 0.5 * rms


def test_two_orders_nearly_folded_onto_one_frequency_are_not_split_into_large_opposite_parts():
    """1000.1 rpm at 50 Hz for one second under a 2 Hz speed wander (an ISO 4392 constant-pressure
    run): orders 1 and 2 alias to frequencies 0.0025 cycle apart over the run, near-collinear but
    not singular.  Fitted together they took a 0.1 rad/s wobble as two ripples of opposite sign whose
    derivatives, weighted ω and 2ω, no longer cancel: an acceleration ten times the truth, J·α of which
    went into the torque residual.  The second order is now left out as folded."""
    rng = np.random.default_rng(5)
    w0, rate = 1000.1 * 2 * np.pi / 60, 50.0
    t = np.arange(51) / rate
    wander, wobble = 0.003 * w0, 0.001 * w0
    theta = w0 * t + 0.6 - wander / (2 * np.pi * 2.0) * np.cos(2 * np.pi * 2.0 * t)
    speed_true = w0 + wander * np.sin(2 * np.pi * 2.0 * t) + wobble * np.cos(theta)
    true_acc = wander * 2 * np.pi * 2.0 * np.cos(2 * np.pi * 2.0 * t) - wobble * np.sin(theta) * w0
    speed = speed_true + 5e-4 * w0 * rng.standard_normal(t.size)
    got = running_acceleration(t, speed, np.mod(theta, 2 * np.pi), np.ones(t.size, bool))
    rms = np.sqrt(np.mean(true_acc**2))
    assert np.sqrt(np.mean((got - true_acc) ** 2)) < 0.5 * rms
    first_only = running_acceleration(t, speed, np.mod(theta, 2 * np.pi), np.ones(t.size, bool), orders=(1,))
    np.testing.assert_allclose(got, first_only, rtol=0, atol=1e-9 * rms)


def test_shaft_ripple_is_resolved_under_a_slow_speed_wander():
    """A dynamometer's speed controller wanders slowly (here 2 Hz, three times the ripple's
    amplitude): what the trend leaves of it raises the misfit, and the ripple, though
    plainly there, no longer passed a strict F test (F ≈ 20 here against 30); it must be kept."""
    rng = np.random.default_rng(4)
    w0, amp, rate = 2500 * 2 * np.pi / 60, 0.2, 50.0
    t = np.arange(100) / rate
    theta = w0 * t + 1.1
    wander = 0.6 * np.sin(2 * np.pi * 2.0 * t + 0.5) + 0.1 * rng.standard_normal(t.size).cumsum() / 3
    speed = w0 + wander + amp * np.cos(theta) + 0.13 * rng.standard_normal(t.size)
    ripple_acc = -amp * np.sin(theta) * w0
    got = running_acceleration(t, speed, np.mod(theta, 2 * np.pi), np.ones(t.size, bool))
    plain = smoothed_acceleration(t, speed)
    inner = slice(5, -5)
    # what is left is the wander's own slow acceleration and the noise, not the ripple
    err = np.sqrt(np.mean((got - ripple_acc - smoothed_acceleration(t, w0 + wander))[inner] ** 2))
    err_plain = np.sqrt(np.mean((plain - ripple_acc - smoothed_acceleration(t, w0 + wander))[inner] ** 2))
    assert err < 0.35 * np.sqrt(np.mean(ripple_acc**2)) < err_plain


def test_shaft_order_sampled_in_step_is_left_to_the_trend():
    """1500 rpm at 50 Hz: the shaft turns half a revolution a sample, so order 2 reads as a
    constant (and order 1 sits on the Nyquist frequency).  Neither may be fitted: a
    'ripple' at order 2 fitted to the trend's leftovers came back as a constant false
    acceleration, 2ω times its size."""
    rng = np.random.default_rng(6)
    w0, rate = 1500 * 2 * np.pi / 60, 50.0
    t = np.arange(400) / rate
    wander = 0.3 * np.sin(2 * np.pi * 0.37 * t) + 0.2 * np.sin(2 * np.pi * 1.3 * t + 1.0)
    speed = w0 + wander + 0.02 * rng.standard_normal(t.size)
    theta = w0 * t + 0.2 + np.cumsum(wander) / rate
    cycles = aliased_cycles(t, speed, (1, 2))
    assert cycles[2] < 1.0 and abs(cycles[1] - 200.0) < 1.0
    got = running_acceleration(t, speed, np.mod(theta, 2 * np.pi), np.ones(t.size, bool))
    true_acc = 0.3 * 2 * np.pi * 0.37 * np.cos(2 * np.pi * 0.37 * t) + 0.2 * 2 * np.pi * 1.3 * np.cos(
        2 * np.pi * 1.3 * t + 1.0)
    plain = smoothed_acceleration(t, speed)
    inner = slice(5, -5)
    assert abs(np.mean((got - true_acc)[inner])) < 0.05  # no false constant acceleration
    rms = lambda x: np.sqrt(np.mean(x[inner] ** 2))  # noqa: E731
    assert rms(got - true_acc) <= 1.05 * rms(plain - true_acc)


def test_speed_noise_is_not_read_as_acceleration():
    """600 rpm logged at 1 kHz (ISO 4392-1 constant speed): a speed noise of 0.3 rpm reads, through
    the derivative, as ±4 rad/s² of acceleration, more than the dynamometer's own wobble (a
    once-per-revolution ripple and a 1.5 Hz controller oscillation).  A fit of the rotor inertia
    against that α came out a third of the truth (regression dilution: var(true)/var(read)); the
    part the trend and the ripple fit leave, mostly noise here, is left out, so the true α regressed
    on the estimate has a slope near 1 again and the error is a fraction of the plain derivative's."""
    rng = np.random.default_rng(21)
    w0, rate = 600 * 2 * np.pi / 60, 1000.0
    t = np.arange(1001) / rate
    slow = 0.002 * w0 * np.sin(2 * np.pi * 1.5 * t + 0.4)
    theta = w0 * t + 0.2 - 0.002 * w0 / (2 * np.pi * 1.5) * np.cos(2 * np.pi * 1.5 * t + 0.4)
    wobble = 0.001 * w0 * np.sin(theta + 0.9)
    speed = w0 + slow + wobble + 0.03 * rng.standard_normal(t.size)
    true_acc = 0.002 * w0 * 2 * np.pi * 1.5 * np.cos(2 * np.pi * 1.5 * t + 0.4) + 0.001 * w0 * w0 * np.cos(
        theta + 0.9)
    got = running_acceleration(t, speed, np.mod(theta, 2 * np.pi), np.ones(t.size, bool))
    plain = smoothed_acceleration(t, speed)
    inner = slice(10, -10)
    slope = lambda est: float(np.sum(est[inner] * true_acc[inner]) / np.sum(est[inner] ** 2))  # noqa: E731
    rms = lambda x: float(np.sqrt(np.mean(x[inner] ** 2)))  # noqa: E731
    assert slope(plain) < 0.6  # what a fit of J saw
    assert 0.85 < slope(got) < 1.15
    assert rms(got - true_acc) < 0.35 * rms(plain - true_acc)


def test_a_real_wobble_the_ripple_fit_leaves_out_is_kept_whole_in_the_cell_means():
    """A shaft-locked wobble at an order the ripple fit does not resolve (3×, orders 1 and 2 asked)
    whose α is about as large as the α the speed noise makes (two fifths of the part's variance is
    noise): the part of α that the trend does not explain is kept whole, so that the shaft-angle
    cell means (what the fit regresses on, where the noise averages down over 110 samples) carry
    all of the wobble.  Scaled by the per-sample share of its variance that is real (0.58), the
    wobble came out 0.58 of itself in every cell, and a J fitted on it 1.9 times the truth."""
    rng = np.random.default_rng(9)
    w0, rate = 600 * 2 * np.pi / 60, 1000.0
    t = np.arange(8001) / rate
    theta = w0 * t + 0.5
    amp = 0.01  # rad/s of speed at 3× (α amplitude 3ω·0.01 ≈ 1.9 rad/s²; the noise's α ≈ 1.0 rad/s² RMS)
    speed = w0 + amp * np.sin(3 * theta) + 0.008 * rng.standard_normal(t.size)
    true_acc = 3 * w0 * amp * np.cos(3 * theta)
    got = running_acceleration(t, speed, np.mod(theta, 2 * np.pi), np.ones(t.size, bool), orders=(1, 2))
    bins = np.minimum((np.mod(theta, 2 * np.pi) / (2 * np.pi) * 72).astype(int), 71)
    inner = np.zeros(t.size, bool)
    inner[10:-10] = True
    cell = lambda x: np.bincount(bins[inner], x[inner], 72) / np.bincount(bins[inner], None, 72)  # noqa: E731
    est, true = cell(got), cell(true_acc)
    slope = float(np.sum(est * true) / np.sum(est * est))
    assert 0.85 < slope < 1.2
