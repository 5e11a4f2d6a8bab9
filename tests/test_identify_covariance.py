"""motorid.identify.covariance: the smoothed viscosity's error carried into the fit, the intervals."""

import dataclasses

import numpy as np
import pytest

from motorid.identify.extract import extract
from motorid.identify.covariance import covariance_from_normal, viscosity_covariance, viscosity_jacobians
from motorid.identify.least_squares import fit_least_squares
from motorid.identify.solver import backend_for
from motorid.identify.types import FitOptions, ViscositySmoothing

from conftest import simulated


def test_fit_carries_the_viscosity_error_as_a_refit_would_show_it():
    """covariance_viscosity rests on dβ/dz from the linearized normal equations;
    moving one run's smoothed viscosity by one of its error modes and refitting
    (noise and inliers held) must move the parameters by that much."""
    frame, spec, truth = simulated(seed=7)
    data = extract(frame, spec)
    assert data.viscosity_error is not None and data.viscosity_error.any
    assert (data.runs["viscosity_degree"] >= 0).sum() >= 10
    ls = fit_least_squares(data, spec)
    V = ls.covariance_viscosity
    assert V is not None and V.shape == ls.covariance.shape
    free = ls.free
    i = free.index("KL0")
    # the run-level error of the viscosity is a real share of K_L0's variance
    assert V[i, i] > 0.05 * ls.covariance[i, i]

    modes = data.viscosity_error.modes(data.run_of_sample, np.asarray(data.running.time))
    hold = FitOptions(fixed_noise={c: ls.noise_by_run[c] for c in ls.noise_by_run} | {"breakaway": ls.noise["breakaway"]},
                      fixed_inliers=ls.inliers)
    base = fit_least_squares(data, spec, options=hold)
    # the share of V that one (run, mode) pair contributes, from a refit
    counts = np.bincount(data.run_of_sample)
    run = int(np.argmax(counts))  # the longest run
    on = data.run_of_sample == run
    mu = np.asarray(data.running.viscosity).copy()
    step = 30.0  # a large move, so that the refit's change stands well above its convergence
    mu[on] += step * modes[on, 0]
    moved = fit_least_squares(dataclasses.replace(data, running=data.running._replace(viscosity=mu)), spec, options=hold)
    d_refit = np.array([(moved.values[k] - base.values[k]) / step for k in free])
    # the same from the linear formula, for this run and mode alone
    only = np.zeros_like(data.viscosity_error.factor)
    only[run, :, 0] = data.viscosity_error.factor[run, :, 0]
    one = dataclasses.replace(data, viscosity_error=ViscositySmoothing(data.viscosity_error.center,
                                                                       data.viscosity_error.half_span, only))
    problem = base.problem
    problem.data = one
    JtJ = backend_for(problem, base.values, free, FitOptions()).normal(base.values)[0]
    V1 = viscosity_covariance(problem, base.values, covariance_from_normal(JtJ))[0]
    # (the parameters this mode moves most; a move 30× smaller, such as K_L_a1's here, also
    # feels the refit's exact Hessian, which differs from Gauss-Newton's JᵀJ by Σ r ∂²r)
    for k in ("KL0", "KL_b1", "KAB"):
        j = free.index(k)
        assert abs(d_refit[j]) == pytest.approx(np.sqrt(V1[j, j]), rel=0.02), k


@pytest.mark.parametrize("name", ["clean_9_seed101", "clean_9_seed103"])
def test_run_means_are_judged_with_the_viscosity_error_they_share(name):
    """The discrepancy search tests each run's mean residual against its noise.
    With the viscosity smoothed, the case flow's per-sample noise shrinks but the
    run's mean still moves with its curve's error; counted in (the fit's
    viscosity_run_variance), the runs' z-scores have unit variance on clean logs."""
    from conftest import REPO
    from motorid.discrepancy.locate import _run_table
    from motorid.identify.pipeline import load_campaign
    from motorid.io.spec import load_motor_spec

    root = REPO / "synthetic_data" / "concealed" / name
    spec = load_motor_spec(root / "motor.toml")
    _, ds = load_campaign([root / "campaign.csv.gz"], spec)
    ls = fit_least_squares(ds, spec)
    n = len(ds.runs)
    ok = ls.inliers["q_case"]
    z = np.where(ok, ls.residuals["q_case"] / ls.sigma["q_case"], np.nan)
    noise = np.array([np.median(ls.sigma["q_case"][(ds.run_of_sample == r) & ok])
                      if np.any((ds.run_of_sample == r) & ok) else np.nan for r in range(n)])
    shared = ls.viscosity_run_variance["q_case"] / noise**2
    mean, se_alone = _run_table(z, ds.run_of_sample, n)
    _, se = _run_table(z, ds.run_of_sample, n, shared)
    have = np.isfinite(mean)
    assert have.sum() >= 40
    # the shared error is a real part of a run mean's uncertainty ...
    assert np.median(se[have] ** 2 / se_alone[have] ** 2) > 1.3
    # ... and with it the z-scores of clean logs are standard normal
    assert 0.65 < np.var(mean[have] / se[have]) < 1.35


