"""Breakaway onset at a low sample rate, where the speed leaves rest within one or two
samples and then meets a speed limit (a dynamometer's limiter): the onset, and so the
pressures at it, must not depend on where the true breakaway falls between samples.

Logs built here from kinematics alone (not by motorid's simulator): speed ω = min(a·u, W),
u = max(t − t0, 0), shaft angle its exact integral, quantized like an encoder."""

import math

import numpy as np
import pytest

from motorid.identify.breakaway import _hinge_costs, find_breakaway
from motorid.identify.events import value_at_onset
from motorid.identify.onset_angle import place_limited_onset

RATE = 25.0  # Hz: 40 ms between samples
RAMP = 2.5e5  # Pa/s on the inlet


def fast_breakaway(t0, alpha, w_max=1.0472, rate=RATE, angle_step=0.0, speed_noise=0.0, seed=0, duration=6.0):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1.0 / rate)
    u = np.clip(t - t0, 0.0, None)
    u_s = w_max / alpha
    speed = np.minimum(alpha * u, w_max) + speed_noise * rng.standard_normal(t.size)
    theta = 0.7 + np.where(u <= u_s, 0.5 * alpha * u * u, w_max * (u - 0.5 * u_s))
    if angle_step:
        theta = np.round(theta / angle_step) * angle_step
    inlet = 50e5 + RAMP * t
    return t, speed, theta, inlet


def onset_errors(alpha, phases, **kw):
    out = []
    for ph in phases:
        t0 = 4.0 + ph / RATE
        t, w, th, _ = fast_breakaway(t0, alpha, **kw)
        out.append(find_breakaway(t, w, theta=th).onset_time - t0)
    return np.array(out)


PHASES = np.linspace(0.03, 0.97, 17)


def test_two_growth_samples_place_the_onset_at_every_sample_phase():
    # limit reached 52 ms after the onset: one or two samples on the linear growth
    err = onset_errors(20.0, PHASES)
    assert np.max(np.abs(err)) < 0.3e-3, err  # (the former quadratic hinge: up to ±20 ms)


def test_one_growth_sample_and_the_angle_place_the_onset():
    # limit reached 26 ms after the onset: the first moving sample is often already on it
    err = onset_errors(40.0, PHASES, angle_step=math.radians(0.01))
    below = PHASES / RATE < 1.0472 / 40.0 - 1e-3  # first moving sample still below the limit
    assert np.max(np.abs(err[~below])) < 0.5e-3, err
    # on the limit the angle bounds the onset to an interval; its middle is within a quarter sample
    assert np.max(np.abs(err[below])) < 0.25 / RATE, err
    assert abs(np.mean(err)) < 3e-3, err


def test_onset_error_is_not_set_by_the_sample_phase_with_noise():
    err = np.array([onset_errors(20.0, PHASES[::4], angle_step=math.radians(0.01), speed_noise=2e-4, seed=s)
                    for s in range(3)])
    assert np.max(np.abs(err)) < 1e-3, err
    assert abs(np.mean(err)) < 0.3e-3


def test_pressure_at_onset_follows_the_ramp_at_every_phase():
    for ph in PHASES[::3]:
        t0 = 4.0 + ph / RATE
        t, w, th, inlet = fast_breakaway(t0, 40.0, angle_step=math.radians(0.01))
        b = find_breakaway(t, w, theta=th)
        p = value_at_onset(t, inlet, b.onset_time, 50)
        assert abs(p - (50e5 + RAMP * t0)) < 0.25 * RAMP / RATE, (ph, p)  # a quarter sample of ramp


def test_reading_against_the_motion_just_before_the_onset_is_not_motion():
    t0 = 4.0 + 0.98 / RATE  # the true onset just before a sample
    t, w, th, _ = fast_breakaway(t0, 20.0)
    k = int(np.searchsorted(t, t0))  # first moving sample
    w[k - 1] = -5e-3  # a reading against the motion at the last sample at rest
    w[: k - 1] += 1e-3 * np.random.default_rng(3).standard_normal(k - 1)
    b = find_breakaway(t, w, theta=th)
    assert b.onset_time == pytest.approx(t0, abs=1e-3)


def test_without_the_angle_a_single_growth_sample_gives_the_middle_of_the_interval():
    t0 = 4.0 + 0.5 / RATE
    t, w, _, _ = fast_breakaway(t0, 100.0)  # on the limit at the first moving sample
    b = find_breakaway(t, w)
    k = int(np.searchsorted(t, t0))
    assert b.onset_time == pytest.approx(0.5 * (t[k - 1] + t[k]))


