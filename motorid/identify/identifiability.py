"""Which parameters the logs can determine: by the data each needs, and by the Jacobian's null space.

Parameters the logs cannot determine are held fixed and reported as not
identifiable, never given a number (MODEL.md, "What the bench can identify").
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from motorid.physics.sensors import ONE_BACK_PRESSURE_PA, one_back_pressure  # noqa: F401 (re-exported)


def relative_spread(x) -> float:
    """The 2-98 % range of the finite values of ``x`` over their largest magnitude [-]; 0 for fewer than two."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size < 2:
        return 0.0
    lo, hi = np.percentile(x, [2, 98])
    return float((hi - lo) / max(np.max(np.abs(x)), 1e-300))


def _has(arr) -> np.ndarray:
    return np.isfinite(np.asarray(arr, dtype=float))


def _why_no_running(data, n_run: int) -> str:
    """Why running runs gave no steady sample (" (every running run: …)"), or "" where none was logged."""
    runs = getattr(data, "runs", None)
    if n_run or runs is None or "excluded" not in getattr(runs, "columns", ()):
        return ""
    why = runs.loc[runs["protocol"].astype(str) != "startability", "excluded"].dropna().astype(str)
    why = why[why != ""]
    if why.empty:
        return ""
    counts = why.value_counts()
    return " (running runs left out: " + ", ".join(f"{w} ×{n}" for w, n in counts.items()) + ")"


#: the reason K_F gets where every torque reading sits at one port-pressure sum (logs and tables)
KF_HELD_FOR_TFC = ("K_F cannot be told from T_Fc, so it is held at its start value and T_Fc carries "
                   "K_F·D·(P_A+P_B) there")


#: the reason K_AB gets where a table's flows hold only K_L0 + K_AB (the inlet flow, its outlet at the case's
#: pressure): K_AB held at 0 and K_L0 fitted, carrying it, so that the inlet flow (and η_v) stays predicted
KAB_HELD_FOR_KL0 = ("K_AB cannot be told from K_L0 with these flows (the inlet flow alone, its outlet port at the "
                    "case's pressure, holds only their sum): it is held at 0 and K_L0 carries K_AB")


def at_bound_warning(k: str) -> str:
    """The words for a parameter ≥ 0 fitted at its bound: not a measurement of zero."""
    return (f"{k} is at its lower bound 0: the fit gives it nothing beyond what the other terms hold; that is the "
            "sign of its absence or of another term taking its share (T_Fc's constant loss taken by "
            "K_F·D·(P_A+P_B) at a boost pressure, K_F taken by a torque transducer's gain error), not a "
            "measurement of 0")


def kl0_carries_kab_warning(reasons: dict, free) -> str | None:
    """The warning that K_L0 is an effective value where K_AB was held for it; else None."""
    if "KL0" not in free or KAB_HELD_FOR_KL0 not in reasons.get("KAB", ""):
        return None
    return ("K_L0 is the leakage the inlet flows see, K_L0 + K_AB (K_AB not identifiable, held at 0): it predicts "
            "the inlet flow and the volumetric efficiency where the outlet port is at the case's pressure, not "
            "the case drain or the outlet flow; a case-drain or outlet flow column tells them apart")


def single_pressure_sum_reason(what: str, psum) -> str:
    """K_F's reason where ``what`` (the running torque, a table's torque) sits at one P_A+P_B [Pa]: K_F is
    held at its start and T_Fc fitted, carrying K_F·D·(P_A+P_B) of that sum, so that the friction torque
    there stays right and K_v does not take what two held values miss."""
    return f"{what} at a single port-pressure sum P_A+P_B ({np.median(psum) / 1e5:.4g} bar): {KF_HELD_FOR_TFC}"


