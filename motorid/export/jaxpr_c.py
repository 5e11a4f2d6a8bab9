"""A small jaxpr → C99 translator: the traced motor model as one C function.

Every array of the jaxpr becomes a C ``double`` (scalars) or ``double[N]``
(flattened, row-major); booleans are 0.0/1.0 and integers are exact in a
double.  Elementwise primitives become one expression (a loop for arrays);
data movement (``broadcast_in_dim``, ``reshape``, ``transpose``, ``slice``)
and reductions over an axis (``reduce_sum/max/min``) become a loop over an
index table computed here with NumPy.  ``integer_pow`` is multiplied out as
JAX lowers it (binary powering).  Any other primitive raises
:class:`UnsupportedPrimitive` naming it: a model the emitter cannot translate
is refused, never approximated.

The generated code calls only <math.h> and evaluates the same operations in
the same order as the jaxpr, so it agrees with JAX to rounding (a few ulp of
the libm functions).
"""

from __future__ import annotations

import math

import numpy as np

from motorid.export.jaxpr_flat import (Program, UnsupportedPrimitive, Value, broadcast_index, flatten,
                                       integer_power_steps, reduce_index, transpose_index)

_UNARY = {
    "neg": "(-{0})", "sin": "sin({0})", "cos": "cos({0})", "tan": "tan({0})",
    "asin": "asin({0})", "acos": "acos({0})", "atan": "atan({0})",
    "sinh": "sinh({0})", "cosh": "cosh({0})", "tanh": "tanh({0})",
    "asinh": "asinh({0})", "acosh": "acosh({0})", "atanh": "atanh({0})",
    "exp": "exp({0})", "exp2": "exp2({0})", "expm1": "expm1({0})",
    "log": "log({0})", "log1p": "log1p({0})",
    "sqrt": "sqrt({0})", "rsqrt": "(1.0 / sqrt({0}))", "cbrt": "cbrt({0})",
    "abs": "fabs({0})", "sign": "(isnan({0}) ? {0} : (double)(({0} > 0.0) - ({0} < 0.0)))",
    "floor": "floor({0})", "ceil": "ceil({0})", "round": "round({0})",
    "logistic": "(1.0 / (1.0 + exp(-{0})))", "square": "({0} * {0})",
    "erf": "erf({0})", "erfc": "erfc({0})",
    "not": "(double)({0} == 0.0)", "is_finite": "(double)isfinite({0})",
    "copy": "{0}", "copy_p": "{0}", "stop_gradient": "{0}", "real": "{0}",
}
_BINARY = {
    "add": "({0} + {1})", "sub": "({0} - {1})", "mul": "({0} * {1})", "div": "({0} / {1})",
    "pow": "pow({0}, {1})", "atan2": "atan2({0}, {1})", "rem": "fmod({0}, {1})",
    "max": "((isnan({0}) || {0} > {1}) ? {0} : {1})", "min": "((isnan({0}) || {0} < {1}) ? {0} : {1})",
    "gt": "(double)({0} > {1})", "lt": "(double)({0} < {1})", "ge": "(double)({0} >= {1})",
    "le": "(double)({0} <= {1})", "eq": "(double)({0} == {1})", "ne": "(double)({0} != {1})",
    "and": "(double)(({0} != 0.0) && ({1} != 0.0))", "or": "(double)(({0} != 0.0) || ({1} != 0.0))",
    "xor": "(double)(({0} != 0.0) != ({1} != 0.0))", "nextafter": "nextafter({0}, {1})",
}
_MOVES = ("broadcast_in_dim", "reshape", "squeeze", "expand_dims", "transpose", "slice")
_REDUCTIONS = {"reduce_sum": ("0.0", "{o} += {x};"), "reduce_prod": ("1.0", "{o} *= {x};"),
               "reduce_max": ("-INFINITY", "if (!({o} >= {x})) {o} = {x};"),
               "reduce_min": ("INFINITY", "if (!({o} <= {x})) {o} = {x};")}

