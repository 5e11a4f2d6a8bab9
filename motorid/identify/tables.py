"""Fitting operating-point tables (steady loss maps), alone or jointly with bench logs.

A table point is a steady operating point averaged over shaft angle.  Its model
is the one model, :func:`motorid.model.predict`, averaged over θ: the mean over
K angles evenly spread over a whole revolution (K = max(64, 2n(M+2)), M the order
of the K_L(θ) series).  It is exact: the parameter-free S(θ) = Σ_{cos θᵢ>0} cos θᵢ,
in which the pressure torque and the swept flow are linear, is given its exact
mean n/π (so that they average to DΔP/2π and Dω/2π, Eq. 16, 43; a grid mean of
S(θ)'s kinks would miss by 5·10⁻⁶ with 64 angles), and every other term that
varies with θ is a trigonometric polynomial of order below K (the K_L(θ)
harmonics of order m·n; a mechanism's shaft-order terms), whose grid mean is its
exact mean.

What a table cannot identify is reported as such, never given a number:
K_FS and K_s (no breakaway in a steady table), the K_L(θ) harmonics (no shaft
angle), and whatever a missing output channel would have given
(:func:`table_coverage_reasons`, then the null space of the weighted Jacobian).

Noise: each output channel c has its σ estimated from the residuals (a table has no first
differences to estimate it from beforehand), one level, or a floor plus a share of the table's own
relative σ per point (``*_std_*`` / ``n_samples`` columns), or a floor plus a share of the reading
where the likelihood says the scatter grows with it (:mod:`motorid.identify.table_noise`).  The fit is a
bounded trust-region least squares (scipy) with the JAX Jacobian; the table
part is linear in the base parameters, so it converges in a few steps, and the
K-fold refits reuse one compiled residual (held-out points get weight 0).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from motorid import _jaxconfig  # noqa: F401
from motorid import model
from motorid.identify.identifiability import (KAB_HELD_FOR_KL0, ROUGH_NOISE_DOF, at_bound_warning, channel_parameters,
                                              coverage_reasons, kl0_carries_kab_warning,
                                              one_back_pressure_warning, relative_spread,
                                              single_pressure_sum_reason, tfc_carries_kf_warning)
from motorid.identify.results import operating_ranges
from motorid.identify.lack_of_fit import model_error_warnings, structured_error
from motorid.identify.table_noise import ChannelNoise, channel_noise, initial_sigma
from motorid.identify.table_model import (THETA_POINTS, angle_points, angle_samples,  # noqa: F401
                                          bind_mechanisms, point_channels, table_samples)
from motorid.identify.table_residual import TABLE_CHANNELS, TableResidual
from motorid.errors import InputError
from motorid.identify.types import FitResult
NO_BREAKAWAY = ("an operating-point table holds running points only, no breakaway: static friction needs "
                "startability runs (ISO 4392-2)")
NO_ANGLE = ("an operating-point table holds means over shaft angle: the K_L(θ) harmonics need flows "
            "recorded over shaft angle at low constant speed")



# ----------------------------------------------------------------------------- what a table identifies




def table_coverage_reasons(table, spec, names: Sequence[str]) -> dict:
    """Reasons why the table cannot identify a parameter (name → words), from what it holds."""
    m = table.measured
    reasons = {}
    tq = np.isfinite(m["torque"])
    if tq.sum() < 3:
        words = ("the table has no torque readings" if not tq.any() else
                 f"the table has only {int(tq.sum())} torque reading{'s' * int(tq.sum() != 1)} (K_v, K_F and T_Fc "
                 "need 3, and one more for the torque's noise)")
        for k in ("Kv", "KF", "TFc"):
            reasons[k] = words
    else:
        if relative_spread(np.abs(table.viscosity * table.speed)[tq]) < 0.05:
            reasons["Kv"] = ("torque at a single speed·viscosity level: viscous and Coulomb friction cannot be "
                             "told apart")
        if relative_spread((table.displacement * (table.p_a + table.p_b))[tq]) < 0.05:
            reasons["KF"] = single_pressure_sum_reason("torque", (table.p_a + table.p_b)[tq])
    for k in ("KFS", "Ks"):
        reasons[k] = NO_BREAKAWAY
    flows = {c: np.isfinite(m[c]) for c in ("q_a", "q_b", "q_case")}
    port = flows["q_a"] | flows["q_b"]
    if (flows["q_case"] | port).sum() < 3:
        # a port flow alone also carries K_L0 (its port's leakage to the case): whether it tells
        # K_L0 from K_AB is the data's to say (the null space of the fit), not a rule's
        reasons["KL0"] = ("the table has no flow readings" if not (flows["q_case"] | port).any() else
                          "the table has fewer than 3 points with flow readings")
    if port.sum() < 3:
        reasons["KAB"] = "the table has no port flow (K_AB shows only in the port flows)"
    elif np.all(np.abs(table.dp[port]) < 1e3):
        reasons["KAB"] = "port flows only at zero pressure difference"
    for name in names:
        if name.startswith("KL_"):
            reasons[name] = NO_ANGLE
    return {k: v for k, v in reasons.items() if k in names}


def _null_space(J: np.ndarray, free: list, tol: float = 1e-7) -> dict:
    """Parameters in directions the weighted Jacobian (columns over ``free``) cannot see."""
    norms = np.linalg.norm(J, axis=0)
    out = {k: "the table's channels do not depend on it" for k, nrm in zip(free, norms)
           if not (np.isfinite(nrm) and nrm > 0)}
    cols = [i for i, k in enumerate(free) if k not in out]
    if not cols:
        return out
    _, s, vt = np.linalg.svd(J[:, cols] / norms[cols], full_matrices=False)
    for j in np.flatnonzero(s < tol * s.max()):
        involved = [free[cols[i]] for i in np.flatnonzero(np.abs(vt[j]) > 0.2)]
        for k in involved:
            others = [o for o in involved if o != k]
            out.setdefault(k, ("cannot be told apart from " + ", ".join(others) + " with this table") if others
                           else "the table does not determine it")
    return out


# ----------------------------------------------------------------------------- the problem


@dataclass
class TableFit:
    """A fit with operating-point tables: the :class:`FitResult` (``ls``, as from the logs'
    fit) and the table's own part: noise levels, predictions, residuals over the points."""

    ls: FitResult
    table: object
    table_noise: dict  # channel → s_c [SI], None where the table has no such channel
    table_prediction: dict  # channel → θ-averaged model at each point [SI]
    table_residuals: dict  # channel → measured − model [SI]
    table_sigma: dict  # channel → σ of each point [SI]
    seconds: float = 0.0
    dataset: object = None
    notes: list = field(default_factory=list)
    table_noise_floor: dict = field(default_factory=dict)  # channel → σ_floor,c [SI] where the table weights points
    model_error: dict = field(default_factory=dict)  # channel → its structured residual (identify/lack_of_fit.py)
    table_reading_share: dict = field(default_factory=dict)  # channel → σ's share of the reading (table_noise.py)


