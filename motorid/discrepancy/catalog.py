"""The catalog of candidate extra physics: named mechanisms the 1992 model leaves out.

Each mechanism is a :class:`motorid.discrepancy.base.Mechanism` that adds its
terms to the one model's channels through hooks (``running``, ``static_limit``,
``breakaway_reading``); none copies the model.  Its parameters live in the
model's parameter dict as ``"<id>.<name>"`` (SI), and their ``typical`` sizes
(starting values and prior scales of fits) are chosen for an 80 cm³/rev motor
running up to about 3000 rpm and 250 bar, where each mechanism is noticeable
but modest: about 1-3 % of the channel it acts on.

Every mechanism here carries, beyond the base interface:

- ``signature``: where its residual shows in the bench data, in words;
- ``neutral()``: parameter values at which it adds exactly nothing;
- ``describe(values, spec=None)``: one sentence with fitted numbers in
  engineering units (``values`` keyed ``"<id>.<name>"`` or ``"<name>"``).

The hooks are pure ``jax.numpy``, elementwise over the samples (so they are
jit- and vmap-safe), differentiable in every parameter with finite gradients
at every operating point, padded samples (zero speed and pressure) included.

Mechanisms are singletons (:data:`CATALOG`): the compiled kernels of the bench
simulator and of the fits are cached by mechanism, and unpickling one gives
back the same object.
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401
from motorid.discrepancy.base import Mechanism
from motorid.errors import InputError
from motorid.model import Channels, ParameterInfo, Samples, leakage_harmonics
from motorid.physics import flow

RPM = 2.0 * math.pi / 60.0  # [rad/s] per rpm
BAR = 1e5  # [Pa] per bar
LPM = 1e-3 / 60.0  # [m³/s] per L/min

#: pressure over which the orifice law √ΔP is smoothed near ΔP = 0 [Pa] (0.1 bar)
ORIFICE_SMOOTHING = 1e4
#: speed over which |ω| is smoothed near ω = 0 [rad/s] (0.01 rpm, far below any test speed)
SPEED_SMOOTHING = 1e-3
#: bulk modulus used only to quote a compression flow as a dead volume [Pa]
BULK_MODULUS = 1.6e9


def smooth_sqrt(x, scale=ORIFICE_SMOOTHING):
    """Signed square root sgn(x)·√|x| made smooth at 0: x / (x² + ε²)^¼ [√(unit of x)].

    Equal to sgn(x)√|x| within 0.01 % for |x| > 100 ε; slope 1/√ε at x = 0.
    """
    return x / (x * x + scale * scale) ** 0.25


def smooth_abs(x, scale=SPEED_SMOOTHING):
    """|x| made smooth at 0: x² / √(x² + ε²) [unit of x].

    Exactly 0 at x = 0, slope 0 there; within (ε/x)²/2 of |x| relative.
    """
    return x * x / jnp.sqrt(x * x + scale * scale)


def _relative_expm1(y):
    """f(y) = (1 − e^(−y))/y, with f(0) = 1, finite with finite gradient everywhere [-]."""
    small = jnp.abs(y) < 1e-4
    y_safe = jnp.where(small, 1.0, y)
    series = 1.0 - y / 2.0 + y * y / 6.0 - y * y * y / 24.0
    return jnp.where(small, series, -jnp.expm1(-y_safe) / y_safe)


class CatalogMechanism(Mechanism):
    """A catalog entry: a :class:`Mechanism` with a residual signature and words for its fit."""

    signature: str = ""  # where its residual shows in the bench data

    def neutral(self) -> dict:
        """Parameter values at which this mechanism adds exactly nothing."""
        return {k: 0.0 for k in self.parameters}

    def value(self, values: dict, name: str) -> float:
        """Parameter ``name`` from ``values`` keyed ``"<id>.<name>"`` or ``"<name>"``."""
        full = f"{self.id}.{name}"
        return float(values[full] if full in values else values[name])

    def describe(self, values: dict, spec=None) -> str:
        """One sentence on the fitted mechanism, numbers in engineering units."""
        raise NotImplementedError

    def param(self, params: dict, name: str):
        """This mechanism's parameter ``name`` from a model parameter dict."""
        return params[f"{self.id}.{name}"]

    def __reduce__(self):  # unpickle to the catalog's singleton
        return (get, (self.id,))


# ---------------------------------------------------------------------------
# friction


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
        where = f"below about {w_s / RPM:.3g} rpm (ω_s = {w_s:.3g} rad/s)"
        if spec is not None:
            at = t_s + k_p * spec.displacement * 250.0 * BAR
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
            return (f"seal friction grows by {k_c * spec.displacement * BAR:.3g} N·m per bar of case pressure "
                    f"(K_c = {k_c:.3g}), opposing motion and raising breakaway alike")
        return f"seal friction grows with case pressure as {k_c:.3g}·D·P_c, opposing motion and raising breakaway alike"


