"""Schlösser's model: Wilson's terms plus hydrodynamic (ω²) torque and turbulent slip.

W. M. J. Schlösser, "Mathematical model for displacement pumps and motors",
Hydraulic Power Transmission, April 1961, 252-257 and 324-328, in the form
later compilations carry (coefficients C_v, C_f, C_h, C_s, C_st; the same
form sits, e.g., in the loss model of a 107 cm³/rev axial-piston unit used in
wave-energy PTO studies).  With d = D/2π [m³/rad]:

    T_loss = C_v d μ |ω| + C_f d |ΔP| + C_h ρ d^{5/3} ω² / 2
    Q_loss = C_s d |ΔP| / μ + C_st d^{2/3} √(2|ΔP|/ρ)

(laminar and turbulent slip; the hydrodynamic term is the churning of the oil).
"""

from __future__ import annotations

import numpy as np

from motorid.comparators.base import LossModel


class Schloesser(LossModel):
    name = "Schlösser (1961)"
    reference = ("W. M. J. Schlösser, Mathematical model for displacement pumps and motors, Hydraulic Power "
                 "Transmission, April 1961, 252-257, 324-328")
    equations = ("T_loss = C_v d μ|ω| + C_f d|ΔP| + C_h ρ d^(5/3) ω²/2;  "
                 "Q_loss = C_s d|ΔP|/μ + C_st d^(2/3) √(2|ΔP|/ρ)")

    def torque_terms(self, op, h):
        return np.column_stack([op.d * op.mu * op.W, op.d * op.P, op.rho * op.d ** (5 / 3) * op.W**2 / 2])

    def flow_terms(self, op, h):
        return np.column_stack([op.d * op.P / op.mu, op.d ** (2 / 3) * np.sqrt(2 * op.P / op.rho)])