def _linear_start(spec, table, names, mechanisms) -> dict:
    """Starting values from the θ-averaged base model, which is linear in K_v, K_F, T_Fc
    (torque) and K_L0, K_AB (flows): a least-squares solve of each part on the table."""
    start = model.default_parameters(spec)
    if table is None:
        return start
    D, mu, w = table.displacement, table.viscosity, table.speed
    sgn = np.sign(w)
    t_ideal = D * table.dp / (2 * np.pi)
    y = table.measured["torque"] - t_ideal
    ok = np.isfinite(y)
    if ok.sum() >= 3:
        A = np.column_stack([-D * mu * w, -D * (table.p_a + table.p_b) * sgn, -sgn])[ok]
        coef = np.linalg.lstsq(A, y[ok], rcond=None)[0]
        for k, c in zip(("Kv", "KF", "TFc"), coef):
            if c > 0:
                start[k] = float(c)
    swept = D * w / (2 * np.pi)
    rows, rhs = [], []
    la, lb = (table.p_a - table.p_case) / mu, (table.p_b - table.p_case) / mu
    ab = table.dp / mu
    for c, ideal, a_kl, a_ab in (("q_a", swept, la, ab), ("q_b", -swept, lb, -ab), ("q_case", 0.0, la + lb, 0 * ab)):
        yy = table.measured[c] - ideal
        ok = np.isfinite(yy)
        if ok.any():
            rows.append(np.column_stack([a_kl, a_ab])[ok])
            rhs.append(yy[ok])
    if rows:
        A, b = np.vstack(rows), np.concatenate(rhs)
        scale = np.linalg.norm(A, axis=0)
        scale[scale == 0] = 1.0
        coef = np.linalg.lstsq(A / scale, b, rcond=None)[0] / scale
        for k, c in zip(("KL0", "KAB"), coef):
            if c > 0:
                start[k] = float(c)
    for mech in mechanisms:
        start.update(mech.initial())
    return start


