"""Rules that revise what the selection named, after it: values that rest on a fragile reading, and
names that only make sense as a pair that cancels (:func:`motorid.discrepancy.select.diagnose`)."""

from __future__ import annotations

import numpy as np

from motorid.discrepancy.locate import CHANNEL_WORDS
from motorid.identify.types import FitResult


#: a displacement error and a torque gain whose sum is within this share of the displacement error cancel
#: in the torque
CANCELLING_SHARE = 0.25


def refuse_by_shape(accepted, shaped, refused, say) -> list:
    """Refuse the name whose law has not the shape of what it was named for (:func:`~motorid.discrepancy.unexplained.stand_ins_by_shape`),
    and every name kept after it (chosen with it in the model) → the names kept."""
    i, channel, check = shaped
    cand = accepted[i]
    gain = check["law_left"] - check["both_left"]
    why = (f"its law has not the shape of what it was named for: in the {CHANNEL_WORDS[channel]}, the empirical "
           f"term{'s' if len(check['terms']) > 1 else ''} {', '.join(check['terms'])} lower{'' if len(check['terms']) > 1 else 's'} "
           f"the held-out χ² by {gain:.4g} beyond it, and beside {'them' if len(check['terms']) > 1 else 'it'} the law "
           f"adds only {max(check['terms_left'] - check['both_left'], 0.0):.3g}: a stand-in for a law in no catalog")
    say(f"refused {cand.mechanism.id}: {why}")
    refused.append({"id": cand.mechanism.id, "why": why, "extrapolation": getattr(cand, "extrapolation", None),
                    "shape_check": {"channel": channel, **check}})
    for later in accepted[i + 1:]:
        refused.append({"id": later.mechanism.id, "why": f"chosen after {cand.mechanism.id}, a refused stand-in, "
                        "was in the model", "extrapolation": getattr(later, "extrapolation", None)})
    for dropped in accepted[i:]:
        if hasattr(dropped, "step_entry"):
            dropped.step_entry["accepted"] = False
            dropped.step_entry["refused_by_shape"] = True
    return accepted[:i]


def refuse_cancelling_pair(accepted, current, base, refused, say):
    """A displacement error named together with a torque-transducer gain that undoes it in the torque
    (g ≈ −ε): the pair says only that the port flows read (1 + ε) times the swept flow while the torque
    does not follow, which both port meters reading high says as well, and so does a flow the samples
    meet at some shaft angles only (a valve-plate notch between slow samples, aliased: a second reader's
    simulator).  Neither is named; the first of the two and every name kept after it are refused (they
    were chosen with it in the model) → (accepted, current fit)."""
    ids = [c.mechanism.id for c in accepted]
    if "displacement_error" not in ids or "torque_meter_gain" not in ids:
        return accepted, current
    values = getattr(accepted[-1].fit, "values", None) or getattr(accepted[-1].fit, "params_all", {}) or {}
    eps, g = values.get("displacement_error.eps"), values.get("torque_meter_gain.g")
    if eps is None or g is None or abs(g + eps) > CANCELLING_SHARE * abs(eps):
        return accepted, current
    i = min(ids.index("displacement_error"), ids.index("torque_meter_gain"))
    why = (f"a displacement error (ε = {eps:+.4f}) and a torque gain (g = {g:+.4f}) that cancel in the torque: the "
           "flows alone read off the swept flow (both port meters reading high, or flow the samples meet at "
           "some shaft angles only, say the same); neither is named")
    say(f"refused displacement_error and torque_meter_gain: {why}")
    for cand in accepted[i:]:
        refused.append({"id": cand.mechanism.id, "why": why if cand.mechanism.id in ("displacement_error",
                        "torque_meter_gain") else "chosen with a refused pair in the model",
                        "extrapolation": getattr(cand, "extrapolation", None)})
        if hasattr(cand, "step_entry"):
            cand.step_entry["accepted"] = False
            cand.step_entry["refused_after_recheck"] = True
    kept = accepted[:i]
    return kept, kept[-1].fit if kept else base


#: where a torque gain is told from K_F by the shaft-angle ripple alone, the share of the ripple's size
#: by which the model's ripple (MODEL.md's ideal kinematics, S(θ)) may be off: two implementations of the
#: same equations, cell-averaged differently, differ by 0.1-0.3 % (a second reader's simulator); a real
#: motor's valve-plate timing by more, which the caveat says
RIPPLE_MODEL_TOLERANCE = 0.005


def ripple_gain_only(accepted: list, dataset) -> bool:
    """A torque gain is named and every running sample has its low-pressure port at one pressure."""
    from motorid.physics.sensors import one_back_pressure

    s = getattr(dataset, "running", None)
    return bool(s is not None and np.size(s.speed) and any(c.mechanism.id == "torque_meter_gain" for c in accepted)
                and one_back_pressure(np.minimum(np.asarray(s.p_a, float), np.asarray(s.p_b, float))))


