"""The solvers of the fit: Gauss-Newton start, then Levenberg-Marquardt (optimistix).

Two backends see the same problem: the full residual through the JAX model
(:class:`FullBackend`; on many cells, Levenberg-Marquardt on normal equations built
block by block), and its exact compression where the model is quadratic
in the free parameters (:class:`CompressedBackend`, :mod:`motorid.identify.compress`).
Both solve in unconstrained coordinates (log for the positive parameters, scaled).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from motorid import model
from motorid._aot import cached_jit
from motorid.identify.compress import Expansion
from motorid.identify.identifiability import null_space_reasons
from motorid.identify.problem import (BLOCK, Ctx, Problem, as_arrays, from_unconstrained, normal_blockwise,
                                      normal_equations, residual_jit, residual_unconstrained, to_unconstrained)
from motorid.identify.types import FitOptions


def parameter_scales(values: dict, free: list, mechanisms) -> np.ndarray:
    """Working scale of each free parameter: its current size, or its typical one at 0."""
    return np.array([abs(values[k]) or model.parameter_info(k, mechanisms).typical for k in free])


_SOLVER = []


def _optimistix():
    """(optimistix, the damped normal-equation solver), imported when a solver is first
    traced: a run whose compiled solvers come from disk (motorid._aot) never pays
    the import of optimistix, lineax and equinox."""
    import optimistix

    if not _SOLVER:
        _SOLVER.append(_dense_cholesky_solver())
    return optimistix, _SOLVER[0]


def cholesky(A):
    """Lower Cholesky factor of a small SPD matrix in plain XLA operations [same units]."""
    n = A.shape[0]
    idx = jnp.arange(n)

    def column(j, L):
        s = A[:, j] - L @ L[j, :]  # columns ≥ j of L are still zero
        d = jnp.sqrt(jnp.maximum(s[j], jnp.finfo(A.dtype).tiny))
        return L.at[:, j].set(jnp.where(idx >= j, s / d, 0.0))

    return jax.lax.fori_loop(0, n, column, jnp.zeros_like(A))


def cholesky_solve(L, b):
    """x with L Lᵀ x = b: forward then backward substitution."""
    n = b.shape[0]
    y = jax.lax.fori_loop(0, n, lambda i, y: y.at[i].set((b[i] - L[i, :] @ y) / L[i, i]), jnp.zeros_like(b))

    def back(k, x):
        i = n - 1 - k
        return x.at[i].set((y[i] - L[:, i] @ x) / L[i, i])

    return jax.lax.fori_loop(0, n, back, jnp.zeros_like(b))


def _dense_cholesky_solver():
    """lineax ``Normal(Cholesky)`` for the damped system of Levenberg-Marquardt, whose
    matrix is parameters × parameters: factorized in plain XLA operations, not by
    LAPACK, so that a compiled solver loads without importing scipy.linalg."""
    import jax.flatten_util as jfu
    import lineax as lx

    class DenseCholesky(lx.AbstractLinearSolver):
        def init(self, operator, options):
            return cholesky(operator.as_matrix())

        def compute(self, state, vector, options):
            flat, unflatten = jfu.ravel_pytree(vector)
            return unflatten(cholesky_solve(state, flat)), lx.RESULTS.successful, {}

        def transpose(self, state, options):
            return state, options  # symmetric

        def conj(self, state, options):
            return state, options  # real

        def assume_full_rank(self):
            return True

    return lx.Normal(DenseCholesky())


def _run_levenberg_marquardt(residual, y0, args, rtol, atol, max_steps):
    """Optimistix LM → (y, steps, converged), arrays only (so the program can be kept on disk)."""
    # normal equations with Cholesky: the damped system is parameters × parameters,
    # eight times faster than QR of a tall Jacobian; float64 and the log/scale
    # transform keep its condition number harmless
    optx, linear_solver = _optimistix()
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=linear_solver)
    sol = optx.least_squares(residual, solver, y0, args=args, max_steps=max_steps, throw=False)
    return sol.value, sol.stats["num_steps"], sol.result == optx.RESULTS.successful


def _tolerances(opt: FitOptions) -> tuple:
    """rtol and atol as arrays: traced, so that a loose screening solve and the final one
    share one compiled program."""
    return np.asarray(opt.rtol, dtype=np.float64), np.asarray(opt.atol, dtype=np.float64)


def levenberg_marquardt_normal(normal, chi2, y0, rtol, atol, max_steps):
    """Levenberg-Marquardt on the normal equations: (y, steps, converged).

    normal(y) → (JᵀJ, Jᵀr, rᵀr) of the residual r(y); chi2(y) → rᵀr.  The matrices are
    parameters × parameters, so that the Jacobian is never held whole (``normal`` builds it
    block by block); the step solves (JᵀJ + λ diag JᵀJ) δ = −Jᵀr (Marquardt's scaling), λ
    updated from the ratio of actual to predicted decrease (Nielsen's rule).  Converged as
    optimistix's Cauchy test: an accepted step with |δ| ≤ atol + rtol |y| and a decrease of
    χ² ≤ atol + rtol χ² (or, where no step lowers χ² any more, a step that small)."""
    y = np.asarray(y0, dtype=float)
    A, g, f = (np.asarray(x, dtype=float) for x in normal(y))
    f = float(f)
    lam, nu = 1e-3, 2.0
    for step in range(1, int(max_steps) + 1):
        d = np.diag(A).copy()
        d = np.maximum(d, 1e-12 * max(float(d.max(initial=0.0)), 1e-300))
        with np.errstate(all="ignore"):
            try:
                dy = -np.linalg.solve(A + lam * np.diag(d), g)
            except np.linalg.LinAlgError:
                dy = np.full_like(y, np.nan)
        small = bool(np.all(np.abs(dy) <= atol + rtol * np.abs(y)))
        trial = y + dy
        f_new = float(chi2(trial)) if np.all(np.isfinite(dy)) else np.inf
        if np.isfinite(f_new) and f_new <= f:
            predicted = -(2.0 * g @ dy + dy @ A @ dy)
            rho = (f - f_new) / predicted if predicted > 0 else 0.0
            done = small and (f - f_new) <= atol + rtol * f
            y, f = trial, f_new
            if done:
                return y, step, True
            A, g, _ = (np.asarray(x, dtype=float) for x in normal(y))
            lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
        else:
            if small:  # no step this short lowers χ²: at the minimum to round-off
                return y, step, True
            lam *= nu
            nu *= 2.0
            if lam > 1e20:
                break
    return y, int(max_steps), False


@cached_jit
def _levenberg_marquardt(y0, ctx: Ctx, rtol, atol, max_steps):
    """Optimistix LM on the full residual → (y, steps, converged): one compiled loop, for
    problems of up to :data:`~motorid.identify.problem.BLOCK` cells (the screening cells of
    diagnose), where a Python loop's calls would cost more than the Jacobian they hold."""
    return _run_levenberg_marquardt(residual_unconstrained, y0, ctx, rtol, atol, max_steps)


@cached_jit
def _normal_unconstrained(y, ctx: Ctx):
    """JᵀJ, Jᵀr, rᵀr over the unconstrained coordinates (chain rule through the diagonal
    d values / d y: the value where log-transformed, the scale elsewhere)."""
    values = from_unconstrained(y, ctx)
    A, g, f = normal_blockwise(values, ctx)
    v = model.constrain(y, np.array(ctx.positive, dtype=bool), ctx.scales)
    dv = jnp.where(np.array(ctx.positive, dtype=bool), v, ctx.scales)
    return A * jnp.outer(dv, dv), g * dv, f


@cached_jit
def _chi2_unconstrained(y, ctx: Ctx):
    r = residual_unconstrained(y, ctx)
    return r @ r


class FullBackend:
    """The optimizer's view of the problem: every cell, through the JAX model."""

    def __init__(self, problem: Problem):
        self.problem = problem

    def normal(self, values: dict):
        JtJ, Jtr, rr = normal_equations(as_arrays(values), self.problem.ctx())
        return np.asarray(JtJ), np.asarray(Jtr), float(rr)

    def chi2(self, values: dict, ctx=None) -> float:
        return float(jnp.sum(residual_jit(as_arrays(values), ctx or self.problem.ctx()) ** 2))

    def levenberg_marquardt(self, values: dict, free: list, opt: FitOptions):
        mechs = self.problem.mechanisms
        scales = parameter_scales(values, free, mechs)
        ctx = self.problem.ctx(scales)
        y0 = np.asarray(to_unconstrained(as_arrays(values), ctx))
        if not self.problem.has_running or self.problem.cell_size <= (self.problem.block or BLOCK):
            y, steps, ok = _levenberg_marquardt(y0, ctx, *_tolerances(opt), opt.max_steps)
        else:  # many cells: the Jacobian block by block (its intermediates for every cell at once
            # were the peak memory of a fit with nonlinear mechanisms)
            y, steps, ok = levenberg_marquardt_normal(lambda y: _normal_unconstrained(y, ctx),
                                                      lambda y: _chi2_unconstrained(y, ctx), y0,
                                                      float(opt.rtol), float(opt.atol), opt.max_steps)
        new = {k: float(v) for k, v in from_unconstrained(y, ctx).items()}
        return new, int(steps), bool(ok)


class CompressedCtx(NamedTuple):
    R0: jax.Array
    R1: jax.Array
    p0: jax.Array
    a: jax.Array
    b: jax.Array
    half: jax.Array
    positive: tuple
    scales: jax.Array


def _compressed_residual(y, c: CompressedCtx):
    d = model.constrain(y, np.array(c.positive, dtype=bool), c.scales) - c.p0
    return c.R0 - c.R1 @ jnp.concatenate([d, d[c.a] * d[c.b] * c.half])


@cached_jit
def _levenberg_marquardt_compressed(y0, c: CompressedCtx, rtol, atol, max_steps):
    """Optimistix LM on the compressed residual → (y, steps, converged)."""
    return _run_levenberg_marquardt(_compressed_residual, y0, c, rtol, atol, max_steps)


class CompressedBackend:
    """The same problem through its exact compression (:mod:`motorid.identify.compress`)."""

    def __init__(self, problem: Problem, expansion):
        self.problem, self.exp = problem, expansion
        self.R0, self.R1 = expansion.compress(*problem.cells)
        self.p = len(expansion.names)

    def _delta(self, values):
        return np.array([values[k] for k in self.exp.names]) - self.exp.p0

    def residual(self, values):
        d = self._delta(values)
        return self.R0 - self.R1 @ np.concatenate([d, self.exp.products(d)])

    def jacobian(self, values):
        d = self._delta(values)
        du = np.zeros((len(self.exp.pairs), self.p))
        for k, (a, b) in enumerate(self.exp.pairs):
            du[k, a] += self.exp.half[k] * d[b]
            du[k, b] += self.exp.half[k] * d[a]
        return -(self.R1[:, : self.p] + self.R1[:, self.p:] @ du)

    def normal(self, values: dict):
        with np.errstate(over="ignore", invalid="ignore"):  # a wild trial point: the caller checks finiteness
            J, r = self.jacobian(values), self.residual(values)
            return J.T @ J, J.T @ r, float(r @ r)

    def chi2(self, values: dict, ctx=None) -> float:
        with np.errstate(over="ignore", invalid="ignore"):
            r = self.residual(values)
            return float(r @ r)

    def levenberg_marquardt(self, values: dict, free: list, opt: FitOptions):
        mechs = self.problem.mechanisms
        scales = parameter_scales(values, free, mechs)
        positive = tuple(bool(model.parameter_info(k, mechs).positive) for k in free)
        c = CompressedCtx(np.asarray(self.R0), np.asarray(self.R1), np.asarray(self.exp.p0),
                           np.asarray(self.exp.a), np.asarray(self.exp.b), np.asarray(self.exp.half),
                           positive, np.asarray(scales, dtype=np.float64))
        pos = np.array(positive)
        y0 = model.unconstrain(np.array([values[k] for k in free], dtype=float), pos, c.scales, xp=np)
        y, steps, ok = _levenberg_marquardt_compressed(y0, c, *_tolerances(opt), opt.max_steps)
        p = model.constrain(np.asarray(y), pos, c.scales, xp=np)
        new = {k: float(p[i]) for i, k in enumerate(free)}
        return new, int(steps), bool(ok)


def backend_for(problem: Problem, values: dict, free: list, opt: FitOptions):
    """The compressed problem where the model is quadratic in the free parameters, else the full one."""
    if opt.compress and free:
        key = tuple(free)
        if problem.expansion_key != key:
            problem.expansion = Expansion.build(problem, values, list(free))
            problem.expansion_key = key
        if problem.expansion is not None:
            cached = problem.compressed
            if cached is None or cached[0] != (key, problem.cells_version):
                problem.compressed = ((key, problem.cells_version), CompressedBackend(problem, problem.expansion))
            return problem.compressed[1]
    return FullBackend(problem)


#: a Gauss-Newton step that lowers χ² by less than this share of it ends the start (near an optimum the
#: steps went on lowering it by 1e-11 … 1e-16 of itself, each an evaluation of the normal equations)
GN_SETTLED = 1e-10


def gauss_newton_start(problem: Problem, values: dict, free: list, reasons: dict, opt: FitOptions):
    """A few Gauss-Newton steps in natural (scaled) coordinates: the base model is linear in
    most parameters, so they land next to the optimum from any start.  Directions the
    weighted Jacobian cannot see are found on the way (:func:`null_space_reasons`): their
    parameters are held (``problem.held``, ``reasons`` updated) → (values, free)."""
    mechs = problem.mechanisms
    for _ in range(8):
        backend = backend_for(problem, values, free, opt)
        JtJ, Jtr, before = backend.normal(values)  # rᵀr: χ² at ``values``
        scales = parameter_scales(values, free, mechs)
        with np.errstate(over="ignore", invalid="ignore"):
            JtJ, Jtr = JtJ * np.outer(scales, scales), Jtr * scales
        if not (np.all(np.isfinite(JtJ)) and np.all(np.isfinite(Jtr))):
            break  # leave a point this wild to Levenberg-Marquardt
        bad = null_space_reasons(JtJ, free, opt.null_space_tol)
        if bad:
            for k, why in bad.items():
                reasons[k] = why
                problem.held[k] = values.pop(k)
            free = [k for k in free if k not in bad]
            problem.free = free
            if not free:
                break
            continue
        norms = np.sqrt(np.diag(JtJ))
        with np.errstate(all="ignore"):
            step = -np.linalg.solve(JtJ / np.outer(norms, norms), Jtr / norms) / norms
        trial = dict(values)
        for i, k in enumerate(free):
            new = values[k] + step[i] * scales[i]
            if model.parameter_info(k, mechs).positive and values[k] > 0:
                # a positive parameter may shrink at most fivefold a step: a
                # nonlinear one (a characteristic speed) must not jump to 0
                new = max(new, 0.2 * values[k])
            trial[k] = new
        after = backend.chi2(trial)
        if not np.all(np.isfinite(step)) or not np.isfinite(after) or after > before:
            break  # Gauss-Newton does not improve here: leave the rest to Levenberg-Marquardt
        values = trial
        if np.max(np.abs(step)) < 1e-10 or (np.isfinite(before) and before - after <= GN_SETTLED * before):
            break  # settled: a further step changes χ² below Levenberg-Marquardt's own tolerance
    for k in free:
        info = model.parameter_info(k, mechs)
        if info.positive and values[k] <= 0:
            values[k] = 1e-3 * info.typical
    return values, free


def solve(problem: Problem, values: dict, free: list, reasons: dict, opt: FitOptions, first: bool):
    """Gauss-Newton start (first round), null-space check, then Levenberg-Marquardt
    → (values, steps, converged, free, reasons)."""
    values = dict(values)
    if first and free:
        values, free = gauss_newton_start(problem, values, free, reasons, opt)
    if not free:
        return values, 0, True, free, reasons
    backend = backend_for(problem, values, free, opt)
    new, steps, ok = backend.levenberg_marquardt(values, free, opt)
    if backend.chi2(new) <= backend.chi2(values) * (1 + 1e-12):
        values = new
    return values, steps, ok, free, reasons
