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

import jax
import jax.numpy as jnp
import numpy as np

from motorid._aot import cached_jit
from motorid.identify.problem import predictions
from motorid.identify.types import CHANNELS


def _flat_predictions(vector, names, ctx, order):
    pred = predictions({k: vector[i] for i, k in enumerate(names)}, ctx)
    return jnp.concatenate([pred[c] for c in order])


_value = cached_jit(_flat_predictions)


@cached_jit
def _jacobian(vector, names, ctx, order):
    return jax.jacfwd(lambda v: _flat_predictions(v, names, ctx, order))(vector)


@cached_jit
def _hessian(vector, names, ctx, order):
    """(n, p, p) second derivatives of the flat predictions, forward over forward, one pair
    of parameters per tangent: the model is elementwise over the cells, so this costs
    p(p+1)/2 passes, where ``jax.hessian`` (forward over reverse) would pay a reverse pass
    per output, n of them."""
    p = vector.size
    eye = jnp.eye(p)
    ia, ib = np.triu_indices(p)

    def f(v):
        return _flat_predictions(v, names, ctx, order)

    def second(ta, tb):
        return jax.jvp(lambda v: jax.jvp(f, (v,), (ta,))[1], (vector,), (tb,))[1]

    upper = jax.vmap(second)(eye[ia], eye[ib]).T  # (n, pairs)
    n = upper.shape[0]
    return jnp.zeros((n, p, p), dtype=upper.dtype).at[:, ia, ib].set(upper).at[:, ib, ia].set(upper)


@cached_jit
def _channel_terms(vector, names, ctx, channels, columns, pairs):
    """Per channel: its predictions f0 (n,), their first derivatives along the
    channel's ``columns`` (k, n) and second derivatives along its ``pairs`` (K, n).

    One channel at a time, so that XLA prunes the other channels' arithmetic and
    no tangent is spent on a parameter the channel does not depend on.
    """
    eye = jnp.eye(vector.size)
    out = {}
    for c, cols, prs in zip(channels, columns, pairs):
        def f(v, c=c):
            return predictions({k: v[i] for i, k in enumerate(names)}, ctx)[c]

        value = f(vector)
        jvp = lambda t, f=f: jax.jvp(f, (vector,), (t,))[1]  # noqa: E731
        first = jax.vmap(jvp)(eye[np.array(cols, dtype=int)]) if cols else jnp.zeros((0, value.size))
        if prs:
            a, b = (np.array([q[i] for q in prs], dtype=int) for i in (0, 1))
            second = jax.vmap(lambda ta, tb, f=f: jax.jvp(lambda v: jax.jvp(f, (v,), (ta,))[1],
                                                          (vector,), (tb,))[1])(eye[a], eye[b])
        else:
            second = jnp.zeros((0, value.size))
        out[c] = (value, first, second)
    return out


def _sample_ctx(ctx, cells: np.ndarray):
    """The same context on a few cells spread over every run (and all events)."""
    running = None if ctx.running is None else jax.tree_util.tree_map(lambda a: np.asarray(a)[cells], ctx.running)
    return ctx._replace(running=running, observed={}, weights={})


