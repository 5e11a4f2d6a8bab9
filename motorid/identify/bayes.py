"""Bayesian inference with emcee on the same model and the same reduced data.

The log-posterior is JAX, jitted and vectorized over walkers (emcee's
``vectorize=True``).  The noise levels of the running channels are those the
least-squares fit estimated from the data (per channel and run, each from
dozens to hundreds of residuals) and are held fixed; the outliers it rejected
stay out.

The breakaway channel is different: its one noise level σ_brk rests on a few
dozen events (≈ ±13 % from campaign to campaign for 30 of them), so holding it
fixed makes the K_FS and K_s intervals too narrow whenever it comes out low.
It is marginalized instead (``marginal_breakaway=True``, the default), under the
scale-invariant prior p(σ_brk) ∝ 1/σ_brk (Jeffreys):

    ∫ Π_i N(r_i; 0, σ²) σ⁻¹ dσ ∝ (Σ_i r_i²)^(−n/2),

r the held − predicted breakaway torque of the n inlier events.  The breakaway
block of the log-likelihood is then −(n/2)·log Σ r_i², which the sufficient
statistics below carry exactly (Σ r_i² is a polynomial of the parameters like
χ²).  For a model linear in its parameters this gives Student-t marginals with
n − p degrees of freedom, the frequentist t-interval (the prior is
probability-matching); with 30 events it widens the 95 % intervals of K_FS and
K_s by ≈ 4 % and, more to the point, gives them the right tails.

Priors (weakly informative, physically positive):

- each positive parameter p ~ HalfNormal(s) with s = 100 × its typical size
  (``motorid.model.BASE_PARAMETERS``), the sizes of T_Fc, K_L0 and K_AB scaled
  with displacement D / 80 cm³;
- each K_L(θ) Fourier coefficient a_m, b_m ~ Normal(0, 1) (a relative ripple of
  order one would already be extreme);
- a mechanism's parameter likewise from its typical size;
- the breakaway noise level σ_brk ~ 1/σ_brk (improper, scale-invariant),
  integrated out analytically (above).

These priors are hundreds of standard errors wide on any campaign that
identifies the parameter, so the posterior is the likelihood's.

The viscosity the model sees is the extraction's smoothed curve per run
(:func:`motorid.identify.viscosity.smooth_viscosity`), whose error is common to a
run.  Its effect on the parameters is linear to first order, β(μ + δμ) ≈ β(μ) +
G z with z ~ N(0, I) per run (the least-squares fit's ``covariance_viscosity`` =
G Gᵀ), so marginalizing it convolves the posterior with N(0, G Gᵀ): every draw
of the chain is moved by its own draw of that Gaussian (exact for a model
linear in μ under flat priors).

Walkers start in a small ball drawn from the least-squares covariance; the run
goes on in chunks until it is at least ``min_tau_multiple`` (50) integrated
autocorrelation times long and τ has settled, or until ``max_steps``.
"""

from __future__ import annotations

import time

import emcee
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from motorid import model
from motorid.identify.problem import Ctx, weighted_residual
from motorid.identify.types import BayesResult, FitResult

SIZE_SCALED = {"TFc", "KL0", "KAB"}
REFERENCE_DISPLACEMENT = 80e-6


def prior_scale(name: str, spec, mechanisms=()) -> float:
    """Width of the weakly informative prior of a parameter [its unit]."""
    info = model.parameter_info(name, mechanisms)
    if name.startswith("KL_"):
        return 1.0
    size = spec.displacement / REFERENCE_DISPLACEMENT if name in SIZE_SCALED else 1.0
    return 100.0 * info.typical * size


def _residual_of_z(z, ctx: Ctx, center, scale):
    p = center + z * scale
    return weighted_residual({k: p[i] for i, k in enumerate(ctx.free)}, ctx)


def _breakaway_rows(ctx: Ctx) -> tuple[int, int]:
    """(rows of the breakaway block at the end of the weighted residual, inlier events in it)."""
    if ctx.observed is None or "breakaway" not in ctx.observed:
        return 0, 0
    rows = int(np.asarray(ctx.observed["breakaway"]).size)
    return rows, int(np.count_nonzero(np.asarray(ctx.weights["breakaway"])))


