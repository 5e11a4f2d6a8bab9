"""A small jaxpr → NumPy translator: the traced motor model as NumPy source.

The jaxpr is traced at scalar inputs; the generated code lets every value
carry any leading batch shape in front of the jaxpr's own (static) shape, so
the same function takes scalars or arrays of operating points.  Elementwise
primitives broadcast as NumPy does; data movement and reductions address the
jaxpr's own axes from the right.  Any primitive it does not know raises
:class:`UnsupportedPrimitive` naming it.
"""

from __future__ import annotations

import math

import numpy as np

from motorid.export.jaxpr_flat import Program, UnsupportedPrimitive, Value, flatten, integer_power_steps

_UNARY = {
    "neg": "-{0}", "sin": "np.sin({0})", "cos": "np.cos({0})", "tan": "np.tan({0})",
    "asin": "np.arcsin({0})", "acos": "np.arccos({0})", "atan": "np.arctan({0})",
    "sinh": "np.sinh({0})", "cosh": "np.cosh({0})", "tanh": "np.tanh({0})",
    "asinh": "np.arcsinh({0})", "acosh": "np.arccosh({0})", "atanh": "np.arctanh({0})",
    "exp": "np.exp({0})", "exp2": "np.exp2({0})", "expm1": "np.expm1({0})",
    "log": "np.log({0})", "log1p": "np.log1p({0})",
    "sqrt": "np.sqrt({0})", "rsqrt": "1.0 / np.sqrt({0})", "cbrt": "np.cbrt({0})",
    "abs": "np.abs({0})", "sign": "np.sign({0})", "floor": "np.floor({0})", "ceil": "np.ceil({0})",
    "logistic": "1.0 / (1.0 + np.exp(-{0}))", "square": "{0} * {0}",
    "not": "np.logical_not({0})", "is_finite": "np.isfinite({0})",
    "copy": "{0}", "copy_p": "{0}", "stop_gradient": "{0}", "real": "{0}",
}
_BINARY = {
    "add": "{0} + {1}", "sub": "{0} - {1}", "mul": "{0} * {1}", "div": "{0} / {1}",
    "pow": "np.power({0}, {1})", "atan2": "np.arctan2({0}, {1})", "rem": "np.fmod({0}, {1})",
    "max": "np.maximum({0}, {1})", "min": "np.minimum({0}, {1})",
    "gt": "np.greater({0}, {1})", "lt": "np.less({0}, {1})", "ge": "np.greater_equal({0}, {1})",
    "le": "np.less_equal({0}, {1})", "eq": "np.equal({0}, {1})", "ne": "np.not_equal({0}, {1})",
    "and": "np.logical_and({0}, {1})", "or": "np.logical_or({0}, {1})", "xor": "np.logical_xor({0}, {1})",
    "nextafter": "np.nextafter({0}, {1})",
}
_REDUCTIONS = {"reduce_sum": "np.sum", "reduce_prod": "np.prod", "reduce_max": "np.max", "reduce_min": "np.min"}

#: helpers the generated module defines (batch-aware data movement)
HELPERS = '''
def _broadcast_in_dim(x, in_ndim, shape, dims):
    """jax.lax.broadcast_in_dim on the trailing in_ndim axes of x, keeping its leading (batch) axes."""
    lead = x.shape[:x.ndim - in_ndim]
    expanded = [1] * len(shape)
    for k, d in enumerate(dims):
        expanded[d] = x.shape[len(lead) + k]
    return np.broadcast_to(x.reshape(lead + tuple(expanded)), lead + tuple(shape))


def _transpose(x, permutation):
    """transpose of the trailing len(permutation) axes of x."""
    lead = x.ndim - len(permutation)
    return x.transpose(tuple(range(lead)) + tuple(lead + p for p in permutation))


def _reshape(x, in_ndim, shape):
    """reshape of the trailing in_ndim axes of x."""
    return x.reshape(x.shape[:x.ndim - in_ndim] + tuple(shape))
'''


def py_literal(x) -> str:
    """A Python float literal that reads back to exactly ``x``."""
    x = float(x)
    if math.isnan(x):
        return "np.nan"
    if math.isinf(x):
        return "np.inf" if x > 0 else "-np.inf"
    return f"({x!r})" if x < 0 else repr(x)


