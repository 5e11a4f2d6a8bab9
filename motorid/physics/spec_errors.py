"""Spec errors: the motor data the model is given are not the motor's.

Three mechanisms of the physics registry (issue 15), each an extension of the
one model through its hooks (:mod:`motorid.physics.base`):

- ``displacement_error``: the true displacement is D' = D·(1 + ε), D the spec's.
  The pressure torque T_p = D ΔP S(θ)/2n (Bartos 1992 Eq. 7) and the swept flow
  Q_A = D ω S(θ)/2n (Eq. 36) carry no fitted parameter, so a wrong D shows
  there and only there: the torque gains ε·T_p (in the running torque and the
  held torque at breakaway), port A gains ε·Q_A and port B loses as much, the
  case drain nothing.  The other D-proportional terms (K_v D μ ω, K_F D(P_A+P_B),
  K_FS) are absorbed by their coefficients, which are then relative to the
  spec's D: divide them by 1 + ε for coefficients relative to the true D.
- ``leak_phase``: the phase φ of K_LB(θ) = K_LA(θ − φ) (Eq. 55) is φ_spec + δφ,
  φ_spec = π/n unless the spec sets it.  It moves the shaft-angle pattern of the
  port-B-to-case leakage, so it shows in the case drain and port B flow
  against shaft angle in the runs where port B holds the high pressure.
- ``inertia_error``: the rotor inertia is J' = J + ΔJ, J the spec's.  The
  inertia torque T_J = −J α (Eq. 17) carries no fitted parameter, so a wrong J
  puts −ΔJ·α into the running torque and nowhere else.  In steady runs α is the
  speed ripple locked to the shaft (and a slow drift): the error shows as a
  torque ripple at the orders of the speed ripple, a quarter period from it,
  growing with speed.  Where the runs hold no acceleration the logs cannot
  give J, and the fit's evidence for ΔJ stays below any threshold.

Why the displacement error is not a torque gain (:mod:`motorid.physics.sensors`):
in the torque the two are the same up to a rescaling of K_v, K_F, T_Fc, K_FS
and K_s (both scale T_p, the friction rescales into its coefficients); the port
flows tell them apart, as a displacement error puts ε·D ω/2π into port A and
takes it from port B (opposite signs, ∝ ω, nothing in the case drain), and a
torque gain puts nothing into any flow.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from motorid import _jaxconfig  # noqa: F401
from motorid.physics import flow, torque
from motorid.physics.base import CatalogMechanism, ParameterInfo
from motorid.physics.flow import leakage_harmonics



class DisplacementError(CatalogMechanism):
    """The motor's true displacement D' = D_spec·(1 + ε) [-].

    ΔT = ε·T_p = ε·D ΔP S(θ)/2n (running and held torque);
    ΔQ_AN = ε·D ω S(θ)/2n, ΔQ_BN = −ΔQ_AN, ΔQ_CN = 0 (Bartos 1992 Eq. 7, 36-37).
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    single_start = True  # linear in ε: one start of the fit is enough
    id = "displacement_error"
    name = "displacement differs from the spec"
    physics = ("The motor's true displacement per revolution differs from the catalogue value in the motor spec "
               "(tolerances of the swash angle and piston bores, a wrong data sheet, another size variant). "
               "Torque per unit pressure and swept flow per unit speed then both differ by the same fraction, "
               "so the flows into port A and out of port B grow with speed by equal and opposite amounts while "
               "the case drain is untouched.")
    reference = ("R. D. Bartos, 'Mathematical Modeling of Bent-Axis Hydraulic Piston Motors', JPL TDA Progress "
                 "Report 42-111, 1992 (Eq. 6-7, 36-37); ISO 8426:2008, Hydraulic fluid power - Positive "
                 "displacement pumps and motors - Determination of derived capacity")
    channels = ("torque", "q_a", "q_b", "breakaway")
    parameters = {
        "displacement_error.eps": ParameterInfo(
            "-", "relative displacement error: true D = spec D·(1 + ε)", False, 0.01),
    }
    signature = ("port flows vs speed: flow into port A off by ε·Dω/2π and out of port B by the same amount with "
                 "the opposite sign, nothing in the case drain (a flow-meter gain would touch one meter only and "
                 "break the mass balance); running and held torque off by ε·DΔP/2π, which in the torque alone "
                 "looks like a change of K_F and T_Fc")

    def seen_by(self, dataset) -> bool:
        """Tried only where the flow meters keep their zeros (:func:`~motorid.physics.mass_balance.flow_zeros_wander`).

        ε shows in the port flows' run means (∝ ω); where the meters' zeros change from run to run the
        fit, which weighs a run mean by its within-run noise alone, cannot tell a small ε from the zeros
        (on ``causes_per_run_offsets`` it took ε = −0.1 % with Δχ² 4449 in the fit but 276 on held-out
        runs): the structure is then reported unexplained, with the mass balance's numbers.
        """
        from motorid.physics.mass_balance import flow_zeros_wander

        return not flow_zeros_wander(dataset)

    def _swept(self, spec, s):
        return flow.swept_flow_a(s.theta, s.speed, spec.displacement, spec.pistons, port_sum=s.port_sum)

    def _pressure_torque(self, spec, s):
        return torque.pressure_torque(s.theta, s.p_a, s.p_b, spec.displacement, spec.pistons, port_sum=s.port_sum)

    def running(self, params, spec, samples, ch):
        eps = self.param(params, "eps")
        q = eps * self._swept(spec, samples)
        return ch._replace(torque=ch.torque + eps * self._pressure_torque(spec, samples),
                           q_a=ch.q_a + q, q_b=ch.q_b - q)

    def breakaway_reading(self, params, spec, events, held):
        return held + self.param(params, "eps") * self._pressure_torque(spec, events)

    def describe(self, values, spec=None) -> str:
        eps = self.value(values, "eps")
        if spec is not None:
            d = spec.displacement * 1e6
            return (f"the measured displacement is {d * (1 + eps):.4g} cm³/rev, {100 * eps:+.3g} % from the spec's "
                    f"{d:.4g} cm³/rev (K_v, K_F, K_FS are relative to the spec's D)")
        return f"the true displacement is {100 * eps:+.3g} % from the spec's (D' = D·(1 {'+' if eps >= 0 else '−'} {abs(eps):.3g}))"

    def describe_per_point(self, values, displacement) -> str:
        """The words where a table gives each point's displacement (a variable unit): ε is relative to that
        column, at every setting alike; ``displacement`` [m³/rev] the table's values."""
        eps = self.value(values, "eps")
        d = np.asarray(displacement, float) * 1e6
        lo, hi = float(np.nanmin(d)), float(np.nanmax(d))
        return (f"the displacement is {100 * eps:+.3g} % from the table's displacement column, at every setting "
                f"alike (cm³/rev: {lo:.4g} → {lo * (1 + eps):.4g} at the smallest, {hi:.4g} → {hi * (1 + eps):.4g} "
                f"at the largest)")