def _best_data_start(problem, free, values, mechanisms, table, train, w_table, w_logs) -> dict:
    """The start of the fit: ``values``, or where a mechanism has a knee or a threshold that a
    start far from it cannot find (``data_starts``, e.g. a relief valve's cracking pressure at
    quantiles of the table's |ΔP|), the solution of the lowest cost over those starts (the
    first-round weights) → values."""
    abs_dp = np.abs(np.asarray(table.dp, dtype=float)[np.asarray(train, bool)])
    starts = [s for m in mechanisms for s in m.data_starts(abs_dp)]
    starts = [s for s in starts if any(k in free for k in s)]
    if not starts or not free:
        return values
    prob = problem(free)
    lower = np.array([0.0 if model.parameter_info(k, mechanisms).positive else -np.inf for k in free])
    best = None
    for s in [{}] + starts:
        x0 = np.array([s.get(k, values[k]) for k in free]) / prob.scales
        x = prob.solve(x0, w_table, w_logs, lower)[0]
        cost = float(np.sum(np.asarray(prob.residual(x, w_table, w_logs)) ** 2))
        if np.isfinite(cost) and (best is None or cost < best[0]):
            best = (cost, {k: float(x[i] * prob.scales[i]) for i, k in enumerate(free)})
    return values if best is None else best[1]


def _table_files(table) -> str:
    files = sorted({str(f) for f in np.asarray(table.file)})
    return files[0] if len(files) == 1 else f"{files[0]} (and {len(files) - 1} more)"