def test_cells_carry_the_mean_leakage_when_viscosity_varies_within_a_cell():
    """A cell averages samples of one run and shaft-angle bin taken at different
    times; the leakage goes as 1/μ, so the cell's viscosity must be the harmonic
    mean of its samples' (the plain mean makes the model's leakage too small by
    var(μ)/μ² and biases K_L0 and K_AB up).  Flows made by the model itself from
    per-sample viscosities that swing ±15 % within every cell are fitted back exactly."""
    from motorid import model
    frame, spec, truth = simulated(seed=3)
    data = extract(frame, spec)
    t = np.asarray(data.running.time)
    mu = np.asarray(data.running.viscosity) * (1.0 + 0.15 * np.random.default_rng(2).choice([-1.0, 1.0], t.size))
    running = model.make_samples(spec, data.running.theta, data.running.speed, data.running.p_a, data.running.p_b,
                                 data.running.p_case, mu, acceleration=data.running.acceleration,
                                 direction=data.running.direction, temperature=data.running.temperature, time=t)
    exact = model.predict(model.as_jax(truth), spec, running)
    measured = {c: np.asarray(getattr(exact, c)) for c in ("torque", "q_a", "q_b", "q_case")}
    ds = dataclasses.replace(data, running=running, measured=measured, viscosity_error=None)
    ls = fit_least_squares(data, spec)  # realistic noise levels to weight the exact data with
    hold = FitOptions(fixed_noise={c: ls.noise_by_run[c] for c in ls.noise_by_run} | {"breakaway": ls.sigma["breakaway"]})
    fit = fit_least_squares(ds, spec, options=hold)
    for k in ("KL0", "KAB"):
        assert fit.values[k] == pytest.approx(truth[k], rel=1e-6), k
    # (the harmonics also see θ vary within the cell: a far smaller, second-order term)
    assert fit.values["KL_a1"] == pytest.approx(truth["KL_a1"], rel=1e-4)


def test_viscosity_jacobians_from_the_expansion_match_the_jax_jacobian():
    """The covariance's fast path (∂r/∂β from the fit's exact quadratic expansion,
    ∂r/∂μ from two passes of the predictions) against forward-mode JAX over every cell."""
    frame, spec, _ = simulated(seed=5)
    data = extract(frame, spec)
    ls = fit_least_squares(data, spec)
    problem = ls.problem
    assert problem.expansion is not None
    values = {k: ls.values[k] for k in ls.free}
    ctx = problem.ctx()
    fast, g_fast = viscosity_jacobians(problem, values, ctx)
    problem.expansion = None  # the fallback: a Jacobian program over every cell
    slow, g_slow = viscosity_jacobians(problem, values, ctx)
    assert set(g_fast) == set(g_slow) == {"torque", "q_a", "q_b", "q_case"}
    for c in g_fast:
        np.testing.assert_allclose(g_fast[c], g_slow[c], rtol=1e-5, atol=1e-7 * np.abs(g_slow[c]).max())
    for j in range(slow.shape[1]):
        np.testing.assert_allclose(fast[:, j], slow[:, j], rtol=1e-5, atol=1e-7 * np.abs(slow[:, j]).max())
    assert np.abs(slow).max() > 0


@pytest.mark.parametrize("dof", [5.0, 7.5, 12.0, 28.0, 300.0])
@pytest.mark.parametrize("level", [0.6827, 0.95])
def test_t_quantile_without_scipy_stats_matches_scipy(dof, level):
    from scipy import stats

    from motorid.identify.covariance import interval_factor

    assert interval_factor(dof, level) == pytest.approx(stats.t.ppf(0.5 + level / 2, dof), rel=1.2e-4)


def test_covariance_from_the_normal_matrix_inverts_it_over_columns_of_any_scale():
    rng = np.random.default_rng(9)
    J = rng.standard_normal((30, 3)) * np.array([1e-12, 1.0, 1e6])  # columns 18 decades apart
    JtJ = J.T @ J
    cov = covariance_from_normal(JtJ)
    s = np.sqrt(np.diag(JtJ))  # (in units of each column's own size)
    np.testing.assert_allclose((cov * np.outer(s, s)) @ (JtJ / np.outer(s, s)), np.eye(3), atol=1e-9)
    np.testing.assert_allclose(np.diag(cov), np.diag(np.linalg.inv(JtJ)), rtol=1e-6)
    # a direction the data do not see has no variance (a pseudo-inverse, not an error)
    Js = np.column_stack([J[:, 1], J[:, 1]])
    cs = covariance_from_normal(Js.T @ Js)
    assert np.all(np.isfinite(cs))
    np.testing.assert_allclose(cs @ np.array([1.0, -1.0]), 0.0, atol=1e-12)


def test_viscosity_sensitivity_block_by_block_equals_the_whole_jacobian():
    """The fallback's ∂r/∂β·∂r/∂μ and ∂r/∂μ, computed over blocks of cells, equal the
    program over every cell at once."""
    frame, spec, _ = simulated(seed=5)
    data = extract(frame, spec)
    ls = fit_least_squares(data, spec)
    problem = ls.problem
    problem.expansion = None  # the fallback: a Jacobian program over the cells
    values = {k: ls.values[k] for k in ls.free}
    whole, g_whole = viscosity_jacobians(problem, values, problem.ctx()._replace(block=problem.cell_size))
    parts, g_parts = viscosity_jacobians(problem, values, problem.ctx()._replace(block=problem.cell_size // 8))
    np.testing.assert_allclose(parts, whole, rtol=1e-11, atol=1e-12 * np.abs(whole).max())
    for c in g_whole:
        np.testing.assert_allclose(g_parts[c], g_whole[c], rtol=1e-11, atol=1e-12 * np.abs(g_whole[c]).max())
