"""Load-driven shaft motion: Karnopp stick-slip after breakaway, flow-fed inlet.

When the load, not the dynamometer, decides the speed (startability after
breakaway, ISO 4392-3 runs), the shaft obeys

    (J_motor + J_load) α = T(θ, ω, P; α = 0) − T_load

where T is the torque the one model (:func:`motorid.model.predict`) delivers to
the shaft at zero acceleration, so kinetic friction, viscous torque and any
mechanism's terms enter by themselves, and J_motor is read off the model as
T(α=0) − T(α=1).  The torque transducer sits between motor and load and reads
T_load + J_load α = T(α).

The inlet pressure is either a prescribed ramp (startability) or a state fed
by a flow source through a compressible line volume V (ISO 4392-3):

    dP_in/dt = (β/V) (Q_pump(t) − Q_in(θ, ω, P))

Integration is at a fixed step per run: speed and pressure by explicit Euler
(exact for the speed while the acceleration is constant, as it is just after
breakaway), the angle by the trapezoidal rule over the step's two speeds (exact
for a constant acceleration; semi-implicit Euler would put the shaft half a step
ahead, W·dt/2, which a breakaway onset read from the angle turned then shows as an
early onset), batched over runs and compiled once per motor spec and mechanism
set (``jax.lax.scan`` in chunks).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from motorid import _jaxconfig  # noqa: F401
from motorid.model import make_samples, predict

#: steps per compiled chunk of the integrator
CHUNK = 1024

#: fields of the per-run drive description (each an array of shape (runs,)), SI
DRIVE_FIELDS = (
    "direction",      # ±1 [-]
    "load_torque",    # signed load torque, opposes the run's direction [N·m]
    "load_inertia",   # inertia beyond the transducer [kg·m²]
    "max_speed",      # speed limiter [rad/s] (inf: none)
    "p_out",          # outlet port pressure [Pa]
    "p_case",         # case pressure [Pa]
    "temp0",          # oil temperature at t = 0 [°C]
    "temp_rate",      # oil temperature drift [°C/s]
    "is_flow",        # 1: inlet fed by a flow source; 0: prescribed pressure ramp
    "dp_start",       # ramp: ΔP magnitude at t = 0 [Pa]
    "ramp_rate",      # ramp: ΔP rise rate after the hold [Pa/s]
    "hold",           # ramp: time before the ramp starts [s]
    "p_ripple",       # supply pressure fluctuation amplitude [Pa]
    "p_ripple_w",     # its angular frequency [rad/s]
    "p_ripple_phase", # its phase [rad]
    "q_set",          # flow source: pump flow magnitude [m³/s]
    "q_ripple",       # flow source: relative ripple amplitude [-]
    "q_ripple_w",     # its angular frequency [rad/s]
    "q_ripple_phase", # its phase [rad]
    "stiffness",      # flow source: β/V of the inlet line [Pa/m³]
)


def ramp_pressure(drive: dict, t, xp=jnp):
    """Inlet-over-outlet pressure difference magnitude of a ramp run at time t [Pa].

    xp : the array module (``jax.numpy`` inside compiled code, ``numpy`` outside).
    """
    ramp = drive["dp_start"] + drive["ramp_rate"] * xp.maximum(t - drive["hold"], 0.0)
    return ramp + drive["p_ripple"] * xp.sin(drive["p_ripple_w"] * t + drive["p_ripple_phase"])


def pump_flow(drive: dict, t):
    """Flow-source delivery at time t [m³/s]."""
    return drive["q_set"] * (1.0 + drive["q_ripple"] * jnp.sin(drive["q_ripple_w"] * t + drive["q_ripple_phase"]))


def port_pressures(direction, p_in, p_out, xp=jnp):
    """(P_A, P_B) [Pa]: the inlet is port A for direction +1, port B for −1."""
    return xp.where(direction > 0, p_in, p_out), xp.where(direction > 0, p_out, p_in)


def oil_temperature(drive: dict, t):
    """Oil temperature at time t [°C]: a linear drift."""
    return drive["temp0"] + drive["temp_rate"] * t


def drive_samples(spec, drive: dict, t, theta, speed, p_in):
    """Model samples of a load-driven run at zero acceleration."""
    temp = oil_temperature(drive, t)
    mu = spec.oil.viscosity(temp)
    p_a, p_b = port_pressures(drive["direction"], p_in, drive["p_out"])
    return make_samples(spec, theta, speed, p_a, p_b, drive["p_case"], mu, acceleration=0.0,
                        direction=drive["direction"], temperature=temp, time=t)


def load_driven_acceleration(params, spec, mechanisms, samples, load_torque, load_inertia):
    """Shaft acceleration of a load-driven run, α [rad/s²], and the channels at α = 0.

    samples : model samples with zero acceleration; load_torque : signed load [N·m];
    load_inertia : J_load [kg·m²].  J_motor comes from the model, T(α=0) − T(α=1).
    """
    ch0 = predict(params, spec, samples, mechanisms)
    ch1 = predict(params, spec, samples._replace(acceleration=samples.acceleration + 1.0), mechanisms)
    j_motor = ch0.torque - ch1.torque
    return (ch0.torque - load_torque) / (j_motor + load_inertia), ch0


@functools.lru_cache(maxsize=16)
def _chunk_integrator(spec, mechanisms: tuple):
    def step(carry, k, params, drive, t0, dt):
        theta, omega, p_in = carry
        t = t0 + k * dt
        p_in = jnp.where(drive["is_flow"] > 0, p_in, drive["p_out"] + ramp_pressure(drive, t))
        s = drive_samples(spec, drive, t, theta, omega, p_in)
        alpha, ch0 = load_driven_acceleration(params, spec, mechanisms, s, drive["load_torque"],
                                              drive["load_inertia"])
        d = drive["direction"]
        q_in = jnp.where(d > 0, ch0.q_a, ch0.q_b)
        dp = drive["stiffness"] * (pump_flow(drive, t) - q_in)
        omega_new = d * jnp.clip(d * (omega + alpha * dt), 0.0, drive["max_speed"])
        theta_new = theta + 0.5 * (omega + omega_new) * dt  # trapezoidal: exact at constant α
        p_new = jnp.maximum(p_in + dp * dt, 0.0)
        return (theta_new, omega_new, p_new), (theta, omega, p_in)

    @jax.jit
    def run_chunk(params, drive, carry, t0, dt, k0):
        ks = k0 + jnp.arange(CHUNK, dtype=jnp.float64)
        return jax.lax.scan(lambda c, k: step(c, k, params, drive, t0, dt), carry, ks)

    return run_chunk


def integrate(params, spec, mechanisms, drive: dict, theta0, omega0, p_in0, t0, dt, steps: int):
    """Integrate load-driven runs, batched.

    drive : dict of :data:`DRIVE_FIELDS`, arrays of shape (runs,); theta0 [rad],
    omega0 [rad/s], p_in0 [Pa] : initial state; t0 [s], dt [s] : per-run start
    time and step; steps : number of steps (the same for every run).
    returns : (times, theta, omega, p_in), arrays of shape (steps, runs), the
    state at t0 + k·dt for k = 0 … steps−1.
    """
    run_chunk = _chunk_integrator(spec, tuple(mechanisms))
    params = {k: jnp.asarray(v, dtype=jnp.float64) for k, v in params.items()}
    drive = {k: jnp.asarray(drive[k], dtype=jnp.float64) for k in DRIVE_FIELDS}
    as_f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    carry = (as_f(theta0), as_f(omega0), as_f(p_in0))
    t0, dt = as_f(t0), as_f(dt)
    out = []
    for k0 in range(0, steps, CHUNK):
        carry, rec = run_chunk(params, drive, carry, t0, dt, as_f(k0))
        out.append(rec)
    theta, omega, p_in = (np.concatenate([np.asarray(r[i]) for r in out])[:steps] for i in range(3))
    times = np.asarray(t0)[None, :] + np.arange(steps)[:, None] * np.asarray(dt)[None, :]
    return times, theta, omega, p_in
