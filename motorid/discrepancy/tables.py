"""Diagnose on operating-point tables: forward selection of registry mechanisms by BIC on the table fit."""

from __future__ import annotations

import math

import numpy as np

from motorid.units import CHANNEL_WORDS


def _profile_bic(tf) -> float:
    """BIC of a table fit with each channel's noise level profiled out:
    Σ_c [n_c ln(RSS_c / n_c) + 2 Σ_i ln w_i] + k ln n (Gaussian likelihood, σ_i = s_c w_i with w_i
    each point's σ relative to the median, its noise floor included: identify/tables.py);
    in a joint fit the logs add their χ² at their own (held) noise levels and their count."""
    total, n_all = _profile_deviance(tf)
    return total + len(tf.ls.free) * math.log(max(n_all, 1))


def _profile_deviance(tf) -> tuple[float, int]:
    """(−2 log L of :func:`_profile_bic` without its k ln n, the count n of what it sums)."""
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
        w = np.asarray(tf.table_sigma[c], float)[ok]  # each point's σ (its floor included), shape only
        w = w / np.median(w)
        r = tf.table_residuals[c][ok] / w
        n = int(ok.sum())
        total += n * math.log(max(float(np.mean(r**2)), 1e-300)) + 2.0 * float(np.sum(np.log(w)))
        n_all += n
    return total, n_all


#: ΔBIC a mechanism short of ``min_evidence`` must still earn ("strong" evidence on Kass & Raftery's
#: scale, J. Am. Stat. Assoc. 90 (1995) 773) to be kept on held-out evidence ...
HELD_OUT_EVIDENCE = 6.0
#: ... where it also removes this share of the 5-fold held-out squared error of a channel of the
#: table's points, as an empirical term must (discrepancy/table_terms.py) ...
HELD_OUT_GAIN = 0.10
#: ... and makes no channel's worse by more than this share
HELD_OUT_COST = 0.02


#: a mechanism named on a table must not fit one channel worse by more than this share of what it gains
#: on the others (a stand-in that trades a channel away: a pressure-viscosity law taking a cross-port
#: turbulent leak bends the case drain, which is laminar), nor by more than ``min_evidence``
CHANNEL_COST_SHARE = 0.25


def channel_costs(before, after) -> dict:
    """channel → Δχ² of its points from table fit ``before`` to ``after``, in ``before``'s noise
    (positive: ``after`` fits it worse)."""
    out = {}
    for c, r0 in before.table_residuals.items():
        r1, s = after.table_residuals.get(c), before.table_sigma.get(c)
        if r1 is None or s is None:
            continue
        r0, r1, s = (np.asarray(x, dtype=float) for x in (r0, r1, s))
        ok = np.isfinite(r0) & np.isfinite(r1) & np.isfinite(s) & (s > 0)
        if ok.any():
            out[c] = float(np.sum((r1[ok] ** 2 - r0[ok] ** 2) / s[ok] ** 2))
    return out


def traded_channel(before, after, min_evidence: float):
    """(channel, its Δχ², the gain elsewhere) where ``after`` buys its gain by fitting a channel
    worse (:data:`CHANNEL_COST_SHARE`), else None."""
    costs = channel_costs(before, after)
    gain = sum(-v for v in costs.values() if v < 0)
    worst = max(costs.items(), key=lambda kv: kv[1], default=None)
    if worst is not None and worst[1] > max(min_evidence, CHANNEL_COST_SHARE * gain):
        return worst[0], worst[1], gain
    return None


#: on a variable unit, a mechanism fitted on the larger (smaller) settings must not predict the others worse
#: than the model without it by more than this factor of a channel's mean squared error
SETTING_SPLIT_FACTOR = 1.25