def marginal_breakaway_loglike(s_brk, n_events: int, xp=np):
    """−(n/2)·log(S/n): the breakaway block's log-likelihood with σ_brk integrated
    out under p(σ) ∝ 1/σ, S = Σ r² in units of the fit's σ_brk (a constant shift
    only, so that it is ≈ −S/2 + const near S = n)."""
    return -0.5 * n_events * xp.log(xp.maximum(s_brk, 1e-300) / n_events)


@eqx.filter_jit
def _log_posterior_batch(z, ctx: Ctx, center, scale, positive, prior_sd, prior_mean=0.0,
                         brk_rows: int = 0, brk_events: int = 0):
    """log posterior at walkers z (W, ndim), z = (p − center)/scale, on the full model.

    brk_rows > 0: the last ``brk_rows`` residuals are the breakaway block, whose
    noise level is marginalized (:func:`marginal_breakaway_loglike`)."""

    def one(zi):
        p = center + zi * scale
        inside = jnp.all(jnp.where(positive, p > 0, True))
        r = _residual_of_z(zi, ctx, center, scale)
        if brk_rows:
            log_like = (-0.5 * jnp.sum(r[:-brk_rows] ** 2)
                        + marginal_breakaway_loglike(jnp.sum(r[-brk_rows:] ** 2), brk_events, jnp))
        else:
            log_like = -0.5 * jnp.sum(r**2)
        log_prior = -0.5 * jnp.sum(((p - prior_mean) / prior_sd) ** 2)
        return jnp.where(inside, log_like + log_prior, -jnp.inf)

    return jax.vmap(one)(z)


@eqx.filter_jit
def _expansion(ctx: Ctx, center, scale):
    """Residual r(z) = r0 + J z + ½ Σ H_ab z_a z_b: value, Jacobian and Hessian at z = 0."""
    f = lambda z: _residual_of_z(z, ctx, center, scale)  # noqa: E731
    z0 = jnp.zeros_like(center)
    return f(z0), jax.jacfwd(f)(z0), jax.jacfwd(jax.jacfwd(f))(z0)


class QuadraticLikelihood:
    """χ²(z) from sufficient statistics of the model's second-order expansion.

    The 1992 model is a polynomial of degree two in its parameters (linear in
    K_v, K_F, K_FS, T_Fc, K_AB; bilinear in K_L0·a_m, K_L0·b_m, T_Fc·K_s), so
    r(z) = r0 + J z + ½ zᵀH z holds *exactly*, and
    χ²(z) = |r0 + J z + H_k u(z)|² with u the products z_a z_b of the few
    parameter pairs whose H is non-zero expands into sums over the data that
    are computed once: the sampler then costs the same for 10 k or 3 M rows.
    For a mechanism that is not polynomial the expansion is checked against
    the full model on posterior draws (the check in :func:`sample_posterior`),
    and the sampler falls back to the full model where they differ.

    split : the number of trailing residual rows kept as a block of their own
        (the breakaway events), so that :meth:`blocks` gives the sum of squares
        of the rest and of that block separately.
    """

    def __init__(self, ctx, center, scale, split: int = 0):
        r0, J, H = (np.asarray(a) for a in _expansion(ctx, jnp.asarray(center), jnp.asarray(scale)))
        n, p = J.shape
        H = H.reshape(n, p * p)
        self.pairs = [(a, b) for a in range(p) for b in range(p) if np.any(H[:, a * p + b] != 0)]
        Hk = 0.5 * H[:, [a * p + b for a, b in self.pairs]] if self.pairs else np.zeros((n, 0))
        self.a = np.array([a for a, _ in self.pairs], dtype=int)
        self.b = np.array([b for _, b in self.pairs], dtype=int)
        cuts = [slice(0, n - split), slice(n - split, n)] if split else [slice(0, n)]
        self._stats = []
        for rows in cuts:
            r, Jr, Hr = r0[rows], J[rows], Hk[rows]
            self._stats.append((float(r @ r), Jr.T @ r, Hr.T @ r, Jr.T @ Jr, Jr.T @ Hr, Hr.T @ Hr))

    def blocks(self, z) -> list:
        """Sum of squares of each block of rows at walkers z (W, p)."""
        u = z[:, self.a] * z[:, self.b] if self.pairs else np.zeros((z.shape[0], 0))
        return [s0 + 2 * z @ g + 2 * u @ h + np.einsum("wi,ij,wj->w", z, JJ, z)
                + 2 * np.einsum("wi,ij,wj->w", z, JH, u) + np.einsum("wi,ij,wj->w", u, HH, u)
                for s0, g, h, JJ, JH, HH in self._stats]

    def chi2(self, z):
        """χ² at walkers z (W, p)."""
        return sum(self.blocks(z))


