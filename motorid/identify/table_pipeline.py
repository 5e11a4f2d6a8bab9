"""`motorid fit` and `motorid diagnose` with operating-point tables (alone or with logs).

The command-line hooks in identify/cli.py and discrepancy/cli.py hand over here
when any given file is a table (no time column).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from motorid.errors import InputError


def identify_tables(log_paths, table_paths, spec, mechanisms=(), harmonics=None):
    """Read the tables (and logs), fit them jointly; returns a :class:`~motorid.identify.tables.TableFit`."""
    from motorid.identify.tables import fit_table
    from motorid.io.tables import read_tables

    t0 = time.time()
    table = read_tables(table_paths, spec)
    dataset = log_fit = None
    if log_paths:
        from motorid.identify.least_squares import FitOptions, fit_least_squares
        from motorid.identify.pipeline import load_campaign

        _, dataset = load_campaign(log_paths, spec)
        log_fit = fit_least_squares(dataset, spec, mechanisms=mechanisms, options=FitOptions(harmonics=harmonics))
    tf = fit_table(table, spec, mechanisms, dataset=dataset, log_fit=log_fit, harmonics=harmonics)
    tf.seconds = time.time() - t0
    return tf


def table_result_document(tf, spec, inputs: dict, comparison: dict | None = None) -> dict:
    """result.json of a fit with tables: the document of a log fit, plus ``table``, ``comparison``
    and ``motor_spec`` (the spec's TOML, so that ``motorid predict`` needs nothing else)."""
    from motorid.identify.results import _clean, result_document
    from motorid.identify.tables import table_document

    doc = result_document(tf.ls, spec, tf.dataset, None, inputs, tf.seconds)
    doc["fit"]["method"] = ("scipy.optimize.least_squares (trust region, bounds), JAX Jacobian; table points: the "
                            "model averaged over shaft angle, each output channel weighted by a noise level "
                            "estimated from its residuals" + ("; jointly with the logs, weighted by the logs' own "
                                                             "noise levels" if tf.dataset is not None else ""))
    doc["table"] = _clean(table_document(tf))
    if comparison is not None:
        doc["comparison"] = _clean(comparison)
    doc["motor_spec"] = spec.to_toml()
    return doc


def run_table_fit(args, logs, tables, spec) -> int:
    """The `motorid fit` command when tables are given."""
    from motorid.comparators.evaluate import compare
    from motorid.identify.cli import check_output, format_summary
    from motorid.identify.results import RESULT_FILE, write_json_atomic

    if getattr(args, "bayes", False):
        raise InputError("--bayes is not available with operating-point tables (the least-squares covariance is "
                         "reported)")
    out = Path(args.out)
    check_output(out, args.force)
    tf = identify_tables(logs, tables, spec, harmonics=args.harmonics)
    comparison = compare(tf.table, spec) if len(tf.table) >= 10 else None
    inputs = {"logs": [str(p) for p in logs], "tables": [str(p) for p in tables], "motor": str(args.motor)}
    doc = table_result_document(tf, spec, inputs, comparison)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(doc, out / RESULT_FILE)
    print(format_summary(doc))
    if comparison is not None:
        print(format_comparison(comparison))
    print(f"wrote {out / RESULT_FILE}")
    if getattr(args, "report", False):
        from motorid.report.maps import write_map_report

        path = write_map_report(out, doc, tf, spec)
        print(f"wrote {path}")
    return 0


def format_comparison(comparison: dict) -> str:
    """A text table of the held-out errors (% of each channel's span)."""
    lines = ["held-out RMS error, % of span (K-fold | extrapolation in ΔP | in speed):"]
    for name, res in comparison["models"].items():
        cells = []
        for c in ("torque", "q_a", "q_b", "q_case"):
            vals = [res.get(k, {}).get(c, {}).get("percent_of_span") for k in
                    ("kfold", "extrapolate_pressure", "extrapolate_speed")]
            if any(v is not None for v in vals):
                cells.append(f"{c} " + "|".join("—" if v is None else f"{v:.2f}" for v in vals))
        lines.append(f"  {name:<26} " + "  ".join(cells))
    return "\n".join(lines)


# ----------------------------------------------------------------------------- diagnose


def _profile_bic(tf) -> float:
    """BIC of a table fit with each channel's noise level profiled out:
    Σ_c n_c ln(RSS_c / n_c) + k ln n (Gaussian likelihood; the relative weights held);
    in a joint fit the logs add their χ² at their own (held) noise levels and their count."""
    t = tf.table
    total, n_all = 0.0, 0
    if tf.dataset is not None:
        chi2_table = sum(float(np.nansum((tf.table_residuals[c] / tf.table_sigma[c]) ** 2))
                         for c in ("torque", "q_a", "q_b", "q_case"))
        total += tf.ls.chi2 - chi2_table
        n_all += sum(int(v) for v in tf.ls.used.values()) - sum(
            int(np.isfinite(t.measured[c]).sum()) for c in ("torque", "q_a", "q_b", "q_case"))
    for c in ("torque", "q_a", "q_b", "q_case"):
        ok = np.isfinite(t.measured[c])
        if not ok.any():
            continue
        r = tf.table_residuals[c][ok] / t.relative_sigma[c][ok]
        n = int(ok.sum())
        total += n * math.log(max(float(np.mean(r**2)), 1e-300))
        n_all += n
    return total + len(tf.ls.free) * math.log(max(n_all, 1))


def diagnose_table(table, spec, min_evidence: float = 10.0, max_mechanisms: int = 3, candidates=None,
                   progress=None, dataset=None, log_fit=None) -> dict:
    """Forward selection of catalog mechanisms on a table: add the mechanism that lowers the
    profiled BIC most, while it lowers it by at least ``min_evidence``; then the held-out
    comparison of the model with what was found and of the classical models."""
    from motorid.comparators.evaluate import compare
    from motorid.discrepancy.catalog import all_mechanisms
    from motorid.identify.tables import fit_table

    cands = list(candidates if candidates is not None else all_mechanisms())
    current = []
    joint = dict(dataset=dataset, log_fit=log_fit)
    fit0 = fit_table(table, spec, **joint)
    bic = _profile_bic(fit0)
    base_fit = best_fit = fit0
    steps = []
    while len(current) < max_mechanisms:
        trials = []
        for mech in cands:
            if mech in current:
                continue
            try:
                tf = fit_table(table, spec, current + [mech], **joint)
            except Exception as exc:  # a mechanism whose hooks do not take θ-averaged table samples
                steps.append({"id": mech.id, "skipped": f"{type(exc).__name__}: {exc}"[:200]})
                continue
            if not any(tf.ls.identifiable.get(k) for k in mech.parameters):
                continue
            trials.append((_profile_bic(tf), mech, tf))
            if progress:
                progress(f"{mech.id}: ΔBIC {bic - trials[-1][0]:.1f}")
        if not trials:
            break
        b, mech, tf = min(trials, key=lambda t: t[0])
        steps.append({"id": mech.id, "delta_bic": bic - b})
        if bic - b < min_evidence:
            break
        current.append(mech)
        bic, best_fit = b, tf
    comparison = compare(table, spec, mechanisms=current) if len(table) >= 10 else None
    return {"mechanisms": current, "fit": best_fit, "base_fit": base_fit, "steps": steps, "comparison": comparison}


def diagnosis_table_document(dg: dict, spec) -> dict:
    from motorid.identify.results import _clean

    fit, base = dg["fit"], dg["base_fit"]
    mechs = []
    for m in dg["mechanisms"]:
        params = {}
        for k in m.parameters:
            info = m.parameters[k]
            params[k] = {"value": fit.ls.values.get(k), "std": fit.ls.std.get(k), "unit": info.unit}
        mechs.append({"id": m.id, "name": getattr(m, "name", m.id), "reference": getattr(m, "reference", ""),
                      "parameters": params, "signature": getattr(m, "signature", "")})
    chans = {}
    for c in ("torque", "q_a", "q_b", "q_case"):
        r0, r1 = base.table_residuals[c], fit.table_residuals[c]
        if np.isfinite(r0).any():
            chans[c] = {"residual_rms_before": float(np.sqrt(np.nanmean(r0**2))),
                        "residual_rms_after": float(np.sqrt(np.nanmean(r1**2)))}
    return _clean({"source": "operating-point tables", "mismatch": bool(dg["mechanisms"]), "mechanisms": mechs,
                   "selection": {"criterion": "BIC with each channel's noise level profiled out", "steps": dg["steps"]},
                   "channels": chans, "comparison": dg["comparison"],
                   "parameters": {k: {"value": fit.ls.values[k], "std": fit.ls.std[k],
                                      "identifiable": fit.ls.identifiable[k],
                                      **({"reason": fit.ls.reasons[k]} if k in fit.ls.reasons else {})}
                                  for k in fit.ls.names}})


def run_table_diagnose(args, logs, tables, spec) -> int:
    """The `motorid diagnose` command when tables are given (with logs: the joint fit's BIC)."""
    import sys

    from motorid.identify.cli import check_output
    from motorid.identify.results import write_json_atomic
    from motorid.io.tables import read_tables

    out = Path(args.out)
    check_output(out, args.force, files=("diagnosis.json",))
    table = read_tables(tables, spec)
    dataset = log_fit = None
    if logs:
        from motorid.identify.least_squares import fit_least_squares
        from motorid.identify.pipeline import load_campaign

        _, dataset = load_campaign(logs, spec)
        log_fit = fit_least_squares(dataset, spec)
    show = sys.stderr.isatty()
    dg = diagnose_table(table, spec, min_evidence=args.min_evidence, dataset=dataset, log_fit=log_fit,
                        progress=(lambda m: print(f"  {m}", file=sys.stderr)) if show else None)
    doc = diagnosis_table_document(dg, spec)
    doc["inputs"] = {"logs": [str(p) for p in logs], "tables": [str(p) for p in tables], "motor": str(args.motor)}
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(doc, out / "diagnosis.json")
    if not doc["mismatch"]:
        print("no mechanism earns its place on the table (ΔBIC below --min-evidence)")
    for m in doc["mechanisms"]:
        print(f"found {m['id']} ({m['name']})")
    if doc["comparison"]:
        print(format_comparison(doc["comparison"]))
    print(f"wrote {out / 'diagnosis.json'}")
    return 0
