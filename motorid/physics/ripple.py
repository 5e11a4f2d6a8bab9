"""Torque ripple at shaft orders the pistons do not make: drive-line misalignment (mechanism).
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401
from motorid.physics.base import CatalogMechanism, ParameterInfo



class MisalignmentRipple(CatalogMechanism):
    """Torque ripple at 1× and 2× shaft order [N·m].

    T_m = A1 cos θ + B1 sin θ + A2 cos 2θ + B2 sin 2θ, unconstrained.

    The amplitudes are fixed torques, not proportional to load: the usual cause
    on a bench is a misaligned coupling or an eccentric shaft whose bending
    reaction is set by the geometric offset and stiffness, not by ΔP.  A
    load-dependent part would shift the ripple's size between pressures but not
    its shaft orders, which is what names this mechanism; the four constants
    are linear in the torque and always identifiable from a full revolution.
    """

    id = "misalignment_ripple"
    name = "misalignment torque ripple (1× and 2× shaft order)"
    physics = ("A misaligned coupling between motor and transducer, or an eccentric or worn shaft bearing or "
               "cylinder block, adds a torque that repeats once and twice per shaft revolution. "
               "The 1992 model's ripple repeats only at the piston order, so 1× and 2× shaft orders in the "
               "torque point to the drive line, not to the pistons.")
    reference = ("J. Piotrowski, 'Shaft Alignment Handbook', 3rd ed., CRC Press, 2006; "
                 "R. B. Randall, 'Vibration-based Condition Monitoring', Wiley, 2011 (1× and 2× orders of "
                 "misalignment)")
    channels = ("torque",)
    parameters = {
        "misalignment_ripple.A1": ParameterInfo("N·m", "ripple, cos θ term (1× shaft order)", False, 1.0),
        "misalignment_ripple.B1": ParameterInfo("N·m", "ripple, sin θ term (1× shaft order)", False, 1.0),
        "misalignment_ripple.A2": ParameterInfo("N·m", "ripple, cos 2θ term (2× shaft order)", False, 1.0),
        "misalignment_ripple.B2": ParameterInfo("N·m", "ripple, sin 2θ term (2× shaft order)", False, 1.0),
    }
    signature = ("running torque vs shaft angle: ripple with period 2π and π (1× and 2× shaft order), not at "
                 "the piston order; the same pattern in θ at every speed, pressure and direction; mean zero")

    def running(self, params, spec, samples, ch):
        th = samples.theta
        t = (self.param(params, "A1") * jnp.cos(th) + self.param(params, "B1") * jnp.sin(th)
             + self.param(params, "A2") * jnp.cos(2.0 * th) + self.param(params, "B2") * jnp.sin(2.0 * th))
        return ch._replace(torque=ch.torque + t)

    def unseen_in_table(self, table) -> str | None:
        """Mean zero over a revolution: nothing of it is left in a steady table's point."""
        return ("a table's points are means over shaft angle, and a ripple at 1× and 2× shaft order averages "
                "to zero over a revolution")

    def describe(self, values, spec=None) -> str:
        a1, b1, a2, b2 = (self.value(values, k) for k in ("A1", "B1", "A2", "B2"))
        parts = []
        for order, a, b in ((1, a1, b1), (2, a2, b2)):
            amp = math.hypot(a, b)
            peak = (math.degrees(math.atan2(b, a)) / order) % (360.0 / order)
            parts.append(f"{amp:.3g} N·m at {order}× shaft order (peak at θ = {peak:.0f}°)")
        return f"torque ripple of {parts[0]} and {parts[1]}"
