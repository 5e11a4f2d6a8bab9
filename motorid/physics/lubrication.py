"""Friction laws that measured loss maps show: mixed lubrication and the ΔP·ω cross term.

Two catalog mechanisms (registered in :mod:`motorid.physics.registry`), each
adding its torque through the ``running`` hook of the one model, pure
``jax.numpy``, elementwise (jit- and vmap-safe), with finite gradients in every
parameter at every operating point, padded samples (ω = 0, ΔP = 0) included.

The torque-loss coefficient.  Loss maps are read as the loss per ideal torque,
C = T_loss / (D |ΔP| / 2π), against the Stribeck (Hersey) value
S = μ |ω| / |ΔP| [-] (Michael et al. 2012).  In the 1992 model
C(S) = 2π K_v S + 2π K_F (P_A+P_B)/|ΔP| + 2π T_Fc/(D|ΔP|): the viscous torque
K_v D μ ω *is* the hydrodynamic branch of the Stribeck curve (the Petroff law,
friction coefficient ∝ Hersey number), and K_F the boundary floor.  What the
model lacks is the mixed-film branch in between, where the films in the loaded
contacts (pistons in their bores, ball joints, the spherical valve plate) are
too thin to carry the load: :class:`MixedLubricationFriction`.  With it C(S)
falls and then rises along S — at a fixed low speed the loss coefficient falls
with pressure from the viscous branch and rises again once the contacts go
mixed — the classical Stribeck curve, now in μω/ΔP and not in speed alone.

Importing: this module subclasses the catalog's ``CatalogMechanism``; import it
through :mod:`motorid.physics.registry` (``catalog.get("mixed_lubrication")``).
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401
from motorid.physics.base import CatalogMechanism, ParameterInfo, smooth_abs
from motorid.units import PA_PER_BAR as BAR, RAD_S_PER_RPM as RPM

#: pressure scale that keeps |ΔP| and μω/|ΔP| smooth and finite at ΔP = 0 [Pa] (0.01 bar)
PRESSURE_SMOOTHING = 1e3
#: viscosity quoted in words when no spec is at hand [Pa·s] (ISO VG 46 at 40 °C)
MU_40 = 0.04


def smooth_pressure(dp, scale=PRESSURE_SMOOTHING):
    """(√(ΔP² + ε²), ΔP² / √(ΔP² + ε²)) [Pa]: the first never below ε (a safe divisor), the
    second |ΔP| made smooth — exactly 0 with slope 0 at ΔP = 0, within (ε/ΔP)²/2 of |ΔP| relative."""
    a = jnp.sqrt(dp * dp + scale * scale)
    return a, dp * dp / a


class MixedLubricationFriction(CatalogMechanism):
    """Mixed-film friction in the Stribeck (Hersey) value μ|ω|/|ΔP| [N·m].

    T_ml = −sgn ω · C_m · (D |ΔP| / 2π) · exp(−S / S_m),   S = μ |ω| / |ΔP|   (1)

    C_m [-] is the extra torque-loss coefficient of the loaded contacts in the
    boundary limit (S → 0), as a fraction of the ideal torque D|ΔP|/2π; S_m [-]
    is the Stribeck value at which the films carry the load and the excess has
    fallen by 1/e.  D [m³/rev], ΔP = P_A − P_B [Pa], μ [Pa·s], ω [rad/s].

    Equivalently the excess fades out above the speed ω_m(ΔP, μ) = S_m |ΔP| / μ:
    it lasts to higher speeds at higher load and in thinner (hotter) oil.  That is
    what tells it from :class:`~motorid.physics.friction.StribeckFriction`,
    whose Stribeck speed ω_s is one constant: on a campaign with low-speed runs at
    several pressures (ISO 4392-1 constant speed: 50, 150, 250 bar) the two
    differ by a factor 5 in the speed where the excess fades; on data at a single
    pressure and temperature (1) *is* a Stribeck curve with T_s = 0 and
    K_p = C_m/2π per unit D|ΔP|, and the two cannot be told apart — the catalog
    then names neither with confidence (see docs/mechanisms.md).  The shape
    exp(−S/S_m) is the exponential form the catalog uses for the speed-only
    Stribeck curve (Armstrong-Hélouvry et al. 1994), here on the Hersey number.
    The breakaway limit is not changed: at ω = 0 the static friction of the
    base model holds the shaft.

    Sign and smoothing: sgn ω is the run's direction (samples.direction), |ω|
    is smoothed within 0.01 rpm and |ΔP| within 0.01 bar of zero, so that the
    torque and its gradient are finite at ω = 0 and ΔP = 0 (where T_ml = 0).
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "mixed_lubrication"
    name = "mixed-lubrication friction (Stribeck curve in μω/ΔP)"
    physics = ("The pistons, ball joints and valve plate carry the pressure load on oil films whose thickness "
               "grows with viscosity × sliding speed and shrinks with load, so the friction coefficient follows "
               "the Stribeck curve in the Hersey number μ|ω|/ΔP: boundary and mixed friction at low speed and "
               "high pressure, fading once the films carry the load. "
               "Unlike a speed-only Stribeck curve the excess lasts to higher speeds at higher pressure and in "
               "hotter, thinner oil.")
    reference = ("M. D. Hersey, 'The laws of lubrication of horizontal journal bearings', J. Wash. Acad. Sci. 4, "
                 "542-552, 1914; B. J. Hamrock, S. R. Schmid, B. O. Jacobson, 'Fundamentals of Fluid Film "
                 "Lubrication', 2nd ed., Marcel Dekker, 2004 (Stribeck curve, lubrication regimes); P. W. Michael, "
                 "H. Khalid, T. Wanke, 'An investigation of external gear pump efficiency and Stribeck values', "
                 "SAE 2012-01-2041 (loss against the Stribeck value μN/ΔP); P. W. Michael, S. Mettakadapa, "
                 "S. Shahahmadi, 'An adsorption model for hydraulic motor lubrication', J. Tribol. 138(1), "
                 "014503, 2016")
    channels = ("torque",)
    parameters = {
        "mixed_lubrication.C_m": ParameterInfo(
            "-", "extra torque-loss coefficient in the boundary limit, per unit ideal torque D|ΔP|/2π", True, 0.01),
        "mixed_lubrication.S_m": ParameterInfo(
            "-", "Stribeck value μ|ω|/|ΔP| at which the mixed-film excess has fallen by 1/e", True, 3e-9),
    }
    signature = ("running torque at low speed: friction opposing motion that grows in proportion to |ΔP| and "
                 "fades out above a speed S_m|ΔP|/μ that itself grows with ΔP (5× higher at 250 than at 50 bar) "
                 "and with oil temperature; gone at rated speed; breakaway unchanged")

    def running(self, params, spec, samples, ch):
        s = samples
        c_m, s_m = self.param(params, "C_m"), self.param(params, "S_m")
        safe, dp = smooth_pressure(s.p_a - s.p_b)
        hersey = s.viscosity * smooth_abs(s.speed) / safe
        t = -s.direction * c_m * spec.displacement / (2.0 * math.pi) * dp * jnp.exp(-hersey / s_m)
        return ch._replace(torque=ch.torque + t)

    def neutral(self) -> dict:
        return {f"{self.id}.C_m": 0.0, f"{self.id}.S_m": self.parameters[f"{self.id}.S_m"].typical}

    def describe(self, values, spec=None) -> str:
        c_m, s_m = (self.value(values, k) for k in ("C_m", "S_m"))
        fades = {p: s_m * p * BAR / MU_40 / RPM for p in (50, 250)}
        words = (f"mixed-film friction of {100 * c_m:.3g} % of the ideal torque at the slowest speeds, fading "
                 f"above the Stribeck value μ|ω|/|ΔP| = {s_m:.3g} (at μ = {MU_40 * 1e3:.0f} mPa·s: above "
                 f"{fades[50]:.3g} rpm at 50 bar, {fades[250]:.3g} rpm at 250 bar)")
        if spec is not None:
            words += f"; {c_m * spec.displacement * 250 * BAR / (2 * math.pi):.3g} N·m near rest at 250 bar"
        return words


