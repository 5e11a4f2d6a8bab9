"""The one motor model: known data (MotorSpec), unknowns (parameters), predict().

Everything that simulates, fits, samples or searches for missing physics calls
:func:`predict` (running samples) and :func:`predict_breakaway` (startability
events).  Extra physics (:mod:`motorid.physics.registry`) enters as *mechanisms*:
objects that add their terms to the channels this module computes, never a
second copy of the model.

Parameters are a plain ``dict`` of name → scalar (a JAX pytree), named as in
MODEL.md: ``Kv``, ``KF``, ``KFS``, ``TFc``, ``Ks``, ``KL0``, ``KL_a1``,
``KL_b1`` (``KL_a2``, … for more harmonics), ``KAB``; SI units.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from motorid import _jaxconfig  # noqa: F401
from motorid._aot import cached_jit
from motorid.physics import flow, oil, torque
from motorid.physics.base import Channels, ParameterInfo, Samples  # noqa: F401  (re-exported)
from motorid.physics.flow import leakage_harmonics  # noqa: F401  (re-exported)
from motorid.physics.kinematics import port_a_sum, port_a_sum_approx, ripple_coefficients


# ---------------------------------------------------------------------------
# known data: the motor and its oil (read from a spec TOML by motorid.io.spec)


@dataclass(frozen=True)
class OilSpec:
    """The oil: Walther viscosity through two points and density at 15 °C."""

    name: str = "ISO VG 46 mineral oil"
    nu40_cSt: float = 46.0
    nu100_cSt: float = 6.8
    density15_kg_m3: float = 875.0
    expansion_per_K: float = 6.5e-4
    temp_C: float | None = None  # oil temperature where an operating-point table gives none [°C]

    def viscosity(self, temperature_C, xp=None):
        """Dynamic viscosity μ at ``temperature_C`` [°C] → [Pa·s] (``xp=numpy`` for a reader's column:
        no JAX compile per column length)."""
        kw = {} if xp is None else {"xp": xp}
        return oil.dynamic_viscosity(
            temperature_C, self.nu40_cSt, self.nu100_cSt, self.density15_kg_m3, self.expansion_per_K, **kw
        )

    def dynamic_from_kinematic(self, nu_m2_s, temperature_C):
        """A viscometer's kinematic reading ν [m²/s] → μ = ρ(T) ν [Pa·s] (numpy, for a reader's column),
        ρ at the oil temperature [°C] where it is finite, else at the temperature at which this oil has
        that ν (the Walther relation inverted)."""
        nu = np.asarray(nu_m2_s, dtype=float)
        t = np.where(np.isfinite(temperature_C), temperature_C,
                     oil.temperature_of_viscosity(nu / 1e-6, self.nu40_cSt, self.nu100_cSt, xp=np))
        return nu * oil.density(t, self.density15_kg_m3, self.expansion_per_K, xp=np)


@dataclass(frozen=True)
class MotorSpec:
    """Known motor data, SI.

    pistons : n [-]; displacement : D [m³/rev]; inertia : J [kg·m²];
    leak_phase : φ of K_LB(θ) = K_LA(θ − φ) [rad], default π/n (MODEL.md);
    leak_harmonics : M, the order of the K_L(θ) Fourier series [-].
    """

    name: str
    pistons: int
    displacement: float
    inertia: float = 0.0
    leak_phase: float | None = None
    leak_harmonics: int = 1
    oil: OilSpec | None = field(default_factory=OilSpec)

    @property
    def phase(self) -> float:
        return math.pi / self.pistons if self.leak_phase is None else self.leak_phase

    @property
    def displacement_cm3(self) -> float:
        return self.displacement * 1e6

    def to_toml(self) -> str:
        lines = [
            "[motor]",
            f'name = "{self.name}"',
            f"pistons = {self.pistons}",
            f"displacement_cm3 = {self.displacement * 1e6!r}",
            f"inertia_kg_m2 = {self.inertia!r}",
        ]
        if self.leak_phase is not None:
            lines.append(f"leak_phase_deg = {math.degrees(self.leak_phase)!r}")
        if self.leak_harmonics != 1:
            lines.append(f"leak_harmonics = {self.leak_harmonics}")
        if self.oil is not None:
            o = self.oil
            lines += [
                "",
                "[oil]",
                f'name = "{o.name}"',
                f"nu40_cSt = {o.nu40_cSt!r}",
                f"nu100_cSt = {o.nu100_cSt!r}",
                f"density15_kg_m3 = {o.density15_kg_m3!r}",
            ]
            if o.expansion_per_K != OilSpec.expansion_per_K:
                lines.append(f"expansion_per_K = {o.expansion_per_K!r}")
            if o.temp_C is not None:
                lines.append(f"temp_C = {o.temp_C!r}")
        return "\n".join(lines) + "\n"

    def as_dict(self) -> dict:
        return asdict(self)


# The spec's numbers enter a compiled program as its inputs, not as constants baked into it: one
# program then serves every motor with the same number of pistons and harmonics (a fleet, a test
# suite, another lab's motors), where each motor compiled its own before.  The names are not part
# of a program (a traced copy has none; no traced code reads them).
def _f64(x):
    return np.asarray(x, dtype=np.float64) if isinstance(x, (int, float)) else x  # None, an array or a tracer


jax.tree_util.register_pytree_node(
    OilSpec,
    lambda o: ((_f64(o.nu40_cSt), _f64(o.nu100_cSt), _f64(o.density15_kg_m3), _f64(o.expansion_per_K),
                _f64(o.temp_C)), None),
    lambda _, c: OilSpec("", *c),
)
jax.tree_util.register_pytree_node(
    MotorSpec,
    lambda s: ((_f64(s.displacement), _f64(s.inertia), _f64(s.leak_phase), s.oil), (s.pistons, s.leak_harmonics)),
    lambda aux, c: MotorSpec("", aux[0], c[0], c[1], c[2], aux[1], c[3]),
)


# ---------------------------------------------------------------------------
# unknowns: the parameters

BASE_PARAMETERS: dict[str, ParameterInfo] = {
    "Kv": ParameterInfo("-", "viscous torque coefficient, T_v = −K_v D μ ω (Eq. 24)", True, 1e3),
    "KF": ParameterInfo("-", "bearing Coulomb friction per unit port-pressure sum, running (Eq. 25)", True, 1e-3),
    "KFS": ParameterInfo("-", "extra bearing friction coefficient while stuck (static, Eq. 25)", True, 1e-2),
    "TFc": ParameterInfo("N·m", "seal and piston Coulomb friction torque, running (Eq. 27)", True, 1.0),
    "Ks": ParameterInfo("-", "static multiplier of T_Fc while stuck (Eq. 27)", True, 1.0),
    "KL0": ParameterInfo("m³", "mean port-to-case leakage coefficient K_L0 (Eq. 52-53)", True, 1e-13),
    "KAB": ParameterInfo("m³", "cross-port leakage coefficient (Eq. 58)", True, 1e-13),
}


def _harmonic_info(kind: str, m: int) -> ParameterInfo:
    trig = "cos" if kind == "a" else "sin"
    return ParameterInfo("-", f"K_L(θ) Fourier coefficient of {trig}({m}·nθ), relative to K_L0", False, 0.1)


def parameter_names(harmonics: int = 1) -> list[str]:
    """Names of the base parameters for a K_L(θ) series of ``harmonics`` orders."""
    names = ["Kv", "KF", "KFS", "TFc", "Ks", "KL0"]
    for m in range(1, harmonics + 1):
        names += [f"KL_a{m}", f"KL_b{m}"]
    return names + ["KAB"]


def parameter_info(name: str, mechanisms: Sequence = ()) -> ParameterInfo:
    """Metadata of a base parameter or of a mechanism's parameter ``id.name``."""
    if name in BASE_PARAMETERS:
        return BASE_PARAMETERS[name]
    if name.startswith("KL_") and name[3] in "ab" and name[4:].isdigit():
        return _harmonic_info(name[3], int(name[4:]))
    for mech in mechanisms:
        if name in mech.parameters:
            return mech.parameters[name]
    raise KeyError(f"unknown parameter '{name}'")


