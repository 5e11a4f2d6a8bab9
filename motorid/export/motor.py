"""The identified motor as one function of the export's inputs, traced to a jaxpr.

Every export (FMU, Python module, Simscape tables) evaluates this one function,
which calls the one model — :func:`motorid.model.predict` and
:func:`motorid.model.predict_breakaway` — with the identified parameters and
mechanisms baked in as constants, and the oil viscosity from the spec's oil
(:mod:`motorid.physics.oil`, Walther / ASTM D341).  The C code of the FMU and
the NumPy code of the Python export are translations of its jaxpr
(:mod:`motorid.export.jaxpr_c`, :mod:`motorid.export.jaxpr_numpy`), so there is
still only one motor model.

Inputs and outputs are those of BENCH_LOG_FORMAT.md, "Exports" (SI):

- inputs  ``p_A``, ``p_B``, ``p_case`` [Pa gauge], ``omega`` [rad/s],
  ``theta`` [rad], ``T_oil`` [K];
- outputs ``torque`` [N·m] (shaft torque to the load, at zero shaft
  acceleration: the rotor inertia J·α is left to the load model, see
  docs/export.md), ``q_A``, ``q_B`` [m³/s] (into port A, B), ``q_case``
  [m³/s] (out of the case), ``torque_breakaway`` [N·m] (the static friction
  limit T_break ≥ 0 at these pressures and this angle).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import jax
import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401
from motorid import model
from motorid.physics import oil, torque
from motorid.model import MotorSpec


@dataclass(frozen=True)
class Port:
    """One input or output of the exported motor."""

    name: str
    unit: str
    description: str
    start: float = 0.0


INPUTS = (
    Port("p_A", "Pa", "pressure at port A (gauge)"),
    Port("p_B", "Pa", "pressure at port B (gauge)"),
    Port("p_case", "Pa", "case pressure (gauge)"),
    Port("omega", "rad/s", "shaft speed, signed as in the bench logs"),
    Port("theta", "rad", "shaft angle of piston 1 from the valve-plate reference"),
    Port("T_oil", "K", "oil temperature (viscosity from the oil of the motor spec)", 313.15),
)
OUTPUTS = (
    Port("torque", "N.m", "shaft torque delivered to the load, rotor inertia J*alpha excluded"),
    Port("q_A", "m3/s", "flow into port A"),
    Port("q_B", "m3/s", "flow into port B"),
    Port("q_case", "m3/s", "flow out of the case drain"),
    Port("torque_breakaway", "N.m", "breakaway (static friction) torque at these pressures and this angle"),
)


@dataclass
class IdentifiedMotor:
    """What an export needs: the spec, the parameter values and the mechanisms included.

    params : parameter dict, SI (base names and ``"<id>.<name>"`` of mechanisms)
    mechanisms : catalog mechanisms whose physics the motor includes
    source : where the values came from, for the exported files' descriptions
    notes : sentences an export writes into its documentation
    """

    spec: MotorSpec
    params: dict
    mechanisms: Sequence = ()
    source: str = ""
    notes: list = field(default_factory=list)

    def __post_init__(self):
        if self.spec.oil is None:
            raise ValueError("the motor spec has no [oil]: the export needs it for the viscosity at T_oil")


def viscosity_at(spec: MotorSpec, T_oil):
    """Dynamic viscosity μ [Pa·s] of the spec's oil at T_oil [K] (Walther, physics/oil.py)."""
    o = spec.oil
    return oil.dynamic_viscosity(T_oil - oil.KELVIN, o.nu40_cSt, o.nu100_cSt, o.density15_kg_m3,
                                 o.expansion_per_K)


def motor_outputs(motor: IdentifiedMotor, p_A, p_B, p_case, omega, theta, T_oil):
    """(torque, q_A, q_B, q_case, torque_breakaway) at an operating point, SI.

    Running channels from :func:`motorid.model.predict` with α = 0 and sgn ω as
    the friction direction (zero friction at exactly ω = 0, where the shaft is
    held by static friction up to ``torque_breakaway`` instead).  The breakaway
    torque is :func:`motorid.model.predict_breakaway` read backwards: at
    breakaway in the + direction the held load is T_p − T_break, so
    T_break = T_p − T_held(+1).
    """
    spec, params, mechs = motor.spec, model.as_jax(motor.params), tuple(motor.mechanisms)
    mu = viscosity_at(spec, T_oil)
    temperature_C = T_oil - oil.KELVIN
    s = model.make_samples(spec, theta, omega, p_A, p_B, p_case, mu, acceleration=0.0,
                           direction=jnp.sign(omega), temperature=temperature_C)
    ch = model.predict(params, spec, s, mechs)
    up = s._replace(direction=jnp.ones_like(s.theta), speed=jnp.zeros_like(s.theta))
    held_up = model.predict_breakaway(params, spec, up, mechs)
    t_p = torque.pressure_torque(s.theta, s.p_a, s.p_b, spec.displacement, spec.pistons, port_sum=s.port_sum)
    return ch.torque, ch.q_a, ch.q_b, ch.q_case, t_p - held_up


def traced(motor: IdentifiedMotor):
    """The closed jaxpr of :func:`motor_outputs` at scalar float64 inputs."""
    x = jnp.zeros((), dtype=jnp.float64)

    def fn(p_A, p_B, p_case, omega, theta, T_oil):
        # theta and every input enter as traced scalars, so nothing is folded at trace time
        return motor_outputs(motor, p_A, p_B, p_case, omega, theta, T_oil)

    return jax.make_jaxpr(fn)(*([x] * len(INPUTS)))


def evaluate(motor: IdentifiedMotor, **inputs):
    """The model itself (JAX, float64) at arrays of operating points: dict of outputs.

    The reference the exports are tested against.  Missing inputs: 0, T_oil 313.15 K.
    """
    args = [jnp.asarray(inputs.get(p.name, p.start), dtype=jnp.float64) for p in INPUTS]
    shape = jnp.broadcast_shapes(*[a.shape for a in args])
    args = [jnp.broadcast_to(a, shape) for a in args]
    out = jax.jit(lambda *a: motor_outputs(motor, *a))(*args)
    return {p.name: jnp.asarray(v) for p, v in zip(OUTPUTS, out)}