# ---------------------------------------------------------------------------
# torque losses and torque shape


class HydrodynamicTorque(CatalogMechanism):
    """Churning / windage loss growing with speed squared [N·m].

    T_h = −C_h ω |ω|,  C_h [N·m·s²], independent of viscosity.
    """

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
        return (f"a churning loss of {c * (1000 * RPM) ** 2:.3g} N·m at 1000 rpm and "
                f"{c * (3000 * RPM) ** 2:.3g} N·m at 3000 rpm (∝ ω², C_h = {c:.3g} N·m·s²), "
                "independent of viscosity")


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

    def describe(self, values, spec=None) -> str:
        a1, b1, a2, b2 = (self.value(values, k) for k in ("A1", "B1", "A2", "B2"))
        parts = []
        for order, a, b in ((1, a1, b1), (2, a2, b2)):
            amp = math.hypot(a, b)
            peak = (math.degrees(math.atan2(b, a)) / order) % (360.0 / order)
            parts.append(f"{amp:.3g} N·m at {order}× shaft order (peak at θ = {peak:.0f}°)")
        return f"torque ripple of {parts[0]} and {parts[1]}"


class TorqueOffset(CatalogMechanism):
    """Torque transducer zero offset [N·m]: +T0 on every torque reading.

    Added to the running torque and to the held torque read at breakaway; its
    sign does not follow the direction of rotation.
    """

    id = "torque_offset"
    name = "torque transducer zero offset"
    physics = ("The torque transducer reads a constant offset on top of the true shaft torque, from an "
               "imperfect zero or a drifting strain-gauge bridge. "
               "Unlike friction, which opposes motion, the offset has the same sign in both directions of "
               "rotation, in the held torque at breakaway too.")
    reference = ("ISO 4392-1:2002 and ISO 9110-1 (measurement accuracy of hydraulic test benches); "
                 "E. O. Doebelin, 'Measurement Systems: Application and Design', 5th ed., McGraw-Hill, 2004 "
                 "(zero offset and drift)")
    channels = ("torque", "breakaway")
    parameters = {
        "torque_offset.T0": ParameterInfo("N·m", "torque reading offset, same in both directions", False, 2.0),
    }
    signature = ("running torque in both directions and the breakaway held torque: a constant shift of the same "
                 "sign whatever the speed, pressure and direction (friction would change sign with direction)")

    def running(self, params, spec, samples, ch):
        return ch._replace(torque=ch.torque + self.param(params, "T0"))

    def breakaway_reading(self, params, spec, events, held):
        return held + self.param(params, "T0")

    def describe(self, values, spec=None) -> str:
        t0 = self.value(values, "T0")
        word = "high" if t0 >= 0 else "low"
        return (f"the torque transducer reads {abs(t0):.3g} N·m {word} in both directions of rotation "
                "and at breakaway (zero offset)")


# ---------------------------------------------------------------------------
# flows


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
        return (f"orifice-type leakage of {c * math.sqrt(250 * BAR) / LPM:.3g} L/min per port at 250 bar above "
                f"case pressure (∝ √ΔP, like a {area * 1e6:.3g} mm² orifice), independent of viscosity")


class CompressibilityFlow(CatalogMechanism):
    """Compression flow of the chamber dead volumes [m³/s].

    Q_AN += C_c (P_A − P_B) |ω|,  Q_BN −= the same, case drain unchanged.
    C_c = n V_0 / (2π β) [m³/(Pa·rad)] for n chambers of dead volume V_0 and oil
    bulk modulus β; |ω| is smoothed within 0.01 rpm of zero (:func:`smooth_abs`).
    """

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
        q = c * 250 * BAR * 1000 * RPM
        volume = 2.0 * math.pi * BULK_MODULUS * c
        return (f"a compression flow loss of {q / LPM:.3g} L/min from the high- to the low-pressure port at "
                f"250 bar and 1000 rpm (∝ ΔP·|ω|; {volume * 1e6:.3g} cm³ of dead volume over all chambers at "
                f"β = {BULK_MODULUS / 1e9:.2g} GPa), absent from the case drain")