class _Target:
    """The log-posterior of the sampler in z = (p − center)/scale, on the full model and
    (``fast``) on its exact second-order expansion (:class:`QuadraticLikelihood`)."""

    def __init__(self, ls: FitResult, spec, prior: dict | None, fast: bool, marginal_breakaway: bool):
        names = list(ls.free)
        ndim = len(names)
        self.center = np.array([ls.values[k] for k in names])
        # the likelihood's own width: a standard error widened by the runs' scatter is not (the draws
        # are spread by that factor afterwards, _with_run_scatter)
        spread = getattr(ls, "run_scatter", None) or {}
        std = np.array([ls.std[k] / spread.get(k, 1.0) for k in names])
        self.scale = np.where(std > 0, std, np.abs(self.center) * 1e-3 + 1e-300)
        self.positive = np.array([model.parameter_info(k, ls.mechanisms).positive for k in names])
        self.prior_sd = np.array([prior_scale(k, spec, ls.mechanisms) for k in names])
        self.prior_mean = np.zeros(ndim)
        for i, k in enumerate(names):
            if prior and k in prior:
                self.prior_mean[i], self.prior_sd[i] = (float(v) for v in prior[k])
        ctx = ls.problem.ctx()
        brk_rows, brk_events = _breakaway_rows(ctx)
        if not marginal_breakaway or brk_events < 3:
            brk_rows, brk_events = 0, 0
        self.brk_rows, self.brk_events = brk_rows, brk_events
        self.args = (ctx, jnp.asarray(self.center), jnp.asarray(self.scale), jnp.asarray(self.positive),
                     jnp.asarray(self.prior_sd), jnp.asarray(self.prior_mean), brk_rows, brk_events)
        self.quad = QuadraticLikelihood(ctx, self.center, self.scale, split=brk_rows) if fast else None

    def full(self, z):
        return np.asarray(_log_posterior_batch(jnp.asarray(z), *self.args))

    def __call__(self, z):
        z = np.atleast_2d(z)
        if self.quad is None:
            return self.full(z)
        p = self.center + z * self.scale
        inside = np.all(np.where(self.positive, p > 0, True), axis=1)
        if self.brk_rows:
            s_run, s_brk = self.quad.blocks(z)
            log_like = -0.5 * s_run + marginal_breakaway_loglike(s_brk, self.brk_events)
        else:
            log_like = -0.5 * self.quad.chi2(z)
        lp = log_like - 0.5 * np.sum(((p - self.prior_mean) / self.prior_sd) ** 2, axis=1)
        return np.where(inside, lp, -np.inf)


def _start(ls: FitResult, log_prob, walkers: int, rng) -> np.ndarray:
    """Walkers drawn from the least-squares Gaussian (in z), pulled in until inside the support.

    The posterior is close to that Gaussian: starting there, the ensemble need not expand
    from a small ball (DE moves expand slowly)."""
    ndim = len(ls.free)
    corr = np.nan_to_num(ls.correlation, nan=0.0)
    np.fill_diagonal(corr, 1.0)
    try:
        chol = np.linalg.cholesky(corr + 1e-9 * np.eye(ndim))
    except np.linalg.LinAlgError:
        chol = np.eye(ndim)
    z0 = rng.standard_normal((walkers, ndim)) @ chol.T
    for _ in range(100):
        bad = ~np.isfinite(log_prob(z0))
        if not bad.any():
            break
        z0[bad] *= 0.5
    return z0