def _campaign_of_fast_breakaways(phases, loads, angle_step=math.radians(0.01), w_max=1.0472):
    """Startability runs at three loads, each breaking away at its own sample phase; just
    after breakaway the shaft accelerates at a = 6 rad/s² + 0.24 rad/s² per bar of P_A + P_B
    (static minus kinetic friction over the inertia, a line in P_A + P_B), then meets a speed
    limiter.  Returns the frame and each run's true onset."""
    import pandas as pd

    from motorid.identify.extract import FRAME_NUMERIC

    frames, truth = [], {}
    for i, (ph, (p0, sign)) in enumerate(zip(phases, loads)):
        t0 = 4.0 + ph / RATE
        inlet_at_t0 = p0 + RAMP * t0
        alpha = 6.0 + 0.24 * (inlet_at_t0 + 7e5) / 1e5
        t, w, th, inlet = fast_breakaway(t0, alpha, w_max=w_max, angle_step=angle_step)
        inlet = inlet - 50e5 + p0
        run = f"S{i:02d}"
        p_a, p_b = (inlet, np.full(t.size, 7e5)) if sign > 0 else (np.full(t.size, 7e5), inlet)
        cols = {c: np.zeros(t.size) for c in FRAME_NUMERIC}
        cols.update(time_s=t, theta_rad=np.mod(sign * th, 2 * np.pi), speed_rad_s=sign * w, torque_Nm=sign * 50.0,
                    p_a_Pa=p_a, p_b_Pa=p_b, p_case_Pa=1e5, oil_temp_C=40.0, viscosity_Pa_s=0.04)
        frames.append(pd.DataFrame({"run_id": run, "protocol": "startability", **cols, "run": run}))
        truth[run] = t0
    return pd.concat(frames, ignore_index=True), truth


def test_onsets_on_the_speed_limit_take_the_acceleration_of_the_other_events():
    """At 25 Hz the shaft of a heavily loaded run meets the limiter before the first moving
    sample, and the angle alone leaves the onset within a quarter sample; the events whose
    growth the samples saw give the acceleration against P_A + P_B, and with it the onset
    of every event comes out within half a millisecond, at every sample phase."""
    from motorid.identify.extract import extract
    from motorid.model import MotorSpec, OilSpec

    spec = MotorSpec("test-9", pistons=9, displacement=80e-6, inertia=0.005, oil=OilSpec())
    rng = np.random.default_rng(5)
    loads = [(p0, sign) for p0 in (40e5, 110e5, 215e5) for sign in (1, -1) for _ in range(5)]
    frame, truth = _campaign_of_fast_breakaways(rng.uniform(0.02, 0.98, len(loads)), loads)
    data = extract(frame, spec)
    assert data.n_events == len(loads)
    err = np.array([data.onset_time[i] - truth[run] for i, run in enumerate(data.event_runs)])
    limited = np.array([find_breakaway(g.time_s.to_numpy(), g.speed_rad_s.to_numpy(),
                                          theta=g.theta_rad.to_numpy()).limited is not None
                        for _, g in frame.groupby("run_id", sort=True)])
    assert 5 <= limited.sum() <= len(loads) - 8  # both kinds of event are there
    assert np.max(np.abs(err)) < 0.5e-3, err
    # the middle of the angle's interval, as each run alone gives it, was off by far more
    middle = np.array([find_breakaway(g.time_s.to_numpy(), g.speed_rad_s.to_numpy(),
                                         theta=g.theta_rad.to_numpy()).onset_time - truth[run]
                       for run, g in frame.groupby("run_id", sort=True)])
    assert np.max(np.abs(middle[limited])) > 2e-3
    # the runs table gives the onset placed
    assert np.allclose(data.runs.set_index("run").loc[data.event_runs, "onset_time_s"], data.onset_time)


def test_place_limited_onset_inverts_the_kinematics():
    for alpha, ph in [(40.0, 0.1), (80.0, 0.5), (200.0, 0.7)]:  # u₁ past u_s = W/a each
        t0 = 4.0 + ph / RATE
        t, w, th, _ = fast_breakaway(t0, alpha)
        b = find_breakaway(t, w, theta=th)
        assert b.limited is not None
        assert place_limited_onset(b.limited, alpha) == pytest.approx(t0, abs=1e-6)