def make_samples(spec: MotorSpec, theta, speed, p_a, p_b, p_case, viscosity, acceleration=None,
                 direction=None, temperature=None, time=None, ripple: str = "exact") -> Samples:
    """Assemble :class:`Samples`, computing the parameter-free S(θ) once.

    ripple : "exact" (per-piston sum, Eq. 7/36) or "approx" (Eq. 8-10/38-40).
    Every field is broadcast to the shape of θ; defaults: acceleration 0,
    direction sign(speed), temperature 40 °C, time 0.  Concrete inputs run as
    one compiled program (kept on disk, :mod:`motorid._aot`); traced inputs (a
    simulator inside ``jax.jit``) are assembled in the trace.
    """
    if ripple == "exact":
        coefficients = None
    elif ripple == "approx":
        with jax.ensure_compile_time_eval():  # constants, also when called inside jax.jit
            c1, c2, _ = ripple_coefficients(spec.pistons)
        coefficients = (float(c1), float(c2))
    else:
        raise ValueError(f"ripple must be 'exact' or 'approx', got {ripple!r}")
    fields = (theta, speed, acceleration, p_a, p_b, p_case, viscosity, direction, temperature, time)
    defaults = (None, None, 0.0, 0.0, 0.0, 0.0, 0.0, None, 40.0, 0.0)
    fields = tuple(d if f is None else f for f, d in zip(fields, defaults))
    if any(isinstance(f, jax.core.Tracer) for f in fields):
        return _assemble_samples(spec.pistons, coefficients, *fields)
    arrays = tuple(None if f is None else np.asarray(f, dtype=np.float64) for f in fields)
    # NumPy views of the result: later arithmetic on concrete samples stays in NumPy
    return Samples(*[np.asarray(f) for f in _assemble_samples_jit(spec.pistons, coefficients, *arrays)])


