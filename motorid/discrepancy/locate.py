"""Locate structure in the residuals of a fit, judged against the noise.

After a fit every channel's residual, divided by the noise level of its run,
should be white noise of unit variance.  Structure is looked for

- *between runs* (variables that a run holds fixed): speed and its sign,
  pressure difference, port-pressure sum, pressure to case, viscosity,
  temperature, protocol and the run itself — each run's mean normalized
  residual, with a standard error that allows for autocorrelation, tested
  in groups along the variable (a χ² test of the group means);
- *within runs*: shaft angle at every shaft order k = 1 … K (not only the
  piston orders; only in runs whose sampling resolves that order) and time
  within the run (a linear and a quadratic trend) — a χ² test of the
  regression on those shapes, summed over runs;
- for breakaway events: along port-pressure sum, pressure difference, shaft
  angle (orders 1, 2 and n) and direction.

Each test gives a p-value; a structure is *significant* when p is below
``alpha`` divided by the number of tests (Bonferroni), and *relevant* when its
size is at least ``min_effect`` of the channel's noise level in the group
affected.  Its place is said in words with its size in engineering units.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.special import chdtrc  # the χ² survival function, without scipy.stats' second of import

from motorid.units import CHANNEL_WORDS, LPM_PER_M3S, PA_PER_BAR, RPM_PER_RAD_S, RUNNING_CHANNELS

UNIT = {"torque": ("N·m", 1.0), "breakaway": ("N·m", 1.0), "q_a": ("L/min", LPM_PER_M3S),
        "q_b": ("L/min", LPM_PER_M3S), "q_case": ("L/min", LPM_PER_M3S)}


@dataclass
class Structure:
    """One located structure in one channel's residuals."""

    channel: str
    variable: str
    statistic: float
    dof: int
    p_value: float
    effect: float  # largest group mean residual [SI]
    effect_sigma: float  # the same in units of the noise level
    where: str  # words
    groups: list = field(default_factory=list)  # [(label, mean residual SI, z)]
    order: int | None = None  # shaft order, for angle structure

    @property
    def log10_p(self) -> float:
        return float(np.log10(max(self.p_value, 1e-300)))

    def as_dict(self) -> dict:
        return {"channel": self.channel, "variable": self.variable, "statistic": self.statistic,
                "dof": self.dof, "p_value": self.p_value, "effect": self.effect,
                "effect_sigma": self.effect_sigma, "where": self.where, "order": self.order}


@dataclass
class Location:
    structures: list  # every test, significant or not
    significant: list  # the significant and relevant ones, strongest first
    tests: int
    threshold: float

    def by_channel(self) -> dict:
        out: dict = {}
        for s in self.significant:
            out.setdefault(s.channel, []).append(s)
        return out


def trend_words(means, variable: str) -> str | None:
    """How group means ordered along ``variable`` run, in words ("rising with …", "falling with …",
    "not monotone in …"); None for fewer than three groups."""
    if len(means) < 3:
        return None
    d = np.diff(means)
    if np.all(d >= 0):
        return f"rising with {variable}"
    if np.all(d <= 0):
        return f"falling with {variable}"
    return f"not monotone in {variable}"


def _fmt(value, channel) -> str:
    unit, f = UNIT[channel]
    return f"{value * f:.3g} {unit}"


def _chi2_sf(x, dof) -> float:
    return float(chdtrc(dof, x)) if dof > 0 else 1.0


def _lag1(z: np.ndarray) -> float:
    if z.size < 4:
        return 0.0
    a, b = z[:-1] - z.mean(), z[1:] - z.mean()
    den = np.sqrt(np.sum(a * a) * np.sum(b * b))
    return float(np.clip(np.sum(a * b) / den, 0.0, 0.95)) if den > 0 else 0.0


class _RunIndex:
    """Each run's samples, in time order: ``of(r)`` → their indices (a stable sort of the run
    numbers, made once; a run's samples are then a slice, not a mask over every sample)."""

    def __init__(self, run_of, n_runs: int):
        self.order = np.argsort(run_of, kind="stable")
        self.bounds = np.searchsorted(np.asarray(run_of)[self.order], np.arange(n_runs + 1))

    def of(self, r: int) -> np.ndarray:
        return self.order[self.bounds[r]:self.bounds[r + 1]]