def setting_split_refusal(table, spec, current: list, mech) -> str | None:
    """Words where ``mech`` fails a variable unit's other displacement settings, else None.

    The model with and without ``mech`` is fitted on the settings above the median setting and predicts
    those at or below it, and the other way round.  A law of the motor predicts the settings it was not
    fitted on; a stand-in for a loss that scales with the swash angle otherwise than the model says (a
    displacement error standing in for losses that keep the largest setting's size) does not."""
    from motorid.comparators.evaluate import MotoridModel

    if not getattr(table, "variable_displacement", False) or len(table) < 20:
        return None
    disp = np.asarray(table.displacement, dtype=float)
    levels = np.unique(np.round(disp / np.nanmax(disp), 3))
    if levels.size < 2:
        return None
    cut = float(np.median(levels)) * np.nanmax(disp)
    for train, words in ((disp > cut, "the smaller settings from the larger"),
                         (disp <= cut, "the larger settings from the smaller")):
        test = ~train
        if train.sum() < 10 or test.sum() < 5:
            continue
        mse = {}
        for name, mechs in (("without", list(current)), ("with", list(current) + [mech])):
            pred = MotoridModel(spec, mechs).fit_split(table, train).predict(table)
            mse[name] = {c: float(np.nanmean((np.asarray(table.measured[c])[test] - np.asarray(pred[c])[test]) ** 2))
                         for c in ("torque", "q_a", "q_b", "q_case")}
        for c, before in mse["without"].items():
            after = mse["with"][c]
            if np.isfinite(before) and np.isfinite(after) and before > 0 and after > SETTING_SPLIT_FACTOR * before:
                return (f"predicts {words} worse than the model without it ({CHANNEL_WORDS.get(c, c)}: mean squared "
                        f"error ×{after / before:.2f}): a stand-in for a loss that scales with the setting otherwise")
    return None


#: a mechanism fitted on one half of a table's speeds (of its |ΔP|) must not predict the other half worse than
#: the model without it by more than this factor of a channel's mean squared error ...
REGION_SPLIT_FACTOR = 1.25


def _split_failure(table, spec, current, mech, train, sigma, min_evidence):
    """(channel, mean-squared-error factor, Δχ²) where ``mech`` fitted on ``train`` predicts the other
    points worse than the model without it (:data:`REGION_SPLIT_FACTOR`, ``min_evidence``), else None;
    None also where ``train`` does not determine its parameters (each beyond twice its std)."""
    from motorid.comparators.evaluate import CHANNELS, MotoridModel

    test = ~train
    if train.sum() < 10 or test.sum() < 5:
        return None
    fitted = MotoridModel(spec, list(current) + [mech]).fit_split(table, train)
    ls = fitted.fit.ls
    if not all(ls.values.get(k) is not None and ls.std.get(k) is not None
               and abs(ls.values[k]) > 2 * ls.std[k] for k in mech.parameters):
        return None
    without = MotoridModel(spec, list(current)).fit_split(table, train).predict(table)
    pred = fitted.predict(table)
    worst = None
    for c in CHANNELS:
        y = np.asarray(table.measured[c], float)[test]
        a = (y - np.asarray(without[c], float)[test]) ** 2
        b = (y - np.asarray(pred[c], float)[test]) ** 2
        ok = np.isfinite(a) & np.isfinite(b)
        s = np.asarray(sigma.get(c, np.full(len(table), np.nan)), float)[test][ok]
        if not ok.any() or not np.all(np.isfinite(s) & (s > 0)) or np.mean(a[ok]) <= 0:
            continue
        worse, factor = float(np.sum((b[ok] - a[ok]) / s**2)), float(np.mean(b[ok]) / np.mean(a[ok]))
        if factor > REGION_SPLIT_FACTOR and worse > min_evidence and (worst is None or worse > worst[2]):
            worst = (c, factor, worse)
    return worst


