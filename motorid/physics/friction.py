"""Extra friction laws beyond the 1992 model's Coulomb and viscous terms (mechanisms).

- :class:`StribeckFriction`     friction excess fading out above a Stribeck speed
- :class:`CasePressureFriction` shaft-seal friction growing with case pressure
"""

from __future__ import annotations

import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401
from motorid.physics.base import CatalogMechanism, ParameterInfo, Samples
from motorid.units import PA_PER_BAR, RAD_S_PER_RPM



class StribeckFriction(CatalogMechanism):
    """Stribeck friction: extra friction below a characteristic speed [N·m].

    T_St = −sgn ω · [T_s + K_p D (P_A + P_B)] · exp(−|ω| / ω_s)

    T_s [N·m] and K_p [-] are the friction excess at standstill over the running
    (kinetic) level, its pressure-independent and pressure-proportional parts;
    ω_s [rad/s] is the Stribeck speed.

    Why free amplitudes, not a gain on the base model's static-minus-kinetic
    friction D(P_A+P_B)K_FS + T_Fc K_s: (1) K_FS and K_s are fixed by the
    breakaway tests, and logs without them would leave a gain × K_FS product
    that no running test can separate; (2) the excess the curve fades out need
    not equal the breakaway excess (breakaway also depends on dwell time and
    rate of loading), and a generator or a real motor with a constant, or a
    purely pressure-proportional, amplitude is fitted exactly by one of the two
    parts.  Both parts are positive: a friction *dip* at low speed is not this
    mechanism.

    Why exponent δ = 1 in exp(−(|ω|/ω_s)^δ): Armstrong-Hélouvry et al. (1994)
    report δ from 0.5 to 2.  Fitted over the log-spaced speeds of ISO 4392-1
    (0.3-2500 rpm), the exponential (δ = 1) matches Gaussian (δ = 2), δ = 0.5,
    Lorentzian 1/(1+(ω/ω_s)²) and 1 − tanh(ω/ω_s) curves to within 3-10 % of
    their size, better in the worst case than δ = 2 does, whose thin tail misses
    the heavy-tailed shapes by up to 18 %.  It does not change the breakaway
    limit: at ω = 0 the shaft is held by static friction (MODEL.md).
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "stribeck_friction"
    name = "Stribeck friction"
    physics = ("At low sliding speed the oil films in the bearings, piston and seal contacts thin out, so "
               "mixed and boundary friction raise the friction torque from its kinetic level toward the "
               "static (breakaway) level as the shaft slows down. "
               "The excess fades out above a characteristic Stribeck speed ω_s, the classical Stribeck curve.")
    reference = ("B. Armstrong-Hélouvry, P. Dupont, C. Canudas de Wit, 'A survey of models, analysis tools and "
                 "compensation methods for the control of machines with friction', Automatica 30(7), "
                 "1083-1138, 1994")
    channels = ("torque",)
    parameters = {
        "stribeck_friction.T_s": ParameterInfo(
            "N·m", "pressure-independent friction excess at standstill over the kinetic level", True, 1.0),
        "stribeck_friction.K_p": ParameterInfo(
            "-", "friction excess at standstill per unit D(P_A+P_B), like K_FS", True, 3e-3),
        "stribeck_friction.w_s": ParameterInfo(
            "rad/s", "Stribeck speed: the excess falls by 1/e per ω_s of speed", True, 0.3),
    }
    signature = ("running torque vs speed: extra friction largest at the slowest speeds, fading out above "
                 "ω_s (a few rpm) and gone at high speed; it opposes motion, so its sign follows the direction "
                 "of rotation, the same size both ways; it may grow with P_A+P_B")

    def amplitude(self, params, spec, s: Samples):
        """Friction excess at standstill T_s + K_p D (P_A + P_B) [N·m]."""
        return self.param(params, "T_s") + self.param(params, "K_p") * spec.displacement * (s.p_a + s.p_b)

    def running(self, params, spec, samples, ch):
        shape = jnp.exp(-jnp.abs(samples.speed) / self.param(params, "w_s"))
        t = -samples.direction * self.amplitude(params, spec, samples) * shape
        return ch._replace(torque=ch.torque + t)

    def neutral(self) -> dict:
        return {f"{self.id}.T_s": 0.0, f"{self.id}.K_p": 0.0,
                f"{self.id}.w_s": self.parameters[f"{self.id}.w_s"].typical}

    def describe(self, values, spec=None) -> str:
        t_s, k_p, w_s = (self.value(values, k) for k in ("T_s", "K_p", "w_s"))
        where = f"below about {w_s / RAD_S_PER_RPM:.3g} rpm (ω_s = {w_s:.3g} rad/s)"
        if spec is not None:
            at = t_s + k_p * spec.displacement * 250.0 * PA_PER_BAR
            return (f"friction rises as the shaft slows {where}, by up to {at:.3g} N·m at standstill at "
                    f"P_A+P_B = 250 bar ({t_s:.3g} N·m of it pressure-independent)")
        return f"friction rises as the shaft slows {where}, by up to {t_s:.3g} N·m + {k_p:.3g}·D(P_A+P_B) at standstill"


class CasePressureFriction(CatalogMechanism):
    """Shaft-seal friction growing with case pressure [N·m].

    T_c = −sgn ω · K_c D P_c  (running);  T_break += K_c D P_c  (breakaway)

    K_c [-] has the form of K_F, applied to the case pressure P_c.  As Coulomb
    friction with no static excess of its own it adds the same amount to the
    breakaway limit.
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "case_pressure_friction"
    name = "case-pressure seal friction"
    physics = ("The shaft lip seal is pressed onto the shaft by the case pressure, so its friction torque grows "
               "with case pressure. "
               "It opposes motion like any Coulomb friction and also raises the torque needed to break away.")
    reference = ("H. K. Müller, B. S. Nau, 'Fluid Sealing Technology', Marcel Dekker, 1998 (rotary lip seals); "
                 "H. Ivantysyn, M. Ivantysynova, 'Hydrostatic Pumps and Motors', Akademia Books, 2001")
    channels = ("torque", "breakaway")
    parameters = {
        "case_pressure_friction.K_c": ParameterInfo(
            "-", "seal friction per unit D·P_c (case pressure)", True, 0.05),
    }
    signature = ("running torque and breakaway torque vs case pressure: friction opposing motion that grows "
                 "with P_c, sign follows direction; with a constant case pressure it merges into T_Fc")

    def _torque(self, params, spec, s):
        return self.param(params, "K_c") * spec.displacement * s.p_case

    def running(self, params, spec, samples, ch):
        return ch._replace(torque=ch.torque - samples.direction * self._torque(params, spec, samples))

    def static_limit(self, params, spec, events, limit):
        return limit + self._torque(params, spec, events)

    def describe(self, values, spec=None) -> str:
        k_c = self.value(values, "K_c")
        if spec is not None:
            return (f"seal friction grows by {k_c * spec.displacement * PA_PER_BAR:.3g} N·m per bar of case pressure "
                    f"(K_c = {k_c:.3g}), opposing motion and raising breakaway alike")
        return f"seal friction grows with case pressure as {k_c:.3g}·D·P_c, opposing motion and raising breakaway alike"