def _run_table(z, index, n_runs, shared_var=None):
    """Per run: mean normalized residual and its standard error (AR(1) corrected;
    plus ``shared_var`` per run, an error common to the run's samples in units of
    its noise level squared, such as that of its smoothed viscosity).  ``index``: a
    :class:`_RunIndex`, or the run of each sample."""
    if not isinstance(index, _RunIndex):
        index = _RunIndex(np.asarray(index, dtype=int), n_runs)
    mean = np.full(n_runs, np.nan)
    se = np.full(n_runs, np.nan)
    for r in range(n_runs):
        v = z[index.of(r)]
        v = v[np.isfinite(v)]
        if v.size < 5:
            continue
        rho = _lag1(v)
        n_eff = v.size * (1 - rho) / (1 + rho)
        mean[r] = v.mean()
        se[r] = max(np.std(v), 1.0) / np.sqrt(max(n_eff, 1.0))
        if shared_var is not None and np.isfinite(shared_var[r]):
            se[r] = np.sqrt(se[r] ** 2 + shared_var[r])
    return mean, se


def _group_test(labels, zrun, words):
    """χ² of group means of run z-scores; returns (stat, dof, [(label, z)])."""
    out, stat = [], 0.0
    for lab in labels.unique_order:
        sel = labels.values == lab
        zz = zrun[sel]
        zz = zz[np.isfinite(zz)]
        if zz.size == 0:
            continue
        zg = zz.sum() / np.sqrt(zz.size)
        stat += zg**2
        out.append((lab, zg, sel))
    return stat, len(out), out


class _Labels:
    def __init__(self, values, order):
        self.values = np.asarray(values, dtype=object)
        self.unique_order = order


def _quantile_groups(x, n_groups, log=False, fmt=str):
    """Runs grouped by level of a variable; labels say the range in words."""
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(x)
    vals = np.abs(x) if log else x
    uniq = np.unique(np.round(vals[ok], 12))
    if uniq.size < 2:
        return None
    if uniq.size <= n_groups:
        edges = np.concatenate([[-np.inf], (uniq[1:] + uniq[:-1]) / 2, [np.inf]])
    else:
        qs = np.quantile(vals[ok], np.linspace(0, 1, n_groups + 1))
        edges = np.unique(np.concatenate([[-np.inf], qs[1:-1], [np.inf]]))
    idx = np.digitize(vals, edges[1:-1])
    order = []
    lab_of = np.array([None] * x.size, dtype=object)
    for g in range(len(edges) - 1):
        sel = ok & (idx == g)
        if not sel.any():
            continue
        lo, hi = vals[sel].min(), vals[sel].max()
        lab = fmt(lo) if np.isclose(lo, hi) or fmt(lo) == fmt(hi) else f"{fmt(lo)} to {fmt(hi)}"
        if lab not in order:  # groups that read alike (within the words' precision) are one group
            order.append(lab)
        lab_of[sel] = lab
    return _Labels(lab_of, order)


def _rpm(v):
    return f"{v * RPM_PER_RAD_S:.3g} rpm"


def _bar(v):
    return f"{v / PA_PER_BAR:.4g} bar"


def _mpas(v):
    return f"{v * 1e3:.3g} mPa·s"


def _degc(v):
    return f"{v:.3g} °C"


