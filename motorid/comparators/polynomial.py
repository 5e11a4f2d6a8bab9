"""Polynomial loss maps: torque and flow losses as 2-D polynomials in ΔP and ω.

As the Maha Fluid Power Research Center (M. Ivantysynova's group, whose
displacement-controlled circuit studies carry measured or simulated loss maps
of axial-piston units as polynomials in ΔP, speed and displacement) and the MSOE
Fluid Power Institute (P. Panwar, P. Michael, "Empirical modelling of hydraulic
pumps and motors based upon the Latin hypercube sampling method", Int. J.
Hydromechatronics 1 (2018) 272-292) describe measured units: each loss a
polynomial

    L(ΔP, ω) = Σ_{i+j ≤ k} c_ij (|ΔP|/ΔP_r)^i (|ω|/ω_r)^j

with separate coefficients in motor and in pump mode where both are measured
(so that the map may differ between the modes), the degree k chosen by 5-fold
cross-validation on the training points (1 … 4).  ΔP_r, ω_r: the largest
|ΔP|, |ω| of the training points (conditioning only).
"""

from __future__ import annotations

import numpy as np

from motorid.comparators.base import LossModel, _lstsq, loss_targets, Operating

DEGREES = (1, 2, 3, 4)


class Polynomial(LossModel):
    name = "polynomial map"
    reference = ("Ivantysynova group (Maha, Purdue) and MSOE Fluid Power Institute (Panwar & Michael, Int. J. "
                 "Hydromechatronics 1 (2018) 272-292): losses as polynomials in ΔP and ω")
    equations = "L(ΔP, ω) = Σ_{i+j≤k} c_ij |ΔP|^i |ω|^j, per mode (motor/pump), k by 5-fold CV"
    shapes = DEGREES

    def __init__(self, degree: int | None = None):
        self.fixed_degree = degree

    def _basis(self, op, k, split):
        x, y = op.P / self.refs[0], op.W / self.refs[1]
        cols = [x**i * y**j for i in range(k + 1) for j in range(k + 1 - i)]
        A = np.column_stack(cols)
        if split:
            m = op.motor[:, None].astype(float)
            A = np.hstack([A * m, A * (1 - m)])
        return A

    def torque_terms(self, op, h):
        return self._basis(op, h[0], h[1])

    flow_terms = torque_terms

    def fit(self, table, density=None):
        op = Operating(table, density)
        self.refs = (max(float(op.P.max()), 1.0), max(float(op.W.max()), 1e-6))
        y = loss_targets(op, table.measured)
        self.coef, self.shape = {}, {}
        rng = np.random.default_rng(0)
        for key, target in y.items():
            ok = np.flatnonzero(np.isfinite(target))
            if ok.size == 0:
                continue
            n_motor, n_pump = int(op.motor[ok].sum()), int((~op.motor[ok]).sum())
            scores = []
            for k in ((self.fixed_degree,) if self.fixed_degree else DEGREES):
                n_terms = (k + 1) * (k + 2) // 2
                split = min(n_motor, n_pump) >= 2 * n_terms
                if ok.size < 2 * n_terms * (2 if split else 1):
                    continue
                folds = np.array_split(rng.permutation(ok), 5)
                A = self._basis(op, k, split)
                sse = 0.0
                for f in folds:
                    tr = np.zeros(len(target), bool)
                    tr[ok] = True
                    tr[f] = False
                    c = _lstsq(A[tr], target[tr])
                    sse += float(np.sum((A[f] @ c - target[f]) ** 2))
                scores.append((sse, (k, split)))
            # the lowest degree within 1 % of the best held-out error (no extra terms for nothing)
            floor = min(s for s, _ in scores) if scores else 0.0
            tiny = 1e-20 * float(np.sum(target[ok] ** 2))  # round-off: a law the basis holds exactly
            h = next((h for s, h in scores if s <= 1.01 * floor + tiny), (1, False))
            self.shape[key] = h
            self.coef[key] = _lstsq(self._basis(op, *h)[ok], target[ok])
        return self
