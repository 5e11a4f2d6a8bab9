"""Leakage laws beyond the 1992 model's laminar gaps: orifice (turbulent) leakage, and gaps that open under
pressure (mechanisms).
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401
from motorid.physics import flow
from motorid.physics.base import CatalogMechanism, ParameterInfo, smooth_sqrt
from motorid.units import M3S_PER_LPM, PA_PER_BAR



class TurbulentLeakage(CatalogMechanism):
    """Orifice-type leakage from each port to the case [m³/s].

    Q_tA = C_t √(P_A − P_c),  Q_tB = C_t √(P_B − P_c)  (signed, smoothed within
    0.1 bar of zero, see :func:`smooth_sqrt`), added to Q_AN, Q_BN and to the case
    drain Q_CN = Q_tA + Q_tB, so the mass balance Q_AN + Q_BN = Q_CN holds.
    C_t = C_d A √(2/ρ) [m³/(s·√Pa)], independent of viscosity.
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "turbulent_leakage"
    name = "turbulent (orifice) leakage"
    physics = ("Leakage through short, wide passages such as valve-plate edges or worn clearances behaves like "
               "flow through an orifice, growing with the square root of the pressure drop from port to case. "
               "Its rate is set by the oil's density, not its viscosity, so it does not change with oil "
               "temperature as the laminar K_L leakage does.")
    reference = ("D. McCandlish, R. E. Dorey, 'The mathematical modelling of hydrostatic pumps and motors', "
                 "Proc. IMechE Part B 198(10), 165-174, 1984; H. E. Merritt, 'Hydraulic Control Systems', "
                 "Wiley, 1967 (orifice equation)")
    channels = ("q_a", "q_b", "q_case")
    parameters = {
        "turbulent_leakage.C_t": ParameterInfo(
            "m³/(s·√Pa)", "orifice leakage coefficient C_d A √(2/ρ), each port to case", True, 5e-10),
    }
    signature = ("case-drain flow (and each port's flow) vs port pressure: leakage ∝ √(P − P_c), strong at low "
                 "pressure and flattening at high, the same at every oil temperature; no speed or shaft-angle "
                 "dependence")

    def running(self, params, spec, samples, ch):
        c = self.param(params, "C_t")
        qa = c * smooth_sqrt(samples.p_a - samples.p_case)
        qb = c * smooth_sqrt(samples.p_b - samples.p_case)
        return ch._replace(q_a=ch.q_a + qa, q_b=ch.q_b + qb, q_case=ch.q_case + qa + qb)

    def describe(self, values, spec=None) -> str:
        c = self.value(values, "C_t")
        area = c / math.sqrt(2.0 / 870.0) / 0.61  # C_d = 0.61, ρ = 870 kg/m³
        return (f"orifice-type leakage of {c * math.sqrt(250 * PA_PER_BAR) / M3S_PER_LPM:.3g} L/min per port at 250 bar above "
                f"case pressure (∝ √ΔP, like a {area * 1e6:.3g} mm² orifice), independent of viscosity")


class GapDeformation(CatalogMechanism):
    """Leakage gaps that open under pressure (elastic deformation) [m³/s].

    A gap of height h(Δp) = h₀ (1 + c |Δp|) passes laminar flow ∝ h³, so each laminar leak
    q = K Δp/μ of the 1992 model becomes q (1 + c |Δp|)³, Δp the pressure across that gap:
    P_A − P_c and P_B − P_c for the port-to-case gaps (K_LA(θ), K_LB(θ)), P_A − P_B for the
    cross-port gap K_AB.  The hook adds q ((1 + c|Δp|)³ − 1) to the base flows, so the mass
    balance holds; at small c|Δp| the leak grows by 3c|Δp| above proportional.  c [1/Pa] is
    the gap's relative opening per pascal: 1e-9 opens it 2.5 % at 250 bar (leak +8 %).
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "gap_deformation"
    name = "leakage gaps opening under pressure (elastic deformation)"
    physics = ("The parts that bound a leakage gap (piston and bore, valve plate and cylinder block) deform "
               "elastically under pressure, and the gap opens as the pressure across it rises. Laminar leakage "
               "grows with the cube of the gap height, so it grows faster than in proportion to the pressure "
               "drop, while keeping the 1/μ temperature dependence of the laminar law.")
    reference = ("H. Ivantysyn, M. Ivantysynova, 'Hydrostatic Pumps and Motors', Akademia Books, 2001 (gap flow, "
                 "elastic deformation of the gap surfaces); M. Pelosi, M. Ivantysynova, 'Heat transfer and thermal "
                 "elastic deformation analysis on the piston/cylinder interface of axial piston machines', ASME J. "
                 "Tribol. 134(4), 041101, 2012; H. E. Merritt, 'Hydraulic Control Systems', Wiley, 1967 (h³ law)")
    channels = ("q_a", "q_b", "q_case")
    parameters = {
        "gap_deformation.c": ParameterInfo(
            "1/Pa", "relative opening of the leakage gaps per pascal across them, h = h₀(1 + c|Δp|)", True, 1e-9),
    }
    signature = ("case-drain and port flows vs port pressure: laminar leakage bends above proportional at high "
                 "pressure (by about 3c·P), while still scaling as 1/μ across oil temperatures (the opposite bend "
                 "of pressure_viscosity)")

    @staticmethod
    def _change(c, q, p_up, p_down):
        """Deformed-gap flow minus laminar flow q of one gap [m³/s]."""
        opening = 1.0 + c * jnp.abs(p_up - p_down)
        return q * (opening * opening * opening - 1.0)

    def running(self, params, spec, samples, ch):
        c = self.param(params, "c")
        return flow.with_changed_gaps(ch, params, spec, samples, lambda q, up, down: self._change(c, q, up, down))

    def describe(self, values, spec=None) -> str:
        c = self.value(values, "c")
        grow = (1.0 + c * 250 * PA_PER_BAR) ** 3 - 1.0
        return (f"leakage gaps open under pressure (c = {c * 1e9:.3g} /GPa: {100 * c * 250 * PA_PER_BAR:.3g} % wider "
                f"at 250 bar), raising laminar leakage at 250 bar by {100 * grow:.3g} % above the laminar law")