class PressureViscosity(CatalogMechanism):
    """Pressure-dependent viscosity (Barus) in the laminar leakage gaps [m³/s].

    With μ(p) = μ e^(α p) along a gap from P_up to P_down, the laminar law
    K (P_up − P_down)/μ becomes K (e^(−α P_down) − e^(−α P_up)) / (α μ)
    = K (P_up − P_down)/μ · e^(−α P_down) f(α (P_up − P_down)), f(y) = (1 − e^(−y))/y.
    Applied to both port-to-case leakages (K_LA(θ), K_LB(θ)) and to the
    cross-port leakage K_AB; the hook adds the difference to the base flows, so
    the mass balance holds.  α [1/Pa] ≈ 1.5-2.5e-8 for bulk mineral oil; the
    typical size, 1e-8, allows for the hotter oil in the gaps (about 10 % less
    port-to-case leakage at 250 bar).
    """

    id = "pressure_viscosity"
    name = "pressure-viscosity (Barus) effect on leakage"
    physics = ("Oil viscosity rises exponentially with pressure (the Barus law), so the oil in a leakage gap is "
               "thicker toward its high-pressure end. "
               "Laminar leakage then grows less than in proportion to the pressure drop at high pressure, while "
               "keeping the 1/μ temperature dependence of the laminar law.")
    reference = ("C. Barus, 'Isothermals, isopiestics and isometrics relative to viscosity', Am. J. Sci. 45, "
                 "87-96, 1893; H. Ivantysyn, M. Ivantysynova, 'Hydrostatic Pumps and Motors', Akademia Books, "
                 "2001 (gap flow with pressure-dependent viscosity)")
    channels = ("q_a", "q_b", "q_case")
    parameters = {
        "pressure_viscosity.alpha": ParameterInfo(
            "1/Pa", "pressure-viscosity coefficient α of μ(p) = μ e^(α p) in the gaps", True, 1e-8),
    }
    signature = ("case-drain and port flows vs port pressure: laminar leakage bends below proportional at high "
                 "pressure (by about αP/2), while still scaling as 1/μ across oil temperatures")

    def _change(self, alpha, q, p_up, p_down):
        """Barus flow minus laminar flow q of one gap [m³/s]."""
        factor = jnp.exp(-alpha * p_down) * _relative_expm1(alpha * (p_up - p_down))
        return q * (factor - 1.0)

    def running(self, params, spec, samples, ch):
        s = samples
        alpha = self.param(params, "alpha")
        m = sum(1 for k in params if k.startswith("KL_a"))
        a, b = leakage_harmonics(params, m)
        k_la = flow.leakage_coefficient(s.theta, params["KL0"], a, b, spec.pistons)
        k_lb = flow.leakage_coefficient(s.theta - spec.phase, params["KL0"], a, b, spec.pistons)
        q_la = flow.port_to_case_leakage(k_la, s.p_a, s.p_case, s.viscosity)
        q_lb = flow.port_to_case_leakage(k_lb, s.p_b, s.p_case, s.viscosity)
        q_ab = flow.cross_port_leakage(params["KAB"], s.p_a, s.p_b, s.viscosity)
        d_la = self._change(alpha, q_la, s.p_a, s.p_case)
        d_lb = self._change(alpha, q_lb, s.p_b, s.p_case)
        d_ab = self._change(alpha, q_ab, s.p_a, s.p_b)
        return ch._replace(q_a=ch.q_a + d_la + d_ab, q_b=ch.q_b + d_lb - d_ab, q_case=ch.q_case + d_la + d_lb)

    def describe(self, values, spec=None) -> str:
        alpha = self.value(values, "alpha")
        ratio = 1.0 - float(_relative_expm1(alpha * 250 * BAR))
        return (f"leakage viscosity rises with pressure (α = {alpha * 1e9:.3g} /GPa, ×{math.exp(alpha * 250 * BAR):.3g} "
                f"at 250 bar), cutting port-to-case leakage at 250 bar by {100 * ratio:.3g} % below the laminar law")


# ---------------------------------------------------------------------------
# the catalog

# physics that measured loss maps show (issue 20); imported here, after CatalogMechanism exists
from motorid.physics.lubrication import MixedLubricationFriction, PressureSpeedTorque  # noqa: E402
from motorid.physics.mode import PumpModeFriction  # noqa: E402
from motorid.physics.volumetric import FillingLoss  # noqa: E402

_ALL = (
    StribeckFriction(),
    HydrodynamicTorque(),
    TurbulentLeakage(),
    CompressibilityFlow(),
    MisalignmentRipple(),
    TorqueOffset(),
    CasePressureFriction(),
    PressureViscosity(),
    MixedLubricationFriction(),
    PressureSpeedTorque(),
    FillingLoss(),
    PumpModeFriction(),
)

#: every mechanism by id (singletons)
CATALOG: dict[str, CatalogMechanism] = {m.id: m for m in _ALL}


def get(mech_id: str) -> CatalogMechanism:
    """The catalog's mechanism ``mech_id``; :class:`InputError` naming the known ones otherwise."""
    try:
        return CATALOG[mech_id]
    except (KeyError, TypeError):
        raise InputError(f"unknown mechanism '{mech_id}'; known: {', '.join(CATALOG)}") from None


def all_mechanisms() -> list[CatalogMechanism]:
    """Every mechanism of the catalog, in catalog order."""
    return list(CATALOG.values())
