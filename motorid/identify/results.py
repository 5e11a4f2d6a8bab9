"""result.json: what a fit found, in the form of BENCH_LOG_FORMAT.md."""

from __future__ import annotations

import io
import json
import platform
from pathlib import Path

import numpy as np

from motorid import model
from motorid._atomic import write_bytes_atomic
from motorid.identify.least_squares import BREAKAWAY_ONLY, CHANNEL_UNITS, FitResult

RESULT_FILE = "result.json"
CHAIN_FILE = "chain.npz"


def interval_dof(ls: FitResult) -> dict:
    """Effective degrees of freedom of each fitted parameter's standard error.

    A standard error is as uncertain as the noise levels it rests on.  The
    running channels' levels come from dozens to hundreds of residuals per run
    (treated as exact here); the breakaway level σ_brk from one residual per
    event, n events less the breakaway-only parameters (K_FS, K_s) — the same
    count the fit divides by.  With V = (JᵀWJ)⁻¹ and A_brk the breakaway
    events' share of JᵀWJ, the share of parameter i's variance that scales with
    σ_brk² is f_i = (V A_brk V)_ii / V_ii, and Welch–Satterthwaite gives
    ν_i = ν_brk / f_i²: ≈ n − 2 for K_FS and K_s, effectively infinite for the
    parameters the running data determine.  Returns name → ν (inf where no
    breakaway noise enters).
    """
    free = list(ls.free)
    out = {k: float("inf") for k in free}
    problem = getattr(ls, "problem", None)
    if not free or problem is None or not getattr(problem, "has_events", False) or problem.cells is None:
        return out
    n_events = int(np.sum(ls.inliers.get("breakaway", np.zeros(0, bool))))
    nu_brk = (n_events - sum(1 for k in BREAKAWAY_ONLY if k in free)
              - (1 if getattr(ls, "breakaway_noise_shape", 0.0) > 0 else 0))  # the variance model's shape
    if nu_brk < 1:
        return out
    from motorid.identify.least_squares import _normal_equations

    ctx = problem.ctx()
    brk = ctx._replace(running=None, observed={"breakaway": ctx.observed["breakaway"]},
                       weights={"breakaway": ctx.weights["breakaway"]})
    values = {k: np.asarray(ls.values[k], dtype=np.float64) for k in free}
    A_brk = np.asarray(_normal_equations(values, brk)[0])
    total = np.asarray(ls.covariance)
    visc = getattr(ls, "covariance_viscosity", None)
    brk = getattr(ls, "covariance_breakaway", None)  # the sandwich's widening, also σ_brk's
    scale = max(ls.reduced_chi2, 1.0)
    V = (total - (0.0 if visc is None else visc) - (0.0 if brk is None else brk)) / scale
    d = np.diag(total)  # the viscosity's share rests on hundreds of readings per run: ν = ∞
    with np.errstate(invalid="ignore", divide="ignore"):
        # (the sandwich's widening scales with the events' scatter as the rest of their share)
        f = np.clip((np.diag(V @ A_brk @ V) + (0.0 if brk is None else np.diag(brk) / scale)) / d, 0.0, 1.0)
    for i, k in enumerate(free):
        if np.isfinite(f[i]) and f[i] > 1e-6:
            out[k] = float(nu_brk / f[i] ** 2)
    return out