#: the primitives this emitter translates
SUPPORTED = frozenset(_UNARY) | frozenset(_BINARY) | frozenset(_MOVES) | frozenset(_REDUCTIONS) | {
    "select_n", "convert_element_type", "integer_pow", "clamp"}


def c_literal(x) -> str:
    """A C double literal that reads back to exactly ``x`` (17 significant digits)."""
    x = float(x)
    if math.isnan(x):
        return "NAN"
    if math.isinf(x):
        return "INFINITY" if x > 0 else "(-INFINITY)"
    text = repr(x)
    if "e" not in text and "." not in text and "inf" not in text:
        text += ".0"
    return f"({text})" if x < 0 or text.startswith("-") else text


def _movement_index(op) -> np.ndarray:
    x, out = op.ins[0], op.outs[0]
    p = op.params
    if op.prim == "broadcast_in_dim":
        return broadcast_index(x.shape, out.shape, tuple(p["broadcast_dimensions"]))
    if op.prim == "transpose":
        return transpose_index(x.shape, tuple(p["permutation"]))
    if op.prim == "slice":
        strides = p.get("strides") or (1,) * len(x.shape)
        sl = tuple(slice(a, b, s) for a, b, s in zip(p["start_indices"], p["limit_indices"], strides))
        return np.arange(x.size).reshape(x.shape)[sl].ravel()
    return np.arange(x.size)  # reshape, squeeze, expand_dims: row-major order kept