def _assemble_samples(pistons: int, coefficients, theta, speed, acceleration, p_a, p_b, p_case, viscosity,
                      direction, temperature, time) -> Samples:
    theta = jnp.asarray(theta, dtype=jnp.float64)
    like = jnp.zeros_like(theta)
    speed = like + jnp.asarray(speed, dtype=jnp.float64)
    if coefficients is None:
        s = port_a_sum(theta, pistons)
    else:
        s = port_a_sum_approx(theta, pistons, *coefficients)
    as_arr = lambda x: like + jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    return Samples(
        theta=theta, speed=speed, acceleration=as_arr(acceleration), p_a=as_arr(p_a), p_b=as_arr(p_b),
        p_case=as_arr(p_case), viscosity=as_arr(viscosity),
        direction=jnp.sign(speed) if direction is None else as_arr(direction),
        port_sum=like + s, temperature=as_arr(temperature), time=as_arr(time),
    )


_assemble_samples_jit = cached_jit(_assemble_samples)


def _harmonic_count(params: dict) -> int:
    return sum(1 for k in params if k.startswith("KL_a"))


def base_channels(params: dict, spec: MotorSpec, s: Samples) -> Channels:
    """The 1992 model of every running channel (Eq. 7, 17, 24-28, 36, 52-61)."""
    D, n = spec.displacement, spec.pistons
    t_p = torque.pressure_torque(s.theta, s.p_a, s.p_b, D, n, port_sum=s.port_sum)
    t_j = torque.inertia_torque(spec.inertia, s.acceleration)
    t_v = torque.viscous_torque(params["Kv"], D, s.viscosity, s.speed)
    t_f1 = torque.bearing_friction_torque(params["KF"], D, s.p_a, s.p_b, s.direction)
    t_f2 = torque.seal_friction_torque(params["TFc"], s.direction)
    t_l = torque.load_torque(t_p, t_j, t_v, t_f1, t_f2)

    a, b = leakage_harmonics(params, _harmonic_count(params))
    k_la = flow.leakage_coefficient(s.theta, params["KL0"], a, b, n)
    k_lb = flow.leakage_coefficient(s.theta - spec.phase, params["KL0"], a, b, n)
    q_la = flow.port_to_case_leakage(k_la, s.p_a, s.p_case, s.viscosity)
    q_lb = flow.port_to_case_leakage(k_lb, s.p_b, s.p_case, s.viscosity)
    q_ab = flow.cross_port_leakage(params["KAB"], s.p_a, s.p_b, s.viscosity)
    q_swept = flow.swept_flow_a(s.theta, s.speed, D, n, port_sum=s.port_sum)
    q_an, q_bn, q_cn = flow.net_flows(q_swept, q_la, q_lb, q_ab)
    return Channels(t_l, q_an, q_bn, q_cn)