def locate(ls, dataset, spec, alpha: float = 1e-3, min_effect: float = 0.3,
           max_order: int | None = None) -> Location:
    """Test every channel's residuals for structure against its noise level.

    ls : :class:`~motorid.identify.least_squares.FitResult`
    dataset : :class:`~motorid.identify.extract.Dataset`
    alpha : family-wise false-alarm rate (Bonferroni over all tests)
    min_effect : smallest effect worth naming, in units of the noise level
    max_order : highest shaft order tested (default 2n + 2)
    """
    s = dataset.running
    run_of = np.asarray(dataset.run_of_sample, dtype=int)
    n_runs = len(dataset.runs)
    runs = dataset.runs
    kmax = max_order or 2 * spec.pistons + 2
    found: list[Structure] = []
    index = _RunIndex(run_of, n_runs)

    per_run = {
        "speed": _quantile_groups(runs["speed_median_rad_s"].abs().to_numpy(), 6, fmt=_rpm),
        "direction": _Labels(np.where(runs["direction"].to_numpy() > 0, "positive rotation",
                                      np.where(runs["direction"].to_numpy() < 0, "negative rotation", None)),
                             ["positive rotation", "negative rotation"]),
        "pressure difference": _quantile_groups(runs["dp_median_Pa"].abs().to_numpy(), 5, fmt=_bar),
        "port-pressure sum": _quantile_groups(runs["psum_median_Pa"].to_numpy(), 5, fmt=_bar),
        "temperature": _quantile_groups(runs["temp_median_C"].to_numpy(), 4, fmt=_degc),
        "protocol": _Labels(runs["protocol"].to_numpy(), list(dict.fromkeys(runs["protocol"].tolist()))),
    }
    # run-level medians of quantities not in the runs table
    for name, arr, fmt in (("pressure to case", np.asarray(s.p_case), _bar),
                           ("viscosity", np.asarray(s.viscosity), _mpas)):
        med = np.full(n_runs, np.nan)
        for r in range(n_runs):
            if index.bounds[r + 1] > index.bounds[r]:
                med[r] = np.median(arr[index.of(r)])
        per_run[name] = _quantile_groups(med, 4, fmt=fmt)

    for c in RUNNING_CHANNELS:
        if c not in ls.residuals:
            continue
        res, sig, ok = ls.residuals[c], ls.sigma[c], ls.inliers[c]
        if ok.sum() < 20:
            continue
        z = np.where(ok, res / sig, np.nan)
        mean_res = np.full(n_runs, np.nan)
        noise_run = np.full(n_runs, np.nan)
        for r in range(n_runs):
            sel = index.of(r)
            sel = sel[ok[sel]]
            if sel.size:
                mean_res[r] = res[sel].mean()
                noise_run[r] = np.median(sig[sel])
        # the smoothed viscosity's error is common to a run: it moves the run's mean residual
        visc = getattr(ls, "viscosity_run_variance", {}).get(c)
        shared = None
        if visc is not None and len(visc) == n_runs:
            with np.errstate(invalid="ignore", divide="ignore"):
                shared = np.asarray(visc) / noise_run**2
        mean_z, se_z = _run_table(z, index, n_runs, shared)
        zrun = mean_z / se_z
        have = np.isfinite(zrun)
        if have.sum() >= 2:
            for var, labels in list(per_run.items()) + [("run", _Labels(runs["run"].to_numpy(), runs["run"].tolist()))]:
                if labels is None:
                    continue
                lab = _Labels(np.where(have, labels.values, None), labels.unique_order)
                stat, dof, groups = _group_test(lab, np.where(have, zrun, np.nan), var)
                if dof < 2 and var not in ("protocol",):
                    continue
                glist = []
                for name, zg, sel in groups:
                    m = np.nanmean(mean_res[sel & have])
                    glist.append((name, float(m), float(zg), float(np.nanmedian(noise_run[sel & have]))))
                worst = max(glist, key=lambda g: abs(g[2]))
                found.append(Structure(
                    channel=c, variable=var, statistic=float(stat), dof=dof, p_value=_chi2_sf(stat, dof),
                    effect=worst[1], effect_sigma=abs(worst[1]) / worst[3] if worst[3] > 0 else np.inf,
                    where=_words_between(c, var, worst, runs, have, labels), groups=glist))
        # within runs: shaft orders and time
        found += _within_runs(c, z, res, sig, ok, s, index, n_runs, kmax, spec, per_run["speed"])

    if "breakaway" in ls.residuals and np.sum(ls.inliers["breakaway"]) >= 6:
        found += _breakaway_structures(ls, dataset, spec)

    tests = max(len(found), 1)
    threshold = alpha / tests
    significant = [f for f in found if f.p_value < threshold and f.effect_sigma >= min_effect]
    significant.sort(key=lambda f: f.p_value)
    return Location(structures=found, significant=significant, tests=tests, threshold=threshold)


