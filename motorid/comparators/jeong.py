"""Jeong's model: torque loss with a ΔP·ω term and speed-dependent friction.

H.-S. Jeong, "A novel performance model given by the physical dimensions of
hydraulic axial piston motors: model derivation", J. Mech. Sci. Technol. 21
(2007) 83-97 (and its experimental companion, 630-641).  The torque loss has
the viscous and pressure terms, a term in ΔP·ω (friction of the pressure-loaded
sliding parts growing with speed) and a friction that depends on speed (high
near rest, falling to a constant: written here as T_c0 + T_c1 e^{−|ω|/ω_s},
ω_s chosen on a grid by least squares, the rest linear).  With d = D/2π:

    T_loss = C_v d μ |ω| + C_f d |ΔP| + C_pω d |ΔP| |ω| / ω_r + T_c0 + T_c1 e^{−|ω|/ω_s}
    Q_loss = C_s d |ΔP| / μ + C_st d^{2/3} √(2|ΔP|/ρ)

ω_r = 100 rad/s (a scale only).  The exact grouping of Jeong's coefficients by
the motor's dimensions is not reproduced: his terms are, here each with one free
coefficient, which is what a fit to a map can determine.
"""

from __future__ import annotations

import numpy as np

from motorid.comparators.base import LossModel

OMEGA_REF = 100.0  # [rad/s]
#: a speed scale ω_s is tried only where e^{−|ω|/ω_s} reaches this at some fitted point
USABLE = 1e-2


class Jeong(LossModel):
    name = "Jeong (2007)"
    reference = ("H.-S. Jeong, A novel performance model given by the physical dimensions of hydraulic axial "
                 "piston motors: model derivation, J. Mech. Sci. Technol. 21 (2007) 83-97")
    equations = ("T_loss = C_v d μ|ω| + C_f d|ΔP| + C_pω d|ΔP||ω|/ω_r + T_c0 + T_c1 exp(−|ω|/ω_s);  "
                 "Q_loss = C_s d|ΔP|/μ + C_st d^(2/3) √(2|ΔP|/ρ)")
    shapes = tuple(np.geomspace(0.3, 300.0, 13))  # candidate ω_s [rad/s]

    def torque_terms(self, op, h):
        return np.column_stack([op.d * op.mu * op.W, op.d * op.P, op.d * op.P * op.W / OMEGA_REF,
                                np.ones(len(op)), np.exp(-op.W / h)])

    def usable(self, kind, op, h, ok) -> bool:
        # e^{−|ω|/ω_s} below 1 % at every fitted point: the term is barely seen there (its coefficient
        # would be any large number, and 10²⁰ N·m at a slower point held out)
        return kind != "torque" or float(np.max(np.exp(-op.W[ok] / h), initial=0.0)) >= USABLE

    def flow_terms(self, op, h):
        return np.column_stack([op.d * op.P / op.mu, op.d ** (2 / 3) * np.sqrt(2 * op.P / op.rho)])