class _Emitter:
    def __init__(self, prog: Program):
        self.prog = prog
        self.lines: list[str] = []
        self.tables: list[str] = []
        self.n_tables = 0

    def ref(self, v: Value, i: str | int = "i") -> str:
        if v.shape == ():
            return c_literal(v.const) if v.const is not None else v.name
        return f"{v.name}[{i}]"

    def table(self, index: np.ndarray) -> str:
        name = f"idx{self.n_tables}"
        self.n_tables += 1
        body = ", ".join(str(int(k)) for k in index)
        self.tables.append(f"static const int {name}[{len(index)}] = {{{body}}};")
        return name

    def define(self, out: Value, expr_of_i) -> None:
        """out = expr elementwise; expr_of_i(i) gives the expression at index i."""
        if out.shape == ():
            self.lines.append(f"const double {out.name} = {expr_of_i('0')};")
        else:
            self.lines.append(f"double {out.name}[{out.size}];")
            self.lines.append(f"for (int i = 0; i < {out.size}; ++i) {out.name}[i] = {expr_of_i('i')};")

    def op(self, op) -> None:
        prim, ins, out = op.prim, op.ins, op.outs[0] if op.outs else None
        if prim in _UNARY:
            self.define(out, lambda i: _UNARY[prim].format(self.ref(ins[0], i)))
        elif prim in _BINARY:
            fmt = _BINARY[prim]
            if prim == "div" and np.issubdtype(out.dtype, np.integer):
                fmt = "trunc({0} / {1})"
            self.define(out, lambda i: fmt.format(self.ref(ins[0], i), self.ref(ins[1], i)))
        elif prim == "clamp":
            self.define(out, lambda i: "fmin(fmax({1}, {0}), {2})".format(*(self.ref(v, i) for v in ins)))
        elif prim == "select_n":
            def expr(i):
                pred, cases = self.ref(ins[0], i), [self.ref(c, i) for c in ins[1:]]
                if len(cases) == 2:
                    return f"(({pred}) != 0.0 ? {cases[1]} : {cases[0]})"
                text = cases[-1]
                for k in range(len(cases) - 2, -1, -1):
                    text = f"(({pred}) == {k}.0 ? {cases[k]} : {text})"
                return text
            self.define(out, expr)
        elif prim == "convert_element_type":
            new = np.dtype(op.params["new_dtype"])
            if new == np.bool_:
                fmt = "(double)({0} != 0.0)"
            elif np.issubdtype(new, np.integer):
                fmt = "trunc({0})"
            elif new == np.float32:
                fmt = "(double)(float)({0})"
            elif new == np.float64:
                fmt = "{0}"
            else:
                raise UnsupportedPrimitive(f"convert_element_type to {new} is not supported by the C emitter")
            self.define(out, lambda i: fmt.format(self.ref(ins[0], i)))
        elif prim == "integer_pow":
            self.integer_pow(ins[0], out, int(op.params["y"]))
        elif prim in _MOVES:
            x = ins[0]
            index = _movement_index(op)
            if x.shape == ():
                self.define(out, lambda i: self.ref(x))
            elif out.shape == ():
                self.define(out, lambda i: f"{x.name}[{int(index[0])}]")
            else:
                t = self.table(index)
                self.define(out, lambda i: f"{x.name}[{t}[{i}]]")
        elif prim in _REDUCTIONS:
            x = ins[0]
            init, update = _REDUCTIONS[prim]
            if x.shape == ():
                self.define(out, lambda i: self.ref(x))
                return
            axes = tuple(op.params["axes"])
            if out.shape == ():
                self.lines.append(f"double {out.name} = {init};")
                self.lines.append(f"for (int i = 0; i < {x.size}; ++i) {update.format(o=out.name, x=x.name + '[i]')}")
            else:
                t = self.table(reduce_index(x.shape, axes))
                self.lines.append(f"double {out.name}[{out.size}];")
                self.lines.append(f"for (int i = 0; i < {out.size}; ++i) {out.name}[i] = {init};")
                self.lines.append(f"for (int i = 0; i < {x.size}; ++i) "
                                  f"{update.format(o=f'{out.name}[{t}[i]]', x=x.name + '[i]')}")
        else:
            raise UnsupportedPrimitive(
                f"the C emitter has no translation for the JAX primitive '{prim}' "
                f"(supported: {', '.join(sorted(SUPPORTED))})")

    def integer_pow(self, x: Value, out: Value, y: int) -> None:
        steps, reciprocal = integer_power_steps(y)
        if not steps:
            self.define(out, lambda i: "1.0")
            return

        def expr(i):
            text_x, text_acc = self.ref(x, i), None
            for s in steps:  # nested expressions: small exponents only, as in a model
                if s == "set_acc":
                    text_acc = text_x
                elif s == "mul_acc":
                    text_acc = f"({text_acc} * {text_x})"
                else:
                    text_x = f"({text_x} * {text_x})"
            return f"(1.0 / {text_acc})" if reciprocal else text_acc
        self.define(out, expr)

    def constants(self) -> list[str]:
        out = []
        for v in self.prog.constants:
            body = ", ".join(c_literal(c) for c in np.asarray(v.const, dtype=np.float64).ravel())
            out.append(f"static const double {v.name}[{v.size}] = {{{body}}};")
        return out


def emit_c_function(closed_jaxpr, name: str = "model_evaluate") -> str:
    """C99 source of ``static void name(const double *u, double *y)``.

    u : the jaxpr's scalar inputs in order; y : its scalar outputs in order.
    Raises :class:`UnsupportedPrimitive` for a primitive it cannot translate and
    ``ValueError`` where an input or output is not a scalar.
    """
    prog = flatten(closed_jaxpr)
    for v in prog.inputs + prog.outputs:
        if v.shape != ():
            raise ValueError(f"the C emitter takes scalar inputs and outputs, got shape {v.shape}")
    em = _Emitter(prog)
    for k, v in enumerate(prog.inputs):
        em.lines.append(f"const double {v.name} = u[{k}];")
    for op in prog.ops:
        em.op(op)
    for k, v in enumerate(prog.outputs):
        em.lines.append(f"y[{k}] = {em.ref(v)};")
    body = "\n".join("    " + line for line in em.lines)
    head = "\n".join(em.constants() + em.tables)
    return (f"{head}\n\nstatic void {name}(const double *u, double *y)\n{{\n{body}\n}}\n")
