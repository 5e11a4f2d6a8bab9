"""motorid.identify.solver: the small dense Cholesky of the Levenberg-Marquardt step, and the solve."""

import numpy as np
import pytest

from motorid.identify.solver import cholesky, cholesky_solve


def test_small_cholesky_solve_against_numpy():
    import jax.numpy as jnp

    rng = np.random.default_rng(6)
    a = rng.standard_normal((11, 11))
    A = a @ a.T + 1e-3 * np.eye(11)
    b = rng.standard_normal(11)
    L = np.asarray(cholesky(jnp.asarray(A)))
    np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.asarray(cholesky_solve(jnp.asarray(L), jnp.asarray(b))),
                               np.linalg.solve(A, b), rtol=1e-8)


def test_levenberg_marquardt_on_normal_equations_finds_a_curved_least_squares_minimum():
    """The blockwise solver's loop on its own: a decaying exponential plus offset (nonlinear in
    the rate) from a far start lands on scipy's optimum."""
    from scipy.optimize import least_squares

    from motorid.identify.solver import levenberg_marquardt_normal

    t = np.linspace(0.0, 4.0, 60)
    rng = np.random.default_rng(3)
    data = 2.5 * np.exp(-1.3 * t) + 0.4 + 0.01 * rng.standard_normal(t.size)

    def residual(y):
        return data - (y[0] * np.exp(-y[1] * t) + y[2])

    def jacobian(y):
        e = np.exp(-y[1] * t)
        return -np.column_stack([e, -y[0] * t * e, np.ones_like(t)])

    def normal(y):
        J, r = jacobian(y), residual(y)
        return J.T @ J, J.T @ r, r @ r

    y, steps, ok = levenberg_marquardt_normal(normal, lambda y: residual(y) @ residual(y),
                                              np.array([0.5, 5.0, 0.0]), 1e-10, 1e-10, 200)
    ref = least_squares(residual, [0.5, 5.0, 0.0], jac=jacobian, xtol=1e-14, ftol=1e-14, gtol=1e-14).x
    assert ok and 2 < steps < 200
    np.testing.assert_allclose(y, ref, rtol=1e-7)


def _nonlinear_fit():
    from conftest import DEMO_TRUTH, simulated
    from motorid.identify.extract import extract
    from motorid.identify.least_squares import fit_least_squares
    from motorid.physics.registry import get

    truth = dict(DEMO_TRUTH, **{"stribeck_friction.T_s": 1.5, "stribeck_friction.K_p": 2e-3,
                                "stribeck_friction.w_s": 0.4})
    frame, spec, _ = simulated(seed=4, truth_items=tuple(sorted(truth.items())))
    mech = get("stribeck_friction")
    return fit_least_squares(extract(frame, spec), spec, [mech]), spec, mech


