"""A relief valve across the ports: flow that bypasses the motor above a cracking pressure (mechanism).

A catalog mechanism (registered in :mod:`motorid.physics.registry`) adding its flows
through the ``running`` hook of the one model; pure ``jax.numpy``, elementwise, finite
gradients everywhere (ΔP = 0 included).

Importing: this module subclasses the catalog's ``CatalogMechanism``; import it
through :mod:`motorid.physics.registry` (``catalog.get("relief_valve")``).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from motorid import _jaxconfig  # noqa: F401
from motorid.physics.base import CatalogMechanism, ParameterInfo
from motorid.units import M3S_PER_LPM as LPM, PA_PER_BAR as BAR

#: width w of the cracking knee, a share of the override line's intercept P_r [-]: a direct-acting
#: relief valve goes from cracking to full flow over 10-20 % of its setting (its pressure override),
#: and a bench's readings average the valve's opening and closing (hysteresis) over that range;
#: the flow is C_r·w/8 at P_r − 2w, C_r·w·ln 2 at P_r, and within 2 % of the line C_r (|ΔP| − P_r) above P_r + 3w
KNEE_SHARE = 0.05
#: pressure scale that makes sgn ΔP smooth at ΔP = 0 [Pa] (0.01 bar)
SIGN_SMOOTHING = 1e3
#: quantiles of the observed |ΔP| the cracking pressure is started from (a knee has local minima)
START_QUANTILES = (0.6, 0.8, 0.9, 0.97)


def relief_flow(dp, p_r, c_r):
    """Flow through a relief valve from the high- to the low-pressure port [m³/s], signed as ΔP.

    Q_r = sgn(ΔP) · C_r · w · ln(1 + exp((|ΔP| − P_r)/w)),  w = KNEE_SHARE · P_r   (1)

    → C_r (|ΔP| − P_r) above the cracking pressure P_r [Pa] (the valve's override line,
    C_r [m³/(s·Pa)]), → 0 below it; ΔP = P_A − P_B [Pa].
    """
    w = KNEE_SHARE * p_r
    a = jnp.sqrt(dp * dp + SIGN_SMOOTHING * SIGN_SMOOTHING)
    return (dp / a) * c_r * w * jnp.logaddexp(0.0, (a - p_r) / w)


class ReliefValve(CatalogMechanism):
    """A cross-port relief valve (in the motor, or between the flow measurement and the motor) [m³/s].

    Q_AN += Q_r(ΔP),   Q_BN −= Q_r(ΔP),   Q_CN unchanged      (:func:`relief_flow`)

    Hydrostatic circuits protect the lines with relief valves from each line to the other
    (cross-port reliefs, often built into the motor or the transmission's pump), set a little
    below the system's rating.  Once |ΔP| passes the setting P_r the valve opens and passes a
    flow that grows along its override line, C_r (|ΔP| − P_r): oil that enters the high-pressure
    port and leaves the low-pressure one without driving the shaft.  A flow meter that sits
    between the valve and the motor does not see it; one upstream of it (a pump's displacement,
    a ram's speed, a meter at the supply) does.  The torque and the case drain are unchanged.

    Told apart from the laminar and orifice leakages (∝ ΔP, ∝ √ΔP from zero) and from the
    compression flow (∝ ΔP·|ω|) by its knee: nothing below P_r, a steep rise above it, the same
    at every speed.  Only pressures above P_r show it; data that never reach P_r say nothing of
    it (its parameters are then not identifiable), and a valve that opens in one direction only
    (a one-way relief) looks the same where only that direction reaches P_r.
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "relief_valve"
    name = "cross-port relief valve (bypass flow above a cracking pressure)"
    physics = ("A relief valve across the two lines opens once the pressure difference passes its setting and "
               "passes oil from the high- to the low-pressure port around the motor, more the further the pressure "
               "rises above the setting. "
               "It shows in the port flows as a loss that is absent below the setting and grows steeply above it, "
               "at every speed, never in the case drain or the torque.")
    reference = ("H. E. Merritt, 'Hydraulic Control Systems', Wiley, 1967 (relief valve pressure-flow "
                 "characteristic, cracking pressure and override); ISO 4411:2019, 'Hydraulic fluid power — Valves — "
                 "Determination of differential pressure/flow rate characteristics'; N. D. Manring, 'Hydraulic "
                 "Control Systems', Wiley, 2005 (cross-port relief valves of hydrostatic transmissions)")
    channels = ("q_a", "q_b")
    parameters = {
        "relief_valve.P_r": ParameterInfo("Pa", "cracking pressure: the |ΔP| above which the valve passes oil",
                                          True, 2.5e7),
        "relief_valve.C_r": ParameterInfo("m³/(s·Pa)", "override gradient: flow per unit |ΔP| above cracking",
                                          True, 1e-10),
    }
    signature = ("port flows, not the case drain, vs ΔP: extra flow into the high-pressure port and out of the "
                 "low one that is absent below a pressure and grows in proportion to the pressure above it, the "
                 "same at every speed")

    def running(self, params, spec, samples, ch):
        q = relief_flow(samples.p_a - samples.p_b, self.param(params, "P_r"), self.param(params, "C_r"))
        return ch._replace(q_a=ch.q_a + q, q_b=ch.q_b - q)

    def neutral(self) -> dict:
        return {f"{self.id}.P_r": self.parameters[f"{self.id}.P_r"].typical, f"{self.id}.C_r": 0.0}

    def data_starts(self, abs_dp) -> list:
        """Starting values from the observed |ΔP| [Pa] of the data: the cracking pressure at
        :data:`START_QUANTILES` of them (a fixed typical setting would start far off the data of
        most units: the fit cannot find a knee it starts outside)."""
        x = np.asarray(abs_dp, dtype=float)
        x = x[np.isfinite(x) & (x > 0)]
        if x.size < 3:
            return []
        return [{f"{self.id}.P_r": float(np.quantile(x, q)),
                 f"{self.id}.C_r": self.parameters[f"{self.id}.C_r"].typical} for q in START_QUANTILES]

    def outside_data(self, values, abs_dp) -> str | None:
        """The knee must lie inside the data: some point must reach P_r − 2w, where the valve
        passes C_r·w/8.  A P_r fitted beyond every point makes the softplus tail a smooth
        exponential in |ΔP|, which fits any cross-port flow that grows faster than linearly
        (gaps that open under pressure): that is not a valve seen to open."""
        x = np.asarray(abs_dp, dtype=float)
        x = x[np.isfinite(x)]
        p_r = self.value(values, "P_r")
        opens = p_r * (1.0 - 2.0 * KNEE_SHARE)
        if x.size and opens <= float(x.max()):
            return None
        top = float(x.max()) / BAR if x.size else 0.0
        return (f"its knee (P_r − 2w = {opens / BAR:.4g} bar) lies above every point's |ΔP| (at most {top:.4g} bar): "
                "the fit used its tail as a flow loss growing faster than linearly with |ΔP|, not a valve seen to open")

    def describe(self, values, spec=None) -> str:
        p_r, c_r = self.value(values, "P_r"), self.value(values, "C_r")
        w = KNEE_SHARE * p_r
        opening = float(relief_flow(p_r - 2 * w, p_r, c_r))
        return (f"a relief valve across the ports passes oil from the high- to the low-pressure port, past the "
                f"motor, opening over ΔP ≈ {(p_r - 2 * w) / BAR:.4g}-{(p_r + 2 * w) / BAR:.4g} bar (a knee of assumed "
                f"width, {100 * KNEE_SHARE:.0f} % of P_r: {opening / LPM:.2g} L/min at its foot) onto an override line "
                f"of {c_r * 10 * BAR / LPM:.3g} L/min per 10 bar that crosses zero at {p_r / BAR:.4g} bar "
                f"(C_r = {c_r:.3g} m³/(s·Pa), P_r = {p_r:.4g} Pa; a one-way valve reads as a two-way one "
                "where only one direction reaches it)")