def region_split_refusal(table, spec, current: list, mech, sigma: dict, min_evidence: float) -> str | None:
    """Words where ``mech`` fails the operating region it was not fitted on, else None (issue 15: a name must
    predict where it was not fitted, as on logs, :func:`~motorid.discrepancy.unexplained.extrapolation_check`).

    The model with and without ``mech`` is fitted on the points up to the median |ω| (|ΔP|) and predicts
    those above, and the other way round (:func:`_split_failure`: a split whose training half does not
    determine the mechanism gives no verdict).  It is refused where it fails both ways along one
    variable: a law of the motor fitted on either half predicts the other at least as well as the model
    without it, but one whose parameters the training half holds loosely may fail one way (a Stribeck
    law fitted on the fast points alone, wild at the slow ones); a stand-in fails both (a displacement
    error standing in for a turbulent √ΔP leak: fitted on the slow points it predicts the fast ones' port
    A flow 3.7 times worse than the model without it, fitted on the fast ones the slow 1.8 times)."""
    if len(table) < 20:
        return None
    for var, v, unit, f in (("speed", np.abs(np.asarray(table.speed, float)), "rpm", 30 / np.pi),
                            ("|ΔP|", np.abs(np.asarray(table.dp, float)), "bar", 1e-5)):
        if np.unique(np.round(v, 9)).size < 4:
            continue
        cut = float(np.median(v))
        up = _split_failure(table, spec, current, mech, v <= cut, sigma, min_evidence)
        if up is None:
            continue
        down = _split_failure(table, spec, current, mech, v > cut, sigma, min_evidence)
        if down is None:
            continue
        return (f"fails where it was not fitted: fitted on {var} up to {cut * f:.3g} {unit} it predicts the points "
                f"above, and fitted above them the points below, worse than the model without it "
                f"({CHANNEL_WORDS.get(up[0], up[0])}: mean squared error ×{up[1]:.2f}, Δχ² +{up[2]:.1f}; "
                f"{CHANNEL_WORDS.get(down[0], down[0])}: ×{down[1]:.2f}, Δχ² +{down[2]:.1f}): a stand-in for a law "
                "it does not hold")
    return None


def held_out_gains(table, spec, current: list, mech) -> dict:
    """channel → share of its 5-fold held-out squared error that ``mech`` removes from the model
    with ``current`` (parameters refitted per fold; negative: worse)."""
    from motorid.comparators.evaluate import MotoridModel, held_out

    before = held_out(MotoridModel(spec, current), table, extrapolate=False)["kfold"]
    after = held_out(MotoridModel(spec, current + [mech]), table, extrapolate=False)["kfold"]
    return {c: 1.0 - (after[c]["rms"] / before[c]["rms"]) ** 2 for c in before
            if c in after and before[c]["rms"] and after[c]["rms"] is not None}


#: on a table of more points than this, diagnose chooses the mechanisms on this many of them, spread over
#: the operating range (:func:`selection_points`), then fits and compares the chosen model on every point.
#: A grid of 50 927 interpolated points (the A6VM map of docs/maps.md) takes a full fit per candidate per
#: round otherwise (over 20 min); its mechanisms are as plain on 2 000 of them.
SELECTION_POINTS = 2000


