"""Wilson's model: laminar slip and viscous + Coulomb (∝ ΔP) torque loss.

W. E. Wilson, "Performance criteria for positive-displacement pumps and fluid
motors", Trans. ASME 71 (1949) 115-120; and *Positive-Displacement Pumps and
Fluid Motors*, Pitman, 1950.  With d = D/2π [m³/rad] (see :mod:`.base` for the
four-quadrant form):

    T_loss = C_v d μ |ω| + C_f d |ΔP|          (viscous, Coulomb ∝ ΔP)
    Q_loss = C_s d |ΔP| / μ                     (laminar slip)

C_v, C_f, C_s dimensionless.
"""

from __future__ import annotations

import numpy as np

from motorid.comparators.base import LossModel


class Wilson(LossModel):
    name = "Wilson (1950)"
    reference = ("W. E. Wilson, Performance criteria for positive-displacement pumps and fluid motors, "
                 "Trans. ASME 71 (1949); Positive-Displacement Pumps and Fluid Motors, Pitman, 1950")
    equations = "T_loss = C_v d μ|ω| + C_f d|ΔP|;  Q_loss = C_s d|ΔP|/μ"

    def torque_terms(self, op, h):
        return np.column_stack([op.d * op.mu * op.W, op.d * op.P])

    def flow_terms(self, op, h):
        return np.column_stack([op.d * op.P / op.mu])
