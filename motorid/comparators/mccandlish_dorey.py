"""McCandlish and Dorey's model: a constant torque loss and a √ΔP-type flow term added.

D. McCandlish and R. E. Dorey, "The mathematical modelling of hydrostatic pumps
and motors", Proc. IMechE Part B 198 (1984) 165-174.  Their torque loss adds a
constant (pressure- and speed-independent) friction torque to the viscous and
pressure-proportional terms; their flow loss adds to the laminar slip a term
∝ √ΔP (leakage through short, non-laminar paths) and a constant.  With
d = D/2π [m³/rad]:

    T_loss = C_v d μ |ω| + C_f d |ΔP| + T_c + C_h ρ d^{5/3} ω² / 2
    Q_loss = C_s d |ΔP| / μ + C_st d^{2/3} √(2|ΔP|/ρ) + Q_c

T_c [N·m], Q_c [m³/s], the rest dimensionless.
"""

from __future__ import annotations

import numpy as np

from motorid.comparators.base import LossModel


class McCandlishDorey(LossModel):
    name = "McCandlish–Dorey (1984)"
    reference = ("D. McCandlish, R. E. Dorey, The mathematical modelling of hydrostatic pumps and motors, "
                 "Proc. IMechE B 198 (1984) 165-174")
    equations = ("T_loss = C_v d μ|ω| + C_f d|ΔP| + T_c + C_h ρ d^(5/3) ω²/2;  "
                 "Q_loss = C_s d|ΔP|/μ + C_st d^(2/3) √(2|ΔP|/ρ) + Q_c")

    def torque_terms(self, op, h):
        return np.column_stack([op.d * op.mu * op.W, op.d * op.P, np.ones(len(op)),
                                op.rho * op.d ** (5 / 3) * op.W**2 / 2])

    def flow_terms(self, op, h):
        return np.column_stack([op.d * op.P / op.mu, op.d ** (2 / 3) * np.sqrt(2 * op.P / op.rho),
                                np.ones(len(op))])
