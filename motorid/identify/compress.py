"""Exact compression of a least-squares problem whose model is polynomial of degree two.

The 1992 model is linear in K_v, K_F, K_FS, T_Fc, K_AB and bilinear in
K_L0·a_m, K_L0·b_m and T_Fc·K_s, so its predictions are exactly

    f(p0 + δ) = f0 + J δ + Σ_k H_k u_k(δ),   u_k = δ_a δ_b (a < b) or ½ δ_a² (a = b)

for the few parameter pairs (a, b) whose second derivative is not zero.  The
weighted residual w(y − f) then lies in the span of m = 1 + p + K columns
[w(y − f0), wJ, wH_k], and with a square root R of those columns' Gram matrix
|w(y − f(p0 + δ))| = |R0 − R1 [δ; u(δ)]| for every δ: a residual of m rows that
gives the same χ², the same optimum and the same Jacobian products as the full
one.  The optimizer then costs nothing however many rows the campaign has;
building the compression costs about 1 + p + K passes of the model over the
data, once per fit (the expansion is global: it holds at any p).

Whether the model *is* quadratic (a mechanism may not be) is checked on the
data at random points; if not, :meth:`Expansion.build` returns None and the
caller uses the full residual.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from motorid.identify import least_squares as ls


def _flat_predictions(vector, names, ctx, order):
    pred = ls._predictions({k: vector[i] for i, k in enumerate(names)}, ctx)
    return jnp.concatenate([pred[c] for c in order])


_value = eqx.filter_jit(_flat_predictions)


@eqx.filter_jit
def _value_and_jacobian(vector, names, ctx, order):
    f = lambda v: _flat_predictions(v, names, ctx, order)  # noqa: E731
    return f(vector), jax.jacfwd(f)(vector)


@eqx.filter_jit
def _second_derivatives(vector, names, ctx, order, pairs_a, pairs_b):
    f = lambda v: _flat_predictions(v, names, ctx, order)  # noqa: E731
    eye = jnp.eye(vector.size)

    def one(a, b):
        return jax.jvp(lambda v: jax.jvp(f, (v,), (eye[a],))[1], (vector,), (eye[b],))[1]

    return jax.vmap(one, out_axes=1)(pairs_a, pairs_b)


@eqx.filter_jit
def _hessian_small(vector, names, ctx, order):
    return jax.hessian(lambda v: _flat_predictions(v, names, ctx, order))(vector)


def _slice_ctx(ctx, n: int):
    """The same context on the first ``n`` cells and events (to find the pairs cheaply)."""
    cut = lambda s: None if s is None else jax.tree_util.tree_map(lambda a: a[:n], s)  # noqa: E731
    return ctx._replace(running=cut(ctx.running), events=cut(ctx.events))


class Expansion:
    """f0, J and the non-zero second derivatives of the cell predictions at p0."""

    def __init__(self, names, p0, order, f0, J, H, pairs):
        self.names, self.p0, self.order = list(names), np.asarray(p0), tuple(order)
        self.f0, self.J, self.H, self.pairs = f0, J, H, pairs
        self.a = np.array([a for a, _ in pairs], dtype=int)
        self.b = np.array([b for _, b in pairs], dtype=int)
        self.half = np.array([0.5 if a == b else 1.0 for a, b in pairs])

    @classmethod
    def build(cls, problem, values: dict, free: list, tol: float = 1e-9):
        """The expansion of ``problem``'s cell predictions, or None if the model is not quadratic."""
        ctx = problem.ctx()
        order = tuple(c for c in ls.CHANNELS if c in ctx.observed)
        names = tuple(free)
        p0 = jnp.asarray([values[k] for k in names], dtype=jnp.float64)
        if not problem.mechanisms:
            # the 1992 model's own products: K_L0 with each Fourier coefficient, T_Fc with K_s
            # (the exactness check below would catch any other)
            products = [("KL0", k) for k in names if k.startswith("KL_")] + [("TFc", "Ks")]
            pairs = sorted((min(names.index(a), names.index(b)), max(names.index(a), names.index(b)))
                           for a, b in products if a in names and b in names)
        else:
            Hs = np.asarray(_hessian_small(p0, names, _slice_ctx(ctx, 64), order))
            pairs = [(a, b) for a in range(len(names)) for b in range(a, len(names))
                     if np.any(Hs[:, a, b] != 0) or np.any(Hs[:, b, a] != 0)]
        f0, J = (np.asarray(x) for x in _value_and_jacobian(p0, names, ctx, order))
        if pairs:
            H = np.asarray(_second_derivatives(p0, names, ctx, order, jnp.asarray([a for a, _ in pairs]),
                                               jnp.asarray([b for _, b in pairs])))
        else:
            H = np.zeros((f0.size, 0))
        exp = cls(names, p0, order, f0, J, H, pairs)
        # exact? compare with the model itself at two points well away from p0
        rng = np.random.default_rng(0)
        scale = np.where(np.asarray(p0) != 0, np.abs(np.asarray(p0)), 1.0)
        for _ in range(2):
            delta = 0.3 * scale * rng.standard_normal(len(names))
            full = np.asarray(_value(p0 + delta, names, ctx, order))
            if np.max(np.abs(full - exp.predict(delta))) > tol * (np.max(np.abs(full)) + 1e-300):
                return None
        return exp

    def products(self, delta):
        return delta[..., self.a] * delta[..., self.b] * self.half

    def predict(self, delta):
        delta = np.asarray(delta)
        return self.f0 + self.J @ delta + (self.H @ self.products(delta) if self.pairs else 0.0)

    def compress(self, observed: dict, weights: dict):
        """(R0, R1): |w(y − f(p0+δ))| = |R0 − R1 [δ; u(δ)]| for every δ."""
        y = np.concatenate([np.asarray(observed[c]) for c in self.order])
        w = np.concatenate([np.asarray(weights[c]) for c in self.order])
        keep = w != 0  # padding and rejected samples carry no weight
        w, y = w[keep], y[keep]
        cols = np.column_stack([w * (y - self.f0[keep]), w[:, None] * self.J[keep], w[:, None] * self.H[keep]])
        # any R with RᵀR = colsᵀcols will do: the symmetric square root of the Gram
        # matrix, on unit-norm columns (cheaper than QR of the tall matrix, as exact)
        norms = np.linalg.norm(cols, axis=0)
        norms = np.where(norms > 0, norms, 1.0)
        gram = (cols / norms).T @ (cols / norms)
        lam, vec = np.linalg.eigh(gram)
        R = (np.sqrt(np.clip(lam, 0.0, None))[:, None] * vec.T) * norms
        return R[:, 0], R[:, 1:]
