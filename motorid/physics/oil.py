"""Oil properties against temperature: viscosity (Walther, ASTM D341) and density.

μ = ρ ν enters the viscous torque (Eq. 24) and every leakage (Eq. 52-58).
"""

from __future__ import annotations

import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401

KELVIN = 273.15
_WALTHER_SHIFT = 0.7  # ASTM D341: Z = ν[cSt] + 0.7


def walther_constants(nu40_cSt: float, nu100_cSt: float, xp=jnp):
    """Constants (A, B) of log10 log10(ν+0.7) = A − B log10 T[K] through two points.

    xp : the array namespace (``jax.numpy``; ``numpy`` where a reader converts a column, whose every
    new length would otherwise compile each JAX operation anew)."""
    t1, t2 = xp.log10(40.0 + KELVIN), xp.log10(100.0 + KELVIN)
    z1 = xp.log10(xp.log10(nu40_cSt + _WALTHER_SHIFT))
    z2 = xp.log10(xp.log10(nu100_cSt + _WALTHER_SHIFT))
    b = (z1 - z2) / (t2 - t1)
    a = z1 + b * t1
    return a, b


def kinematic_viscosity(temperature_C, nu40_cSt: float, nu100_cSt: float, xp=jnp):
    """Kinematic viscosity ν by the Walther relation (ASTM D341) [m²/s].

    temperature_C : oil temperature [°C]; nu40_cSt, nu100_cSt : ν at 40 and 100 °C [cSt]
    """
    a, b = walther_constants(nu40_cSt, nu100_cSt, xp)
    z = a - b * xp.log10(xp.asarray(temperature_C) + KELVIN)
    nu_cSt = 10.0 ** (10.0**z) - _WALTHER_SHIFT
    return nu_cSt * 1e-6


def temperature_of_viscosity(nu_cSt, nu40_cSt: float, nu100_cSt: float, xp=jnp):
    """The oil temperature [°C] at which the Walther relation gives the kinematic viscosity ν [cSt]
    (its inverse: log10 T = (A − log10 log10(ν + 0.7))/B): what a kinematic reading without a
    temperature says about the density to convert it with."""
    a, b = walther_constants(nu40_cSt, nu100_cSt, xp)
    z = xp.log10(xp.log10(xp.asarray(nu_cSt) + _WALTHER_SHIFT))
    return 10.0 ** ((a - z) / b) - KELVIN


def density(temperature_C, density15: float, expansion_per_K: float = 6.5e-4, xp=jnp):
    """Oil density ρ(T) = ρ15 / (1 + β (T − 15 °C)) [kg/m³].

    density15 : ρ at 15 °C [kg/m³]; expansion_per_K : volumetric expansion β [1/K]
    (about 6.5e-4 /K for mineral oils).
    """
    return density15 / (1.0 + expansion_per_K * (xp.asarray(temperature_C) - 15.0))


def dynamic_viscosity(temperature_C, nu40_cSt, nu100_cSt, density15, expansion_per_K=6.5e-4, xp=jnp):
    """Dynamic viscosity μ = ρ ν [Pa·s]."""
    return density(temperature_C, density15, expansion_per_K, xp) * kinematic_viscosity(
        temperature_C, nu40_cSt, nu100_cSt, xp
    )