def interval_factor(dof: float, level: float = 0.95) -> float:
    """Half-width of a central ``level`` interval in standard errors: Student-t
    with ``dof`` degrees of freedom (the normal quantile where dof is infinite).

    From ν = 5 on by the Cornish-Fisher expansion of the t quantile in 1/ν
    (Abramowitz & Stegun 26.7.5, four terms: relative error below 1e-4 at ν = 5,
    1e-7 at ν = 20), which keeps scipy.stats (a second of import) out of
    ``motorid fit``; below that, scipy's exact quantile.
    """
    from statistics import NormalDist

    q = 0.5 * (1.0 + level)
    if not np.isfinite(dof) or dof > 1e6:
        return NormalDist().inv_cdf(q)
    if dof < 5:
        from scipy import stats

        return float(stats.t.ppf(q, dof))
    z = NormalDist().inv_cdf(q)
    g = ((z**3 + z) / 4, (5 * z**5 + 16 * z**3 + 3 * z) / 96,
         (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / 384,
         (79 * z**9 + 776 * z**7 + 1482 * z**5 - 1920 * z**3 - 945 * z) / 92160)
    return float(z + sum(gk / dof ** (k + 1) for k, gk in enumerate(g)))


def versions() -> dict:
    """Versions of the packages a result depends on (read from their metadata, not imported)."""
    from importlib.metadata import PackageNotFoundError, version

    import motorid

    out = {"motorid": motorid.__version__, "python": platform.python_version()}
    for name in ("numpy", "scipy", "pandas", "jax", "jaxlib", "optimistix", "emcee"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = None
    return out


def _clean(x):
    """JSON-safe: numpy scalars to float, NaN/inf to None."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if np.isfinite(x) else None
    return x


def result_document(ls: FitResult, spec, dataset=None, bayes=None, inputs: dict | None = None,
                    seconds: float | None = None, priors: dict | None = None) -> dict:
    """The result.json document of a least-squares (and optional Bayesian) fit."""
    params = {}
    dof = interval_dof(ls)
    for k in ls.names:
        info = model.parameter_info(k, ls.mechanisms)
        entry = {"value": ls.values[k], "unit": info.unit, "std": ls.std[k], "ci95": None,
                 "identifiable": bool(ls.identifiable[k]), "meaning": info.meaning}
        if ls.identifiable[k] and ls.values[k] is not None and ls.std[k] is not None:
            # Student-t where the standard error rests on the few breakaway events (interval_dof)
            half = interval_factor(dof.get(k, float("inf"))) * ls.std[k]
            entry["ci95"] = [ls.values[k] - half, ls.values[k] + half]
            if np.isfinite(dof.get(k, float("inf"))):
                entry["dof"] = dof[k]
            visc = getattr(ls, "covariance_viscosity", None)
            if visc is not None and k in ls.free:
                i = ls.free.index(k)
                if visc[i, i] > 1e-4 * ls.std[k] ** 2:
                    # the part of std that the smoothed viscosity's run-level error carries
                    entry["std_viscosity"] = float(np.sqrt(visc[i, i]))
            brk = getattr(ls, "covariance_breakaway", None)
            if brk is not None and k in ls.free and brk[ls.free.index(k), ls.free.index(k)] > 0:
                # the breakaway events scattered more than their variance model says: the
                # sandwich's widening, as a share of the variance
                i = ls.free.index(k)
                entry["widened_by_scatter"] = float(brk[i, i] / ls.std[k] ** 2)
        else:
            entry["reason"] = ls.reasons.get(k, "not determined by these logs")
        if bayes is not None and k in bayes.median:
            entry["posterior"] = {"median": bayes.median[k], "std": bayes.std[k], "ci95": bayes.ci95[k]}
        params[k] = entry
    doc = {
        "motor": {"name": spec.name, "pistons": spec.pistons, "displacement_m3": spec.displacement,
                  "inertia_kg_m2": spec.inertia, "leak_phase_rad": spec.phase},
        "inputs": inputs or {},
        "parameters": params,
        "noise": {c: {"sigma": v, "unit": CHANNEL_UNITS[c]} for c, v in ls.noise.items()},
        "fit": {
            "method": "optimistix.LevenbergMarquardt, all channels jointly, residuals weighted by the "
                      "noise level of each channel and run estimated from the data",
            "chi2": ls.chi2, "dof": ls.dof, "reduced_chi2": ls.reduced_chi2, "steps": ls.steps,
            "converged": ls.converged, "warnings": list(ls.warnings),
            "outliers": ls.outliers, "used": ls.used, "seconds": seconds,
            "mechanisms": [m.id for m in ls.mechanisms],
        },
        "correlation": {"names": list(ls.free), "matrix": ls.correlation},
        "versions": versions(),
    }
    if dataset is not None:
        doc["data"] = dataset_summary(dataset)
    if bayes is not None:
        doc["mcmc"] = {
            "sampler": "emcee.EnsembleSampler (DEMove), vectorized JAX log-posterior",
            "tau": bayes.tau, "ess": bayes.ess, "converged": bayes.converged,
            "acceptance": bayes.acceptance, "steps": bayes.steps, "walkers": bayes.walkers,
            "burn": bayes.burn, "thin": bayes.thin, "seconds": bayes.seconds,
            "warnings": bayes.warnings, "chain_file": CHAIN_FILE, "priors": priors or {},
            "likelihood": ("exact second-order expansion of the model (sufficient statistics), checked on "
                           f"posterior draws: largest |Δ log p| {bayes.expansion_gap:.2g}"
                           if bayes.expansion_gap is not None else "full model at every step"),
            "breakaway_noise": ("integrated out under p(σ_brk) ∝ 1/σ_brk" if bayes.breakaway_noise == "marginalized"
                                else "held at the least-squares value"),
        }
    return _clean(doc)


def dataset_summary(ds) -> dict:
    runs = []
    if getattr(ds, "runs", None) is not None:
        for rec in ds.runs.to_dict(orient="records"):
            runs.append({k: (v.item() if hasattr(v, "item") else v) for k, v in rec.items()})
    by_protocol: dict = {}
    for r in runs:
        p = by_protocol.setdefault(str(r.get("protocol")), {"runs": 0, "samples": 0, "steady": 0})
        p["runs"] += 1
        p["samples"] += int(r.get("n_samples", 0) or 0)
        p["steady"] += int(r.get("n_steady", 0) or 0)
    return {
        "protocols": by_protocol,
        "runs": runs,
        "events": int(np.asarray(ds.held_torque).size) if getattr(ds, "held_torque", None) is not None else 0,
        "excluded": dict(getattr(ds, "excluded", {}) or {}),
        "notes": list(getattr(ds, "notes", []) or []),
    }


def write_json_atomic(doc: dict, path) -> Path:
    text = json.dumps(doc, indent=1, allow_nan=False) + "\n"
    return write_bytes_atomic(path, text.encode())


def write_chain(bayes, path) -> Path:
    buf = io.BytesIO()
    np.savez_compressed(buf, chain=bayes.chain, log_prob=bayes.log_prob, names=np.array(bayes.names),
                        burn=bayes.burn, thin=bayes.thin)
    return write_bytes_atomic(path, buf.getvalue())
