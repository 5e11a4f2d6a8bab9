"""Piston kinematics of a bent-axis motor: which pistons see which port.

Bartos 1992, Eq. 2-5 and 31-35.  Both the pressure torque (Eq. 7) and the swept
flow (Eq. 36-37) are the displacement times one geometric sum,

    S(θ) = Σ_{i: cos θᵢ > 0} cos θᵢ ,   θᵢ = θ + 2π(i−1)/n ,

so this module computes that sum once (exactly, per piston) and its ripple
approximations (Eq. 8-10 and 38-40) with the least-squares constants C1, C2 of
the report's Tables 1-3.
"""

from __future__ import annotations

import numpy as np
import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401


def piston_angles(theta, pistons: int):
    """Angles θᵢ of all pistons, Eq. 2 [rad].

    theta : shaft angle θ of piston 1 from the valve-plate reference [rad], any shape
    pistons : number of pistons n [-]
    returns : array of shape theta.shape + (n,) [rad]
    """
    offsets = 2.0 * jnp.pi * jnp.arange(pistons) / pistons
    return jnp.asarray(theta)[..., None] + offsets


def port_a_sum(theta, pistons: int):
    """S(θ) = Σ cos θᵢ over the pistons connected to port A (cos θᵢ > 0) [-].

    Eq. 3-4 and 31-32.  The pistons with cos θᵢ < 0 see port B and sum to −S(θ)
    because Σᵢ cos θᵢ = 0 for n ≥ 2.  S has mean n/π over a revolution.
    """
    c = jnp.cos(piston_angles(theta, pistons))
    return jnp.sum(jnp.where(c > 0.0, c, 0.0), axis=-1)


def ripple_period(pistons: int) -> float:
    """Period of one torque/flow ripple [rad]: π/n for odd n, 2π/n for even n."""
    return np.pi / pistons if pistons % 2 else 2.0 * np.pi / pistons


def ripple_shape(theta, pistons: int):
    """The approximating shape of Eq. 8-10: |cos nθ|, |cos(nθ/2)| or |sin(nθ/2)| [-]."""
    theta = jnp.asarray(theta)
    if pistons % 2 == 1:  # n = 2k+1, Eq. 8
        return jnp.abs(jnp.cos(pistons * theta))
    if pistons % 4 == 2:  # n = 4k-2, Eq. 9
        return jnp.abs(jnp.cos(pistons * theta / 2.0))
    return jnp.abs(jnp.sin(pistons * theta / 2.0))  # n = 4k, Eq. 10


def ripple_coefficients(pistons: int, points: int = 500):
    """Least-squares C1, C2 and normalized error σ of the ripple approximation.

    The report's procedure (Tables 1-3): ``points`` samples evenly spaced over one
    ripple period, both ends included; fit the normalized exact torque
    2π T_p/(D ΔP) = (π/n) S(θ) by C1 + C2·shape(θ) in least squares.

    returns : (C1, C2, sigma) as floats; σ is the standard deviation of the
        approximation error normalized by the mean torque (2πσ/(DΔP)).
    """
    if pistons < 2:
        raise ValueError(f"pistons must be >= 2, got {pistons}")
    theta = np.linspace(0.0, ripple_period(pistons), points)
    exact = (np.pi / pistons) * np.asarray(port_a_sum(theta, pistons))
    basis = np.column_stack([np.ones_like(theta), np.asarray(ripple_shape(theta, pistons))])
    (c1, c2), *_ = np.linalg.lstsq(basis, exact, rcond=None)
    error = exact - basis @ np.array([c1, c2])
    return float(c1), float(c2), float(np.std(error))


def port_a_sum_approx(theta, pistons: int, c1: float | None = None, c2: float | None = None):
    """Ripple approximation of S(θ) (Eq. 8-10, 38-40): (n/π)[C1 + C2·shape(θ)] [-]."""
    if c1 is None or c2 is None:
        c1, c2, _ = ripple_coefficients(pistons)
    return pistons / np.pi * (c1 + c2 * ripple_shape(theta, pistons))