class _Emitter:
    def __init__(self, prog: Program):
        self.prog = prog
        self.lines: list[str] = []

    def ref(self, v: Value) -> str:
        if v.const is not None and v.shape == ():
            if v.dtype == np.bool_:
                return "np.True_" if bool(v.const) else "np.False_"
            return py_literal(v.const)
        return v.name

    def set(self, out: Value, expr: str) -> None:
        self.lines.append(f"{out.name} = {expr}")

    def op(self, op) -> None:
        prim, ins, out = op.prim, op.ins, op.outs[0] if op.outs else None
        r = [self.ref(v) for v in ins]
        if prim in _UNARY:
            self.set(out, "np.asarray(" + _UNARY[prim].format(*r) + ")")
        elif prim in _BINARY:
            expr = _BINARY[prim].format(*r)
            if prim == "div" and np.issubdtype(out.dtype, np.integer):
                expr = f"np.trunc({expr})"
            self.set(out, f"np.asarray({expr})")
        elif prim == "clamp":
            self.set(out, f"np.minimum(np.maximum({r[1]}, {r[0]}), {r[2]})")
        elif prim == "select_n":
            if len(r) == 3:
                self.set(out, f"np.where({r[0]}, {r[2]}, {r[1]})")
            else:
                self.set(out, f"np.choose(np.asarray({r[0]}, dtype=int), [{', '.join(r[1:])}])")
        elif prim == "convert_element_type":
            new = np.dtype(op.params["new_dtype"])
            if new == np.bool_:
                self.set(out, f"np.not_equal({r[0]}, 0)")
            elif np.issubdtype(new, np.integer):
                self.set(out, f"np.trunc({r[0]})")
            elif new in (np.float64, np.float32):
                self.set(out, f"np.asarray({r[0]}, dtype=np.{new.name})")
            else:
                raise UnsupportedPrimitive(f"convert_element_type to {new} is not supported by the NumPy emitter")
        elif prim == "integer_pow":
            steps, reciprocal = integer_power_steps(int(op.params["y"]))
            x, acc = r[0], None
            for s in steps:
                if s == "set_acc":
                    acc = x
                elif s == "mul_acc":
                    acc = f"({acc} * {x})"
                else:
                    x = f"({x} * {x})"
            expr = "np.ones_like(np.asarray({0}, dtype=float))".format(r[0]) if acc is None else acc
            self.set(out, f"np.asarray(1.0 / {expr})" if reciprocal else f"np.asarray({expr})")
        elif prim == "broadcast_in_dim":
            x = ins[0]
            self.set(out, f"_broadcast_in_dim(np.asarray({r[0]}), {len(x.shape)}, {tuple(out.shape)!r}, "
                          f"{tuple(op.params['broadcast_dimensions'])!r})")
        elif prim in ("reshape", "squeeze", "expand_dims"):
            self.set(out, f"_reshape(np.asarray({r[0]}), {len(ins[0].shape)}, {tuple(out.shape)!r})")
        elif prim == "transpose":
            self.set(out, f"_transpose(np.asarray({r[0]}), {tuple(int(k) for k in op.params['permutation'])!r})")
        elif prim in _REDUCTIONS:
            nd = len(ins[0].shape)
            axes = tuple(int(a) - nd for a in op.params["axes"])
            self.set(out, f"{_REDUCTIONS[prim]}({r[0]}, axis={axes!r})" if axes else f"np.asarray({r[0]})")
        else:
            raise UnsupportedPrimitive(f"the NumPy emitter has no translation for the JAX primitive '{prim}'")


def emit_numpy_function(closed_jaxpr, name: str, arg_names, out_names, doc: str = "") -> str:
    """Python source of ``def name(*arg_names) -> dict`` evaluating the jaxpr with NumPy.

    The inputs are broadcast together first; every output has their common shape.
    """
    prog = flatten(closed_jaxpr)
    if len(prog.inputs) != len(arg_names) or len(prog.outputs) != len(out_names):
        raise ValueError("names do not match the jaxpr's inputs and outputs")
    em = _Emitter(prog)
    lines = []
    for v in prog.constants:
        values = ", ".join(py_literal(c) for c in np.asarray(v.const, dtype=np.float64).ravel())
        lines.append(f"_{v.name} = np.array([{values}], dtype=np.float64).reshape({tuple(v.shape)!r})")
    head = "\n".join(lines)
    body = [f"{', '.join(arg_names)}, = np.broadcast_arrays("
            + ", ".join(f"np.asarray({a}, dtype=np.float64)" for a in arg_names) + ")"]
    for v, a in zip(prog.inputs, arg_names):
        body.append(f"{v.name} = {a}")
    for v in prog.constants:
        body.append(f"{v.name} = _{v.name}")
    for op in prog.ops:
        em.op(op)
    body += em.lines
    outs = ", ".join(f"{n!r}: np.broadcast_to({em.ref(v)}, {arg_names[0]}.shape).astype(np.float64)"
                     for n, v in zip(out_names, prog.outputs))
    body.append(f"return {{{outs}}}")
    text = "\n".join("    " + b for b in body)
    return f"{head}\n\n\ndef {name}({', '.join(arg_names)}):\n    \"\"\"{doc}\"\"\"\n{text}\n"