def selection_points(table, n: int | None = None) -> np.ndarray | None:
    """Indices of at most ``n`` of ``table``'s points spread evenly over its operating range, or None where
    it has no more than ``n``.

    The range (signed speed, signed ΔP, and where they vary the case pressure, log viscosity and
    displacement, each scaled to [0, 1]) is cut into equal cells, as many per recording as ``n`` allows.
    Every occupied cell gives its points nearest the cell's centre, as many as an even share of ``n``
    over the occupied cells (a map whose points crowd a few cells, or repeat one operating point, keeps
    ``n`` of them, not one per cell); the first of every cell before any second.  Every recording keeps
    its cells (a per-recording temperature stays identifiable); nothing random: the same table gives the
    same points."""
    n = SELECTION_POINTS if n is None else int(n)
    N = len(table)
    if N <= n:
        return None
    cols = [np.asarray(table.speed, float), np.asarray(table.dp, float)]
    for extra in (np.asarray(table.p_case, float), np.log(np.asarray(table.viscosity, float)),
                  np.asarray(table.displacement, float)):
        seen = extra[np.isfinite(extra)]
        if seen.size and np.ptp(seen) > 1e-9 * max(float(np.max(np.abs(seen))), 1e-300):
            cols.append(extra)
    X = np.column_stack(cols)
    X = np.where(np.isfinite(X), X, np.nanmedian(X, axis=0))
    span = np.ptp(X, axis=0)
    X = (X - X.min(axis=0)) / np.where(span > 0, span, 1.0)
    _, group = np.unique(table.recordings().astype(str), return_inverse=True)
    per_group = n / (group.max() + 1)
    # bins along each axis: the largest count whose cells number at most per_group (at least 2)
    bins = max(2, int(np.floor(per_group ** (1.0 / X.shape[1]) + 1e-9)))
    cell = np.minimum(np.floor(X * bins), bins - 1)
    distance = np.sum((X * bins - cell - 0.5) ** 2, axis=1)
    key = np.column_stack([group, cell]).astype(np.int64)
    order = np.lexsort((distance,) + tuple(key.T[::-1]))  # by cell, nearest the centre first
    new_cell = np.ones(N, bool)
    new_cell[1:] = np.any(key[order][1:] != key[order][:-1], axis=1)
    start = np.maximum.accumulate(np.where(new_cell, np.arange(N), 0))
    rank = np.arange(N) - start  # 0: the point nearest its cell's centre
    quota = int(np.ceil(n / int(new_cell.sum())))
    keep = []
    for r in range(quota):  # every cell's first, then its second, …, up to n; a last level taken evenly
        level = order[rank == r]
        need = n - sum(k.size for k in keep)
        if level.size > need:
            level = level[np.unique(np.round(np.linspace(0, level.size - 1, need)).astype(int))]
        keep.append(level)
    chosen = np.sort(np.concatenate(keep))
    return chosen if chosen.size < N else None


def table_tie(table, spec, current: list, trials: list, bic: float, best_fit, min_evidence: float,
              joint: dict, alone: bool) -> dict | None:
    """The selection step where the two best candidates explain the table alike, else None
    (discrepancy/tie.py: a wrong name is worse than none).

    ``trials``: (BIC, mechanism, table fit), best first.  Both must lower the BIC by ``min_evidence``;
    they tie where the first beats the second by less than ``min_evidence`` in BIC or in −2 log L
    (one parameter fewer must not decide the name), or by less than :data:`~motorid.discrepancy.tie.TIE_Z`
    standard errors with the points as units (:func:`~motorid.discrepancy.tie.point_vuong_z`).  Not a
    tie where the two are two effects (fitted together, the second still lowers the BIC by more than
    ``min_evidence`` and by more than half of what it gains alone), nor, on a table alone, where the
    second is a stand-in the first was not (it trades a channel away or fails the region splits)."""
    from motorid.discrepancy.tie import TIE_Z, point_vuong_z
    from motorid.identify.tables import fit_table

    if len(trials) < 2:
        return None
    (b1, m1, f1), (b2, m2, f2) = trials[:2]
    if bic - b1 < min_evidence or bic - b2 < min_evidence:
        return None
    gap = min(b2 - b1, _profile_deviance(f2)[0] - _profile_deviance(f1)[0])
    z = point_vuong_z(f1, f2, best_fit.table_sigma)
    if gap >= min_evidence and (z is None or z >= TIE_Z):
        return None
    both = fit_table(table, spec, list(current) + [m1, m2], start_values={**f2.ls.params_all, **f1.ls.params_all},
                     **joint)
    added = b1 - _profile_bic(both)
    if added > min_evidence and added > 0.5 * (bic - b2):
        return None  # two effects: the first is named now, the second asked in turn
    if alone and (traded_channel(best_fit, f2, min_evidence) is not None
                  or setting_split_refusal(table, spec, current, m2) is not None
                  or region_split_refusal(table, spec, current, m2, best_fit.table_sigma, min_evidence) is not None):
        return None  # the runner-up is a stand-in: no rival to the first
    by = f"; the first better by {z:.2g} point-level standard errors" if z is not None else ""
    return {"id": f"{m1.id} and {m2.id}", "delta_bic": bic - b1, "tied": [m1.id, m2.id], "point_z": z,
            "refused": f"the two explain it alike (ΔBIC {bic - b1:.1f} and {bic - b2:.1f}{by}): naming one "
                       "would be a guess"}


