"""Hydrodynamic torque losses: churning and windage of the oil in the case (mechanism).
"""

from __future__ import annotations

import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401
from motorid.physics.base import CatalogMechanism, ParameterInfo
from motorid.units import RAD_S_PER_RPM



class HydrodynamicTorque(CatalogMechanism):
    """Churning / windage loss growing with speed squared [N·m].

    T_h = −C_h ω |ω|,  C_h [N·m·s²], independent of viscosity.
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "hydrodynamic_torque"
    name = "hydrodynamic (churning) torque loss"
    physics = ("The rotating cylinder block and pistons churn the oil that fills the case, and the drag of this "
               "turbulent flow grows with the square of speed. "
               "It is set by the oil's inertia, not its viscosity, so unlike the viscous torque K_v D μ ω it "
               "hardly changes with oil temperature.")
    reference = ("D. McCandlish, R. E. Dorey, 'The mathematical modelling of hydrostatic pumps and motors', "
                 "Proc. IMechE Part B 198(10), 165-174, 1984; W. M. J. Schlösser, 'Mathematical model for "
                 "displacement pumps and motors', Hydraulic Power Transmission, 1961")
    channels = ("torque",)
    parameters = {
        "hydrodynamic_torque.C_h": ParameterInfo(
            "N·m·s²", "churning loss coefficient, T_h = −C_h ω|ω|", True, 3e-5),
    }
    signature = ("running torque vs speed: a loss opposing motion that grows as ω², largest at rated speed, "
                 "negligible below 100 rpm, the same at every oil temperature")

    def running(self, params, spec, samples, ch):
        w = samples.speed
        return ch._replace(torque=ch.torque - self.param(params, "C_h") * w * jnp.abs(w))

    def describe(self, values, spec=None) -> str:
        c = self.value(values, "C_h")
        return (f"a churning loss of {c * (1000 * RAD_S_PER_RPM) ** 2:.3g} N·m at 1000 rpm and "
                f"{c * (3000 * RAD_S_PER_RPM) ** 2:.3g} N·m at 3000 rpm (∝ ω², C_h = {c:.3g} N·m·s²), "
                "independent of viscosity")
