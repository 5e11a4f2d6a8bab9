"""The residual core of the fit: the data reduced to cells, and the weighted residual over them.

Least squares, Bayes, the exact compression and the experiment planner all
evaluate the same thing: the model (:func:`motorid.model.predict`,
:func:`~motorid.model.predict_breakaway`) at the cells or events of a
:class:`Problem`, each channel's residual weighted by its noise level.
"""

from __future__ import annotations

import weakref
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from motorid import model
from motorid._aot import cached_jit
from motorid.identify.types import CHANNELS, RUNNING_CHANNELS
from motorid.model import Samples


class Ctx(NamedTuple):
    """Everything the residual needs; arrays are traced, the rest is static."""

    spec: object
    mechanisms: tuple
    free: tuple
    positive: tuple
    scales: jax.Array
    held: dict
    running: object
    events: object
    observed: dict
    weights: dict
    block: int = 0  # cells per block of the blockwise Jacobians (0: BLOCK); static


def _params(values: dict, ctx: Ctx) -> dict:
    p = dict(ctx.held)
    p.update(values)
    return p


def predictions(values: dict, ctx: Ctx) -> dict:
    p = _params(values, ctx)
    out = {}
    if ctx.running is not None:
        ch = model.predict(p, ctx.spec, ctx.running, ctx.mechanisms)
        out.update(torque=ch.torque, q_a=ch.q_a, q_b=ch.q_b, q_case=ch.q_case)
    if ctx.events is not None:
        out["breakaway"] = model.predict_breakaway(p, ctx.spec, ctx.events, ctx.mechanisms)
    return out


def weighted_residual(values: dict, ctx: Ctx):
    pred = predictions(values, ctx)
    return jnp.concatenate([(ctx.observed[c] - pred[c]) * ctx.weights[c] for c in CHANNELS if c in ctx.observed])


def from_unconstrained(y, ctx: Ctx) -> dict:
    v = model.constrain(y, np.array(ctx.positive, dtype=bool), ctx.scales)
    return {k: v[i] for i, k in enumerate(ctx.free)}


def to_unconstrained(values: dict, ctx: Ctx):
    v = jnp.stack([jnp.asarray(values[k], dtype=jnp.float64) for k in ctx.free])
    return model.unconstrain(v, np.array(ctx.positive, dtype=bool), ctx.scales)


def residual_unconstrained(y, ctx: Ctx):
    return weighted_residual(from_unconstrained(y, ctx), ctx)


residual_jit = cached_jit(weighted_residual)


#: cells per block of :func:`normal_equations`: the Jacobian and its intermediates are alive for
#: one block at a time (on 131 k padded cells with two mechanisms, 14 MiB of temporaries instead
#: of 108 MiB; the optimistix Levenberg-Marquardt that materialized them for every cell held 382 MiB)
BLOCK = 16384


def _normal_dense(values: dict, ctx: Ctx):
    r = weighted_residual(values, ctx)
    jac = jax.jacfwd(weighted_residual)(values, ctx)
    J = jnp.stack([jac[k] for k in ctx.free], axis=1)
    return J.T @ J, J.T @ r, r @ r


def running_only(ctx: Ctx) -> Ctx:
    """The context without its breakaway events (the running cells' channels only)."""
    running = [c for c in CHANNELS if c in ctx.observed and c != "breakaway"]
    return ctx._replace(events=None, observed={c: ctx.observed[c] for c in running},
                        weights={c: ctx.weights[c] for c in running})


