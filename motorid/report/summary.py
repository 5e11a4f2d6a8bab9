"""Plain-text summaries of a fit (result.json) and a diagnosis (diagnosis.json).

What ``motorid fit`` and ``motorid diagnose`` print, and what the result objects
of :mod:`motorid.api` show as ``str()``.  Values in the SI units of the document.
"""

from __future__ import annotations


def format_fit(doc: dict) -> str:
    """The fit in a table: each parameter's value, std, unit and whether the logs identify it; χ²/dof,
    outliers and warnings in words."""
    lines = [f"{'parameter':<8} {'value':>12} {'std':>10}  {'unit':<5} identifiable"]
    for k, e in doc["parameters"].items():
        if e["identifiable"]:
            weak = ", but not told from 0 (95 % interval reaches it)" if e.get("indistinct_from_zero") else ""
            lines.append(f"{k:<8} {e['value']:>12.5g} {e['std']:>10.3g}  {e['unit']:<5} yes{weak}")
        else:
            lines.append(f"{k:<8} {'—':>12} {'—':>10}  {e['unit']:<5} no: {e.get('reason', '')}")
    fit = doc["fit"]
    lines.append(f"χ²/dof = {fit['reduced_chi2']:.3f}; outliers rejected: "
                 + ", ".join(f"{c} {n}" for c, n in fit["outliers"].items()))
    for w in fit["warnings"]:
        lines.append(f"warning: {w}")
    notes = (doc.get("data") or {}).get("notes") or []
    runs = [n for n in notes if str(n).startswith("run ")]
    lines += [f"note: {n}" for n in notes if not str(n).startswith("run ")]  # the campaign's (encoder, gearbox)
    if runs:
        lines.append(f"note: {len(runs)} note(s) on single runs (result.json data.notes), the first: {runs[0]}")
    if "mcmc" in doc:
        m = doc["mcmc"]
        lines.append(f"emcee: {m['steps']} steps × {m['walkers']} walkers, converged: {m['converged']}")
    return "\n".join(lines)


def format_diagnosis(doc: dict) -> str:
    """The mechanisms found, where and with what parameters; what stays unexplained; RMS before → after."""
    if not doc["mismatch"]:
        return "no mismatch: the residuals of every channel are consistent with the noise"
    lines = []
    for m in doc["mechanisms"]:
        lines.append(f"found {m['id']} ({m['name']}): {m['where']}")
        lines.append(f"  {m['explanation']}")
        for k, p in m["parameters"].items():
            if p["value"] is not None:
                lines.append(f"  {k} = {p['value']:.4g} ± {(p['std'] or 0):.2g} {p['unit']}")
    for u in doc["unexplained"]:
        lines.append(f"unexplained: {u.get('description', u['where'])}")
    for r in doc.get("refused_stand_ins") or []:  # the best ranked that were not named, and why
        if isinstance(r, dict) and r.get("why"):
            lines.append(f"not named {r.get('id')}: {r['why']}")
    for c, v in doc["channels"].items():
        if v["residual_rms_before"] is not None:
            lines.append(f"{c}: residual RMS {v['residual_rms_before']:.4g} → {v['residual_rms_after']:.4g} "
                         f"(noise {v['noise']:.4g}) [SI]")
    return "\n".join(lines)
