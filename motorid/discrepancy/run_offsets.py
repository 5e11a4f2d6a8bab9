"""Transducer zeros that differ from run to run, told from the motor's physics (issue 15).

A zero offset that changes between runs adds one constant to each run of one
channel.  Within a run it is invisible; across runs it is a spread that no
operating variable follows.  Two ways the data tell it from physics:

- :func:`flow_balance` — the mass balance Q_A + Q_B = Q_case (Bartos 1992
  Eq. 59-61) holds for the motor whatever its parameters, so the per-run mean
  of the measured Q_A + Q_B − Q_case is exactly the meters' error: gains make
  it follow the flows (only differences of gains are seen: with Q_A + Q_B =
  Q_case, g_A Q_A + g_B Q_B − g_c Q_c = (g_A − g_c) Q_A + (g_B − g_c) Q_B), per-run
  zeros make it scatter from run to run beyond the noise of the run means.
  Nothing is fitted to the motor, so nothing can stand in for it.
- :func:`run_spread` — for any channel, the spread of the per-run mean residual
  of a fit beyond what the within-run noise allows (a random-effects variance,
  DerSimonian & Laird, Controlled Clinical Trials 7, 177, 1986), and whether
  runs at one operating point share it: the ISO 4392 plans run every point in
  both directions, and physics left in the residual, being a law of the
  operating point, is the same (or opposite) in the two; per-run zeros are not.

Both are descriptions, not fitted mechanisms: the one model has no run index,
so per-run offsets are not a catalog mechanism (a random run effect in the fit
would be; see docs/diagnosis-causes.md).
"""

from __future__ import annotations

import numpy as np
from scipy import stats

#: twin runs (one operating point, both directions) whose mean residuals correlate less than this: offset-like
TWIN_CORRELATION = 0.5
#: fewest twin pairs for the test (the correlation of unrelated pairs scatters as 1/√pairs)
MIN_TWINS = 8


def _lag1(v: np.ndarray) -> float:
    if v.size < 4:
        return 0.0
    a, b = v[:-1] - v.mean(), v[1:] - v.mean()
    den = np.sqrt(np.sum(a * a) * np.sum(b * b))
    return float(np.clip(np.sum(a * b) / den, 0.0, 0.95)) if den > 0 else 0.0


def run_means(values, run_of, n_runs, mask=None):
    """Per run: mean [unit of values] and its standard error (AR(1)-corrected effective count); NaN where < 5 samples."""
    values = np.asarray(values, dtype=float)
    run_of = np.asarray(run_of, dtype=int)
    ok = np.isfinite(values) if mask is None else (np.asarray(mask, bool) & np.isfinite(values))
    mean, se = np.full(n_runs, np.nan), np.full(n_runs, np.nan)
    for r in range(n_runs):
        v = values[ok & (run_of == r)]
        if v.size < 5:
            continue
        rho = _lag1(v)
        n_eff = max(v.size * (1 - rho) / (1 + rho), 1.0)
        mean[r] = v.mean()
        se[r] = np.std(v, ddof=1) / np.sqrt(n_eff)
    return mean, se


def between_run_variance(mean, se, X=None) -> dict:
    """Random-effects spread of run means about a weighted regression on X (default: a constant).

    DerSimonian–Laird moment estimator: Q = Σ w_j e_j², w = 1/se², e the weighted-LS residuals;
    τ² = max(0, (Q − (k − p)) / (Σw − tr((XᵀWX)⁻¹ XᵀW²X))).  Returns tau [unit of mean], Q, dof,
    p_value (χ²_{k−p} test of τ = 0) and the coefficients of X.
    """
    ok = np.isfinite(mean) & np.isfinite(se) & (se > 0)
    m, s = mean[ok], se[ok]
    X = np.ones((m.size, 1)) if X is None else np.asarray(X, dtype=float)[ok]
    k, p = X.shape
    if k <= p + 1:
        return {"tau": 0.0, "Q": 0.0, "dof": 0, "p_value": 1.0, "coef": np.zeros(p), "coef_std": np.full(p, np.inf),
                "runs": int(k)}
    w = 1.0 / s**2
    X = X[:, np.any(X != 0, axis=0)]  # a group with no run left
    p = X.shape[1]
    A_inv = np.linalg.pinv((X.T * w) @ X)
    coef = A_inv @ ((X.T * w) @ m)
    e = m - X @ coef
    Q = float(np.sum(w * e * e))
    dof = k - np.linalg.matrix_rank(X)
    trace = float(np.sum(w) - np.trace(A_inv @ ((X.T * w**2) @ X)))
    tau2 = max(0.0, (Q - dof) / trace) if trace > 0 else 0.0
    # the coefficients again with the random-effects weights 1/(se² + τ²): with a spread between runs
    # the few most precise runs must not decide them alone
    w_re = 1.0 / (s**2 + tau2)
    cov = np.linalg.pinv((X.T * w_re) @ X)
    coef = cov @ ((X.T * w_re) @ m)
    return {"tau": float(np.sqrt(tau2)), "Q": Q, "dof": int(dof), "p_value": float(stats.chi2.sf(Q, dof)),
            "coef": coef, "coef_std": np.sqrt(np.diag(cov)), "runs": int(k)}