def _run_chain(sampler, state, chunk: int, max_steps: int, min_tau_multiple: float, max_seconds,
               show: bool | None):
    """Run in chunks until the chain is ``min_tau_multiple`` τ long and τ has settled →
    (converged, τ per parameter, warnings, seconds).  ``show``: a progress bar
    (:func:`motorid.progress.bar`; None: where stderr is a terminal and not quiet) whose
    total is the steps the current τ asks for."""
    from motorid.progress import bar

    t0 = time.time()
    tau_prev, converged, tau = None, False, np.full(sampler.ndim, np.nan)
    warnings = []
    with bar(total=max_steps, desc="emcee", unit="step", progress=show) as pbar:
        while sampler.iteration < max_steps:
            state = sampler.run_mcmc(state, chunk, progress=False)
            tau = sampler.get_autocorr_time(tol=0)
            n = sampler.iteration
            settled = tau_prev is not None and abs(np.max(tau) - np.max(tau_prev)) < 0.1 * np.max(tau)
            if np.all(np.isfinite(tau)):
                pbar.total = int(min(max(min_tau_multiple * np.max(tau), n + chunk), max_steps))
            pbar.set_postfix_str(f"{sampler.nwalkers} walkers, τ_max {np.max(tau):.0f}", refresh=False)
            pbar.update(n - pbar.n)
            if np.all(np.isfinite(tau)) and n >= min_tau_multiple * np.max(tau) and settled:
                converged = True
                break
            tau_prev = tau
            if max_seconds is not None and time.time() - t0 > max_seconds:
                warnings.append(f"stopped after {max_seconds:.0f} s before reaching {min_tau_multiple:.0f} τ")
                break
    if not converged and not warnings:
        warnings.append(f"stopped at max_steps={max_steps} before reaching {min_tau_multiple:.0f} τ")
    return converged, tau, warnings, t0


def _expansion_gap(target: _Target, chain_z, burn: int, rng) -> float:
    """Largest |Δ log p| of the expansion against the full model on up to 64 posterior draws."""
    draws = chain_z[burn:].reshape(-1, chain_z.shape[-1])
    pick = draws[rng.choice(len(draws), size=min(64, len(draws)), replace=False)]
    full = target.full(pick)
    approx = target(pick)
    ok = np.isfinite(full) & np.isfinite(approx)
    return float(np.max(np.abs(full[ok] - approx[ok]))) if ok.any() else np.inf


def _with_viscosity_error(ls: FitResult, chain, rng):
    """The smoothed viscosity's run-level error (see the module docstring): each draw moved
    by its own draw from N(0, covariance_viscosity)."""
    visc = getattr(ls, "covariance_viscosity", None)
    if visc is not None and np.any(visc):
        w, v = np.linalg.eigh(0.5 * (visc + visc.T))
        root = v * np.sqrt(np.clip(w, 0.0, None))
        chain = chain + rng.standard_normal(chain.shape) @ root.T
    return chain


def _with_run_scatter(ls: FitResult, chain, burn: int, warnings: list):
    """Each parameter whose runs disagree beyond their errors (``ls.run_scatter``: name → R, the
    factor its least-squares standard error was widened by, :mod:`motorid.identify.run_scatter`):
    its draws spread about their mean by R, as that standard error was (correlations kept)."""
    spread = getattr(ls, "run_scatter", None) or {}
    for i, k in enumerate(ls.free):
        factor = spread.get(k)
        if factor and factor > 1.0:
            mean = float(np.mean(chain[burn:, :, i]))
            chain[:, :, i] = mean + factor * (chain[:, :, i] - mean)
            warnings.append(f"{k}: the draws are spread {factor:.3g}× about their mean, as its runs' own "
                            "estimates scatter that much beyond their errors (the least-squares fit's warning)")
            if model.parameter_info(k, ls.mechanisms).positive and np.any(chain[burn:, :, i] <= 0):
                warnings.append(f"{k}: some of its spread draws are not positive, which the parameter must be: "
                                "its interval is a Gaussian reading of the runs' scatter, not a posterior")
    return chain


