"""Locate structure in the residuals of a fit, judged against the noise.

After a fit every channel's residual, divided by the noise level of its run,
should be white noise of unit variance.  Structure is looked for

- *between runs* (variables that a run holds fixed): speed and its sign,
  pressure difference, port-pressure sum, pressure to case, viscosity,
  temperature, protocol and the run itself — each run's mean normalized
  residual, with a standard error that allows for autocorrelation, tested
  in groups along the variable (a χ² test of the group means); for torque and
  port flows also along |ω| with each run's mean taken with the sign of the
  rotation, where runs turn both ways (a law of the speed reverses with the
  rotation, and what it leaves cancels between the directions in the |ω| groups);
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

from motorid.discrepancy.run_segments import RunIndex, Segments
from motorid.identify.types import RUNNING_PROTOCOLS
from motorid.units import CHANNEL_WORDS, LPM_PER_M3S, PA_PER_BAR, RPM_PER_RAD_S, RUNNING_CHANNELS

def running_runs(runs) -> np.ndarray:
    """Per run of ``Dataset.runs``: True where it is a running protocol that turns (not a startability
    run, whose creep as the shaft breaks away is a few thousandths of an rpm)."""
    return runs["protocol"].isin(RUNNING_PROTOCOLS).to_numpy() & \
        (np.abs(runs["speed_median_rad_s"].to_numpy(dtype=float)) > 0)


#: run means taken with the sign of the rotation, grouped by |ω|: what a law of the speed leaves
SIGNED_SPEED = "speed with the rotation's sign"
#: the channels whose laws of the speed reverse with the rotation (the case drain's does not)
SIGNED_CHANNELS = ("torque", "q_a", "q_b")

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


def _run_table(z, index, n_runs, shared_var=None):
    """Per run: mean normalized residual and its standard error (AR(1) corrected;
    plus ``shared_var`` per run, an error common to the run's samples in units of
    its noise level squared, such as that of its smoothed viscosity).  ``index``: a
    :class:`~motorid.discrepancy.run_segments.RunIndex`, or the run of each sample."""
    if not isinstance(index, RunIndex):
        index = RunIndex(np.asarray(index, dtype=int), n_runs)
    z = np.asarray(z, dtype=float)
    seg = index.kept(np.isfinite(z))
    v = seg.take(z)
    mean = seg.mean(v)
    rho = seg.lag1(v)
    n_eff = seg.n * (1 - rho) / (1 + rho)
    d = v - mean[seg.run]
    with np.errstate(invalid="ignore", divide="ignore"):
        std = np.sqrt(seg.sum(d * d) / seg.n)
    se = np.maximum(std, 1.0) / np.sqrt(np.maximum(n_eff, 1.0))
    if shared_var is not None:
        shared = np.asarray(shared_var, dtype=float)
        se = np.where(np.isfinite(shared), np.sqrt(se**2 + np.where(np.isfinite(shared), shared, 0.0)), se)
    few = seg.n < 5
    mean[few] = np.nan
    se[few] = np.nan
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
    index = RunIndex(run_of, n_runs)
    every = index.kept()

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
    # a law of the speed reverses with the rotation (a friction, a swept flow): where the runs turn both
    # ways, what such a law leaves cancels in the |ω| groups above; taken with the sign of the rotation
    # it adds up (an ω³ torque loss fitted by a churning law ∝ ω|ω| left only a run-to-run spread)
    turning = np.sign(runs["direction"].to_numpy(dtype=float))
    running = running_runs(runs) & (turning != 0)
    if (turning[running] > 0).sum() >= 2 and (turning[running] < 0).sum() >= 2:
        speed = np.where(running, np.abs(runs["speed_median_rad_s"].to_numpy(dtype=float)), np.nan)
        per_run[SIGNED_SPEED] = _quantile_groups(speed, 6, fmt=_rpm)
    # run-level medians of quantities not in the runs table
    for name, arr, fmt in (("pressure to case", np.asarray(s.p_case), _bar),
                           ("viscosity", np.asarray(s.viscosity), _mpas)):
        per_run[name] = _quantile_groups(every.median(every.take(arr)), 4, fmt=fmt)

    for c in RUNNING_CHANNELS:
        if c not in ls.residuals:
            continue
        res, sig, ok = ls.residuals[c], ls.sigma[c], ls.inliers[c]
        if ok.sum() < 20:
            continue
        z = np.where(ok, res / sig, np.nan)
        kept = index.kept(ok)
        mean_res = kept.mean(kept.take(res))
        noise_run = kept.median(kept.take(sig))
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
                sign = 1.0
                if var == SIGNED_SPEED:
                    if c not in SIGNED_CHANNELS:
                        continue
                    sign = turning
                lab = _Labels(np.where(have, labels.values, None), labels.unique_order)
                stat, dof, groups = _group_test(lab, np.where(have, zrun * sign, np.nan), var)
                if dof < 2 and var not in ("protocol",):
                    continue
                glist = []
                for name, zg, sel in groups:
                    m = np.nanmean((mean_res * sign)[sel & have])
                    glist.append((name, float(m), float(zg), float(np.nanmedian(noise_run[sel & have]))))
                worst = max(glist, key=lambda g: abs(g[2]))
                found.append(Structure(
                    channel=c, variable=var, statistic=float(stat), dof=dof, p_value=_chi2_sf(stat, dof),
                    effect=worst[1], effect_sigma=abs(worst[1]) / worst[3] if worst[3] > 0 else np.inf,
                    where=_words_between(c, var, worst, runs, have, labels), groups=glist))
        # within runs: shaft orders and time
        found += _within_runs(c, z, sig, ok, s, kept, kmax, spec, per_run["speed"], noise_run)

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
    if var == SIGNED_SPEED:
        return (f"{CHANNEL_WORDS[c]} at speed {name}, taken with the sign of the rotation, {verb} by "
                f"{_fmt(abs(m), c)} on average (the opposite way in the other direction)")
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


#: what depends on a channel's mask alone (:func:`_sampling`, :func:`_angle_sums`), for the masks seen
#: last: diagnose judges several fits whose inliers are the base fit's
_ANGLE_SUMS: dict = {}
_ANGLE_SUMS_KEPT = 16


def _mask_key(theta_all, kept: Segments, *extra) -> tuple:
    import hashlib

    digest = hashlib.blake2b(b"".join([kept.idx.tobytes(), kept.n.tobytes(),
                                       *(np.asarray(x).tobytes() for x in extra)]),
                             digest_size=16).digest()
    return id(theta_all), theta_all.size, digest


def _kept_for(key, arrays: tuple, compute):
    """``compute()`` for a channel mask, kept for the masks seen last (:data:`_ANGLE_SUMS`); ``arrays``:
    the per-sample arrays it reads, whose ids are in ``key`` (held with the value: an id is not reused
    while its array lives)."""
    hit = _ANGLE_SUMS.get(key)
    if hit is not None and all(a is b for a, b in zip(hit[0], arrays)):
        return hit[1]
    value = compute()
    while len(_ANGLE_SUMS) >= _ANGLE_SUMS_KEPT:
        _ANGLE_SUMS.pop(next(iter(_ANGLE_SUMS)), None)
    _ANGLE_SUMS[key] = (arrays, value)
    return value


def _sampling(theta_all, kept: Segments, t, theta, speed, time_all) -> tuple:
    """Per run: the shaft angle a sample step covers (|median speed| × median time step) [rad]
    and the range of the unwrapped angle where steps are under a quarter turn [rad]."""

    def compute():
        dt = np.where(kept.n > 1, kept.pair_median(t), np.inf)
        step = np.abs(kept.median(kept.take(speed))) * dt
        with np.errstate(invalid="ignore"):
            span = np.where(step < np.pi / 2, kept.unwrapped_ptp(theta), 0.0)
        return step, span

    return _kept_for((id(speed), id(time_all)) + _mask_key(theta_all, kept, b"sampling"),
                     (theta_all, speed, time_all), compute)


def _angle_sums(theta_all, kept: Segments, theta, runs, start, n, kmax: int) -> list:
    """Per order k = 1 … ``kmax`` and fitted run: (mean cos kθ, mean sin kθ, Σc², Σs², Σcs) of the
    run-centred c = cos kθ − mean, s = sin kθ − mean → [(mc, ms, cc, ss, cs)].  They depend on
    the shaft angles and the mask alone, so they are kept for the masks seen last."""

    def compute():
        out = []
        e1 = np.exp(1j * theta)
        e = e1
        for k in range(1, kmax + 1):
            if k > 1:
                e = e * e1
            C, S = e.real, e.imag
            tot = np.add.reduceat(np.stack([C, S, C * C, S * S, C * S]), start, axis=1)
            mc, ms = tot[0] / n, tot[1] / n
            out.append((mc, ms, tot[2] - n * mc * mc, tot[3] - n * ms * ms, tot[4] - n * mc * ms))
        return out

    return _kept_for(_mask_key(theta_all, kept, runs, np.int64(kmax)), (theta_all,), compute)


def _harmonic_fits_by_run(theta_all, theta, z, kept: Segments, orders):
    """Each shaft order k = 1 … ``orders[r]`` (0: none) fitted alone, with an intercept (a run's offset is
    not angle structure), to run r's kept samples, in every run at once:
    z − z̄ ≈ a (cos kθ − mean) + b (sin kθ − mean), from the 2×2 normal equations of each order (the
    numbers of one least-squares solve per run and order); ``theta``, ``z``: the kept samples in segment
    order, ``theta_all`` the per-sample array they were taken from → [(k, runs, (a, b) per run, Σ fit² per
    run)] for each order fitted in some run."""
    orders = np.asarray(orders, dtype=int)
    kmax = int(orders.max(initial=0))
    if kmax == 0:
        return []
    runs = orders > 0
    sub = runs[kept.run]  # the samples of the runs fitted
    th, zz, run = theta[sub], z[sub], kept.run[sub]
    n = kept.n[runs].astype(float)
    start = np.concatenate([[0], np.cumsum(kept.n[runs])[:-1]])
    seg_runs = np.flatnonzero(runs)
    local = np.full(kept.n_runs, -1)
    local[seg_runs] = np.arange(seg_runs.size)
    row = local[run]
    angle = _angle_sums(theta_all, kept, th, runs, start, n, kmax)
    y = zz - (np.add.reduceat(zz, start) / n)[row]
    e1 = np.exp(1j * th)
    e = e1
    out = []
    for k in range(1, kmax + 1):
        if k > 1:
            e = e * e1
        mc, ms, cc, ss, cs = angle[k - 1]
        ye = y * e  # Σ y (c − mean) = Σ y cos kθ: y sums to 0 in each run
        bc, bs = np.add.reduceat(np.stack([ye.real, ye.imag]), start, axis=1)
        det = cc * ss - cs**2
        good = det > 1e-12 * np.maximum(cc * ss, 1e-300)
        with np.errstate(divide="ignore", invalid="ignore"):
            beta = np.stack([ss * bc - cs * bs, cc * bs - cs * bc], axis=1) / det[:, None]
        for i in np.flatnonzero(~good):  # the angles do not tell cos from sin at this order
            sl = slice(start[i], start[i] + int(n[i]))
            X = np.column_stack([e.real[sl] - mc[i], e.imag[sl] - ms[i]])
            beta[i] = np.linalg.lstsq(X, y[sl], rcond=None)[0]
        explained = beta[:, 0] * bc + beta[:, 1] * bs
        here = orders[seg_runs] >= k
        out.append((k, seg_runs[here], beta[here], explained[here]))
    return out


def _within_runs(c, z, sig, ok, s, kept: Segments, kmax, spec, speed_groups, noise_run) -> list:
    """Shaft-order and time-trend structure within runs, summed over runs (``kept``: the
    channel's inlier samples by run; ``noise_run``: each run's median σ)."""
    theta = kept.take(s.theta)
    t = kept.take(s.time)
    zk = kept.take(z)
    n_runs = kept.n_runs
    sig_run = np.asarray(noise_run)
    out = []
    stat_k = np.zeros(kmax + 1)
    dof_k = np.zeros(kmax + 1, int)
    amp_k: list = [None] * (kmax + 1)  # per order: the ripple's amplitude in each run [SI]
    zamp_k: list = [None] * (kmax + 1)  # the same over the run's noise level
    run_k: list = [None] * (kmax + 1)  # the runs
    long = kept.n >= 30
    inflate = np.ones(n_runs)
    if long.any():
        rho = kept.lag1(zk)
        inflate = (1 + rho) / (1 - rho)
    # shaft orders resolved in a run: at least 6 samples per cycle of order k
    step, span = _sampling(np.asarray(s.theta), kept, t, theta, np.asarray(s.speed), np.asarray(s.time))
    resolved = np.sum(step[:, None] * np.arange(1, kmax + 1)[None, :] <= 2 * np.pi / 6, axis=1)
    harmonic = long & (span >= 2 * np.pi * 0.9) & (resolved > 0)
    for k, runs, beta, explained in _harmonic_fits_by_run(np.asarray(s.theta), theta, zk, kept,
                                                          np.where(harmonic, resolved, 0)):
        size = np.hypot(beta[:, 0], beta[:, 1])
        stat_k[k] = float(np.sum(explained / inflate[runs]))
        dof_k[k] = 2 * runs.size
        amp_k[k], zamp_k[k], run_k[k] = size * sig_run[runs], size, runs
    # time trend within the run
    ptp_t = kept.ptp(t)
    trending = long & (ptp_t > 0)
    stat_t, dof_t, trend = 0.0, 0, []
    if trending.any():
        with np.errstate(invalid="ignore", divide="ignore"):
            u = 2 * (t - kept.extreme(t, False)[kept.run]) / ptp_t[kept.run] - 1
        X = np.column_stack([u, 1.5 * u**2 - 0.5])
        Xc = X - kept.mean(X)[kept.run]
        y = kept.spread(zk)
        S = kept.sum(np.column_stack([Xc[:, 0] ** 2, Xc[:, 1] ** 2, Xc[:, 0] * Xc[:, 1],
                                      Xc[:, 0] * y, Xc[:, 1] * y]))
        for r in np.flatnonzero(trending):
            A = np.array([[S[r, 0], S[r, 2]], [S[r, 2], S[r, 1]]])
            g = S[r, 3:5]
            det = A[0, 0] * A[1, 1] - A[0, 1] ** 2
            if det > 1e-12 * max(A[0, 0] * A[1, 1], 1e-300):
                beta = np.array([A[1, 1] * g[0] - A[0, 1] * g[1], A[0, 0] * g[1] - A[0, 1] * g[0]]) / det
            else:  # the times do not tell the two shapes apart: the least-norm solution
                sl = slice(kept.start[r], kept.start[r] + kept.n[r])
                beta = np.linalg.lstsq(Xc[sl], y[sl], rcond=None)[0]
            stat_t += float(beta @ g) / inflate[r]
            dof_t += 2
            trend.append(beta[0] * sig_run[r])
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
