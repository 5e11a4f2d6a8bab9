"""result.json: what a fit found, in the form of BENCH_LOG_FORMAT.md."""

from __future__ import annotations

import io
import platform
from pathlib import Path

import numpy as np

from motorid import model
from motorid._atomic import write_bytes_atomic
from motorid.io.results import write_json
from motorid.identify.covariance import interval_dof, interval_factor
from motorid.identify.types import CHANNEL_UNITS, FitResult

RESULT_FILE = "result.json"
CHAIN_FILE = "chain.npz"


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


def json_safe(x):
    """JSON-safe: numpy scalars to float, NaN/inf to None."""
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
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
            if info.positive and entry["ci95"][0] <= 0:
                # a positive parameter ends at 0: the interval is cut there, and said to reach it
                entry["ci95"][0] = 0.0
                entry["indistinct_from_zero"] = True
                entry["note"] = ("its 95 % interval reaches 0 (cut there: the parameter is positive): these data "
                                 "do not tell it from zero")
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
            "noise_correlation_samples": dict(getattr(ls, "noise_correlation", {}) or {}),
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
    return json_safe(doc)


def operating_ranges(speed, dp, viscosity) -> dict:
    """The operating region a fit saw, [min, max] of |speed| [rad/s], |ΔP| [Pa] and viscosity [Pa·s]
    over its points or steady samples (``motorid predict`` says where it extrapolates)."""
    out = {}
    for name, v in (("speed_rad_s", np.abs(np.asarray(speed, float))), ("dp_Pa", np.abs(np.asarray(dp, float))),
                    ("viscosity_Pa_s", np.asarray(viscosity, float))):
        v = v[np.isfinite(v)]
        if v.size:
            out[name] = [float(v.min()), float(v.max())]
    seen = quadrants(speed, dp)
    out["quadrants"] = sorted(set(seen[seen != ""].tolist()))
    return out


#: |ΔP| [Pa] and |ω| [rad/s] below which a point has no quadrant (no power flows through it)
QUADRANT_DP, QUADRANT_SPEED = 1e5, 1e-3


def quadrants(speed, dp) -> np.ndarray:
    """Each point's quadrant: "motor, forward", "pump, reverse", … ("" where |ΔP| < 1 bar or at rest);
    forward is the direction flow into port A drives, motor the mode where ΔP·ω > 0."""
    w, p = np.asarray(speed, float), np.asarray(dp, float)
    mode = np.where(w * p > 0, "motor", "pump")
    way = np.where(w > 0, "forward", "reverse")
    label = np.char.add(np.char.add(mode, ", "), way).astype(object)
    return np.where((np.abs(p) >= QUADRANT_DP) & (np.abs(w) >= QUADRANT_SPEED), label, "")


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
    s = getattr(ds, "running", None)
    return {
        # the steady running region the fit saw (motorid predict notes points outside)
        "ranges": (operating_ranges(s.speed, np.asarray(s.p_a, float) - np.asarray(s.p_b, float), s.viscosity)
                   if s is not None and np.size(s.speed) else {}),
        "protocols": by_protocol,
        "runs": runs,
        "events": int(np.asarray(ds.held_torque).size) if getattr(ds, "held_torque", None) is not None else 0,
        "excluded": dict(getattr(ds, "excluded", {}) or {}),
        "notes": list(getattr(ds, "notes", []) or []),
    }


#: result.json written whole or not at all (the one JSON writer, motorid.io.results)
write_json_atomic = write_json


def write_chain(bayes, path) -> Path:
    buf = io.BytesIO()
    np.savez_compressed(buf, chain=bayes.chain, log_prob=bayes.log_prob, names=np.array(bayes.names),
                        burn=bayes.burn, thin=bayes.thin)
    return write_bytes_atomic(path, buf.getvalue())
