"""Leakage laws beyond the 1992 model's laminar gaps: orifice (turbulent) leakage (mechanism).
"""

from __future__ import annotations

import math

from motorid import _jaxconfig  # noqa: F401
from motorid.physics.base import CatalogMechanism, ParameterInfo, smooth_sqrt
from motorid.units import M3S_PER_LPM, PA_PER_BAR



class TurbulentLeakage(CatalogMechanism):
    """Orifice-type leakage from each port to the case [m³/s].

    Q_tA = C_t √(P_A − P_c),  Q_tB = C_t √(P_B − P_c)  (signed, smoothed within
    0.1 bar of zero, see :func:`smooth_sqrt`), added to Q_AN, Q_BN and to the case
    drain Q_CN = Q_tA + Q_tB, so the mass balance Q_AN + Q_BN = Q_CN holds.
    C_t = C_d A √(2/ρ) [m³/(s·√Pa)], independent of viscosity.
    """

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
