"""THE BASELINE of bench_diagnose: motorid's diagnose as it was before issue 16 (commit 702c862),
kept verbatim (every candidate a full fit on every sample, several starts each, held-out
folds as full fits).  Run as a script it is the whole job end to end:

    python benchmarks/diagnose_baseline.py CAMPAIGN.csv.gz MOTOR.toml OUT.json

Name and model the missing physics: fit candidates, compare, keep what earns its place.

Forward selection over the catalog (the registry of mechanisms, :mod:`motorid.physics.registry`):

1. fit the base model; :func:`~motorid.discrepancy.locate.locate` its residuals;
2. if structure is found, fit the current model plus each candidate mechanism
   that touches a channel with structure, with the noise levels and outlier
   set of the base fit held fixed so that χ² values compare;
3. score each by evidence that punishes extra parameters,
   ΔBIC = Δχ² − k ln N (k extra parameters, N residuals), and the best few by
   the χ² of runs held out of the fit (K-fold over runs);
4. keep the best if ΔBIC exceeds ``min_evidence``, the held-out error falls
   and it removes some located structure; repeat while structure remains;
5. refit the final model (noise re-estimated) and report what is left
   unexplained in words — never forcing a name on it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from motorid.discrepancy.locate import CHANNEL_WORDS, Location, locate
from motorid.identify.least_squares import fit_least_squares
from motorid.identify.types import FitOptions, FitResult
from motorid.physics.registry import all_mechanisms


@dataclass
class Candidate:
    mechanism: object
    fit: FitResult
    delta_chi2: float
    delta_bic: float
    cv_gain: float | None = None  # held-out χ² of the current model minus this one's
    removed: list = field(default_factory=list)  # structures it explains


@dataclass
class Diagnosis:
    mismatch: bool
    base: FitResult
    final: FitResult
    accepted: list  # [Candidate]
    location_before: Location
    location_after: Location
    steps: list  # per stage: [{id, delta_bic, cv_gain, accepted}]
    unexplained: list  # [Structure]
    # issue 15: candidates refused as stand-ins, and the unexplained structure in words with empirical terms
    refused: list = field(default_factory=list)  # [{id, why, extrapolation}]
    unexplained_detail: list | None = None  # unexplained.unexplained_entries


def _fixed(ls: FitResult) -> tuple[dict, dict]:
    noise = {c: ls.noise_by_run[c] for c in ls.noise_by_run}
    if "breakaway" in ls.noise and ls.noise["breakaway"] is not None:
        noise["breakaway"] = np.asarray(ls.sigma["breakaway"], dtype=float)  # per event
    return noise, dict(ls.inliers)


def _n_residuals(ls: FitResult) -> int:
    return int(sum(ls.used.values()))


def _folds(dataset, k: int) -> list[np.ndarray]:
    """Run indices in k folds, spread over speed and protocol."""
    runs = dataset.runs
    order = np.lexsort((runs["speed_median_rad_s"].abs().to_numpy(), runs["protocol"].astype(str).to_numpy()))
    folds = [[] for _ in range(k)]
    for i, r in enumerate(order):
        folds[i % k].append(int(r))
    return [np.array(f, dtype=int) for f in folds]


def _held_out_chi2(dataset, spec, mechanisms, noise, inliers, initial, folds) -> float:
    run_of = np.asarray(dataset.run_of_sample, dtype=int)
    ev_run = np.asarray(getattr(dataset, "run_of_event", np.zeros(0, int)), dtype=int)
    total = 0.0
    for fold in folds:
        keep = {}
        held = {}
        for c, mask in inliers.items():
            where = np.isin(ev_run, fold) if c == "breakaway" else np.isin(run_of, fold)
            keep[c] = mask & ~where
            held[c] = mask & where
        fit = fit_least_squares(dataset, spec, mechanisms, FitOptions(fixed_noise=noise, fixed_inliers=keep),
                                initial=initial)
        for c, mask in held.items():
            if not mask.any():
                continue
            sig = np.full(mask.shape, noise[c]) if c == "breakaway" else np.asarray(noise[c])[run_of]
            r = fit.residuals[c][mask] / sig[mask]
            total += float(np.sum(np.minimum(r**2, 25.0)))  # a held-out spike counts like an outlier
    return total


def _starts(current: dict, mech) -> list:
    """Starting points for a candidate: the current fit with the mechanism at its
    typical size, smaller and larger, and the default start (a nonlinear
    parameter such as a characteristic speed has local minima)."""
    init = mech.initial()
    if getattr(mech, "single_start", False):  # linear in its parameters (a gain, an error ε): one start
        return [{**current, **init}]
    out = [{**current, **init}, dict(init)]
    for factor in (0.25, 4.0):
        out.append({**current, **{k: v * factor if mech.parameters[k].positive else v for k, v in init.items()}})
    return out


def _best_of_starts(dataset, spec, mechanisms, noise, inliers, current, mech) -> FitResult:
    """Screen the starts with a few Levenberg-Marquardt steps, finish the best."""
    best = None
    for start in _starts(current, mech):
        fit = fit_least_squares(dataset, spec, mechanisms,
                                FitOptions(fixed_noise=noise, fixed_inliers=inliers, max_steps=12), initial=start)
        if np.isfinite(fit.chi2) and (best is None or fit.chi2 < best.chi2):
            best = fit
    if best is None:
        return fit
    return fit_least_squares(dataset, spec, mechanisms, FitOptions(fixed_noise=noise, fixed_inliers=inliers),
                             initial=best.params_all)


def _tied(scored: list, min_evidence: float) -> bool:
    """Whether the two best candidates both earn their place (ΔBIC > ``min_evidence``) and
    the data do not tell them apart: the first beats the second by less than ``min_evidence``
    in ΔBIC or in Δχ² (the fit itself — where both fit alike, one parameter fewer must not
    decide the name).  Mechanisms whose signatures coincide on these data (a Stribeck curve
    in speed and one in μω/ΔP where all slow runs share one pressure) tie; a wrong name is
    worse than none, so diagnose then names neither."""
    if len(scored) < 2 or scored[1].delta_bic <= min_evidence:
        return False
    a, b = scored[0], scored[1]
    return min(a.delta_bic - b.delta_bic, a.delta_chi2 - b.delta_chi2) < min_evidence


def _structure_key(s) -> tuple:
    return (s.channel, s.variable, s.order)


def diagnose(dataset, spec, base: FitResult | None = None, mechanisms=None, min_evidence: float = 10.0,
             alpha: float = 1e-3, min_effect: float = 0.3, folds: int = 3, cv_top: int = 1,
             max_mechanisms: int = 3, progress=None, check_regions: bool = False) -> Diagnosis:
    """Find, name and model what the base model leaves out (see module doc)."""
    from motorid.discrepancy.unexplained import extrapolation_check, unexplained_entries

    say = progress or (lambda msg: None)
    refused: list = []
    catalog = list(mechanisms) if mechanisms is not None else all_mechanisms()
    base = base or fit_least_squares(dataset, spec)
    noise, inliers = _fixed(base)
    loc0 = locate(base, dataset, spec, alpha=alpha, min_effect=min_effect)
    current, current_mechs, accepted, steps = base, [], [], []
    loc = loc0
    fold_runs = _folds(dataset, folds)
    n_res = max(_n_residuals(base), 2)
    current_cv = None
    while loc.significant and len(accepted) < max_mechanisms:
        channels = {s.channel for s in loc.significant}
        say(f"structure in {', '.join(sorted(channels))}; trying {len(catalog) - len(current_mechs)} mechanisms")
        scored = []
        for mech in catalog:
            # shows_in: where its residual appears once the base fit has compromised (a case-meter gain shows
            # in the port flows, as K_L0 follows the case meter); default: the channels it acts on
            if mech in current_mechs or not channels & set(getattr(mech, "shows_in", mech.channels)):
                continue
            if not getattr(mech, "seen_by", lambda ds: True)(dataset):  # e.g. pump-mode law, no pump runs
                continue
            fit = _best_of_starts(dataset, spec, current_mechs + [mech], noise, inliers, current.params_all, mech)
            d = current.chi2 - fit.chi2
            k = sum(1 for p in mech.parameters if fit.identifiable.get(p))
            scored.append(Candidate(mech, fit, d, d - k * np.log(n_res)))
        if not scored:
            break
        scored.sort(key=lambda c: -c.delta_bic)
        if _tied(scored, min_evidence):  # two names explain it alike: naming one would be a guess
            steps.append([{"id": c.mechanism.id, "delta_chi2": c.delta_chi2, "delta_bic": c.delta_bic,
                           "cv_gain": None, "accepted": False, "tied": i < 2} for i, c in enumerate(scored)])
            say(f"{scored[0].mechanism.id} and {scored[1].mechanism.id} explain it alike; neither is named")
            break
        if current_cv is None and folds > 1:
            current_cv = _held_out_chi2(dataset, spec, current_mechs, noise, inliers, current.params_all, fold_runs)
        for cand in scored[:cv_top]:
            if cand.delta_bic <= min_evidence or folds < 2:
                continue
            cv = _held_out_chi2(dataset, spec, current_mechs + [cand.mechanism], noise, inliers,
                                cand.fit.params_all, fold_runs)
            cand.cv_gain = current_cv - cv
            cand.cv = cv
        best = None
        for cand in scored[:cv_top]:
            if cand.delta_bic > min_evidence and (folds < 2 or (cand.cv_gain or 0) > 0):
                after = locate(cand.fit, dataset, spec, alpha=alpha, min_effect=min_effect)
                before_keys = {_structure_key(s) for s in loc.significant}
                after_keys = {_structure_key(s) for s in after.significant}
                removed = [s for s in loc.significant if _structure_key(s) in before_keys - after_keys]
                if removed or len(after.significant) < len(loc.significant):
                    cand.removed = removed
                    cand.location = after
                    best = cand
                    break
        if best is not None and check_regions:  # issue 15: a name must also predict where it was not fitted
            best.extrapolation = extrapolation_check(dataset, spec, current_mechs + [best.mechanism], noise,
                                                     inliers, best.fit)
            if not best.extrapolation["passed"]:
                say(f"refused {best.mechanism.id}: it does not predict the operating regions it was not fitted on")
                refused.append({"id": best.mechanism.id, "why": "fails where it was not fitted (stand-in)",
                                "extrapolation": best.extrapolation})
                best = None
        steps.append([{"id": c.mechanism.id, "delta_chi2": c.delta_chi2, "delta_bic": c.delta_bic,
                       "cv_gain": c.cv_gain, "accepted": c is best,
                       "extrapolation": getattr(c, "extrapolation", None)} for c in scored])
        if best is None:
            break
        say(f"kept {best.mechanism.id} (ΔBIC {best.delta_bic:.1f})")
        accepted.append(best)
        current_mechs.append(best.mechanism)
        current = best.fit
        current_cv = getattr(best, "cv", None)
        loc = best.location
    # final model with its own noise estimate
    final = fit_least_squares(dataset, spec, current_mechs, initial=current.params_all) if accepted else base
    loc_after = locate(final, dataset, spec, alpha=alpha, min_effect=min_effect) if accepted else loc0
    unexplained = list(loc_after.significant)
    detail = unexplained_entries(unexplained, final, dataset, spec) if unexplained else []
    return Diagnosis(mismatch=bool(accepted or unexplained), base=base, final=final, accepted=accepted,
                     location_before=loc0, location_after=loc_after, steps=steps, unexplained=unexplained,
                     refused=refused, unexplained_detail=detail)


def _rms(ls: FitResult, c: str):
    r = ls.residuals[c][ls.inliers[c]]
    return float(np.sqrt(np.mean(r**2))) if r.size else None


def _noise_rms(ls: FitResult, c: str):
    """The noise level the residual RMS should come down to: RMS of the σ of the samples."""
    s = np.asarray(ls.sigma[c])[ls.inliers[c]]
    return float(np.sqrt(np.mean(s**2))) if s.size else None


def diagnosis_document(dg: Diagnosis, spec) -> dict:
    """diagnosis.json: what was found, where, and what it did to the fit."""
    from motorid.identify.results import json_safe as _clean
    from motorid.model import parameter_info

    mechs = []
    for cand in dg.accepted:
        m = cand.mechanism
        params = {k: {"value": dg.final.values.get(k), "std": dg.final.std.get(k),
                      "unit": parameter_info(k, dg.final.mechanisms).unit} for k in m.parameters}
        where = "; ".join(s.where for s in cand.removed[:4]) or "; ".join(
            s.where for s in dg.location_before.significant if s.channel in m.channels)[:400]
        try:
            words = m.describe({k: dg.final.values.get(k) for k in m.parameters}, spec=spec)
        except Exception:  # a description is a courtesy, never a failure
            words = ""
        mechs.append({
            "id": m.id, "name": m.name, "channels": list(m.channels), "where": where,
            "explanation": f"{m.physics} {words}".strip(), "reference": m.reference,
            "parameters": params,
            "evidence": {"delta_chi2": cand.delta_chi2, "delta_bic": cand.delta_bic,
                         "held_out_chi2_gain": cand.cv_gain},
        })
    channels = sorted(dg.base.residuals)
    doc = {
        "mismatch": dg.mismatch,
        "mechanisms": mechs,
        "channels": {c: {"residual_rms_before": _rms(dg.base, c), "residual_rms_after": _rms(dg.final, c),
                         "noise": _noise_rms(dg.final, c), "words": CHANNEL_WORDS[c]} for c in channels},
        "parameters_before": {k: {"value": dg.base.values[k], "std": dg.base.std[k]} for k in dg.base.names},
        "parameters_after": {k: {"value": dg.final.values.get(k), "std": dg.final.std.get(k)} for k in dg.base.names},
        "located_before": [s.as_dict() for s in dg.location_before.significant],
        "unexplained": dg.unexplained_detail if dg.unexplained_detail is not None else [
            {"channel": s.channel, "where": s.where, "p_value": s.p_value,
             "effect": s.effect, "effect_sigma": s.effect_sigma} for s in dg.unexplained],
        "refused_stand_ins": dg.refused,
        "selection": dg.steps,
        "tests": {"count": dg.location_before.tests, "threshold_p": dg.location_before.threshold},
    }
    return _clean(doc)


def residual_arrays(dg: Diagnosis, dataset) -> dict:
    """Residuals before and after (over σ) with their operating points, for the report's plots."""
    out = {}
    s = dataset.running
    for c in dg.base.residuals:
        before = dg.base.residuals[c] / dg.base.sigma[c]
        after = dg.final.residuals[c] / dg.final.sigma[c]
        ok = dg.base.inliers[c] & np.isfinite(before) & np.isfinite(after)
        if c == "breakaway":  # at rest: plotted against the port-pressure sum instead of speed
            ev = dataset.events
            x_speed, x_theta = np.asarray(ev.p_a + ev.p_b), np.asarray(ev.theta)
        else:
            x_speed, x_theta = np.asarray(s.speed), np.asarray(s.theta)
        out[f"{c}__before"] = before[ok]
        out[f"{c}__after"] = after[ok]
        out[f"{c}__speed"] = x_speed[ok]
        out[f"{c}__theta"] = np.mod(x_theta[ok], 2 * np.pi)
    return out


if __name__ == "__main__":
    import json
    import sys

    from motorid.identify.pipeline import load_campaign
    from motorid.io.spec import load_motor_spec as load_spec

    log, motor, out = sys.argv[1:4]
    spec = load_spec(motor)
    _, data = load_campaign([log], spec)
    dg = diagnose(data, spec)
    with open(out, "w") as f:
        json.dump({"mechanisms": [c.mechanism.id for c in dg.accepted], "mismatch": dg.mismatch}, f)
