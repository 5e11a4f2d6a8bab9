"""Viscous heating of the lubricating films: the viscous torque that grows less than ω (mechanism).

The 1992 model's viscous torque T_v = −K_v D μ ω (Eq. 24) takes the film's viscosity
as the oil's, μ(T_oil).  The films that carry it (pistons in their bores, the valve
plate, the spherical joints) are sheared at speeds of metres per second across a few
micrometres, and the work of the shear heats them: their oil is hotter, thinner, than
the oil the bench measures, and the more so the faster the unit turns and the more
viscous the oil.  The size of the effect is the Nahme–Griffith number of a Couette
film (Nahme 1940; Pinkus & Sternlicht 1961, ch. 11; Szeri 2011, §3.6),

    Na = β μ U² / k                                                         (1)

β [1/K] the oil's viscosity–temperature coefficient (μ ∝ e^{−βT}), U [m/s] the sliding
speed, k [W/(m·K)] the oil's thermal conductivity: the temperature rise that shear
dissipation drives across the film, in units of 1/β (the rise over which the viscosity
falls by 1/e).  For a film between walls held at the oil temperature, the shear stress is
μU/h·(1 − Na/12 + …) for small Na, and it saturates as Na grows (the film's middle
thins most).  Here U = r ω with one effective radius r of the sliding contacts, and the
saturation is written in its simplest rational form, exact to first order:

    T_h = + K_v D μ ω · N / (1 + N),   N = c_N μ ω²                        (2)

c_N = β r² / (12 k) [s/Pa] (≈ 1.7·10⁻⁵ s/Pa for r = 3 cm, β = 0.03 /K, k = 0.13 W/(m·K)).
T_h is the part of the isothermal viscous loss that the heated films do not cause: it
is added to the base model's T_v = −K_v D μ ω, so the viscous loss becomes
−K_v D μ ω /(1 + N), equal to the 1992 law at low speed and in thin oil, and growing
less than linearly in ω where μω² is large (fast, cold, small units: N ≈ 2 at 5600 rpm
in 25 °C VG 32 oil for r = 2 cm).

It is told apart from the hydrodynamic (churning) loss C_h ω² by its sign (it *reduces*
the loss at high speed; churning adds to it) and by its viscosity: N ∝ μ, so it is
largest in cold oil, where churning does not change.  A loss map that, fitted with the
classical laws, gives a negative ω² coefficient (Schlösser's C_h < 0) shows it.

Importing: through :mod:`motorid.physics.registry` (``catalog.get("film_heating")``).
"""

from __future__ import annotations


from motorid import _jaxconfig  # noqa: F401
from motorid.physics.base import CatalogMechanism, ParameterInfo
from motorid.units import RAD_S_PER_RPM as RPM

#: viscosity at which describe() quotes the effect when no spec is at hand [Pa·s] (ISO VG 46 at 40 °C)
MU_40 = 0.04


class FilmHeating(CatalogMechanism):
    """Shear heating of the viscous films: T_h = +K_v D μ ω · N/(1+N), N = c_N μ ω² [N·m], Eq. (2).

    c_N [s/Pa] ≥ 0 (β r²/12k of Eq. 1); K_v [-] the base model's viscous coefficient,
    D [m³/rev], μ [Pa·s] the oil's viscosity, ω [rad/s].  Zero at c_N = 0 (the 1992 law).
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "film_heating"
    name = "viscous heating of the films (viscous loss growing less than ω)"
    physics = ("The oil films of the pistons, valve plate and joints are sheared fast across a few micrometres "
               "and the shear work heats them, so the oil in them is thinner than the oil the bench measures: "
               "the viscous torque grows less than in proportion to speed. "
               "The effect scales with the Nahme-Griffith number β μ U²/k, largest at high speed in cold, "
               "viscous oil, and it lowers the loss where churning would raise it.")
    reference = ("H. Nahme, 'Beiträge zur hydrodynamischen Theorie der Lagerreibung', Ingenieur-Archiv 11, "
                 "191-209, 1940; O. Pinkus, B. Sternlicht, 'Theory of Hydrodynamic Lubrication', McGraw-Hill, "
                 "1961, ch. 11 (thermal effects); A. Z. Szeri, 'Fluid Film Lubrication', 2nd ed., Cambridge "
                 "University Press, 2011, §3.6 (Couette flow with viscous heating, Nahme-Griffith number); "
                 "M. Ivantysynova, 'Prediction of pump and motor performance by computer simulation', "
                 "Proc. 1st FPNI PhD Symposium, 2000 (thermal effects in the lubricating gaps of piston units)")
    channels = ("torque",)
    parameters = {
        "film_heating.c_N": ParameterInfo(
            "s/Pa", "film heating coefficient: N = c_N μ ω² (β r²/12k), the viscous loss is K_v D μ ω/(1+N)",
            True, 2e-5),
    }
    signature = ("running torque vs speed: the viscous loss bends over at high speed (less than linear in ω), "
                 "more so in cold, viscous oil; the same at every pressure; the opposite sign of churning")

    def running(self, params, spec, samples, ch):
        s = samples
        n = self.param(params, "c_N") * s.viscosity * s.speed * s.speed
        t = params["Kv"] * spec.displacement * s.viscosity * s.speed * n / (1.0 + n)
        return ch._replace(torque=ch.torque + t)

    def describe(self, values, spec=None) -> str:
        c = self.value(values, "c_N")
        at = {rpm: c * MU_40 * (rpm * RPM) ** 2 for rpm in (1000, 3000)}
        return (f"the viscous films heat as they shear: at μ = {MU_40 * 1e3:.0f} mPa·s the viscous loss is "
                f"{100 / (1 + at[1000]):.3g} % of the isothermal K_v D μ ω at 1000 rpm and "
                f"{100 / (1 + at[3000]):.3g} % at 3000 rpm (c_N = {c:.3g} s/Pa; N = c_N μ ω²)")