def _abs_dp(table, dataset) -> np.ndarray:
    """|ΔP| [Pa] of the table's points and of the logs' running samples (a joint fit)."""
    out = [np.abs(np.asarray(table.dp, dtype=float))]
    if dataset is not None and dataset.n_running:
        out.append(np.abs(np.asarray(dataset.running.p_a, dtype=float) - np.asarray(dataset.running.p_b, dtype=float)))
    return np.concatenate(out)


def diagnose_table(table, spec, min_evidence: float = 10.0, max_mechanisms: int = 6, candidates=None,
                   progress=None, dataset=None, log_fit=None) -> dict:
    """Forward selection of catalog mechanisms on a table: add the mechanism that lowers the
    profiled BIC most, while it lowers it by at least ``min_evidence``, or, on a table alone, by
    at least :data:`HELD_OUT_EVIDENCE` while it removes :data:`HELD_OUT_GAIN` of a channel's
    5-fold held-out squared error and costs no channel more than :data:`HELD_OUT_COST` (a law
    that pays for itself on points it was not fitted on);
    then the held-out comparison of the model with what was found and of the classical models."""
    from motorid.comparators.evaluate import compare
    from motorid.physics.registry import all_mechanisms
    from motorid.identify.tables import fit_table

    cands = list(candidates if candidates is not None else all_mechanisms())
    if candidates is None and dataset is None:  # the table's own: an oil temperature no recording holds
        from motorid.physics.recording_temperature import RecordingTemperature

        per_recording = RecordingTemperature.for_table(table)
        if per_recording is not None:
            cands.append(per_recording)
    current = []
    joint = dict(dataset=dataset, log_fit=log_fit)
    alone = dataset is None or not dataset.n_running
    chosen = selection_points(table) if alone else None
    every = table  # where the chosen model is fitted and compared
    if chosen is not None:
        table = table.subset(chosen)
        if progress:
            progress(f"mechanisms chosen on {len(table)} of the {len(every)} points, spread over the operating "
                     "range; the model then fitted on every point")
    fit0 = fit_table(table, spec, **joint)
    bic = _profile_bic(fit0)
    base_fit = best_fit = fit0
    steps = []
    if alone:  # the points alone: what they cannot tell from what it mimics
        for mech in list(cands):
            why = mech.unseen_in_table(every)
            if why is not None:
                cands.remove(mech)
                steps.append({"id": mech.id, "skipped": why})
    abs_dp = _abs_dp(table, dataset)  # where a threshold mechanism's knee must lie (outside_data)
    while len(current) < max_mechanisms:
        trials = []
        for mech in cands:
            if mech in current:
                continue
            try:
                # from the current model's fit: its mechanisms start where they were fitted (a knee's
                # data starts are tried for the new candidate alone)
                tf = fit_table(table, spec, current + [mech], start_values=best_fit.ls.params_all, **joint)
            except Exception as exc:  # a mechanism whose hooks do not take θ-averaged table samples
                steps.append({"id": mech.id, "skipped": f"{type(exc).__name__}: {exc}"[:200]})
                continue
            if not any(tf.ls.identifiable.get(k) for k in mech.parameters):
                continue
            beyond = mech.outside_data(tf.ls.values, abs_dp)
            if beyond is not None:  # a threshold fitted past every point: its tail stands in for another law
                steps.append({"id": mech.id, "skipped": beyond})
                continue
            trials.append((_profile_bic(tf), mech, tf))
            if progress:
                progress(f"{mech.id}: ΔBIC {bic - trials[-1][0]:.1f}")
        if not trials:
            break
        trials.sort(key=lambda t: t[0])
        while alone and trials and bic - trials[0][0] >= min_evidence:
            traded = traded_channel(best_fit, trials[0][2], min_evidence)
            if traded is not None:
                # a stand-in: it fits one channel worse to fit the others; the next best is asked
                c, cost, gain = traded
                c = CHANNEL_WORDS.get(c, c).replace("running ", "")
                why = (f"fits the {c} worse (Δχ² +{cost:.1f}) to gain {gain:.1f} on the other channels: a stand-in "
                       "for physics it does not hold")
            else:
                why = setting_split_refusal(table, spec, current, trials[0][1]) or region_split_refusal(
                    table, spec, current, trials[0][1], best_fit.table_sigma, min_evidence)
                if why is None:
                    break
            steps.append({"id": trials[0][1].id, "delta_bic": bic - trials[0][0], "refused": why})
            if progress:
                progress(f"{trials[0][1].id}: refused, it {why}")
            trials.pop(0)  # refused this round; asked again once another mechanism is in the model
        if not trials:
            break
        tie = table_tie(table, spec, current, trials, bic, best_fit, min_evidence, joint, alone)
        if tie is not None:  # two names explain it alike: neither is named
            steps.append(tie)
            if progress:
                progress(f"{tie['id']}: {tie['refused']}; neither is named")
            break
        b, mech, tf = trials[0]
        steps.append({"id": mech.id, "delta_bic": bic - b})
        if bic - b < min_evidence:
            if dataset is not None or bic - b < HELD_OUT_EVIDENCE or len(table) < 20:
                break
            gains = held_out_gains(table, spec, current, mech)
            steps[-1]["held_out_gain"] = gains
            if not gains or max(gains.values()) < HELD_OUT_GAIN or min(gains.values()) < -HELD_OUT_COST:
                break
            why = setting_split_refusal(table, spec, current, mech) or region_split_refusal(
                table, spec, current, mech, best_fit.table_sigma, min_evidence)  # as the ΔBIC route asks (above)
            if why is not None:
                steps[-1]["refused"] = why
                if progress:
                    progress(f"{mech.id}: refused, it {why}")
                break
            if progress:
                progress(f"{mech.id}: ΔBIC {bic - b:.1f}; held out, it removes "
                         + ", ".join(f"{100 * g:.0f} % of the {c} error" for c, g in gains.items()))
        current.append(mech)
        bic, best_fit = b, tf
    selection = {"points": len(table), "of": len(every)}
    if chosen is not None:  # the chosen model (and the base one) on every point
        table = every
        base_fit = fit_table(table, spec, **joint)
        best_fit = fit_table(table, spec, current, **joint) if current else base_fit
    from motorid.discrepancy.table_terms import MotoridWithTerms, confirm_by_refit, unexplained_table_entries

    unexplained = unexplained_table_entries(best_fit, spec)  # on the table's points, logs or not
    model = None
    label = "motorid" + "".join(" + " + m.id for m in current)
    # held out, the empirical term is chosen again on each fold's training points alone
    if any(u.get("empirical_term") for u in unexplained):
        model = MotoridWithTerms(spec, current, label=label + " + empirical term")
    comparison = compare(table, spec, mechanisms=current, motorid_model=model) if len(table) >= 10 else None
    if comparison is not None and model is not None:  # the same model without the term, on the same fits
        confirm_by_refit(unexplained, comparison, model, table, label)
    return {"mechanisms": current, "fit": best_fit, "base_fit": base_fit, "steps": steps, "comparison": comparison,
            "unexplained": unexplained, "selection_points": selection}