def _words_between(c, var, worst, runs, have, labels) -> str:
    name, m, zg, noise = worst
    verb = "falls short of the model" if m < 0 else "exceeds the model"
    if var == "run":
        return f"{CHANNEL_WORDS[c]} in run {name} {verb} by {_fmt(abs(m), c)} on average"
    if var == "protocol":
        return f"{CHANNEL_WORDS[c]} in the {name} runs {verb} by {_fmt(abs(m), c)} on average"
    if var == "direction":
        return f"{CHANNEL_WORDS[c]} in {name} {verb} by {_fmt(abs(m), c)} on average"
    return f"{CHANNEL_WORDS[c]} at {var} {name} {verb} by {_fmt(abs(m), c)} on average"


def _ripple_size(amps, zamps, runs_seen, speed_groups):
    """Size of a shaft-order ripple → (amplitude [SI], in noise levels, speed words or None).

    A shaft-locked ripple may grow with speed (a transducer lag, a flow ripple ∝ ω) and be
    nothing in the slow runs: its size is the median over the runs of the speed group where it
    is largest, each run's amplitude over that run's own noise level (a structure confined to
    the fast runs also raises their residual noise estimate, and the median over all runs
    would hide it behind the slow ones).  Where the runs do not group by speed, the median over all.
    """
    amps, zamps, runs_seen = np.asarray(amps), np.asarray(zamps), np.asarray(runs_seen, dtype=int)
    best = (float(np.median(amps)), float(np.median(zamps)), None)
    if speed_groups is None:
        return best
    labels = speed_groups.values[runs_seen]
    for lab in speed_groups.unique_order:
        sel = labels == lab
        if sel.sum() >= 2 and np.median(zamps[sel]) > best[1]:
            best = (float(np.median(amps[sel])), float(np.median(zamps[sel])), lab)
    return best