def predict(params: dict, spec: MotorSpec, samples: Samples, mechanisms: Sequence = ()) -> Channels:
    """Predicted running channels at every sample: the base model plus mechanisms.

    params : parameter dict (SI); spec : motor data; samples : :class:`Samples`
    mechanisms : extra physics from :mod:`motorid.physics.registry`, each adding
        its terms through ``mechanism.running(params, spec, samples, channels)``.
    """
    ch = base_channels(params, spec, samples)
    for mech in mechanisms:
        ch = mech.running(params, spec, samples, ch)
    return ch


def static_friction_limit(params: dict, spec: MotorSpec, p_a, p_b):
    """Breakaway torque T_break = D(P_A+P_B)(K_F+K_FS) + T_Fc(1+K_s) [N·m] (MODEL.md)."""
    return torque.breakaway_torque(params["KF"], params["KFS"], params["TFc"], params["Ks"],
                                   spec.displacement, p_a, p_b)


def predict_breakaway(params: dict, spec: MotorSpec, events: Samples, mechanisms: Sequence = ()):
    """Held load torque read at the breakaway instant of a startability run [N·m].

    At breakaway the pressure torque exceeds the held load by exactly the static
    friction limit, in the direction the shaft then moves:
    T_held = T_p(θ, ΔP) − sgn ω · T_break(P_A, P_B).  ``events`` are
    :class:`Samples` at the breakaway instants (``direction`` = the way the
    shaft breaks away; speed zero).
    """
    D, n = spec.displacement, spec.pistons
    t_p = torque.pressure_torque(events.theta, events.p_a, events.p_b, D, n, port_sum=events.port_sum)
    limit = static_friction_limit(params, spec, events.p_a, events.p_b)
    for mech in mechanisms:
        limit = mech.static_limit(params, spec, events, limit)
    held = t_p - events.direction * limit
    for mech in mechanisms:
        held = mech.breakaway_reading(params, spec, events, held)
    return held


def default_parameters(spec: MotorSpec | None = None) -> dict:
    """Plausible values for a motor of spec's size (a starting point, not a fit)."""
    harmonics = 1 if spec is None else spec.leak_harmonics
    p = {name: parameter_info(name).typical for name in parameter_names(harmonics)}
    for m in range(1, harmonics + 1):
        p[f"KL_a{m}"] = 0.0
        p[f"KL_b{m}"] = 0.0
    return p


def as_jax(params: dict) -> dict:
    return {k: jnp.asarray(v, dtype=jnp.float64) for k, v in params.items()}


def as_float(params: dict) -> dict:
    return {k: float(np.asarray(v)) for k, v in params.items()}


def constrain(y, positive, scales, xp=jnp):
    """Unconstrained vector → parameter values: p = s·exp(y) where positive, else s·y.

    xp : the array module (``numpy`` outside traced code saves JAX dispatches)."""
    return xp.where(positive, xp.exp(y), y) * scales


def unconstrain(values, positive, scales, xp=jnp):
    """Parameter values → unconstrained vector: y = log(p/s) where positive, else p/s."""
    v = values / scales
    return xp.where(positive, xp.log(xp.where(positive, v, 1.0)), v)


class ParameterTransform:
    """Map a parameter dict to an unconstrained vector for the optimizers and back.

    Positive parameters (``ParameterInfo.positive``) go through a log, the others
    are divided by a scale: x = log(p/s) or x = p/s.  ``scales`` default to each
    parameter's typical size.
    """

    def __init__(self, names: Sequence[str], scales: dict | None = None, mechanisms: Sequence = ()):
        self.names = list(names)
        infos = [parameter_info(n, mechanisms) for n in self.names]
        self.positive = np.array([i.positive for i in infos])
        sc = {n: i.typical for n, i in zip(self.names, infos)}
        if scales:
            sc.update({k: abs(float(v)) for k, v in scales.items() if k in sc and float(v) != 0.0})
        self.scales = np.array([sc[n] for n in self.names])

    def to_unconstrained(self, params: dict):
        v = jnp.stack([jnp.asarray(params[n], dtype=jnp.float64) for n in self.names])
        return unconstrain(v, self.positive, self.scales)

    def from_unconstrained(self, x) -> dict:
        v = constrain(x, self.positive, self.scales)
        return {n: v[i] for i, n in enumerate(self.names)}