def diagnose_tables(log_paths, table_paths, spec, min_evidence: float = 10.0, progress=None, channels=None) -> dict:
    """Read the tables (and logs) and diagnose them jointly (:func:`diagnose_table`; with logs, their own
    least-squares fit weights them), as identify/table_pipeline.identify_tables fits them.
    channels : a channel map (path or ChannelMap): for the tables where it maps no time_s, for the
        logs where it does."""
    from motorid.io.tables import read_tables, split_channel_map

    table_map, log_map = split_channel_map(channels)
    table = read_tables(table_paths, spec, channels=table_map)
    dataset = log_fit = None
    if log_paths:
        from motorid.identify.least_squares import fit_least_squares
        from motorid.identify.pipeline import load_campaign

        _, dataset = load_campaign(log_paths, spec, log_map)
        log_fit = fit_least_squares(dataset, spec)
    return diagnose_table(table, spec, min_evidence=min_evidence, dataset=dataset, log_fit=log_fit,
                          progress=progress)


def _selection_words(sel) -> dict:
    """The selection's points in result.json: how many, of how many, in words where a share."""
    if not sel:
        return {}
    out = {"points": sel["points"], "of_points": sel["of"]}
    if sel["points"] < sel["of"]:
        out["points_note"] = (f"mechanisms chosen on {sel['points']} of the table's {sel['of']} points, spread over "
                              "the cells of an even grid over the operating range; the chosen model fitted and "
                              "compared on every point")
    return out