class LeakPhase(CatalogMechanism):
    """Leakage phase φ of K_LB(θ) = K_LA(θ − φ) off the spec's by δφ [rad].

    ΔQ_BN = ΔQ_CN = [K_L(θ − φ − δφ) − K_L(θ − φ)] (P_B − P_c)/μ (Eq. 53-55).
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "leak_phase"
    name = "leakage phase differs from the spec"
    physics = ("The port-to-case leakage repeats every piston pitch, and port B's pattern is port A's shifted by a "
               "phase φ set by the valve-plate geometry, taken as half a pitch (π/n) unless the spec says "
               "otherwise. "
               "A valve plate with other timing shifts port B's leakage pattern against the shaft angle.")
    reference = ("R. D. Bartos, JPL TDA Progress Report 42-111, 1992 (Eq. 52-55); R. E. Johnson, 'Leakage in "
                 "hydraulic motors as a function of shaft angle', 1980 (the seed's reference on K_L(θ))")
    channels = ("q_b", "q_case")
    shows_in = ("q_a", "q_b", "q_case")  # the shared K_L harmonics compromise between the ports
    parameters = {
        "leak_phase.dphi": ParameterInfo("rad", "leak phase φ minus the spec's (π/n by default)", False, 0.1),
    }
    signature = ("case-drain and port B flow vs shaft angle at the piston order, in the runs where port B holds "
                 "the high pressure: the pattern is shifted against the one the spec's phase predicts; nothing "
                 "where port A is the high-pressure port")

    def running(self, params, spec, samples, ch):
        s = samples
        m = sum(1 for k in params if k.startswith("KL_a"))
        a, b = leakage_harmonics(params, m)
        dphi = self.param(params, "dphi")
        k_old = flow.leakage_coefficient(s.theta - spec.phase, params["KL0"], a, b, spec.pistons)
        k_new = flow.leakage_coefficient(s.theta - spec.phase - dphi, params["KL0"], a, b, spec.pistons)
        dq = flow.port_to_case_leakage(k_new - k_old, s.p_b, s.p_case, s.viscosity)
        return ch._replace(q_b=ch.q_b + dq, q_case=ch.q_case + dq)

    def describe(self, values, spec=None) -> str:
        d = self.value(values, "dphi")
        if spec is not None:
            return (f"port B's leakage pattern lies at φ = {math.degrees(spec.phase + d):.3g}° "
                    f"(spec: {math.degrees(spec.phase):.3g}°, {math.degrees(d):+.3g}°)")
        return f"port B's leakage pattern is shifted by {math.degrees(d):+.3g}° of shaft angle from the spec's phase"


class InertiaError(CatalogMechanism):
    """The rotor's true inertia J' = J_spec + ΔJ [kg·m²].

    ΔT = −ΔJ·α in the running torque (Bartos 1992 Eq. 17); the held torque at
    breakaway (α = 0 at the instant the shaft moves) is untouched.
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    single_start = True  # linear in ΔJ: one start of the fit is enough
    id = "inertia_error"
    name = "rotor inertia differs from the spec"
    physics = ("The rotating group's moment of inertia differs from the value in the motor spec (a data-sheet "
               "value for another variant, a coupling or a torque-flange hub counted or not counted). "
               "The torque that accelerates the rotor, J·α, is then wrong by ΔJ·α: in steady runs it shows where "
               "the shaft speed ripples, as a torque ripple a quarter period from the speed ripple, growing "
               "with speed.")
    reference = ("R. D. Bartos, JPL TDA Progress Report 42-111, 1992 (Eq. 17, T_J = −J α); ISO 4392-1:2002, "
                 "Hydraulic fluid power - Determination of characteristics of motors - Part 1: At constant low "
                 "speed and constant pressure")
    channels = ("torque",)
    parameters = {
        "inertia_error.dJ": ParameterInfo("kg·m²", "rotor inertia minus the spec's: true J = spec J + ΔJ",
                                          False, 0.002),
    }
    signature = ("running torque against the shaft acceleration: a torque ripple at the orders of the speed "
                 "ripple, in quadrature with the speed and in phase with −α, its size ∝ the acceleration (∝ ω² "
                 "for a ripple locked to the shaft); nothing in the flows or at breakaway")

    def running(self, params, spec, samples, ch):
        return ch._replace(torque=ch.torque + torque.inertia_torque(self.param(params, "dJ"), samples.acceleration))

    def unseen_in_table(self, table) -> str | None:
        return ("a table's points are steady means: the acceleration that shows a rotor inertia averages to "
                "nothing there")

    def fold_into_spec(self, params: dict, spec):
        """The spec with the measured inertia J + ΔJ: what an export writes for the load model (the
        exported torque leaves J·α to the load, so ΔJ belongs with J, not in the torque)."""
        import dataclasses

        from motorid.errors import InputError

        j = float(spec.inertia) + float(params[f"{self.id}.dJ"])
        if not j > 0:
            raise InputError(f"inertia_error: the measured rotor inertia J = {j:.4g} kg·m² (spec "
                             f"{float(spec.inertia):.4g} + ΔJ) is not positive; export with --no-diagnosis, or "
                             f"check the spec's inertia_kg_m2")
        return dataclasses.replace(spec, inertia=j)

    def describe(self, values, spec=None) -> str:
        dj = self.value(values, "dJ")
        if spec is not None and getattr(spec, "inertia", 0.0):
            j = float(spec.inertia)
            return (f"the logs give a rotor inertia of {j + dj:.4g} kg·m², {100 * dj / j:+.3g} % from the "
                    f"spec's {j:.4g} kg·m²")
        if spec is not None:
            return f"the logs give a rotor inertia of {dj:.4g} kg·m² (the spec gives none)"
        return f"the rotor inertia is {dj:+.4g} kg·m² from the spec's"


MECHANISMS = (DisplacementError(), LeakPhase(), InertiaError())