def fit_table(table, spec, mechanisms: Sequence = (), dataset=None, log_fit: FitResult | None = None,
              harmonics: int | None = None, train=None, rounds: int = 3, fixed_noise: dict | None = None,
              start_values: dict | None = None, _cache: dict | None = None) -> TableFit:
    """Fit the model (plus ``mechanisms``) to operating-point tables, alone or with logs.

    table : :class:`motorid.io.tables.PointTable` (None: logs only is not this function's job)
    spec : :class:`motorid.model.MotorSpec`; mechanisms : extra physics whose parameters are fitted too
    dataset, log_fit : the logs' extracted :class:`~motorid.identify.extract.Dataset` and their own
        least-squares fit (its per-sample noise and inliers weight the logs in the joint fit)
    train : bool mask over the table points to fit on (the rest get weight 0: K-fold refits)
    fixed_noise : channel → s_c to hold instead of estimating it (a refit on a fold)
    start_values : parameter → value (SI) of a fit of a model that these mechanisms extend (a
        diagnosis's current model): the start of the parameters it holds; a mechanism whose
        parameters it all holds starts there instead of from its data starts (a knee's quantiles)
    Returns a :class:`TableFit`.
    """
    t0 = time.time()
    M = spec.leak_harmonics if harmonics is None else harmonics
    names = model.parameter_names(M)
    for mech in mechanisms:
        names += list(mech.parameters)
    reasons = table_coverage_reasons(table, spec, names)
    if dataset is not None:
        from_logs = coverage_reasons(dataset, spec, names, elsewhere=[k for k in names if k not in reasons])
        reasons = {k: f"{v}; and from the logs: {from_logs[k]}" for k, v in reasons.items() if k in from_logs}
    n = len(table)
    train = np.ones(n, bool) if train is None else np.asarray(train, bool)
    # a mechanism of the table's own points, set for the points fitted (e.g. the recordings they hold)
    mechanisms = tuple(m.for_training(table, train) for m in mechanisms)
    for mech in mechanisms:
        reasons.update({k: v for k, v in mech.table_reasons(table, train).items() if k not in reasons})
    start = _linear_start(spec, table.subset(train), names, mechanisms)
    if log_fit is not None:
        start.update({k: v for k, v in log_fit.params_all.items() if v is not None and k in names})
    given = {k: float(v) for k, v in (start_values or {}).items()
             if k in names and v is not None and np.isfinite(float(v))}
    start.update(given)
    free = [k for k in names if k not in reasons]
    has = {c: np.isfinite(table.measured[c]) & train for c in TABLE_CHANNELS}
    whole = bool(np.all(train))  # not a fold's training points (a fold too small is the comparison's to say)
    if whole and dataset is None and not any(k in free for k in ("Kv", "KF", "TFc", "KL0", "KAB")):
        n = len(table)
        raise InputError(f"{_table_files(table)}: {n} point{'s' * (n != 1)}: too few to identify any parameter "
                         "(a fit needs at least 4 points with torque, for K_v, K_F, T_Fc and the torque's noise, "
                         "or at least 3 with flows)")
    rough: set = set()
    sigma_c = {c: initial_sigma(table.measured[c][has[c]]) for c in TABLE_CHANNELS}
    if fixed_noise:
        sigma_c.update({c: v for c, v in fixed_noise.items() if v})
    w_logs = {}
    if dataset is not None and log_fit is not None:
        for c in TABLE_CHANNELS + ("breakaway",):
            if c in log_fit.sigma:
                ok = np.asarray(log_fit.inliers[c], bool) & np.isfinite(np.asarray(log_fit.residuals[c], float))
                w_logs[c] = np.where(ok, 1.0 / np.asarray(log_fit.sigma[c], float), 0.0)
    # logs that give breakaways alone (logs without a shaft angle beside their points: identify/log_points.py):
    # their own fit could not settle K_F and T_Fc, so its breakaway noise is not the events' noise; its
    # scale is estimated again from the joint residuals each round, as a table channel's is
    rescale_breakaway = (dataset is not None and log_fit is not None and not dataset.n_running
                         and "breakaway" in w_logs and not fixed_noise)
    breakaway_scale = 1.0
    steps, converged = 0, True
    cache = {} if _cache is None else _cache

    def problem(free_now):
        key = (tuple(free_now), id(table), id(dataset),  # a fold's own recordings: its own problem
               tuple((getattr(m, 'fitted', None), getattr(m, 'implied', None)) for m in mechanisms))
        held = {k: float(start.get(k, 0.0) or 0.0) for k in names if k not in free_now}
        if key not in cache:
            scales = [abs(model.parameter_info(k, mechanisms).typical) or 1.0 for k in free_now]
            cache[key] = TableResidual(spec, table, names, free_now, held, scales, mechanisms, dataset)
        else:  # a refit on another fold: its own start values for what it holds (inputs of the program)
            cache[key].hold(held)
        return cache[key]

    noise_c = {c: ChannelNoise(0.0, sigma_c[c]) for c in TABLE_CHANNELS}  # table_noise.py
    pred_now = {c: np.zeros(n) for c in TABLE_CHANNELS}  # the model at every point, as of the last round

    def point_sigma(c):
        return noise_c[c].sigma(table.relative_sigma[c], pred_now[c])

    def weights():
        return {c: np.where(has[c], 1.0 / point_sigma(c), 0.0) for c in TABLE_CHANNELS}

    values = {k: float(start[k]) for k in free}
    searched = [m for m in mechanisms if not (m.parameters and all(k in given for k in m.parameters))]
    values = _best_data_start(problem, free, values, searched, table, train, weights(), w_logs)
    for round_ in range(max(rounds, 1) + 1):
        prob = problem(free)
        lower = np.array([0.0 if model.parameter_info(k, mechanisms).positive else -np.inf for k in free])
        x0 = np.array([values[k] for k in free]) / prob.scales
        x, nfev, ok, J = prob.solve(x0, weights(), w_logs, lower)
        steps += nfev
        converged = ok
        values = {k: float(x[i] * prob.scales[i]) for i, k in enumerate(free)}
        weak = _null_space(J, free) if free else {}
        if {"KL0", "KAB"} <= set(weak) and not any("KL0" in weak[k] or "KAB" in weak[k] for k in weak
                                                   if k not in ("KL0", "KAB")):
            # the flows hold only K_L0 + K_AB (an efficiency sheet's inlet flow): K_L0 carries the sum, K_AB
            # held at 0 (its reason set with the others' below)
            values["KL0"] = start["KL0"] = values["KL0"] + values["KAB"]
            start["KAB"] = 0.0
            weak = {k: v for k, v in weak.items() if k != "KL0"}
            weak["KAB"] = KAB_HELD_FOR_KL0
        if weak:
            for k in weak:
                reasons[k] = weak[k]
            free = [k for k in free if k not in weak]
            values = {k: values[k] for k in free}
            continue
        if round_ == rounds or fixed_noise:
            break
        # the noise level of each channel from the residuals (degrees of freedom shared out by count)
        pred = {c: np.asarray(v) for c, v in prob.table_pred(x).items()}
        n_all = sum(int(has[c].sum()) for c in TABLE_CHANNELS) + sum(int((w > 0).sum()) for w in w_logs.values())
        n_pad = len(prob.obs["torque"])
        for i, c in enumerate(TABLE_CHANNELS):
            k = int(has[c].sum())
            if k == 0:
                continue
            tiny = 1e-12 * max(np.max(np.abs(table.measured[c][has[c]])), 1e-300)
            dof = max(k - len(free) * k / max(n_all, 1), 1.0)
            if not w_logs and free:  # the table alone: the channel's own parameters use up its points
                rank, reach = channel_parameters(J, free, i, n_pad)
                own = k - rank
                if own < 1 and whole:
                    raise InputError(
                        f"{_table_files(table)}: {k} point{'s' * (k != 1)} with {c} for the {rank} parameter"
                        f"{'s' * (rank != 1)} it determines ({', '.join(reach)}): nothing is left to estimate "
                        f"its noise and so their uncertainty; give at least {rank + 1} points with {c}")
                if own < ROUGH_NOISE_DOF and whole:
                    rough.add(f"the {c} noise rests on {own} degree{'s' * (own != 1)} of freedom ({k} points, "
                              f"{rank} parameter{'s' * (rank != 1)}): its standard errors are rough")
                dof = max(min(dof, own), 1.0)
            weighted = table.weights_from.get(c, "none") != "none"
            pred_now[c] = np.abs(pred[c])
            noise_c[c] = channel_noise((table.measured[c] - pred[c])[has[c]], pred[c][has[c]],
                                       table.relative_sigma[c][has[c]] if weighted else None, k / dof,
                                       sigma_c[c], tiny)
            sigma_c[c] = noise_c[c].scale
        if rescale_breakaway:
            wb = w_logs["breakaway"]
            on = wb > 0
            rb = (np.asarray(prob.log_obs["breakaway"]) - np.asarray(prob.log_pred(x)["breakaway"]))[on] * wb[on]
            dof_b = max(int(on.sum()) - sum(1 for k in free if k in ("KFS", "Ks")), 1)
            factor = float(np.sqrt(np.sum(rb ** 2) / dof_b)) if on.any() else 1.0
            if np.isfinite(factor) and factor > 0:
                w_logs["breakaway"] = wb / factor
                breakaway_scale *= factor

    prob = problem(free)
    x = np.array([values[k] for k in free]) / prob.scales if free else np.zeros(0)
    pred = {c: np.asarray(v) for c, v in prob.table_pred(x).items()}
    w = weights()
    r_all = np.asarray(prob.residual(x, w, w_logs))
    chi2 = float(r_all @ r_all)
    used_t = {c: int(has[c].sum()) for c in TABLE_CHANNELS}
    n_res = sum(used_t.values()) + sum(int((v > 0).sum()) for v in w_logs.values())
    dof = max(n_res - len(free), 1)
    if free:
        J = np.asarray(prob.jacobian(x, w, w_logs))
        cov_x = np.linalg.pinv(J.T @ J)
        cov = cov_x * np.outer(prob.scales, prob.scales)
        if chi2 / dof > 1.0:
            cov = cov * (chi2 / dof)
        std = np.sqrt(np.clip(np.diag(cov), 0, None))
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = cov / np.outer(std, std)
    else:
        cov = corr = np.zeros((0, 0))
        std = np.zeros(0)
    out_values, out_std, ident = {}, {}, {}
    for k in names:
        if k in free:
            i = free.index(k)
            out_values[k], out_std[k], ident[k] = values[k], float(std[i]), True
        else:
            out_values[k], out_std[k], ident[k] = None, None, False
    warnings = []
    for k in free:
        info = model.parameter_info(k, mechanisms)
        if info.positive and values[k] < 1e-4 * abs(info.typical):
            warnings.append(at_bound_warning(k))
        elif std[free.index(k)] > abs(values[k]):
            warnings.append(f"{k}: standard error exceeds the value; the data barely constrain it")
    if not converged:
        warnings.append("the table fit stopped before converging (scipy least_squares, max_nfev)")
    for effective in (tfc_carries_kf_warning(reasons, free, "data", "points"), kl0_carries_kab_warning(reasons, free)):
        if effective:
            warnings.append(effective)
    if "KF" in free:
        tq = np.isfinite(table.measured["torque"]) & train
        note = one_back_pressure_warning(np.minimum(table.p_a, table.p_b)[tq], values["KF"])
        if note:
            warnings.append(note)
    warnings += sorted(rough)
    warnings += list(getattr(table, "notes", []))
    resid = {c: table.measured[c] - pred[c] for c in TABLE_CHANNELS}
    sig = {c: point_sigma(c) for c in TABLE_CHANNELS}
    # what neighbouring points share of their residuals: the model's error, not noise (lack_of_fit.py)
    model_error = structured_error(table, {c: np.where(has[c], resid[c], np.nan) for c in TABLE_CHANNELS},
                                   sigma={c: sig[c] for c in TABLE_CHANNELS if noise_c[c].reading_share}) \
        if whole else {}
    warnings += model_error_warnings(model_error)
    tnoise = {c: (sigma_c[c] if np.isfinite(table.measured[c]).any() else None) for c in TABLE_CHANNELS}
    if log_fit is not None:
        noise, noise_by_run, outliers = dict(log_fit.noise), dict(log_fit.noise_by_run), dict(log_fit.outliers)
        if breakaway_scale != 1.0 and "breakaway" in noise:
            noise["breakaway"] = noise["breakaway"] * breakaway_scale
        used = {c: int(log_fit.used.get(c, 0)) + used_t.get(c, 0) for c in set(log_fit.used) | set(used_t)}
        residuals = dict(log_fit.residuals)
        sigma, inliers = dict(log_fit.sigma), dict(log_fit.inliers)
        if breakaway_scale != 1.0 and "breakaway" in sigma:
            sigma["breakaway"] = np.asarray(sigma["breakaway"], dtype=float) * breakaway_scale
    else:
        noise = {c: v for c, v in tnoise.items() if v is not None}
        noise_by_run = {c: np.array([v]) for c, v in noise.items()}
        outliers = {c: 0 for c in noise}
        used = {c: used_t[c] for c in noise}
        residuals = {c: resid[c] for c in noise}
        sigma = {c: sig[c] for c in noise}
        inliers = {c: has[c] for c in noise}
    params_all = {k: float(start.get(k, 0.0) or 0.0) for k in names}
    params_all.update(values)
    ls = FitResult(names=names, free=list(free), values=out_values, std=out_std, covariance=cov, correlation=corr,
                   identifiable=ident, reasons={k: v for k, v in reasons.items() if k in names}, noise=noise,
                   noise_by_run=noise_by_run, outliers=outliers, used=used, chi2=chi2, dof=dof, steps=steps,
                   converged=converged, warnings=warnings, residuals=residuals, sigma=sigma, inliers=inliers,
                   params_all=params_all, mechanisms=tuple(mechanisms), problem=None)
    floors = {c: noise_c[c].floor for c in TABLE_CHANNELS
              if has[c].any() and (table.weights_from.get(c, "none") != "none" or noise_c[c].reading_share)}
    shares = {c: noise_c[c].reading_share for c in TABLE_CHANNELS if has[c].any() and noise_c[c].reading_share}
    return TableFit(ls, table, tnoise, pred, resid, sig, time.time() - t0, dataset, table_noise_floor=floors,
                    model_error=model_error, table_reading_share=shares)


