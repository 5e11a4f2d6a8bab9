"""Volumetric, hydromechanical and overall efficiency of a unit, in both directions of power flow.

ISO 4409 defines them for a motor and for a pump; here one function takes the
four quadrants, with the sign conventions of BENCH_LOG_FORMAT.md (ω signed, ΔP =
P_A − P_B, T the torque delivered to the load, flows into the ports).  With the
theoretical flow Q_th = D|ω|/2π and torque T_th = D|ΔP|/2π [D in m³/rev], and
Q_hp the flow into the port of higher pressure (A where ΔP ≥ 0, else B):

motor mode (ΔP·ω > 0: hydraulic power in, mechanical power out)

    η_v  = Q_th / Q_hp          η_hm = T·sgn ω / T_th          η = T ω / (|ΔP| Q_hp)

pump mode (ΔP·ω < 0: mechanical power in, hydraulic power out)

    η_v  = −Q_hp / Q_th         η_hm = T_th / (−T·sgn ω)       η = |ΔP| (−Q_hp) / (−T ω)

so that in each mode η = η_v·η_hm is output power over input power.  Undefined
(NaN) where ΔP·ω = 0 (no power flows).  Functions take NumPy or JAX arrays.
"""

from __future__ import annotations

import numpy as np


def _xp(*arrays):
    try:
        import jax

        if any(isinstance(a, jax.Array) for a in arrays):
            import jax.numpy as jnp

            return jnp
    except ImportError:  # pragma: no cover
        pass
    return np


def efficiencies(torque, q_a, q_b, speed, p_a, p_b, displacement):
    """(η_v, η_hm, η) [-] of each point; torque [N·m], flows [m³/s], speed [rad/s],
    pressures [Pa], displacement [m³/rev].  Mode from the sign of ΔP·ω."""
    xp = _xp(torque, q_a, q_b, speed, p_a, p_b)
    dp = p_a - p_b
    q_hp = xp.where(dp >= 0, q_a, q_b)
    q_th = displacement * xp.abs(speed) / (2 * np.pi)
    t_th = displacement * xp.abs(dp) / (2 * np.pi)
    power = dp * speed
    motor = power > 0
    pump = power < 0
    sgn = xp.sign(speed)
    nan = xp.nan
    safe = lambda x: xp.where(x == 0, 1.0, x)  # noqa: E731
    eta_v = xp.where(motor, q_th / safe(q_hp), xp.where(pump, -q_hp / safe(q_th), nan))
    eta_hm = xp.where(motor, torque * sgn / safe(t_th), xp.where(pump, t_th / safe(-torque * sgn), nan))
    eta = xp.where(motor, torque * speed / safe(xp.abs(dp) * q_hp),
                   xp.where(pump, xp.abs(dp) * (-q_hp) / safe(-torque * speed), nan))
    return eta_v, eta_hm, eta


def operating_mode(speed, p_a, p_b):
    """"motor", "pump" or "none" (ΔP·ω = 0) for each point."""
    power = (np.asarray(p_a) - np.asarray(p_b)) * np.asarray(speed)
    return np.where(power > 0, "motor", np.where(power < 0, "pump", "none"))