def over_cell_blocks(one, ctx: Ctx):
    """``one(sub_ctx)`` on the running cells of ``ctx`` cut in blocks of :data:`BLOCK` cells, one
    block at a time (``jax.lax.map``) → its outputs stacked over the blocks (a leading axis);
    a single block where the cells are few.  The model is cell by cell, so that each block's
    Jacobian (and its intermediates) is all that is alive at once.  Traced code only.
    ``ctx.block``, where not 0, sets the block size instead."""
    c = running_only(ctx)
    n = int(next(iter(c.observed.values())).shape[0])
    size = ctx.block or BLOCK
    if n <= size or n % size:
        return jax.tree_util.tree_map(lambda x: x[None], one(c))
    cut = lambda a: a.reshape((n // size, size) + a.shape[1:])  # noqa: E731
    parts = (jax.tree_util.tree_map(cut, c.running), {k: cut(v) for k, v in c.observed.items()},
             {k: cut(v) for k, v in c.weights.items()})
    return jax.lax.map(lambda part: one(c._replace(running=part[0], observed=part[1], weights=part[2])), parts)


def normal_blockwise(values: dict, ctx: Ctx):
    """JᵀJ, Jᵀr, rᵀr as :func:`normal_equations`, traced (see :func:`over_cell_blocks`)."""
    A, g, f = 0.0, 0.0, 0.0
    if ctx.running is not None and any(c != "breakaway" for c in ctx.observed):
        A, g, f = (x.sum(axis=0) for x in over_cell_blocks(lambda c: _normal_dense(values, c), ctx))
    if "breakaway" in ctx.observed and ctx.events is not None:
        A2, g2, f2 = _normal_dense(values, ctx._replace(
            running=None, observed={"breakaway": ctx.observed["breakaway"]},
            weights={"breakaway": ctx.weights["breakaway"]}))
        A, g, f = A + A2, g + g2, f + f2
    return A, g, f


@cached_jit
def normal_equations(values: dict, ctx: Ctx):
    """JᵀJ, Jᵀr and rᵀr of the weighted residual over the free parameters (in
    the order of ``ctx.free``): the sufficient statistics of a Gauss-Newton step,
    computed where the data are, so that no tall matrix leaves the device, and
    block by block (:data:`BLOCK` cells: the model is cell by cell), so that no tall
    matrix is held at once either."""
    return normal_blockwise(values, ctx)


predictions_jit = cached_jit(predictions)


def as_arrays(values: dict) -> dict:
    """Parameter values as float64 arrays (NumPy: a jitted call takes them without a JAX dispatch)."""
    return {k: np.asarray(v, dtype=np.float64) for k, v in values.items()}


def bucket(n: int, minimum: int = 64) -> int:
    """Padded array length: the next power of two (so that campaigns of similar
    size share compiled functions instead of recompiling for every length)."""
    return max(minimum, 1 << max(int(n) - 1, 0).bit_length())


_PAD = {"viscosity": 1.0, "temperature": 40.0}


def pad_samples(s: Samples, size: int) -> Samples:
    """Samples padded to ``size`` with harmless values (weights there are zero)."""
    n = int(np.asarray(s.theta).size)
    return Samples(*[
        np.concatenate([np.asarray(f, dtype=np.float64), np.full(size - n, _PAD.get(name, 0.0))])
        for name, f in zip(Samples._fields, s)
    ])


#: the padded running samples of each dataset, shared by every Problem made from it (diagnose
#: makes several: base fit, screening cells, finalists, final fit; each copy is ~20 MB per
#: 100 k rows).  Keyed by id (a Dataset is not hashable), dropped with the dataset.
_PADDED: dict = {}


def _padded_running(data, size: int) -> Samples:
    """``pad_samples(data.running, size)``, made once per dataset (and running samples)."""
    key = id(data)
    cached = _PADDED.get(key)
    if cached is not None and cached[0]() is data and cached[1] is data.running and cached[2] == size:
        return cached[3]
    padded = pad_samples(data.running, size)
    try:
        ref = weakref.ref(data, lambda _, k=key: _PADDED.pop(k, None))
    except TypeError:  # not weakly referenceable: no sharing
        return padded
    _PADDED[key] = (ref, data.running, size, padded)
    return padded


def pad(x, size: int, value: float = 0.0):
    x = np.asarray(x, dtype=float)
    return np.concatenate([x, np.full(size - x.size, value)])


class Problem:
    """The data of a fit, per sample and reduced to cells for the optimizer.

    The optimizer sees cell means: samples of one run that share a shaft-angle
    bin (``bins_per_pitch`` per piston pitch, over the whole revolution so that
    shaft-order effects survive).  Inside a steady run speed, pressures and
    viscosity hardly change, so the model of the cell mean is the mean of the
    model; the parameter-free S(θ) is averaged exactly, and the viscosity as its
    harmonic mean (the leakage goes as 1/μ).  The fit then costs the same for
    10 k or 3 M rows of the same runs.

    A dataset already reduced to cells as it was read (``data.cells``, see
    :mod:`motorid.identify.cells`) has one row per cell: each row then counts with
    its number of samples (``cells.n`` for the inputs, ``cells.counts`` per channel).
    """

    def __init__(self, data, spec, free, held, mechanisms, bins_per_pitch=48):
        self.data, self.spec, self.free, self.held = data, spec, list(free), dict(held)
        self.mechanisms = tuple(mechanisms)
        self.block = 0  # cells per block of the blockwise Jacobians (0: BLOCK)
        self.has_running = data.running is not None and int(np.asarray(data.running.theta).size) > 0
        self.has_events = data.events is not None and int(np.asarray(data.held_torque).size) > 0
        self.measured = {c: np.asarray(data.measured[c], dtype=float) for c in RUNNING_CHANNELS} if self.has_running else {}
        self.held_torque = np.asarray(data.held_torque, dtype=float) if self.has_events else np.zeros(0)
        self.run_of = np.asarray(data.run_of_sample, dtype=int) if self.has_running else np.zeros(0, int)
        self.n_samples, self.n_cells = 0, 0
        stats = getattr(data, "cells", None) if self.has_running else None
        # samples behind each row: None where each row is one sample
        self.row_n = None if stats is None else np.asarray(stats.n, dtype=float)
        self.row_counts = None if stats is None else {c: np.asarray(stats.counts[c], dtype=float)
                                                      for c in RUNNING_CHANNELS}
        self.viscosity_basis = None  # cell means of the viscosity curve's Chebyshev basis (reduced data)
        if self.has_running:
            bins = bins_per_pitch * spec.pistons
            theta = np.mod(np.asarray(data.running.theta), 2 * np.pi)
            b = np.minimum((theta / (2 * np.pi) * bins).astype(np.int64), bins - 1)
            key = self.run_of.astype(np.int64) * bins + b
            # cells numbered in key order: a counting pass instead of a sort
            occupied = np.bincount(key, minlength=int(key.max()) + 1) > 0
            self.cell_of = (np.cumsum(occupied) - 1)[key]
            self.n_cells = int(occupied.sum())
            counts = np.bincount(self.cell_of, minlength=self.n_cells).astype(float)
            weigh = (lambda x: x) if self.row_n is None else (lambda x: x * self.row_n)  # noqa: E731
            if self.row_n is not None:
                counts = np.bincount(self.cell_of, weights=self.row_n, minlength=self.n_cells)
                self.viscosity_basis = np.stack([
                    np.bincount(self.cell_of, weights=weigh(col), minlength=self.n_cells) / counts
                    for col in np.asarray(stats.viscosity_basis, dtype=float).T], axis=1)
            self.cell_run = np.zeros(self.n_cells, int)
            self.cell_run[self.cell_of] = self.run_of
            self.cell_size = bucket(self.n_cells)
            # cell means; θ wrapped first (a bin never straddles the wrap), so that
            # samples of one bin from different revolutions average to that bin
            fields = data.running._replace(theta=theta)
            means = Samples(*[
                np.bincount(self.cell_of, weights=weigh(np.asarray(f, dtype=float)), minlength=self.n_cells) / counts
                for f in fields
            ])
            # the leakage flows go as 1/μ: the cell's viscosity is the harmonic mean of its
            # samples', so that the cell's leakage is their mean leakage (Jensen: the plain
            # mean would make the model's leakage too small by var(μ)/μ² and bias K_L, K_AB up;
            # on the demo campaign by 8.6·10⁻⁶, a quarter of K_L0's standard error).  The viscous
            # torque, ∝ μ, then sees the harmonic mean: off by the same var(μ)/μ² of its size,
            # a thousandth of K_v's standard error there
            with np.errstate(divide="ignore", invalid="ignore"):
                inv = np.bincount(self.cell_of, weights=weigh(1.0 / np.asarray(data.running.viscosity, dtype=float)),
                                  minlength=self.n_cells) / counts
                means = means._replace(viscosity=np.where(inv > 0, 1.0 / inv, means.viscosity))
            self.cell_samples = pad_samples(means, self.cell_size)
            self.n_samples = int(self.run_of.size)
            self.running_padded = _padded_running(data, bucket(self.n_samples))
        if self.has_events:
            self.n_events = int(self.held_torque.size)
            self.events_padded = pad_samples(data.events, bucket(self.n_events, 16))
        self.cells = None  # (observed, weights) per channel over the cells: set_cells
        self.cells_version = 0  # counts set_cells calls (a compression of older cells is stale)
        # the exact quadratic expansion of the cell predictions over the free parameters
        # named by expansion_key (None: not built, or the model is not quadratic), and the
        # compressed backend of the current cells (motorid.identify.solver.backend)
        self.expansion, self.expansion_key, self.compressed = None, None, None

    def n_real(self, channel: str) -> int:
        """How many of a channel's (padded) cells or events are real."""
        return getattr(self, "n_events", 0) if channel == "breakaway" else self.n_cells

    def observed(self):
        out = dict(self.measured)
        if self.has_events:
            out["breakaway"] = self.held_torque
        return out

    def set_cells(self, inliers: dict, sigma_runs: dict, sigma_breakaway):
        """Cell means of each channel over its inlier samples, and their weights."""
        obs, w = {}, {}
        for c in RUNNING_CHANNELS if self.has_running else ():
            ok = inliers[c]
            y = np.where(ok, self.measured[c], 0.0)
            if self.row_counts is None:
                cnt = np.bincount(self.cell_of, weights=ok.astype(float), minlength=self.n_cells)
                tot = np.bincount(self.cell_of, weights=y, minlength=self.n_cells)
            else:  # rows that are cells: each counts with its inlier samples
                k = np.where(ok, self.row_counts[c], 0.0)
                cnt = np.bincount(self.cell_of, weights=k, minlength=self.n_cells)
                tot = np.bincount(self.cell_of, weights=y * k, minlength=self.n_cells)
            obs[c] = pad(np.where(cnt > 0, tot / np.maximum(cnt, 1), 0.0), self.cell_size)
            w[c] = pad(np.sqrt(cnt) / sigma_runs[c][self.cell_run], self.cell_size)
        if self.has_events:
            ok = inliers["breakaway"]
            size = int(np.asarray(self.events_padded.theta).size)
            obs["breakaway"] = pad(np.where(ok, self.held_torque, 0.0), size)
            w["breakaway"] = pad(np.where(ok, 1.0 / np.broadcast_to(sigma_breakaway, ok.shape), 0.0), size)
        self.cells = (obs, w)
        self.cells_version += 1

    def entry_runs(self, data) -> dict:
        """Per channel of :attr:`cells`: the run of each cell (each breakaway event for
        ``"breakaway"``, from ``data.run_of_event``), −1 for the padding."""
        w = self.cells[1]
        out = {}
        for c in w:
            runs = (np.asarray(getattr(data, "run_of_event", np.zeros(0, int)), dtype=int) if c == "breakaway"
                    else np.asarray(self.cell_run, dtype=int))
            out[c] = np.concatenate([runs, np.full(max(w[c].size - runs.size, 0), -1)])
        return out

    def ctx(self, scales=None) -> Ctx:
        free = tuple(self.free)
        if scales is None:
            scales = np.ones(len(free))
        positive = tuple(bool(model.parameter_info(k, self.mechanisms).positive) for k in free)
        obs, w = self.cells
        return Ctx(
            spec=self.spec, mechanisms=self.mechanisms, free=free, positive=positive,
            scales=np.asarray(scales, dtype=np.float64),
            held={k: np.asarray(v, dtype=np.float64) for k, v in self.held.items()},
            running=self.cell_samples if self.has_running else None,
            events=self.events_padded if self.has_events else None,
            observed=obs, weights=w, block=self.block,
        )

    def predictions(self, values: dict) -> dict:
        """Per-sample predictions of every channel (not the cells)."""
        ctx = Ctx(
            spec=self.spec, mechanisms=self.mechanisms, free=tuple(self.free), positive=(),
            scales=np.zeros(0), held={k: np.asarray(v, dtype=np.float64) for k, v in self.held.items()},
            running=self.running_padded if self.has_running else None,
            events=self.events_padded if self.has_events else None, observed={}, weights={},
        )
        out = predictions_jit(as_arrays(values), ctx)
        n = {c: self.n_samples for c in RUNNING_CHANNELS}
        n["breakaway"] = getattr(self, "n_events", 0)
        return {c: np.asarray(v)[: n[c]] for c, v in out.items()}
