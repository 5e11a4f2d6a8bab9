"""Classical steady-state loss models of hydrostatic units, fitted as comparators.

Every classical model writes the shaft torque and the flows of a unit as the
ideal values of its displacement minus losses, each loss a sum of terms in
(ΔP, ω, μ, ρ, D) with coefficients fitted to measurements.  Here each model is
a set of *basis terms* for the torque loss and for the flow losses; the
coefficients enter linearly, so each model is fitted by linear least squares
(per channel); a model with a shape parameter (Jeong's friction speed, the
polynomial's degree) chooses it on the training points (a grid, or K-fold
cross-validation).  That is the fit the references describe.

Four quadrants (signs as BENCH_LOG_FORMAT.md; d = D/2π [m³/rad], s = sgn ΔP):

    torque      T      = d ΔP − sgn(ω) · T_loss(|ΔP|, |ω|, μ)
    high port   Q_hp   = s d ω + Q_hp,loss(|ΔP|, |ω|, μ)     (flow into the high-pressure port)
    low port    Q_lp   = −s d ω + Q_lp,loss(|ΔP|, |ω|, μ)    (flow into the low-pressure port)
    case drain  Q_case = Q_case,loss(|ΔP|, |ω|, μ)

so that friction opposes the motion and leakage runs from the high-pressure
side, in motor and in pump mode; the classical papers write one quadrant (motor
or pump, ΔP > 0, ω > 0), and this is that law mirrored.  The port of higher
pressure is A where ΔP ≥ 0.  Each flow channel gets its own coefficients of
the same law (the classical papers lump them into one "slip" flow).
"""

from __future__ import annotations

import numpy as np

CHANNELS = ("torque", "q_a", "q_b", "q_case")


class Operating:
    """The operating points a comparator sees, SI: ΔP [Pa], ω [rad/s], μ [Pa·s],
    ρ [kg/m³] (870 where not given: a constant ρ is absorbed by the coefficients),
    d = D/2π [m³/rad]."""

    def __init__(self, table, density=None):
        self.dp = np.asarray(table.p_a - table.p_b, dtype=float)
        self.omega = np.asarray(table.speed, dtype=float)
        self.mu = np.asarray(table.viscosity, dtype=float)
        self.d = np.asarray(table.displacement, dtype=float) / (2 * np.pi)
        self.rho = np.full(self.dp.shape, 870.0) if density is None else np.asarray(density, dtype=float)
        self.P = np.abs(self.dp)
        self.W = np.abs(self.omega)
        self.s = np.where(self.dp >= 0, 1.0, -1.0)
        self.motor = self.dp * self.omega > 0  # hydraulic power in

    def __len__(self):
        return self.dp.size


def loss_targets(op: Operating, measured: dict) -> dict:
    """Measured channels → the loss of each channel in the form above (NaN where absent):
    "torque" T_loss, "hp", "lp", "case" flow losses."""
    sgn = np.sign(op.omega)
    t_loss = np.where(sgn != 0, (op.d * op.dp - measured["torque"]) * sgn, np.nan)
    q_hp = np.where(op.s > 0, measured["q_a"], measured["q_b"])
    q_lp = np.where(op.s > 0, measured["q_b"], measured["q_a"])
    return {"torque": t_loss, "hp": q_hp - op.s * op.d * op.omega, "lp": q_lp + op.s * op.d * op.omega,
            "case": np.asarray(measured["q_case"], dtype=float)}


def channels_from_losses(op: Operating, loss: dict) -> dict:
    """Inverse of :func:`loss_targets`: losses → predicted torque [N·m], q_a, q_b, q_case [m³/s]."""
    sgn = np.sign(op.omega)
    torque = op.d * op.dp - sgn * loss["torque"]
    q_hp = op.s * op.d * op.omega + loss["hp"]
    q_lp = -op.s * op.d * op.omega + loss["lp"]
    return {"torque": torque, "q_a": np.where(op.s > 0, q_hp, q_lp), "q_b": np.where(op.s > 0, q_lp, q_hp),
            "q_case": loss["case"]}


def _lstsq(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    return np.linalg.lstsq(A / scale, y, rcond=None)[0] / scale


class LossModel:
    """A classical loss model: basis terms, linear coefficients per channel.

    Subclasses set ``name``, ``reference``, ``equations`` and implement
    :meth:`torque_terms` and :meth:`flow_terms` (columns over the points, for one
    value of the shape parameter ``h``); ``shapes`` lists the candidate values of
    ``h`` (one None where the law has none)."""

    name = "?"
    reference = ""
    equations = ""
    shapes: tuple = (None,)

    def torque_terms(self, op: Operating, h) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def flow_terms(self, op: Operating, h) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def usable(self, kind, op: Operating, h, ok) -> bool:
        """Whether the shape ``h`` may be fitted on the points ``ok`` (a term that vanishes on all of
        them would get an arbitrary coefficient, and blow up where it does not vanish)."""
        return True

    def _terms(self, kind, op, h):
        return self.torque_terms(op, h) if kind == "torque" else self.flow_terms(op, h)

    def fit(self, table, density=None) -> "LossModel":
        """Fit every channel the table holds; returns self (coefficients in ``coef``)."""
        op = Operating(table, density)
        y = loss_targets(op, table.measured)
        self.coef, self.shape = {}, {}
        for key, target in y.items():
            ok = np.isfinite(target)
            if ok.sum() == 0:
                continue
            kind = "torque" if key == "torque" else "flow"
            best = None
            for h in self.shapes:
                if not self.usable(kind, op, h, ok):
                    continue
                A = self._terms(kind, op, h)[ok]
                c = _lstsq(A, target[ok])
                sse = float(np.sum((A @ c - target[ok]) ** 2))
                if best is None or sse < best[0]:
                    best = (sse, h, c)
            if best is not None:
                self.shape[key], self.coef[key] = best[1], best[2]
        return self

    def predict(self, table, density=None) -> dict:
        """Predicted channels at the table's points (NaN for a channel not fitted)."""
        op = Operating(table, density)
        loss = {}
        for key in ("torque", "hp", "lp", "case"):
            if key not in self.coef:
                loss[key] = np.full(len(op), np.nan)
                continue
            kind = "torque" if key == "torque" else "flow"
            loss[key] = self._terms(kind, op, self.shape[key]) @ self.coef[key]
        return channels_from_losses(op, loss)