def flow_balance(dataset, alpha: float = 1e-3) -> dict | None:
    """The parameter-free mass balance of the three flow meters, run by run.

    Returns None without the three flows, else ``{law, gain_differences {"g_A − g_case",
    "g_B − g_case"} [-], offset_spread [m³/s] (σ of o_A + o_B − o_case from run to run), p_value,
    runs, offsets (bool: a significant spread at ``alpha``), words}``.
    """
    meas = getattr(dataset, "measured", None)
    if meas is None or any(c not in meas for c in ("q_a", "q_b", "q_case")):
        return None
    run_of = np.asarray(dataset.run_of_sample, dtype=int)
    n_runs = len(dataset.runs)
    qa, qb, qc = (np.asarray(meas[c], dtype=float) for c in ("q_a", "q_b", "q_case"))
    balance = qa + qb - qc
    mean, se = run_means(balance, run_of, n_runs)
    ma, _ = run_means(qa, run_of, n_runs)
    mb, _ = run_means(qb, run_of, n_runs)
    X = np.column_stack([ma, mb, np.ones(n_runs)])
    ok = np.isfinite(mean) & np.isfinite(ma) & np.isfinite(mb)
    if ok.sum() < 6:
        return None
    fit = between_run_variance(np.where(ok, mean, np.nan), se, np.where(ok[:, None], X, np.nan))
    ga, gb, zero = (float(c) for c in fit["coef"])
    sa, sb, _ = (float(c) for c in fit["coef_std"])
    offsets = fit["p_value"] < alpha
    words = (f"the flow meters' mass balance Q_A + Q_B − Q_case, which the motor keeps exactly, "
             f"{'scatters' if offsets else 'does not scatter'} from run to run beyond its noise"
             + (f" by {fit['tau'] * 6e4:.3g} L/min (σ of the meters' combined zero, p = {fit['p_value']:.2g}): "
                "zero offsets that change between runs" if offsets else "")
             + f"; gains relative to the case meter: port A {100 * ga:+.3g} ± {100 * sa:.2g} %, "
               f"port B {100 * gb:+.3g} ± {100 * sb:.2g} %")
    return {"law": "Q_A + Q_B = Q_case (Bartos 1992 Eq. 59-61)", "gain_differences": {"g_A − g_case": ga,
            "g_B − g_case": gb}, "gain_differences_std": {"g_A − g_case": sa, "g_B − g_case": sb}, "mean_zero": zero, "offset_spread": fit["tau"], "p_value": fit["p_value"],
            "runs": fit["runs"], "offsets": bool(offsets), "words": words}


def twin_runs(dataset) -> list[tuple[int, int]]:
    """Pairs of runs at one operating point (protocol, |speed|, |ΔP|, oil temperature) in opposite directions."""
    runs = dataset.runs
    key = {}
    for r in range(len(runs)):
        row = runs.iloc[r]
        d = float(row["direction"])
        if not np.isfinite(d) or d == 0:
            continue
        k = (str(row["protocol"]), round(abs(float(row["speed_median_rad_s"])) * 60 / (2 * np.pi) / 5) * 5,
             round(abs(float(row["dp_median_Pa"])) / 2e5) * 2, round(float(row["temp_median_C"]) / 2) * 2)
        key.setdefault(k, {}).setdefault(d > 0, []).append(r)
    pairs = []
    for sides in key.values():
        pairs += list(zip(sides.get(True, []), sides.get(False, [])))
    return pairs


def run_spread(residuals, sigma_ok_mask, dataset, noise: float | None = None, min_effect: float = 0.3) -> dict:
    """Spread of a channel's per-run mean residual beyond its noise, and whether it follows the operating point.

    residuals : the fit's residual per sample [SI]; sigma_ok_mask : its inliers; noise : the channel's noise
    level [SI].  ``tau`` is the random-effects σ of the run means about their mean [SI].  Physics is a law
    of the operating point, so two runs at one operating point in opposite directions (:func:`twin_runs`)
    share it, with the same sign (a law even in ω) or the opposite (odd in ω): their mean residuals are
    correlated; per-run zeros are drawn afresh for each run and are not.  ``offset_like`` when the spread
    is significant, at least ``min_effect`` noise levels, and the twins' correlation is below
    :data:`TWIN_CORRELATION` in size over at least :data:`MIN_TWINS` pairs.
    """
    run_of = np.asarray(dataset.run_of_sample, dtype=int)
    n_runs = len(dataset.runs)
    mean, se = run_means(residuals, run_of, n_runs, sigma_ok_mask)
    total = between_run_variance(mean, se)
    pairs = [(a, b) for a, b in twin_runs(dataset) if np.isfinite(mean[a]) and np.isfinite(mean[b])]
    corr = float(np.corrcoef([mean[a] for a, _ in pairs], [mean[b] for _, b in pairs])[0, 1]) if len(
        pairs) >= MIN_TWINS else float("nan")
    offset_like = bool(total["p_value"] < 1e-3 and np.isfinite(corr) and abs(corr) < TWIN_CORRELATION
                       and (noise is None or total["tau"] >= min_effect * noise))
    return {"tau": total["tau"], "p_value": total["p_value"], "runs": total["runs"], "twin_pairs": len(pairs),
            "twin_correlation": corr, "offset_like": offset_like}
