"""Compressibility of the oil in the chambers' dead volumes: a flow loss (mechanism).
"""

from __future__ import annotations

import math

from motorid import _jaxconfig  # noqa: F401
from motorid.physics.base import CatalogMechanism, ParameterInfo, smooth_abs
from motorid.units import M3S_PER_LPM, PA_PER_BAR, RAD_S_PER_RPM

#: bulk modulus used only to quote a compression flow as a dead volume [Pa]
BULK_MODULUS = 1.6e9



class CompressibilityFlow(CatalogMechanism):
    """Compression flow of the chamber dead volumes [m³/s].

    Q_AN += C_c (P_A − P_B) |ω|,  Q_BN −= the same, case drain unchanged.
    C_c = n V_0 / (2π β) [m³/(Pa·rad)] for n chambers of dead volume V_0 and oil
    bulk modulus β; |ω| is smoothed within 0.01 rpm of zero (:func:`smooth_abs`).
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "compressibility_flow"
    name = "compressibility (dead-volume) flow loss"
    physics = ("Each cylinder carries a dead volume of oil that is compressed from the low to the high port "
               "pressure as it passes one valve-plate bridge and expands again at the other. "
               "This draws from the high-pressure port a flow proportional to ΔP and to speed that returns to the "
               "low-pressure port, so it shows in the port flows but never in the case drain.")
    reference = ("H. Ivantysyn, M. Ivantysynova, 'Hydrostatic Pumps and Motors', Akademia Books, 2001 "
                 "(compression losses); D. McCandlish, R. E. Dorey, Proc. IMechE Part B 198(10), 1984")
    channels = ("q_a", "q_b")
    parameters = {
        "compressibility_flow.C_c": ParameterInfo(
            "m³/(Pa·rad)", "compressed volume per unit ΔP per radian, n V_0/(2π β)", True, 5e-15),
    }
    signature = ("port flows, not the case drain, vs speed × ΔP: extra flow into the high-pressure port and "
                 "out of the low one, growing in proportion to speed at each ΔP, the same in both directions")

    def running(self, params, spec, samples, ch):
        q = self.param(params, "C_c") * (samples.p_a - samples.p_b) * smooth_abs(samples.speed)
        return ch._replace(q_a=ch.q_a + q, q_b=ch.q_b - q)

    def describe(self, values, spec=None) -> str:
        c = self.value(values, "C_c")
        q = c * 250 * PA_PER_BAR * 1000 * RAD_S_PER_RPM
        volume = 2.0 * math.pi * BULK_MODULUS * c
        return (f"a compression flow loss of {q / M3S_PER_LPM:.3g} L/min from the high- to the low-pressure port at "
                f"250 bar and 1000 rpm (∝ ΔP·|ω|; {volume * 1e6:.3g} cm³ of dead volume over all chambers at "
                f"β = {BULK_MODULUS / 1e9:.2g} GPa), absent from the case drain")