def table_document(tf: TableFit) -> dict:
    """The ``table`` block of result.json: what the tables gave (noise per channel, weights, points)."""
    t = tf.table
    return {
        "points": len(t),
        "files": sorted(set(map(str, t.file))),
        "channels": t.channels(),
        "theta_average": "model.predict averaged over a revolution: S(θ) at its exact mean n/π, the rest over "
                         "K ≥ 64 evenly spread shaft angles (exact for trigonometric terms of order < K), or at one "
                         "angle where nothing in the model varies with θ (probed)",
        "noise": {c: {"sigma": v, "unit": "N·m" if c == "torque" else "m³/s",
                      **({"floor": tf.table_noise_floor[c]} if c in tf.table_noise_floor else {}),
                      **({"reading_share": tf.table_reading_share[c]} if c in tf.table_reading_share else {}),
                      **({"model_error": tf.model_error[c]["sigma"], "model_error_share": tf.model_error[c]["share"]}
                         if c in tf.model_error else {})}
                  for c, v in tf.table_noise.items()},
        "weights_from": dict(t.weights_from),
        "variable_displacement": bool(t.variable_displacement),
        "residual_rms": {c: (float(np.sqrt(np.nanmean(r**2))) if np.isfinite(r).any() else None)
                         for c, r in tf.table_residuals.items()},
        "ranges": operating_ranges(t.speed, t.dp, t.viscosity),
    }