def test_damped_load_breakaway_at_a_low_rate_from_speed_and_angle():
    """A load with damping reaches near its speed within a sample (first-order lag, τ = 40 ms,
    plus a slow rise as the ramp goes on) at 10 Hz: a line through the growth samples reaches
    back past samples still at rest; speed and angle of the first moving samples place it."""
    rate, tau, V, rise = 10.0, 0.04, 1.5, 2.0
    errs = []
    for ph in np.linspace(0.05, 0.95, 10):
        t0 = 3.0 + ph / rate
        t = np.arange(0.0, 6.0, 1.0 / rate)
        u = np.clip(t - t0, 0.0, None)
        speed = V * -np.expm1(-u / tau) + rise * u
        theta = 0.4 + V * (u + tau * np.expm1(-u / tau)) + 0.5 * rise * u * u
        theta = np.round(theta / math.radians(0.01)) * math.radians(0.01)
        noise = 3e-4 * np.random.default_rng(int(ph * 100)).standard_normal(t.size)
        b = find_breakaway(t, speed + noise, theta=theta)
        errs.append(b.onset_time - t0)
    errs = np.array(errs)
    # where the first moving sample is still on the rise (u₁ < 2τ here), within a few ms (a line
    # through the growth was up to 100 ms early); where it is already near the plateau the angle
    # fixes t₀ + τ only, and the onset is known to within the part of the interval left
    on_rise = (1.0 - np.linspace(0.05, 0.95, 10)) / rate < 2 * tau
    assert np.max(np.abs(errs[on_rise])) < 2e-3, errs
    assert np.max(np.abs(errs)) < 0.25 / rate, errs


def test_pressure_at_the_onset_follows_a_supply_ripple_and_skips_the_hold():
    """The shaft breaks away where the supply ripple lifts the pressure over the threshold;
    a line through fifty readings would average the ripple out and read it low.  And a
    hold before the ramp, within the window, must not bend the line."""
    rng = np.random.default_rng(3)
    rate, ramp = 100.0, 2e5
    t = np.arange(0.0, 8.0, 1.0 / rate)
    errs, long_errs = [], []
    for k in range(20):
        phase = rng.uniform(0, 2 * np.pi)
        p = 40e5 + ramp * t + 0.1e5 * np.sin(2 * np.pi * 6.0 * t + phase)
        onset = t[600 + int(np.argmax(p[600:700]))] + 0.004  # near a crest
        read = p + 300.0 * rng.standard_normal(t.size)
        truth = 40e5 + ramp * onset + 0.1e5 * np.sin(2 * np.pi * 6.0 * onset + phase)
        errs.append(value_at_onset(t, read, onset, 50) - truth)
        sel = np.flatnonzero(t < onset)[-50:]
        long_errs.append(np.polyval(np.polyfit(t[sel] - onset, read[sel], 1), 0.0) - truth)
    assert np.sqrt(np.mean(np.square(errs))) < 0.25 * np.sqrt(np.mean(np.square(long_errs)))
    assert abs(np.mean(errs)) < 0.02e5 < abs(np.mean(long_errs))
    # a hold, then a ramp starting 0.3 s before the onset, 25 readings a second
    t = np.arange(0.0, 4.0, 0.04)
    p = 30e5 + 10e5 * np.clip(t - 2.7, 0.0, None) + 1e3 * rng.standard_normal(t.size)
    assert abs(value_at_onset(t, p, 3.0, 50) - (30e5 + 10e5 * 0.3)) < 0.05e5


def test_hinge_costs_equal_nonnegative_least_squares():
    from scipy.optimize import nnls

    rng = np.random.default_rng(7)
    t = np.linspace(0, 1, 40)
    y = np.clip(t - 0.4, 0, None) * 3 + np.clip(t - 0.4, 0, None) ** 2 + 0.01 * rng.standard_normal(t.size)
    y[5] = -0.5  # forces a bound to be active at some t0
    grid = np.linspace(-0.1, 1.05, 60)
    want = [nnls(np.column_stack([np.clip(t - g, 0, None), np.clip(t - g, 0, None) ** 2]), y)[1] ** 2
            for g in grid]
    np.testing.assert_allclose(_hinge_costs(t, y, grid), want, rtol=1e-9, atol=1e-12)
