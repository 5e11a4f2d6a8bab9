"""The weighted residual of operating-point tables (and logs) as one compiled program.

:class:`TableResidual` gives the residual, its Jacobian over the scaled free parameters and the
θ-averaged predictions at the table's points from one program (one trace, one lowering, one compile
per problem); the table's points, the weights, the held values and the spec's numbers are its inputs,
so that K-fold refits and tables of one size class run it again.  Used by
:func:`motorid.identify.tables.fit_table`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from motorid import _jaxconfig  # noqa: F401
from motorid import model
from motorid.identify.table_model import angle_points, bind_mechanisms, point_channels, table_samples

TABLE_CHANNELS = ("torque", "q_a", "q_b", "q_case")


def _padded(table):
    """``table`` with its last point repeated up to a power of two (at least 16) points: the
    compiled residual then serves every table of that size class (the extra points get weight 0)."""
    n = len(table)
    if n == 0:
        return table
    size = max(16, 1 << max(n - 1, 1).bit_length())
    return table if size == n else table.subset(np.concatenate([np.arange(n), np.full(size - n, n - 1)]))


class TableResidual:
    """The weighted residual of tables (and logs) as a function of the scaled free parameters.

    One compiled program per set of free parameters (residual, Jacobian and predictions together,
    :meth:`evaluate`); the weights are arguments, so that
    refits on other folds or with other noise levels reuse it.  So are the table's points (padded
    to a power of two with points of weight 0), the held values and the spec's numbers: the
    program is not this table's, and any table of the same size class, mechanisms and free
    parameters runs it (from the disk cache in a later process)."""

    def __init__(self, spec, table, names, free, held, scales, mechanisms, dataset=None):
        self.spec, self.free = spec, list(free)
        self.hold(held)
        self.n = len(table) if table is not None else 0
        padded = _padded(table) if table is not None else None
        self.mechanisms = bind_mechanisms(mechanisms, padded) if table is not None else tuple(mechanisms)
        self.scales = np.asarray(scales, dtype=float)
        probe = {**held, **{k: float(v) for k, v in zip(free, scales)}}
        # probed on the table's own points (not the padding's repeats), evaluated on the padded table
        self.samples = table_samples(spec, padded, angle_points(spec, table, mechanisms, probe, free)) \
            if table is not None else None
        disp = None
        if table is not None and table.variable_displacement:
            disp = np.asarray(padded.displacement, dtype=float)
        self.disp = disp
        self.obs = {c: np.nan_to_num(np.asarray(padded.measured[c], dtype=float)) for c in TABLE_CHANNELS} \
            if table is not None else {}
        self.dataset = dataset
        self.log_obs = {}
        if dataset is not None:
            if dataset.n_running:
                self.log_obs.update({c: np.nan_to_num(np.asarray(dataset.measured[c], dtype=float))
                                     for c in TABLE_CHANNELS})
            if dataset.n_events:
                self.log_obs["breakaway"] = np.nan_to_num(np.asarray(dataset.held_torque, dtype=float))
        mechs = self.mechanisms
        scales_j = jnp.asarray(self.scales)

        def params(x, held_values):
            p = dict(held_values)
            for i, k in enumerate(self.free):
                p[k] = x[i] * scales_j[i]
            return p

        def table_pred(x, data, held_values, spec_):
            samples, _, disp_ = data
            ch = point_channels(params(x, held_values), spec_, samples, disp_, mechs)
            return dict(zip(TABLE_CHANNELS, ch))

        def log_pred(x, held_values, spec_):
            out = {}
            p = params(x, held_values)
            if dataset is not None and dataset.n_running:
                ch = model.predict(p, spec_, dataset.running, mechs)
                out.update(zip(TABLE_CHANNELS, ch))
            if dataset is not None and dataset.n_events:
                out["breakaway"] = model.predict_breakaway(p, spec_, dataset.events, mechs)
            return out

        def residual(x, w_table, w_logs, data, held_values, spec_):
            parts, tpred, lpred = [], {}, {}
            if table is not None:
                tpred = table_pred(x, data, held_values, spec_)
                parts += [(data[1][c] - tpred[c]) * w_table[c] for c in TABLE_CHANNELS]
            if self.log_obs:
                lpred = log_pred(x, held_values, spec_)
                parts += [(self.log_obs[c] - lpred[c]) * w_logs[c] for c in self.log_obs]
            r = jnp.concatenate(parts)
            return r, (r, tpred, lpred)

        def evaluate(x, w_table, w_logs, data, held_values, spec_):
            # one program for the residual, its Jacobian and the predictions: one trace, one lowering and
            # one compile per problem (a diagnosis builds one for every candidate and fold), and the
            # residual a solver asks for at a point comes with the Jacobian it asks for next
            jac, (r, tpred, lpred) = jax.jacfwd(residual, has_aux=True)(x, w_table, w_logs, data, held_values, spec_)
            return r, jac, tpred, lpred

        # on the device once: a call then hands over the weights and x alone (each numpy leaf costs a transfer)
        self._data = jax.device_put((self.samples, self.obs, self.disp))
        self._spec = jax.device_put(spec)
        self._evaluate = jax.jit(evaluate)
        self._w = None  # the weights of the last evaluation (predictions do not depend on them)

    def hold(self, held: dict):
        """Hold these values (SI; the same names on a refit) from now on: inputs of the programs."""
        self.held = dict(held)
        self._held = {k: jnp.asarray(v, dtype=jnp.float64) for k, v in self.held.items()}

    def _pad(self, w_table):
        extra = len(self.obs["torque"]) - self.n if self.obs else 0
        return {c: np.concatenate([np.asarray(w, dtype=float), np.zeros(extra)]) for c, w in w_table.items()}

    def evaluate(self, x, w_table, w_logs):
        """(weighted residual, its Jacobian over x, table predictions (padded), log predictions) at x."""
        w = (self._pad(w_table), dict(w_logs))
        self._w = w
        return self._evaluate(np.asarray(x, dtype=float), *w, self._data, self._held, self._spec)

    def _unit_weights(self):
        if self._w is not None:
            return self._w
        n = len(self.obs["torque"]) if self.obs else 0
        return ({c: np.ones(n) for c in TABLE_CHANNELS} if self.obs else {},
                {c: np.ones(len(v)) for c, v in self.log_obs.items()})

    def log_pred(self, x):
        w = self._unit_weights()
        return self._evaluate(np.asarray(x, dtype=float), *w, self._data, self._held, self._spec)[3]

    def table_pred(self, x):
        """The θ-averaged model at the table's points (its own n, the padding cut off)."""
        w = self._unit_weights()
        pred = self._evaluate(np.asarray(x, dtype=float), *w, self._data, self._held, self._spec)[2]
        return {c: v[: self.n] for c, v in pred.items()}

    def residual(self, x, w_table, w_logs):
        return self.evaluate(x, w_table, w_logs)[0]

    def jacobian(self, x, w_table, w_logs):
        return self.evaluate(x, w_table, w_logs)[1]

    def solve(self, x0, w_table, w_logs, lower):
        from scipy.optimize import least_squares

        last = {}  # the residual and the Jacobian at the point last evaluated (one program gives both)

        def at(x):
            key = np.asarray(x, dtype=float).tobytes()
            if last.get("x") != key:
                r, J = self.evaluate(x, w_table, w_logs)[:2]
                last.update(x=key, r=np.asarray(r), J=np.asarray(J))
            return last

        fun = lambda x: at(x)["r"]  # noqa: E731
        jac = lambda x: at(x)["J"]  # noqa: E731
        x0 = np.maximum(np.asarray(x0, dtype=float), lower + 1e-12)
        sol = least_squares(fun, x0, jac=jac, bounds=(lower, np.inf), method="trf", x_scale="jac",
                            xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200)
        return sol.x, int(sol.nfev), bool(sol.success), jac(sol.x)
