"""A jaxpr flattened to one straight-line program, for the code emitters.

Nested calls (``jit``/``pjit``, ``closed_call``, ``custom_jvp_call``,
``custom_vjp_call``, ``remat``) are inlined; ``iota`` is folded to a constant;
literals and closed-over constants become :class:`Value` objects that carry
their value.  The emitters (:mod:`motorid.export.jaxpr_c`,
:mod:`motorid.export.jaxpr_numpy`) translate the resulting list of
:class:`Op` one by one and refuse any primitive they do not know, naming it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from jax.extend import core as jcore

from motorid.errors import MotorIdError


class UnsupportedPrimitive(MotorIdError):
    """The traced model uses a primitive the emitter cannot translate."""


@dataclass(eq=False)
class Value:
    """One array of the program: a static shape, a dtype, and a value if it is a constant."""

    index: int
    shape: tuple
    dtype: np.dtype
    const: np.ndarray | None = None

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def name(self) -> str:
        return f"v{self.index}"


@dataclass
class Op:
    """One primitive application: ``outs = prim[params](*ins)``."""

    prim: str
    params: dict
    ins: list
    outs: list


@dataclass
class Program:
    inputs: list
    outputs: list
    ops: list = field(default_factory=list)
    constants: list = field(default_factory=list)  # Values with an array value (not scalars)


#: call-like primitives whose body is inlined, and the parameter holding it
_CALLS = {"pjit": "jaxpr", "jit": "jaxpr", "closed_call": "call_jaxpr", "core_call": "call_jaxpr",
          "custom_jvp_call": "call_jaxpr", "custom_vjp_call": "call_jaxpr",
          "custom_vjp_call_jaxpr": "fun_jaxpr", "remat": "jaxpr", "checkpoint": "jaxpr"}


def _open(j):
    """(Jaxpr, consts) of a Jaxpr or ClosedJaxpr."""
    if hasattr(j, "jaxpr") and hasattr(j, "consts"):
        return j.jaxpr, list(j.consts)
    return j, []


def flatten(closed_jaxpr) -> Program:
    """Flatten a closed jaxpr into a :class:`Program` (see the module docstring)."""
    counter = iter(range(1 << 30))
    prog = Program(inputs=[], outputs=[])

    def new(aval, const=None) -> Value:
        v = Value(next(counter), tuple(int(d) for d in aval.shape), np.dtype(aval.dtype), const)
        if const is not None and v.shape != ():
            prog.constants.append(v)
        return v

    def constant(x) -> Value:
        arr = np.asarray(x)
        v = Value(next(counter), tuple(arr.shape), arr.dtype, arr)
        if v.shape != ():
            prog.constants.append(v)
        return v

    def run(jaxpr, consts, args) -> list:
        env = {}
        for var, c in zip(jaxpr.constvars, consts):
            env[var] = constant(c)
        for var, a in zip(jaxpr.invars, args):
            env[var] = a

        def read(atom):
            if isinstance(atom, jcore.Literal):
                return constant(atom.val)
            return env[atom]

        for eqn in jaxpr.eqns:
            name = eqn.primitive.name
            ins = [read(a) for a in eqn.invars]
            if name in _CALLS:
                key = _CALLS[name] if _CALLS[name] in eqn.params else next(
                    (k for k in ("jaxpr", "call_jaxpr", "fun_jaxpr") if k in eqn.params), None)
                if key is None:
                    raise UnsupportedPrimitive(f"call primitive '{name}' without a body the emitter knows")
                body, body_consts = _open(eqn.params[key])
                n_in = len(body.invars)
                outs = run(body, body_consts, ins[len(ins) - n_in:])
            elif name == "iota":
                p = eqn.params
                shape, dim = tuple(p["shape"]), p["dimension"]
                arr = np.broadcast_to(np.arange(shape[dim]).reshape(
                    [shape[dim] if k == dim else 1 for k in range(len(shape))]), shape)
                outs = [constant(np.asarray(arr, dtype=np.dtype(p["dtype"])))]
            else:
                outs = [new(v.aval) for v in eqn.outvars]
                prog.ops.append(Op(name, dict(eqn.params), ins, outs))
            for var, val in zip(eqn.outvars, outs):
                if not isinstance(var, jcore.DropVar):
                    env[var] = val
        return [read(a) for a in jaxpr.outvars]

    jaxpr, consts = _open(closed_jaxpr)
    prog.inputs = [new(v.aval) for v in jaxpr.invars]
    prog.outputs = run(jaxpr, consts, prog.inputs)
    return prog


def broadcast_index(in_shape, out_shape, dims) -> np.ndarray:
    """Flat input index of each output element of ``broadcast_in_dim``."""
    expanded = [1] * len(out_shape)
    for k, d in enumerate(dims):
        expanded[d] = in_shape[k]
    src = np.arange(int(np.prod(in_shape, dtype=np.int64))).reshape(expanded)
    return np.broadcast_to(src, out_shape).ravel()


def reduce_index(in_shape, axes) -> np.ndarray:
    """Flat output index of each input element of a reduction over ``axes``."""
    kept = [1 if k in axes else n for k, n in enumerate(in_shape)]
    dst = np.arange(int(np.prod(kept, dtype=np.int64))).reshape(kept)
    return np.broadcast_to(dst, in_shape).ravel()


def transpose_index(in_shape, permutation) -> np.ndarray:
    """Flat input index of each output element of a transpose."""
    return np.arange(int(np.prod(in_shape, dtype=np.int64))).reshape(in_shape).transpose(permutation).ravel()


def integer_power_steps(y: int):
    """The multiplications of ``integer_pow`` as JAX lowers it (binary powering).

    returns (steps, reciprocal): steps of "set_acc" (acc = x), "mul_acc"
    (acc = acc·x) and "square" (x = x·x), in order; reciprocal: the result is 1/acc.
    y = 0 gives no step (the result is 1).
    """
    steps, reciprocal = [], y < 0
    y = abs(y)
    have_acc = False
    while y > 0:
        if y & 1:
            steps.append("mul_acc" if have_acc else "set_acc")
            have_acc = True
        y >>= 1
        if y > 0:
            steps.append("square")
    return steps, reciprocal
