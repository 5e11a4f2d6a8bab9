"""Shaft torques of a bent-axis motor, Bartos 1992 Eq. 7, 17, 24-28.

Sign convention: positive torque drives the load in the positive direction of
rotation; every loss term opposes motion.  Pressures are gauge [Pa].
"""

from __future__ import annotations

import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401
from motorid.physics.kinematics import port_a_sum


def pressure_torque(theta, p_a, p_b, displacement, pistons: int, port_sum=None):
    """Torque of the pressure forces on the pistons, exact, Eq. 7 [N·m].

    T_p = (D/2n) Σᵢ Pᵢ cos θᵢ = (D ΔP / 2n) S(θ).

    theta : shaft angle [rad];  p_a, p_b : port pressures [Pa]
    displacement : D [m³/rev];  pistons : n [-]
    port_sum : S(θ) if already computed (it does not depend on any parameter)
    """
    s = port_a_sum(theta, pistons) if port_sum is None else port_sum
    return displacement * (p_a - p_b) / (2.0 * pistons) * s


def inertia_torque(inertia, acceleration):
    """T_J = −J α, Eq. 17 [N·m].  inertia J [kg·m²], acceleration α [rad/s²]."""
    return -inertia * acceleration


def viscous_torque(Kv, displacement, viscosity, speed):
    """T_v = −K_v D μ ω, Eq. 24 [N·m].  Kv [-], D [m³/rev], μ [Pa·s], ω [rad/s]."""
    return -Kv * displacement * viscosity * speed


def smooth_sign(speed, smoothing_speed=1e-6):
    """sgn ω (Eq. 26) as tanh(ω/ω_s); ω_s [rad/s] far below any test speed."""
    return jnp.tanh(speed / smoothing_speed)


def bearing_friction_torque(KF, displacement, p_a, p_b, direction):
    """Running bearing Coulomb friction T_F1 = −D (P_A + P_B) K_F sgn ω, Eq. 25 [N·m].

    direction : sgn ω [-] (±1 in a running test; see :func:`smooth_sign`)
    """
    return -displacement * (p_a + p_b) * KF * direction


def seal_friction_torque(TFc, direction):
    """Running seal/piston Coulomb friction T_F2 = −T_Fc sgn ω, Eq. 27 [N·m]."""
    return -TFc * direction


def running_friction(KF, TFc, displacement, p_a, p_b):
    """Magnitude of the kinetic Coulomb friction D(P_A+P_B)K_F + T_Fc [N·m]."""
    return displacement * (p_a + p_b) * KF + TFc


def breakaway_torque(KF, KFS, TFc, Ks, displacement, p_a, p_b):
    """Static friction limit T_break = D(P_A+P_B)(K_F+K_FS) + T_Fc(1+K_s) [N·m].

    Eq. 25 and 27 read as a two-level static/kinetic law (MODEL.md): while the
    shaft is stuck, friction holds any torque up to this limit; the shaft breaks
    away when the other torques exceed it.
    """
    return displacement * (p_a + p_b) * (KF + KFS) + TFc * (1.0 + Ks)


def load_torque(pressure, inertia, viscous, bearing, seal):
    """Torque delivered to the load, Eq. 28: T_L = T_p + T_J + T_v + T_F1 + T_F2 [N·m]."""
    return pressure + inertia + viscous + bearing + seal