def tfc_carries_kf_warning(reasons: dict, free, data: str, more: str) -> str | None:
    """The warning that T_Fc is an effective value (``data``: "logs", "data"; ``more``: what tells them
    apart, "runs", "points"), where K_F was held for a single pressure sum and T_Fc fitted; else None."""
    if "TFc" not in free or KF_HELD_FOR_TFC not in reasons.get("KF", ""):
        return None
    return (f"T_Fc is the Coulomb friction at the one port-pressure sum of these {data}: it holds K_F·D·(P_A+P_B) "
            f"there (K_F not identifiable, held at its start value); {more} at a second pressure tell them apart")


def coverage_reasons(data, spec, names: Sequence[str], elsewhere: Sequence[str] = ()) -> dict:
    """Reasons why the logs cannot identify a parameter, from what data exist.

    Returns name -> reason for parameters that lack the data they need
    (MODEL.md, "What the bench can identify").  elsewhere : parameters that other data fitted jointly
    determine (a table's running points give K_F and T_Fc, against which the logs' breakaways
    measure the static friction).
    """
    reasons = {}
    s = data.running
    m = data.measured
    n_run = 0 if s is None else int(np.asarray(s.theta).size)
    tq = _has(m["torque"]) if n_run else np.zeros(0, bool)
    psum = np.asarray(s.p_a + s.p_b) if n_run else np.zeros(0)
    if tq.sum() < 3:
        for k in ("Kv", "KF", "TFc"):
            reasons[k] = "no running-torque samples in these logs" + _why_no_running(data, n_run)
    else:
        mu_w = np.asarray(s.viscosity * s.speed)[tq]
        if relative_spread(np.abs(mu_w)) < 0.05:
            reasons["Kv"] = "running torque at a single speed·viscosity level: viscous and Coulomb friction cannot be told apart"
        if relative_spread(psum[tq]) < 0.05:
            reasons["KF"] = single_pressure_sum_reason("running torque", psum[tq])
    n_ev = 0 if data.events is None else int(np.asarray(data.held_torque).size)
    good_ev = _has(data.held_torque) if n_ev else np.zeros(0, bool)
    if good_ev.sum() == 0:
        why = ("no startability breakaway found in these logs (ISO 4392-2 runs needed)" if n_ev == 0 else
               f"{n_ev} breakaway(s) found, but no torque reading while the shaft was held")
        for k in ("KFS", "Ks"):
            reasons[k] = why
    elif good_ev.sum() < 3 or relative_spread(np.asarray(data.events.p_a + data.events.p_b)[good_ev]) < 0.05:
        msg = "breakaway at a single port-pressure level: K_FS and K_s cannot be told apart"
        reasons["KFS"] = msg
        reasons["Ks"] = msg
    for k in ("KFS", "Ks"):
        if k not in reasons and any(j in reasons and j not in elsewhere for j in ("KF", "TFc")):
            reasons[k] = "static friction is measured relative to K_F and T_Fc, which these logs do not determine"
    flows = {c: _has(m[c]) if n_run else np.zeros(0, bool) for c in ("q_a", "q_b", "q_case")}
    case_info = flows["q_case"] | (flows["q_a"] & flows["q_b"])
    if case_info.sum() < 3:
        reasons["KL0"] = "no case-drain flow (nor both port flows) in these logs" + _why_no_running(data, n_run)
    else:
        pitch = 2 * np.pi / spec.pistons
        phase = np.mod(np.asarray(s.theta)[case_info], pitch) / pitch
        bins = np.unique(np.floor(phase * 12).astype(int))
        for name in names:
            if name.startswith("KL_") and len(bins) < 8:
                reasons[name] = "case-drain flow not seen over a whole piston pitch of shaft angle (a slow constant-speed run is needed)"
    port = flows["q_a"] | flows["q_b"]
    if port.sum() < 3:
        reasons["KAB"] = "no port flow in these logs" + _why_no_running(data, n_run)
    elif np.all(np.abs(np.asarray(s.p_a - s.p_b)[port]) < 1e3):
        reasons["KAB"] = "port flows only at zero pressure difference"
    if "KL0" in reasons:
        for name in names:
            if name.startswith("KL_"):
                reasons.setdefault(name, reasons["KL0"])
    return {k: v for k, v in reasons.items() if k in names}