def sample_posterior(ls: FitResult, spec, walkers: int | None = None,
                     min_tau_multiple: float = 50.0, max_steps: int = 40000, chunk: int = 500,
                     seed: int = 0, progress: bool | None = None, max_seconds: float | None = None,
                     fast: bool = True, prior: dict | None = None,
                     marginal_breakaway: bool = True) -> BayesResult:
    """Run emcee from the least-squares solution until the chain is long enough.

    ls : the least-squares result: start, scales, free parameters, and its
        reduced problem with the final noise levels and inliers
    prior : optional name → (mean, sd): a Normal(mean, sd) prior (truncated to
        p > 0 for positive parameters) in place of the default weakly
        informative one, for the parameters it names (e.g. a calibration prior
        in simulation-based calibration); default None keeps the module's priors
    marginal_breakaway : integrate the breakaway noise level out under
        p(σ_brk) ∝ 1/σ_brk (default) instead of holding the least-squares value
        fixed; only where there are at least 3 breakaway events
    """
    names = list(ls.free)
    ndim = len(names)
    if ndim == 0:
        raise ValueError("no identifiable parameter to sample")
    walkers = walkers or max(4 * ndim, 24)
    walkers += walkers % 2
    target = _Target(ls, spec, prior, fast, marginal_breakaway)
    rng = np.random.default_rng(seed)
    z0 = _start(ls, target, walkers, rng)
    # differential-evolution moves mix about three times faster than the stretch
    # move on the nearly Gaussian, correlated posteriors of this model (τ ≈ 30
    # steps, not ≈ 100, in 9 dimensions).  (The DE-snooker move was tried and
    # left out: on a 9-D Gaussian test it came out 6 % too narrow.)
    moves = [(emcee.moves.DEMove(), 1.0)]
    sampler = emcee.EnsembleSampler(walkers, ndim, target, vectorize=True, moves=moves)
    sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
    converged, tau, warnings, t0 = _run_chain(sampler, z0, chunk, max_steps, min_tau_multiple, max_seconds, progress)
    tau_max = float(np.max(tau)) if np.all(np.isfinite(tau)) else float(sampler.iteration)
    burn = int(min(max(3 * tau_max, 1), sampler.iteration // 2))
    thin = max(int(tau_max / 2), 1)
    chain_z = sampler.get_chain()
    expansion_gap = None
    if target.quad is not None:
        # the expansion must agree with the full model where the posterior lives
        expansion_gap = _expansion_gap(target, chain_z, burn, rng)
        if expansion_gap > 0.05:
            warnings.append(f"second-order expansion off by {expansion_gap:.3g} in log-posterior; "
                            f"resampled on the full model")
            return sample_posterior(ls, spec, walkers, min_tau_multiple, max_steps, chunk, seed, progress,
                                    max_seconds, fast=False, prior=prior, marginal_breakaway=marginal_breakaway)
    chain = _with_viscosity_error(ls, target.center + chain_z * target.scale, rng)
    chain = _with_run_scatter(ls, chain, burn, warnings)
    flat = chain[burn::thin].reshape(-1, ndim)
    q = np.percentile(flat, [2.5, 50.0, 97.5], axis=0)
    kept = (sampler.iteration - burn) * walkers
    return BayesResult(
        names=names, chain=chain, log_prob=sampler.get_log_prob(),
        median={k: float(q[1, i]) for i, k in enumerate(names)},
        ci95={k: [float(q[0, i]), float(q[2, i])] for i, k in enumerate(names)},
        std={k: float(np.std(flat[:, i])) for i, k in enumerate(names)},
        tau={k: float(tau[i]) for i, k in enumerate(names)},
        ess={k: float(kept / tau[i]) if np.isfinite(tau[i]) and tau[i] > 0 else 0.0 for i, k in enumerate(names)},
        converged=bool(converged), acceptance=float(np.mean(sampler.acceptance_fraction)),
        steps=int(sampler.iteration), walkers=walkers, burn=burn, thin=thin,
        seconds=time.time() - t0, warnings=warnings, expansion_gap=expansion_gap,
        breakaway_noise="marginalized" if target.brk_rows else "fixed",
    )