def _harmonic_fits(theta, z, kmax: int):
    """Each shaft order k = 1…kmax fitted alone to z with an intercept (a run's offset is not
    angle structure): z − z̄ ≈ a (cos kθ − mean) + b (sin kθ − mean) → [(k, (a, b), Σ fit²)].
    All orders at once from the 2×2 normal equations of each (the same numbers as one
    least-squares solve per order)."""
    e = np.cumprod(np.broadcast_to(np.exp(1j * theta)[:, None], (theta.size, kmax)), axis=1)  # e^{ikθ}: n × K
    c, s = e.real - e.real.mean(axis=0), e.imag - e.imag.mean(axis=0)
    y = z - z.mean()
    cc, ss, cs = np.sum(c * c, axis=0), np.sum(s * s, axis=0), np.sum(c * s, axis=0)
    bc, bs = y @ c, y @ s
    det = cc * ss - cs**2
    good = det > 1e-12 * np.maximum(cc * ss, 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        beta = np.stack([ss * bc - cs * bs, cc * bs - cs * bc], axis=1) / det[:, None]
    for k in np.flatnonzero(~good):  # the angles do not tell cos from sin at this order
        beta[k] = np.linalg.lstsq(np.column_stack([c[:, k], s[:, k]]), y, rcond=None)[0]
    explained = beta[:, 0] * bc + beta[:, 1] * bs
    return [(k + 1, beta[k], float(explained[k])) for k in range(kmax)]


def _within_runs(c, z, res, sig, ok, s, index: _RunIndex, n_runs, kmax, spec, speed_groups=None) -> list:
    theta = np.asarray(s.theta)
    t = np.asarray(s.time)
    speed = np.asarray(s.speed)
    out = []
    stat_k = np.zeros(kmax + 1)
    dof_k = np.zeros(kmax + 1, int)
    amp_k = [[] for _ in range(kmax + 1)]
    zamp_k = [[] for _ in range(kmax + 1)]  # the same over the run's noise level
    run_k = [[] for _ in range(kmax + 1)]
    stat_t, dof_t, trend = 0.0, 0, []
    for r in range(n_runs):
        sel = index.of(r)
        sel = sel[ok[sel]]
        n = int(sel.size)
        if n < 30:
            continue
        zr, th, tr = z[sel], theta[sel], t[sel]
        rho = _lag1(zr)
        inflate = (1 + rho) / (1 - rho)
        # shaft orders resolved in this run: at least 6 samples per cycle of order k
        dt = np.median(np.diff(tr)) if n > 1 else np.inf
        step = abs(np.median(speed[sel])) * dt
        span = np.ptp(np.unwrap(th)) if step < np.pi / 2 else 0.0
        if span >= 2 * np.pi * 0.9:
            orders = [k for k in range(1, kmax + 1) if step * k <= 2 * np.pi / 6]
            if orders:
                sig_r = np.median(sig[sel])
                for k, beta, explained in _harmonic_fits(th, zr, len(orders)):
                    stat_k[k] += explained / inflate
                    dof_k[k] += 2
                    amp_k[k].append(np.hypot(*beta) * sig_r)
                    zamp_k[k].append(np.hypot(*beta))
                    run_k[k].append(r)
        # time trend within the run
        if np.ptp(tr) > 0:
            u = 2 * (tr - tr.min()) / np.ptp(tr) - 1
            X = np.column_stack([u, 1.5 * u**2 - 0.5])
            X = X - X.mean(axis=0)
            beta, *_ = np.linalg.lstsq(X, zr - zr.mean(), rcond=None)
            stat_t += np.sum((X @ beta) ** 2) / inflate
            dof_t += 2
            trend.append(beta[0] * np.median(sig[sel]))
    noise = float(np.median(sig[ok]))
    for k in range(1, kmax + 1):
        if dof_k[k] == 0:
            continue
        amp, amp_sigma, at = _ripple_size(amp_k[k], zamp_k[k], run_k[k], speed_groups)
        kind = f"{k}× shaft order" + (f" ({k // spec.pistons}× piston order)" if k % spec.pistons == 0 else "")
        out.append(Structure(
            channel=c, variable="shaft angle", statistic=float(stat_k[k]), dof=int(dof_k[k]),
            p_value=_chi2_sf(stat_k[k], dof_k[k]), effect=amp, effect_sigma=amp_sigma,
            where=f"{CHANNEL_WORDS[c]} varies with shaft angle at the {kind}, amplitude {_fmt(amp, c)}"
                  + (f" at speed {at}" if at else ""),
            order=k))
    if dof_t:
        amp = float(np.median(np.abs(trend))) if trend else 0.0
        out.append(Structure(
            channel=c, variable="time within run", statistic=float(stat_t), dof=dof_t,
            p_value=_chi2_sf(stat_t, dof_t), effect=amp, effect_sigma=amp / noise if noise > 0 else np.inf,
            where=f"{CHANNEL_WORDS[c]} drifts within runs by about {_fmt(2 * amp, c)} from start to end"))
    return out


def _breakaway_structures(ls, dataset, spec) -> list:
    ev = dataset.events
    res, sig, ok = ls.residuals["breakaway"], ls.sigma["breakaway"], ls.inliers["breakaway"]
    z = np.where(ok, res / sig, np.nan)
    out = []
    theta = np.asarray(ev.theta)
    variables = {
        "port-pressure sum": _quantile_groups(np.asarray(ev.p_a + ev.p_b), 4, fmt=_bar),
        "pressure difference": _quantile_groups(np.abs(np.asarray(ev.p_a - ev.p_b)), 4, fmt=_bar),
        "direction": _Labels(np.where(np.asarray(ev.direction) > 0, "positive rotation", "negative rotation"),
                             ["positive rotation", "negative rotation"]),
    }
    for var, labels in variables.items():
        if labels is None:
            continue
        stat, dof, groups = _group_test(labels, z, var)
        if dof < 2:
            continue
        glist = [(name, float(np.nanmean(res[sel & ok])), float(zg), float(np.median(sig))) for name, zg, sel in groups]
        worst = max(glist, key=lambda g: abs(g[2]))
        out.append(Structure("breakaway", var, float(stat), dof, _chi2_sf(stat, dof), worst[1],
                             abs(worst[1]) / worst[3], _words_between("breakaway", var, worst, None, None, None),
                             glist))
    for k in sorted({1, 2, spec.pistons}):
        X = np.column_stack([np.cos(k * theta), np.sin(k * theta)])[ok]
        if X.shape[0] < 8:
            continue
        beta, *_ = np.linalg.lstsq(X, z[ok], rcond=None)
        stat = float(np.sum((X @ beta) ** 2))
        amp = float(np.hypot(*beta) * np.median(sig))
        out.append(Structure("breakaway", "shaft angle", stat, 2, _chi2_sf(stat, 2), amp, amp / np.median(sig),
                             f"breakaway (held) torque varies with shaft angle at the {k}× shaft order, amplitude {_fmt(amp, 'breakaway')}",
                             order=k))
    return out
