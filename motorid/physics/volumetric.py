"""Volumetric loss that grows with speed: incomplete filling of the cylinders.

A catalog mechanism (registered in :mod:`motorid.physics.registry`) adding
its flows through the ``running`` hook of the one model; pure ``jax.numpy``,
elementwise, finite gradients everywhere (ω = 0 and ΔP = 0 included).

Importing: this module subclasses the catalog's ``CatalogMechanism``; import it
through :mod:`motorid.physics.registry` (``catalog.get("filling_loss")``).
"""

from __future__ import annotations

import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401
from motorid.physics.base import CatalogMechanism, ParameterInfo
from motorid.units import M3S_PER_LPM as LPM, RAD_S_PER_RPM as RPM


class FillingLoss(CatalogMechanism):
    """Incomplete filling of the cylinders, a flow deficit growing as ω² [m³/s].

    Q_AN −= C_f ω|ω|,   Q_BN += C_f ω|ω|,   Q_CN unchanged            (1)

    C_f [m³·s/rad²]; ω [rad/s].  Each cylinder opens to the port it fills from
    for a time ∝ 1/ω; the oil must be accelerated through the valve-plate kidney
    and the passages, a pressure drop ∝ (flow velocity)² ∝ ω², so at high speed
    the cylinders take in less than their swept volume (the rest is vapour or
    air released from the oil, which collapses again on the other side).  Both
    ports see the same deficit: the flow into the filling port falls short of
    D ω/2π, and the flow out of the other port by as much; the case drain is
    not touched.  Only the speed enters: the deficit is there at ΔP = 0, the
    volumetric loss that grows with speed at zero pressure in measured loss maps.

    Told apart from :class:`~motorid.physics.compressibility.CompressibilityFlow`
    (C_c ΔP |ω|: proportional to speed and to ΔP, absent at ΔP = 0, carried by
    the sign of ΔP) by its ω² growth at every pressure; from the laminar and
    orifice leakages (pressure-driven, no speed dependence) and from the case
    drain (untouched).  A displacement D off by a fraction would give a flow
    error ∝ ω, not ω²: on a campaign whose only fast runs are at a single
    speed the two are one.  The simplest form of the filling law: one speed
    exponent, no dependence on the inlet (boost) pressure, which the bench's
    constant back pressure would not resolve.
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "filling_loss"
    name = "incomplete-filling flow loss (∝ ω²)"
    physics = ("At high speed the cylinders are open to their filling port for a short time, and the oil has to be "
               "accelerated through the valve-plate kidney into them, so they do not fill completely: the port flows "
               "fall short of the swept flow by an amount growing with the square of speed. "
               "It appears in both port flows, at every pressure including zero, and never in the case drain.")
    reference = ("H. Ivantysyn, M. Ivantysynova, 'Hydrostatic Pumps and Motors', Akademia Books, 2001 (filling "
                 "and cavitation in the suction/filling port); N. D. Manring, 'Fluid Power Pumps and Motors: "
                 "Analysis, Design and Control', McGraw-Hill, 2013 (volumetric losses of piston machines); "
                 "W. M. J. Schlösser, 'Mathematical model for displacement pumps and motors', Hydraulic Power "
                 "Transmission, 1961 (speed-dependent volumetric loss terms)")
    channels = ("q_a", "q_b")
    parameters = {
        "filling_loss.C_f": ParameterInfo(
            "m³·s/rad²", "filling-loss coefficient, flow deficit C_f ω|ω| at both ports", True, 2e-10),
    }
    signature = ("port flows, not the case drain, vs speed: both ports carry less than the swept flow by an "
                 "amount ∝ ω² (largest at rated speed), the same at every pressure including ΔP = 0 and in both "
                 "directions of rotation")

    def running(self, params, spec, samples, ch):
        w = samples.speed
        q = self.param(params, "C_f") * w * jnp.abs(w)  # ω|ω|: C¹ at ω = 0, gradient 0 there
        return ch._replace(q_a=ch.q_a - q, q_b=ch.q_b + q)

    def describe(self, values, spec=None) -> str:
        c = self.value(values, "C_f")
        words = (f"the cylinders fill short by {c * (1000 * RPM) ** 2 / LPM:.3g} L/min at 1000 rpm and "
                 f"{c * (3000 * RPM) ** 2 / LPM:.3g} L/min at 3000 rpm (∝ ω², C_f = {c:.3g} m³·s/rad²), "
                 "at both ports, at every pressure")
        if spec is not None:
            swept = spec.displacement * 3000 / 60.0
            words += f"; {100 * c * (3000 * RPM) ** 2 / swept:.3g} % of the swept flow at 3000 rpm"
        return words

