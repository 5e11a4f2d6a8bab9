"""Transducer zeros that differ from run to run, told from the motor's physics (issue 15).

A zero offset that changes between runs adds one constant to each run of one
channel.  Within a run it is invisible; across runs it is a spread that no
operating variable follows.  Two ways the data tell it from physics:

- :func:`~motorid.physics.mass_balance.flow_balance` — the mass balance Q_A + Q_B = Q_case (Bartos 1992
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

from motorid.physics.mass_balance import between_run_variance, flow_balance, run_means  # noqa: F401  (re-exported)

#: twin runs (one operating point, both directions) whose mean residuals correlate less than this: offset-like
TWIN_CORRELATION = 0.5
#: fewest twin pairs for the test (the correlation of unrelated pairs scatters as 1/√pairs)
MIN_TWINS = 8


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
