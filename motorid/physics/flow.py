"""Flows through a bent-axis motor, Bartos 1992 Eq. 36-37, 52-61.

Positive flow goes into the motor through a port, or into the case (and leaves
by the case drain).  Pressures gauge [Pa], viscosity μ [Pa·s], flows [m³/s].
"""

from __future__ import annotations

import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401
from motorid.physics.kinematics import port_a_sum


def swept_flow_a(theta, speed, displacement, pistons: int, port_sum=None):
    """Flow swept by the pistons into port A, exact, Eq. 36 [m³/s].

    Q_A = (D ω / 2n) S(θ); Q_B = −Q_A (Eq. 37, 42).  Mean D ω / 2π (Eq. 43).
    """
    s = port_a_sum(theta, pistons) if port_sum is None else port_sum
    return displacement * speed / (2.0 * pistons) * s


def leakage_coefficient(theta, KL0, harmonics_cos, harmonics_sin, pistons: int):
    """K_L(θ) = K_L0 [1 + Σ_m a_m cos(m n θ) + b_m sin(m n θ)] [m³].

    The port-to-case leakage coefficient repeats every piston pitch (Eq. 52-55,
    MODEL.md).  harmonics_cos/sin : sequences (a_1..a_M), (b_1..b_M) [-].
    """
    theta = jnp.asarray(theta)
    shape = jnp.ones_like(theta)
    for m, (a, b) in enumerate(zip(harmonics_cos, harmonics_sin), start=1):
        shape = shape + a * jnp.cos(m * pistons * theta) + b * jnp.sin(m * pistons * theta)
    return KL0 * shape


def port_to_case_leakage(coefficient, p_port, p_case, viscosity):
    """Laminar leakage from a port to the case, Eq. 52-53: K_L (P − P_c)/μ [m³/s]."""
    return coefficient * (p_port - p_case) / viscosity


def cross_port_leakage(KAB, p_a, p_b, viscosity):
    """Laminar leakage from port A to port B, Eq. 58: K_AB (P_A − P_B)/μ [m³/s]."""
    return KAB * (p_a - p_b) / viscosity


def net_flows(swept_a, leak_a, leak_b, cross):
    """Net flows measured on the bench, Eq. 59-61 [m³/s].

    returns (Q_AN, Q_BN, Q_CN): into port A, into port B, into the case.
    Mass balance Q_AN + Q_BN = Q_CN holds identically (Q_B = −Q_A).
    """
    q_an = swept_a + leak_a + cross
    q_bn = -swept_a + leak_b - cross
    q_cn = leak_a + leak_b
    return q_an, q_bn, q_cn


def leakage_harmonics(params: dict, harmonics: int):
    """(a_1..a_M), (b_1..b_M) of K_L(θ) from a parameter dict."""
    a = [params.get(f"KL_a{m}", 0.0) for m in range(1, harmonics + 1)]
    b = [params.get(f"KL_b{m}", 0.0) for m in range(1, harmonics + 1)]
    return a, b


def with_changed_gaps(ch, params: dict, spec, samples, change):
    """The channels ``ch`` with each laminar gap of the 1992 model changed by ``change(q, p_up, p_down)``
    [m³/s] (the gap's laminar flow q and its end pressures → what the changed law adds to it): port A and
    port B to the case (K_LA(θ), K_LB(θ) = K_LA(θ − φ), Eq. 38-41) and A to B (K_AB).  Into port A and B
    what leaves them, out of the case drain what reaches it: the mass balance holds."""
    s = samples
    a, b = leakage_harmonics(params, sum(1 for k in params if k.startswith("KL_a")))
    k_la = leakage_coefficient(s.theta, params["KL0"], a, b, spec.pistons)
    k_lb = leakage_coefficient(s.theta - spec.phase, params["KL0"], a, b, spec.pistons)
    d_la = change(port_to_case_leakage(k_la, s.p_a, s.p_case, s.viscosity), s.p_a, s.p_case)
    d_lb = change(port_to_case_leakage(k_lb, s.p_b, s.p_case, s.viscosity), s.p_b, s.p_case)
    d_ab = change(cross_port_leakage(params["KAB"], s.p_a, s.p_b, s.viscosity), s.p_a, s.p_b)
    return ch._replace(q_a=ch.q_a + d_la + d_ab, q_b=ch.q_b + d_lb - d_ab, q_case=ch.q_case + d_la + d_lb)