def null_space_reasons(JtJ: np.ndarray, free: list, tol: float) -> dict:
    """Parameters in directions the weighted Jacobian cannot see (relative
    singular value below ``tol``, from the eigenvalues of the normal matrix)."""
    norms = np.sqrt(np.clip(np.diag(JtJ), 0, None))
    out = {}
    for i, k in enumerate(free):
        if norms[i] == 0 or not np.isfinite(norms[i]):
            out[k] = "the fitted channels do not depend on it in these logs"
    cols = np.where((norms > 0) & np.isfinite(norms))[0]
    if cols.size == 0:
        return out
    Jn = JtJ[np.ix_(cols, cols)] / np.outer(norms[cols], norms[cols])
    w, v = np.linalg.eigh(Jn)
    s = np.sqrt(np.clip(w, 0, None))
    weak = np.where(s < tol * s.max())[0]
    vt = v.T
    for j in weak:
        involved = [free[cols[i]] for i in np.where(np.abs(vt[j]) > 0.2)[0]]
        for k in involved:
            others = [o for o in involved if o != k]
            out.setdefault(k, "cannot be told apart from " + ", ".join(others) + " with these logs"
                           if others else "the logs do not determine it")
    return out


def one_back_pressure_warning(low_port_pressure, kf) -> str:
    """A warning where every running point has its low-pressure port at one pressure: the friction
    K_F·D·(P_A + P_B) is then K_F·D·|ΔP| plus a constant, the shape a gain error g of the torque
    transducer gives the ideal torque D·ΔP/2π, so K_F carries g/2π (a 1 % gain error moves it by
    0.0016) and its std does not include it; "" where the back pressure varies.  Points at a second
    back pressure tell them apart (diagnose's torque_meter_gain then shows).

    low_port_pressure : min(P_A, P_B) of each running point [Pa]; kf : the fitted K_F [-]."""
    low = np.asarray(low_port_pressure, dtype=float)
    low = low[np.isfinite(low)]
    if kf is None or not one_back_pressure(low):
        return ""
    share = 0.01 / (2 * np.pi) / abs(kf) if kf else np.inf
    share = f", {100 * share:.0f} % of this fit's K_F" if share < 10 else ", more than this fit's whole K_F"
    return (f"every running point has its low-pressure port at one pressure ({np.median(low) / 1e5:.3g} bar): "
            f"K_F cannot be told from a gain error of the torque transducer, which it takes as g/2π (a 1 % "
            f"gain error moves K_F by 0.0016{share}), and its std does not include it; runs at a second back "
            f"pressure tell them apart")


#: a channel's parameters take at most this share of its Jacobian's largest singular value and still
#: count as determined by it (they use up its degrees of freedom)
RANK_TOL = 1e-3
#: a table channel's noise resting on fewer degrees of freedom than this is reported as rough
ROUGH_NOISE_DOF = 3


def channel_parameters(J: np.ndarray, free: list, row: int, n_pad: int) -> tuple:
    """(rank, names): how many directions of the free parameters the table channel whose rows start
    at ``row * n_pad`` determines, and the parameters that reach it (columns scaled to unit norm
    over the whole Jacobian, so that the count does not depend on units)."""
    block = np.asarray(J[row * n_pad:(row + 1) * n_pad], float)
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    block = block / norms
    if block.size == 0:
        return 0, []
    s = np.linalg.svd(block, compute_uv=False)
    rank = int(np.sum(s > RANK_TOL * max(float(s.max()), 1e-300)))
    reach = np.linalg.norm(block, axis=0)
    names = [k for k, v in zip(free, reach) if v > RANK_TOL * max(float(reach.max()), 1e-300)]
    return rank, names