class Expansion:
    """f0, J and the non-zero second derivatives of the cell predictions at p0.

    Held per channel, on the channel's real cells only (padding dropped), and
    only over the columns that channel depends on (torque does not depend on the
    leakage, nor the flows on the friction): the Gram matrix of the compression
    then costs a few columns per channel instead of all of them.
    """

    def __init__(self, names, p0, order, pairs, blocks: dict):
        self.names, self.p0, self.order = list(names), np.asarray(p0), tuple(order)
        self.pairs = pairs
        self.a = np.array([a for a, _ in pairs], dtype=int)
        self.b = np.array([b for _, b in pairs], dtype=int)
        self.half = np.array([0.5 if a == b else 1.0 for a, b in pairs])
        self.blocks = blocks  # channel -> (real rows, columns of [δ; u], (k, rows) derivatives, f0)

    @classmethod
    def build(cls, problem, values: dict, free: list, tol: float = 1e-9):
        """The expansion of ``problem``'s cell predictions, or None if the model is not quadratic."""
        ctx = problem.ctx()
        order = tuple(c for c in CHANNELS if c in ctx.observed)
        names = tuple(free)
        p = len(names)
        p0 = np.array([values[k] for k in names], dtype=np.float64)
        # which parameters each channel depends on, and the products: on a few cells
        # of every run (a dependency missed here fails the exactness check below)
        n_cells = problem.n_real("torque") if problem.has_running else 0
        cells = np.unique(np.linspace(0, max(n_cells - 1, 0), min(n_cells, 256)).astype(int))
        small = _sample_ctx(ctx, cells)
        small_order = tuple(c for c in order if c != "breakaway" or small.events is not None)
        sizes = {c: (cells.size if c != "breakaway" else int(np.asarray(ctx.observed[c]).size)) for c in order}
        if not problem.mechanisms:
            # the 1992 model's own products: K_L0 with each Fourier coefficient, T_Fc with K_s
            products = [("KL0", k) for k in names if k.startswith("KL_")] + [("TFc", "Ks")]
            pairs = sorted((min(names.index(a), names.index(b)), max(names.index(a), names.index(b)))
                           for a, b in products if a in names and b in names)
        else:
            Hs = np.asarray(_hessian(p0, names, small, small_order))
            # a quadratic model has one Hessian everywhere: where it differs at a second point
            # (a mechanism with a characteristic speed, a gain on a product), give up now,
            # before the costly pass over every cell
            scale = np.where(p0 != 0, np.abs(p0), 1.0)
            other = p0 + 0.3 * scale * np.random.default_rng(1).standard_normal(p)
            H2 = np.asarray(_hessian(other, names, small, small_order))
            ok = np.isfinite(Hs) & np.isfinite(H2)
            size_h = np.max(np.where(ok, np.abs(Hs) + np.abs(H2), 0.0), axis=0, keepdims=True)
            if np.any((np.abs(Hs - H2) > 1e-7 * size_h + 1e-300) & ok):
                return None
            pairs = [(a, b) for a in range(p) for b in range(a, p)
                     if np.any(Hs[:, a, b] != 0) or np.any(Hs[:, b, a] != 0)]
        Js = np.asarray(_jacobian(p0, names, small, small_order))
        columns, channel_pairs, start = [], [], 0
        for c in order:
            rows = Js[start:start + sizes[c]]
            start += sizes[c]
            used = np.any((rows != 0) & np.isfinite(rows), axis=0)
            columns.append(tuple(int(i) for i in np.flatnonzero(used)))
            channel_pairs.append(tuple((a, b) for a, b in pairs if used[a] and used[b]))
        terms = _channel_terms(p0, names, ctx, order, tuple(columns), tuple(channel_pairs))
        blocks = {}
        for c, cols, prs in zip(order, columns, channel_pairs):
            n_real = problem.n_real(c)
            f0, first, second = (np.asarray(x)[..., :n_real] for x in terms[c])
            X = np.concatenate([first, second]) if second.size else first
            nz = np.array(list(cols) + [p + pairs.index(q) for q in prs], dtype=int)
            blocks[c] = (n_real, nz, np.ascontiguousarray(np.where(np.isfinite(X), X, 0.0)),
                         np.where(np.isfinite(f0), f0, 0.0))
        exp = cls(names, p0, order, pairs, blocks)
        # exact? compare with the model itself, on the sampled cells, at two points well
        # away from p0 (a term of higher order would show at any generic point)
        rng = np.random.default_rng(0)
        scale = np.where(np.asarray(p0) != 0, np.abs(np.asarray(p0)), 1.0)
        rows_of = {c: (cells if c != "breakaway" else np.arange(problem.n_real(c))) for c in order}
        for _ in range(2):
            delta = 0.3 * scale * rng.standard_normal(p)
            full = np.asarray(_value(p0 + delta, names, small, small_order))
            start, worst, size_ = 0, 0.0, 0.0
            for c in order:
                want = full[start:start + rows_of[c].size]
                start += sizes[c]
                got = exp.predict_channel(c, delta, rows_of[c])
                ok = np.isfinite(want)
                if ok.any():
                    worst = max(worst, float(np.max(np.abs(got[ok] - want[ok]))))
                    size_ = max(size_, float(np.max(np.abs(want[ok]))))
            if not worst <= tol * (size_ + 1e-300):
                return None
        return exp

    def products(self, delta):
        return delta[..., self.a] * delta[..., self.b] * self.half

    def derivative(self, delta):
        """∂[δ; u(δ)]/∂δ at δ: (p + pairs) × p (the identity over δ, then one row per product)."""
        p = len(self.names)
        dz = np.zeros((p + len(self.pairs), p))
        dz[:p] = np.eye(p)
        for k, (a, b) in enumerate(self.pairs):
            dz[p + k, a] += self.half[k] * delta[b]
            dz[p + k, b] += self.half[k] * delta[a]
        return dz

    def predict_channel(self, channel: str, delta, rows=slice(None)):
        """The expansion's prediction of one channel's real cells (or ``rows`` of them) at p0 + δ."""
        delta = np.asarray(delta, dtype=float)
        z = np.concatenate([delta, self.products(delta)])
        n_real, nz, X, f0 = self.blocks[channel]
        return f0[rows] + z[nz] @ X[:, rows]

    def compress(self, observed: dict, weights: dict):
        """(R0, R1): |w(y − f(p0+δ))| = |R0 − R1 [δ; u(δ)]| for every δ."""
        m = 1 + len(self.names) + len(self.pairs)
        gram = np.zeros((m, m))
        for c in self.order:
            n_real, nz, X, f0 = self.blocks[c]
            w = np.asarray(weights[c])[:n_real]
            y = np.asarray(observed[c])[:n_real]
            r = w * np.where(w != 0, y - f0, 0.0)  # rejected samples: weight 0, any value
            Xw = X * w
            idx = 1 + nz
            # einsum, not BLAS: a multi-threaded BLAS on these few long rows loses more to
            # waking its threads (and fighting XLA's) than the products cost
            gram[0, 0] += np.einsum("n,n->", r, r)
            g = np.einsum("in,n->i", Xw, r)
            gram[0, idx] += g
            gram[idx, 0] += g
            gram[np.ix_(idx, idx)] += np.einsum("in,jn->ij", Xw, Xw)
        # any R with RᵀR = Gram will do: its symmetric square root, on unit-norm
        # columns (cheaper than QR of the tall matrix, as exact)
        norms = np.sqrt(np.clip(np.diag(gram), 0.0, None))
        norms = np.where(norms > 0, norms, 1.0)
        lam, vec = np.linalg.eigh(gram / np.outer(norms, norms))
        R = (np.sqrt(np.clip(lam, 0.0, None))[:, None] * vec.T) * norms
        return R[:, 0], R[:, 1:]
