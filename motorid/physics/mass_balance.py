"""The flow meters' mass balance, run by run: what the bench's redundancy says about its meters (issue 15).

The motor keeps Q_A + Q_B = Q_case (Bartos 1992 Eq. 59-61) whatever its
parameters, so the per-run mean of the measured Q_A + Q_B − Q_case is exactly
the meters' error: gains make it follow the flows (only differences of gains
are seen: with Q_A + Q_B = Q_case, g_A Q_A + g_B Q_B − g_c Q_c =
(g_A − g_c) Q_A + (g_B − g_c) Q_B), per-run zeros make it scatter from run to
run beyond the noise of the run means (a random-effects variance,
DerSimonian & Laird, Controlled Clinical Trials 7, 177, 1986).  Nothing is
fitted to the motor.  Used by the flow mechanisms' ``seen_by`` (a cause judged
on the flows' run means is not tried where the meters' zeros wander) and by
:mod:`motorid.discrepancy.run_offsets`.
"""

from __future__ import annotations

import numpy as np
from scipy.special import chdtrc  # the χ² survival function, without scipy.stats' second of import


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
    return {"tau": float(np.sqrt(tau2)), "Q": Q, "dof": int(dof), "p_value": float(chdtrc(dof, Q)),
            "coef": coef, "coef_std": np.sqrt(np.diag(cov)), "runs": int(k)}


def flow_balance(dataset, alpha: float = 1e-3) -> dict | None:
    """The parameter-free mass balance of the three flow meters, run by run.

    Returns None without the three flows, else ``{law, gain_differences {"g_A − g_case",
    "g_B − g_case"} [-] and their std, mean_zero [m³/s] (the balance's intercept: o_A + o_B − o_case
    of zeros that stay put), offset_spread [m³/s] (σ of o_A + o_B − o_case from run to run), p_value,
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


_LAST: list = [None, None]  # (dataset, its flow balance): the catalog asks once per mechanism


def flow_zeros_wander(dataset) -> bool:
    """Whether the flow meters' zeros change from run to run (:func:`flow_balance` ``offsets``)."""
    if _LAST[0] is not dataset:
        _LAST[:] = [dataset, flow_balance(dataset)]
    return bool(_LAST[1] is not None and _LAST[1]["offsets"])


#: |t| the mass balance of a table's points must reach for a flow meter's error to be named there
TABLE_BALANCE_T = 3.0
#: points with all three flows a table needs for its mass balance
TABLE_BALANCE_POINTS = 6


def table_balance_shows(table, channel: str, gain: bool) -> str | None:
    """Whether the mass balance b = Q_A + Q_B − Q_case of a table's points (Bartos 1992 Eq. 59-61,
    which the motor keeps exactly) shows an error of the ``channel`` meter: a zero moves b by one
    constant (−c for the case meter), a gain by g·Q of that meter.  b is regressed on that shape
    (a gain's with an intercept, for zeros the meters may also have; and Q_A·|ΔP|, Q_B·|ΔP|, the
    compression of the oil between meters at different pressures, where |ΔP| varies); the error shows
    where the coefficient's |t| reaches :data:`TABLE_BALANCE_T` → None, else the reason in words."""
    m = table.measured
    qa, qb, qc = (np.asarray(m[c], dtype=float) for c in ("q_a", "q_b", "q_case"))
    ok = np.isfinite(qa) & np.isfinite(qb) & np.isfinite(qc)
    if ok.sum() < TABLE_BALANCE_POINTS:
        return ("the table does not hold all three flows at enough points for the meters' mass balance "
                "Q_A + Q_B = Q_case: a flow meter's error cannot be told from a leakage law")
    b = (qa + qb - qc)[ok]
    shape = {"q_a": qa, "q_b": qb, "q_case": qc}[channel][ok]
    size = max(float(np.max(np.abs(np.concatenate([qa[ok], qb[ok], qc[ok]])))), 1e-300)
    if np.max(np.abs(b)) <= 1e-9 * size:  # a table whose case flow is the sum of the port flows
        return ("the table's case flow is the sum of its port flows (its mass balance holds by construction): "
                "a flow meter's error cannot be seen in it")
    X = np.column_stack([shape, np.ones_like(shape)]) if gain else np.ones((b.size, 1))
    # volumetric meters at different pressures: the balance of volumes breaks by the oil's compression,
    # about Q·|ΔP|/β at each port (1-2 % of the flow at 300 bar), which is no meter's error
    dp = np.abs(np.asarray(table.p_a, float) - np.asarray(table.p_b, float))[ok]
    if np.ptp(dp) > 0.05 * max(float(np.max(dp)), 1e-300):
        X = np.column_stack([X, qa[ok] * dp, qb[ok] * dp])
    coef, *_ = np.linalg.lstsq(X, b, rcond=None)
    dof = b.size - X.shape[1]
    s2 = float(np.sum((b - X @ coef) ** 2)) / max(dof, 1)
    try:
        se = float(np.sqrt(s2 * np.linalg.inv(X.T @ X)[0, 0]))
    except np.linalg.LinAlgError:
        se = np.inf
    t = abs(float(coef[0])) / se if se > 0 else np.inf
    if t >= TABLE_BALANCE_T:
        return None
    what = "in proportion to that meter's flow" if gain else "by a constant"
    return (f"the meters' mass balance Q_A + Q_B − Q_case over the table's {b.size} points does not move {what} "
            f"(|t| = {t:.2g} < {TABLE_BALANCE_T:g}): the meter's error cannot be told from a leakage law")