def _refused(dg: dict) -> list:
    """The selection's refusals in diagnosis.json's ``refused_stand_ins`` (id, why; the tied pair where
    two explained it alike): a mechanism refused in one round and named in a later one is left out, one
    refused twice keeps its last word."""
    named = {m.id for m in dg["mechanisms"]}
    out = {st["id"]: {"id": st["id"], "why": st["refused"], **({"tied": st["tied"]} if "tied" in st else {})}
           for st in dg["steps"] if isinstance(st, dict) and st.get("refused") and st["id"] not in named}
    return list(out.values())


def diagnosis_table_document(dg: dict, spec) -> dict:
    from motorid.identify.results import json_safe as _clean

    fit, base = dg["fit"], dg["base_fit"]
    mechs = []
    for m in dg["mechanisms"]:
        params = {}
        for k in m.parameters:
            info = m.parameters[k]
            params[k] = {"value": fit.ls.values.get(k), "std": fit.ls.std.get(k), "unit": info.unit}
        entry = {"id": m.id, "name": getattr(m, "name", m.id), "reference": getattr(m, "reference", ""),
                 "parameters": params, "signature": getattr(m, "signature", "")}
        try:
            values = {k: fit.ls.params_all[k] for k in m.parameters}
            if getattr(fit.table, "variable_displacement", False) and hasattr(m, "describe_per_point"):
                entry["description"] = m.describe_per_point(values, fit.table.displacement)
            else:
                entry["description"] = m.describe(values, spec)
        except (NotImplementedError, KeyError, TypeError, ValueError):
            pass
        if hasattr(m, "temperature_differences"):
            entry["temperature_difference_K"] = {
                label: {"value": dt, "std": sd} for label, (dt, sd) in
                m.temperature_differences(fit.ls.params_all, spec, fit.ls.covariance, fit.ls.free).items()}
            entry["recordings_too_small"] = m.too_small(fit.table)  # at the assumed temperature
        mechs.append(entry)
    chans = {}
    for c in ("torque", "q_a", "q_b", "q_case"):
        r0, r1 = base.table_residuals[c], fit.table_residuals[c]
        if np.isfinite(r0).any():
            chans[c] = {"residual_rms_before": float(np.sqrt(np.nanmean(r0**2))),
                        "residual_rms_after": float(np.sqrt(np.nanmean(r1**2)))}
    return _clean({"source": "operating-point tables", "mismatch": bool(dg["mechanisms"] or dg.get("unexplained")),
                   "mechanisms": mechs, "unexplained": dg.get("unexplained", []),
                   "selection": {"criterion": "BIC with each channel's noise level profiled out", "steps": dg["steps"],
                                 **_selection_words(dg.get("selection_points"))},
                   "refused_stand_ins": _refused(dg),
                   "channels": chans, "comparison": dg["comparison"],
                   "parameters": {k: {"value": fit.ls.values[k], "std": fit.ls.std[k],
                                      "identifiable": fit.ls.identifiable[k],
                                      **({"reason": fit.ls.reasons[k]} if k in fit.ls.reasons else {})}
                                  for k in fit.ls.names}})
