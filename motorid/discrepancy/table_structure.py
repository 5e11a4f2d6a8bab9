"""Structure left in the residuals of a table fit, judged against the points' own noise.

The table counterpart of :func:`motorid.discrepancy.locate.locate`: after a fit on
operating points every channel's residual over its σ should scatter as unit noise
with no trend along any operating variable.  The points are grouped along |ω|,
direction, |ΔP|, port-pressure sum P_A + P_B, viscosity, operating mode (motor /
pump) and recording, the residual taken as signed, in the sense of rotation and in
the sense of the pressure difference (a loss that follows ω or ΔP cancels in a
mean over both signs); each group's summed z-score over √n is a standard normal
under the model, and Σ z_g² over a variable's groups is tested as χ² (dof = the
number of groups; the fitted parameters only shrink it, so the test errs on the
side of silence).  A structure counts where p is below ``alpha`` over the number
of tests (Bonferroni) and its largest group mean is at least ``min_effect`` of the
channel's noise level.  This is what makes a misfit that no term of the empirical
library takes (a friction with a hump in ΔP) a reported mismatch, in words and
numbers, rather than nothing.
"""

from __future__ import annotations

import numpy as np

from motorid.discrepancy.locate import (CHANNEL_WORDS, _bar, _chi2_sf, _fmt, _group_test, _Labels, _mpas,
                                        _quantile_groups, _rpm, trend_words)
from motorid.identify.identifiability import relative_spread
from motorid.physics.efficiency import operating_mode

CHANNELS = ("torque", "q_a", "q_b", "q_case")


def _variables(table) -> dict:
    """variable → point labels (left out where the table does not vary along it)."""
    w = np.asarray(table.speed, float)
    pa, pb = np.asarray(table.p_a, float), np.asarray(table.p_b, float)
    out = {}
    for name, v, n_groups, fmt in (("speed", np.abs(w), 5, _rpm), ("pressure difference", np.abs(pa - pb), 5, _bar),
                                   ("port-pressure sum", pa + pb, 4, _bar),
                                   ("viscosity", np.asarray(table.viscosity, float), 4, _mpas)):
        # a variable held within its scatter (one speed, one temperature) is no variable
        out[name] = _quantile_groups(v, n_groups, fmt=fmt) if relative_spread(v) >= 0.05 else None
    sign = np.where(w > 0, "positive rotation", np.where(w < 0, "negative rotation", None))
    if len({s for s in sign if s is not None}) == 2:
        out["direction"] = _Labels(sign, ["positive rotation", "negative rotation"])
    mode = operating_mode(w, pa, pb)
    if {"motor", "pump"} <= set(mode):
        out["operating mode"] = _Labels(np.where(mode == "none", None, mode), ["motor", "pump"])
    rec = table.recordings()
    names = list(dict.fromkeys(str(r) for r in rec))
    if len(names) >= 2:
        out["recording"] = _Labels(np.array([str(r) for r in rec], dtype=object), names)
    return {k: v for k, v in out.items() if v is not None and len(v.unique_order) >= 2}


def table_structures(fit, alpha: float = 1e-3, min_effect: float = 0.3) -> list:
    """The significant and relevant structures of a table fit's residuals (:class:`TableFit`)
    → [dict(channel, variable, statistic, dof, p_value, effect [SI], effect_sigma, where, groups)],
    strongest first."""
    table = fit.table
    variables = _variables(table)
    found = []
    for c in CHANNELS:
        r = np.asarray(fit.table_residuals[c], float)
        sig = np.asarray(fit.table_sigma[c], float)
        ok = np.isfinite(r) & np.isfinite(sig) & (sig > 0)
        if ok.sum() < 10:
            continue
        z = np.where(ok, r / np.where(ok, sig, 1.0), 0.0)
        # a loss (friction, leakage) keeps its sense to the rotation: in a map of both directions its
        # residual changes sign with ω, and a mean over the directions would cancel it; a flow between
        # the ports keeps its sense to the pressure difference: in a map where either port holds the
        # high pressure its residual changes sign with ΔP, and a mean over |ΔP| would cancel it
        w_sign = np.sign(np.asarray(table.speed, float))
        senses = [("", np.ones_like(z))]
        if "direction" in variables:
            senses.append((" (taken in the sense of rotation)", w_sign))
        dp_sign = np.sign(np.asarray(table.p_a, float) - np.asarray(table.p_b, float))
        # where sgn ΔP is ± sgn ω at every point (motor mode only, pump mode only) it is the same test again
        if ((dp_sign[ok] > 0).sum() >= 5 and (dp_sign[ok] < 0).sum() >= 5
                and not np.all(dp_sign[ok] == w_sign[ok]) and not np.all(dp_sign[ok] == -w_sign[ok])):
            senses.append((" (taken in the sense of the pressure difference)", dp_sign))
        for sense, sgn in senses:
            use = ok & (sgn != 0)  # a point at ω = 0 or ΔP = 0 has no sense to take
            zs, rs = z * sgn, r * sgn
            for var, labels in variables.items():
                # by direction the sense of rotation is the signed test again; by operating mode (within
                # which sgn ΔP = ± sgn ω) the sense of ΔP is the sense of rotation again
                if (sense and var == "direction") or ("pressure" in sense and var == "operating mode"):
                    continue
                stat, dof, tested = _group_test(labels, np.where(use, zs, np.nan), var)
                if dof < 2:
                    continue
                groups = [(lab, float(np.mean(rs[sel & use])), float(zg), float(np.median(sig[sel & use])),
                           int((sel & use).sum())) for lab, zg, sel in tested]
                worst = max(groups, key=lambda g: abs(g[2]))
                verb = "falls short of the model" if worst[1] < 0 else "exceeds the model"
                at = {"direction": "in", "operating mode": "in", "recording": "in recording"}.get(var, f"at {var}")
                found.append({"channel": c, "variable": var, "statistic": stat, "dof": dof,
                              "p_value": _chi2_sf(stat, dof), "effect": worst[1],
                              "effect_sigma": abs(worst[1]) / worst[3] if worst[3] > 0 else np.inf,
                              "where": f"{CHANNEL_WORDS[c]}{sense} {at} {worst[0]} {verb} by "
                                       f"{_fmt(abs(worst[1]), c)} on average ({worst[4]} points, "
                                       f"{abs(worst[2]):.3g} standard errors)",
                              "groups": [(g[0], g[1], g[2]) for g in groups]})
    tests = max(len(found), 1)
    out = [s for s in found if s["p_value"] < alpha / tests and s["effect_sigma"] >= min_effect]
    return sorted(out, key=lambda s: s["p_value"])


def shape_words(structures: list) -> str:
    """How the residual runs along each variable of ``structures`` (one channel's), in words: per
    variable its strongest structure (as signed, in the sense of rotation or of the pressure difference)."""
    words = []
    strongest: dict = {}
    for s in sorted(structures, key=lambda s: s["p_value"]):
        strongest.setdefault(s["variable"], s)
    for s in strongest.values():
        if s["variable"] not in ("direction", "operating mode", "recording"):
            trend = trend_words([g[1] for g in s["groups"]], s["variable"])
            if trend:
                words.append(trend)
    return ", ".join(words)