def test_normal_equations_block_by_block_equal_the_whole_jacobians():
    """JᵀJ, Jᵀr and rᵀr summed over blocks of cells (lax.map) are those of the Jacobian over
    every cell at once (the model is cell by cell)."""
    from motorid.identify.problem import as_arrays, normal_equations

    ls, _, _ = _nonlinear_fit()
    ctx = ls.problem.ctx()
    n = int(np.asarray(ctx.observed["torque"]).size)
    assert n >= 1024
    values = as_arrays({k: ls.values[k] for k in ls.free})
    whole = normal_equations(values, ctx._replace(block=n))
    parts = normal_equations(values, ctx._replace(block=n // 16))
    (A1, g1, f1), (A0, g0, f0) = ([np.asarray(x) for x in t] for t in (parts, whole))
    d = np.sqrt(np.diag(A0))
    np.testing.assert_allclose(A1 / np.outer(d, d), A0 / np.outer(d, d), rtol=0, atol=1e-11)  # correlations
    np.testing.assert_allclose(f1, f0, rtol=1e-11)
    # Jᵀr at the optimum is a sum that cancels: its round-off scales with |J_j|·|r| (Cauchy-Schwarz)
    np.testing.assert_allclose(g1 / (d * np.sqrt(f0)), g0 / (d * np.sqrt(f0)), rtol=0, atol=1e-10)


def test_blockwise_levenberg_marquardt_lands_where_optimistix_does():
    """A fit with a mechanism that is not quadratic in its parameters goes through the full
    residual: optimistix's compiled LM on few cells, the normal-equation LM block by block
    on many.  From the same perturbed start both reach the same optimum."""
    from motorid.identify.solver import FullBackend
    from motorid.identify.types import FitOptions

    ls, _, _ = _nonlinear_fit()
    problem = ls.problem
    assert problem.expansion is None  # not quadratic: the full residual
    start = {k: ls.values[k] * (1.3 if i % 2 else 0.8) for i, k in enumerate(ls.free)}
    opt = FitOptions()
    ends = {}
    for block in (0, problem.cell_size // 8):
        problem.block = block
        values, steps, ok = FullBackend(problem).levenberg_marquardt(dict(start), list(ls.free), opt)
        assert ok and steps > 1
        ends[block] = (values, FullBackend(problem).chi2(values))
    problem.block = 0
    (a, chi_a), (b, chi_b) = ends.values()
    assert abs(chi_a - chi_b) <= 1e-8 * chi_a
    for k in ls.free:
        assert abs(a[k] - b[k]) <= 1e-3 * ls.std[k] + 1e-12 * abs(a[k]), k


def test_noise_rounds_seeded_by_a_near_optimum_fit_skip_the_first_round_and_end_at_the_same_fit(monkeypatch):
    """FitOptions.start_residuals (diagnose's final fit, seeded by its last finalist): the first noise
    round's robust estimate and outlier test are taken from the residuals given, so one solve fewer is
    run, and the fit ends where a fit from scratch ends: the same outliers, values within 1 % of a
    standard error, standard errors, noise levels and χ² within 0.1 % (the noise levels, the χ²'s
    weights, are estimated from residuals at slightly different points: here 1e-4 apart)."""
    import motorid.identify.least_squares as LS
    from conftest import DEMO_TRUTH, simulated
    from motorid.identify.extract import extract
    from motorid.identify.types import FitOptions
    from motorid.physics.registry import get

    truth = dict(DEMO_TRUTH, **{"stribeck_friction.T_s": 1.5, "stribeck_friction.K_p": 2e-3,
                                "stribeck_friction.w_s": 0.4})
    frame, spec, _ = simulated(seed=4, truth_items=tuple(sorted(truth.items())))
    data, mech = extract(frame, spec), get("stribeck_friction")
    base = LS.fit_least_squares(data, spec)
    held = FitOptions(fixed_noise={**base.noise_by_run, "breakaway": base.sigma["breakaway"]},
                      fixed_inliers=dict(base.inliers), uncertainty=False)
    finalist = LS.fit_least_squares(data, spec, [mech], held, initial=base.params_all)  # the base fit's noise
    solves = [0]  # calls of the real solve, counted
    real_solve = LS.solve

    def counted(*args, **kwargs):
        solves[0] += 1
        return real_solve(*args, **kwargs)

    monkeypatch.setattr(LS, "solve", counted)
    scratch = LS.fit_least_squares(data, spec, [mech], initial=finalist.params_all)
    n_scratch, solves[0] = solves[0], 0
    seeded = LS.fit_least_squares(data, spec, [mech], FitOptions(start_residuals=finalist.residuals),
                                  initial=finalist.params_all)
    assert solves[0] == n_scratch - 1
    assert seeded.free == scratch.free and seeded.outliers == scratch.outliers
    for k in scratch.free:
        assert abs(seeded.values[k] - scratch.values[k]) <= 1e-2 * scratch.std[k], k
        assert seeded.std[k] == pytest.approx(scratch.std[k], rel=1e-3), k
    for c, v in scratch.noise.items():
        assert seeded.noise[c] == pytest.approx(v, rel=1e-3), c
    assert seeded.chi2 == pytest.approx(scratch.chi2, rel=1e-3)