def widen_for_the_ripple_model(final: FitResult, name: str = "torque_meter_gain.g",
                               tolerance: float = RIPPLE_MODEL_TOLERANCE) -> None:
    """Add to ``final``'s covariance the error a ripple held ``tolerance`` wrong gives a value read from the
    ripple's size: σ_r = tolerance·(1 + g) on ``name``, carried to every parameter correlated with it as the
    fit carries a shift of ``name`` (C ← C + σ_r² b bᵀ, b = C[:, g] / C_gg: the regression of each
    parameter on it); std and correlation follow."""
    if name not in final.free or final.covariance is None:
        return
    C = np.asarray(final.covariance, dtype=float)
    i = final.free.index(name)
    if not (np.all(np.isfinite(C)) and C[i, i] > 0):
        return
    b = C[:, i] / C[i, i]
    sigma = tolerance * (1.0 + float(final.values.get(name) or 0.0))
    C = C + sigma**2 * np.outer(b, b)
    final.covariance = C
    d = np.sqrt(np.maximum(np.diag(C), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        final.correlation = C / np.outer(d, d)
    for j, k in enumerate(final.free):
        if final.std.get(k) is not None:
            final.std[k] = float(d[j])


def caveats(accepted: list, dataset) -> dict:
    """What a named value rests on where that is fragile: a torque gain at one back pressure is told from
    K_F (K_F·D·(P_A+P_B) is then K_F·D·|ΔP| plus a constant) by the shaft-angle torque ripple alone, so a
    ripple the model holds a little wrong moves it (a second reader's simulator: −7σ of the fit's own std;
    :func:`widen_for_the_ripple_model` adds :data:`RIPPLE_MODEL_TOLERANCE` of the ripple to it)."""
    out = {}
    if ripple_gain_only(accepted, dataset):
        out["torque_meter_gain"] = (
            "every running sample has its low-pressure port at one pressure: the gain is told from K_F only by "
            "the torque's shaft-angle ripple, so its value (and K_F's, T_Fc's) rests on the model's ripple; "
            f"their std include {100 * RIPPLE_MODEL_TOLERANCE:.1f} % of the ripple's size for the ideal "
            "kinematics, a real motor's valve-plate timing may move them further; runs at a second back "
            "pressure determine the gain")
    return out


#: a transducer's linearity class: a smooth error curve of its own reading up to this share of its reading
#: scale (the 99th percentile of |reading|) is within what a calibrated bench transducer holds (torque
#: transducers 0.05-0.1 % of full scale, flow meters 0.1-0.5 % of reading)
LINEARITY_SHARE = 1e-3
#: a mechanism's change of a channel is calibration-like where a smooth curve of the reading explains it but
#: for this share of its size (the 99th percentiles of |change| and of |what the curve leaves|)
CALIBRATION_LIKE = 0.25


def _calibration_curve_left(change, reading, scale) -> np.ndarray:
    """What a smooth calibration curve of the reading (1, y, y|y|, y², y³ in y = reading / scale) leaves
    of ``change`` (least squares)."""
    y = reading / scale
    X = np.column_stack([np.ones_like(y), y, y * np.abs(y), y**2, y**3])
    beta = np.linalg.lstsq(X, change, rcond=None)[0]
    return change - X @ beta


def transducer_like(mechanism, fit) -> dict | None:
    """Whether what ``mechanism`` adds in ``fit`` (a fit on every sample with it in the model) could be a
    transducer's own calibration error: in every channel it acts on, its change of the predictions (its
    values against its neutral ones) is a smooth curve of that channel's reading (:data:`CALIBRATION_LIKE`)
    and smaller than the transducer's linearity class (:data:`LINEARITY_SHARE` of the reading scale).  A
    filling loss ∝ ω² of 0.04 % of the port flow is a flow meter's curvature as well, and a gain error of
    0.015 % its slope: which of the two (or the meter's curvature, or a law of the motor) it is, the data
    do not say.  A change that is the same at every sample (a transducer's zero offset) is exempt: its
    name says what it is at any size.
    → {channel, size, scale, share, calibration_share} of the channel where the change is largest, when
    transducer-like; None otherwise (or where it cannot be taken)."""
    prob = getattr(fit, "problem", None)
    if prob is None or not hasattr(prob, "predictions") or any(k in prob.held for k in mechanism.parameters):
        return None
    neutral = mechanism.neutral()
    values = {k: float(fit.params_all[k]) for k in prob.free}
    with_it = prob.predictions(values)
    without = prob.predictions({k: float(neutral.get(k, v)) for k, v in values.items()})
    obs = prob.observed()
    largest, seen = None, False
    for c in mechanism.channels:
        if c not in with_it or c not in obs or c not in fit.inliers:
            continue
        ok = np.asarray(fit.inliers[c], bool) & np.isfinite(obs[c])
        if ok.sum() < 3:
            continue
        change = (np.asarray(with_it[c]) - np.asarray(without[c]))[ok]
        reading = np.asarray(obs[c])[ok]
        scale = float(np.quantile(np.abs(reading), 0.99))
        if not scale > 0 or not np.all(np.isfinite(change)):
            return None
        size = float(np.quantile(np.abs(change), 0.99))
        if ok.sum() < 20:  # too few (breakaway events) for a curve: it only must stay within the linearity
            if size >= LINEARITY_SHARE * scale:
                return None
            continue
        if not np.any(change):
            continue  # it does not act on this channel here
        seen = True
        if np.ptp(change) <= 1e-9 * np.max(np.abs(change)):
            return None  # a constant: a zero offset, named as such
        left = float(np.quantile(np.abs(_calibration_curve_left(change, reading, scale)), 0.99)) if size > 0 else 0.0
        if size >= LINEARITY_SHARE * scale or left >= CALIBRATION_LIKE * size:
            return None  # beyond a transducer's linearity, or a shape no calibration curve of the reading has
        entry = {"channel": c, "size": size, "scale": scale, "share": size / scale,
                 "calibration_share": 1.0 - left / size if size > 0 else 1.0}
        if largest is None or entry["share"] > largest["share"]:
            largest = entry
    return largest if seen else None