class PressureSpeedTorque(CatalogMechanism):
    """Torque loss growing with both pressure and speed: the ΔP·ω cross term [N·m].

    T_x = −C_x |ΔP| ω                                               (2)

    C_x [m³·s/rad] (N·m per Pa per rad/s); ΔP = P_A − P_B [Pa], ω [rad/s].  It
    opposes motion (odd in ω) and grows with the load |ΔP|.

    Physics: a friction force proportional to the contact load whose coefficient
    grows with sliding speed — the load-dependent moment of the shaft's rolling
    bearings (which grows with ν·n as well as with the load), the piston side
    forces ∝ ΔP sliding at a speed ∝ ω in films that thicken and shear more with
    speed.  Empirical loss models carry it as the n·Δp term of their polynomial
    torque-loss maps (Ivantysyn & Ivantysynova 2001, ch. 4; the ISO 4409 maps
    fitted by the Ivantysynova and MSOE groups, e.g. Panwar & Michael 2018).

    Told apart from the base model by the slope of torque vs ω changing with
    ΔP (the viscous K_v D μ ω has one slope at all pressures; the friction
    K_F D(P_A+P_B) does not grow with speed); from
    :class:`~motorid.physics.hydrodynamic.HydrodynamicTorque` (ω², the same at
    every pressure) by its pressure dependence.  A pressure-dependent
    viscosity in the shearing gaps (Barus, μ(p) ≈ μ(1 + αp)) would give the
    same shape times μ; on a campaign whose fast runs are all at one oil
    temperature the two are one, and this term stands for both.
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "pressure_speed_loss"
    name = "pressure × speed torque loss (ΔP·ω cross term)"
    physics = ("Contacts loaded in proportion to the pressure (pistons against their bores, the shaft bearings) "
               "also lose more torque the faster they slide, so part of the torque loss grows with the product of "
               "pressure and speed. "
               "It is the ΔP·ω cross term of the polynomial loss maps, absent from a model whose viscous loss is "
               "the same at every pressure.")
    reference = ("H. Ivantysyn, M. Ivantysynova, 'Hydrostatic Pumps and Motors', Akademia Books, 2001 (torque "
                 "losses; polynomial loss approximations in n and Δp); P. Panwar, P. W. Michael, 'Empirical modelling of "
                 "hydraulic pumps and motors based upon the Latin hypercube sampling method', Int. J. "
                 "Hydromechatronics 1(3), 2018 (torque-loss regression terms); T. A. Harris, M. N. Kotzalas, 'Rolling Bearing "
                 "Analysis', 5th ed., CRC, 2006 (load- and speed-dependent bearing friction)")
    channels = ("torque",)
    parameters = {
        "pressure_speed_loss.C_x": ParameterInfo(
            "m³·s/rad", "cross-term coefficient, T_x = −C_x |ΔP| ω", True, 3e-10),
    }
    signature = ("running torque vs speed at each pressure: a loss opposing motion, proportional to ω with a "
                 "slope proportional to |ΔP| (zero at ΔP = 0, largest at rated speed and pressure), the same in "
                 "both directions")

    def running(self, params, spec, samples, ch):
        _, dp = smooth_pressure(samples.p_a - samples.p_b)
        return ch._replace(torque=ch.torque - self.param(params, "C_x") * dp * samples.speed)

    def describe(self, values, spec=None) -> str:
        c = self.value(values, "C_x")
        at = c * 250 * BAR * 1000 * RPM
        return (f"a torque loss of {at:.3g} N·m at 250 bar and 1000 rpm, growing with ΔP × speed "
                f"(C_x = {c:.3g} N·m per Pa per rad/s; {c * BAR * RPM * 1000:.3g} N·m per bar per 1000 rpm)")
