"""examples/antenna_servo.py, shortened: the stick-slip the identified friction causes, against physics.

With the shaft held by static friction, the loop's integral grows with the ramp
until the eight motors' pressure torque reaches the sum of their breakaway
torques; once running, the lag settles where the integral balances the
kinetic friction.  Both follow from the friction law (motorid.physics.torque)
and the loop gains alone, and the example's simulation — the exported motor
with Karnopp's stick-slip — must reproduce them; the ideal motor must track
the ramp exactly.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent


def _example():
    spec = importlib.util.spec_from_file_location("antenna_servo", REPO / "examples" / "antenna_servo.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


def test_identified_friction_holds_then_lags_as_the_friction_law_says():
    from motorid.physics.torque import breakaway_torque, running_friction

    ex = _example()
    motor = ex.identified_motor(REPO / "reports" / "demo")
    axis = ex.Axis()
    rate = ex.SIDEREAL / 10
    held = ex.simulate(motor, axis, rate, 12.0, ideal=False)
    ideal = ex.simulate(motor, axis, rate, 2.0, ideal=True)

    p, D, n = motor.params, motor.spec.displacement, 2 * axis.motors_per_group
    # |ΔP| of a drive motor is bias + u, of a counter motor bias − u: the eight sum to 8·bias
    p_sum = 2 * axis.p_low + axis.bias
    gain = n * D / (2 * math.pi)  # shaft torque per Pa of the loop's command u [N·m/Pa]
    w_ref = rate * axis.gear_ratio
    u_break = n * float(breakaway_torque(p["KF"], p["KFS"], p["TFc"], p["Ks"], D, p_sum, 0.0)) / gain
    t_hold = (u_break - axis.kp * w_ref) / (axis.ki * w_ref)
    mu = float(motor.spec.oil.viscosity(axis.T_oil - 273.15))
    u_run = n * (float(running_friction(p["KF"], p["TFc"], D, p_sum, 0.0)) + p["Kv"] * D * mu * w_ref) / gain
    lag = u_run / axis.ki / axis.gear_ratio / ex.ARCSEC  # [arcsec at the axis]

    t, err, stuck = held["time"], held["error_arcsec"], held["stuck"]
    first_move = t[np.argmax(~stuck)]
    assert stuck[0] and abs(first_move - t_hold) < 0.1 * t_hold, (first_move, t_hold)
    late = t > t_hold + 4.0
    assert not stuck[late].any()  # a damped loop: once moving, the shaft does not stick again at this rate
    assert abs(np.mean(err[late]) / lag - 1) < 0.05, (np.mean(err[late]), lag)
    assert np.ptp(err[late]) > 0.01  # the pistons' torque ripple shows in the lag
    # the ideal motor tracks the ramp exactly once the start-up transient (a 20 Hz loop) has passed
    assert np.max(np.abs(ideal["error_arcsec"][ideal["time"] > 1.0])) < 1e-9
