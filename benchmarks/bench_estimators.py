"""Efficiency and calibration of the estimators (issue 7).

    python benchmarks/run.py --only bench_estimators [--quick]

1. Cramér–Rao bound of every parameter of a standard campaign (the lighter
   ISO 4392-1/-2 protocols of synthetic_data/concealed/protocols, demo truth),
   from the Fisher information of the noise model at the truth
   (:func:`motorid.design.fisher_information`); then N replications (new
   noise each) fitted by least squares: bias, empirical std, bound, ratio, and
   the coverage of the 68 % / 95 % least-squares intervals.
2. Simulation-based calibration (Talts et al. 2018) of the emcee posterior:
   truth drawn from a calibration prior, posterior sampled with that prior,
   rank of the truth among L posterior draws, χ² test of uniform ranks.
"""

from __future__ import annotations

import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
PROTOCOL_DIR = ROOT / "synthetic_data" / "concealed" / "protocols"
TRUTH = ROOT / "synthetic_data" / "demo" / "truth.toml"
MOTOR = ROOT / "synthetic_data" / "demo" / "motor.toml"
INPUTS = ("p_a", "p_b", "p_case", "speed", "viscosity", "acceleration")
IN_COLUMN = {"p_a": "p_a_Pa", "p_b": "p_b_Pa", "p_case": "p_case_Pa", "speed": "speed_rad_s",
             "viscosity": "viscosity_Pa_s"}
OUT_COLUMN = {"torque": "torque_Nm", "q_a": "q_a_m3_s", "q_b": "q_b_m3_s", "q_case": "q_case_m3_s"}
SBC_PRIOR_REL = 0.05  # calibration prior: Normal(truth_demo, 5 % of it), truncated positive
SBC_DRAWS = 99  # L posterior draws per replication → ranks 0..L


def _setup():
    import motorid  # noqa: F401
    from motorid.bench.protocols import load_protocol
    from motorid.bench.truth import load_truth
    from motorid.spec import load_motor_spec

    spec = load_motor_spec(MOTOR)
    truth = load_truth(TRUTH)
    prots = [load_protocol(p) for p in sorted(PROTOCOL_DIR.glob("*.toml"))]
    return spec, truth, prots


def _var(sensor, x):
    x = np.asarray(x, dtype=float)
    return sensor.noise**2 + (sensor.relative_noise * x) ** 2 + sensor.resolution**2 / 12.0


def noise_model_sigma(spec, truth_params, prots, camp, data, unresolved=True):
    """Per-sample σ of each running channel at the truth: the sensor model at the
    true channel value (noise² + (relative·|x|)² + resolution²/12), plus the
    measured inputs' noise carried through the model (σ_in · ∂channel/∂input for
    the port and case pressures, speed, viscosity, and the acceleration the fit
    takes from the noisy speed by a 9-point quadratic derivative).  Also returns
    the true-operating-point Samples."""
    import jax
    import jax.numpy as jnp

    from motorid import model

    sensors = {p.procedure: p.sensors.channels for p in prots}
    rates = {}
    for p in prots:
        for r in p.runs:
            rates[(p.procedure, r.index)] = r.sample_rate
    tf = camp.true_frame.iloc[data.frame_index]
    proc = data.runs["protocol"].to_numpy()[data.run_of_sample]
    s = data.running
    true_s = model.make_samples(spec, tf["theta_rad"].to_numpy(), tf["speed_rad_s"].to_numpy(), tf["p_a_Pa"].to_numpy(),
                                tf["p_b_Pa"].to_numpy(), tf["p_case_Pa"].to_numpy(), tf["viscosity_Pa_s"].to_numpy(),
                                acceleration=tf["acceleration_rad_s2"].to_numpy(), direction=np.asarray(s.direction),
                                temperature=tf["oil_temp_C"].to_numpy(), time=tf["time_s"].to_numpy())
    # sample period of each running sample, from the run's median time step
    dt = np.empty(data.n_running)
    t_all = np.asarray(s.time)
    for r in np.unique(data.run_of_sample):
        sel = data.run_of_sample == r
        dt[sel] = np.median(np.diff(np.sort(t_all[sel]))) if sel.sum() > 1 else 0.01
    params = model.as_jax(truth_params)

    def f(x):
        return model.predict(params, spec, x)

    var = {c: np.zeros(data.n_running) for c in OUT_COLUMN}
    for c, col in OUT_COLUMN.items():
        for pr in np.unique(proc):
            sel = proc == pr
            var[c][sel] = _var(sensors[pr][col], tf[col].to_numpy()[sel])
    for name in INPUTS:
        tangent = true_s._replace(**{k: jnp.zeros_like(getattr(true_s, k)) for k in model.Samples._fields})
        tangent = tangent._replace(**{name: jnp.ones_like(getattr(true_s, name))})
        _, d = jax.jvp(f, (true_s,), (tangent,))
        if name == "acceleration":
            sig2 = np.zeros(data.n_running)
            for pr in np.unique(proc):
                sel = proc == pr
                sig2[sel] = _var(sensors[pr]["speed_rad_s"], tf["speed_rad_s"].to_numpy()[sel])
            sig2 = sig2 / (60.0 * dt**2)  # Σ k² over k = −4..4 is 60: the quadratic's slope
            if unresolved:
                sig2 = sig2 + unresolved_acceleration(camp, data)
        else:
            sig2 = np.zeros(data.n_running)
            for pr in np.unique(proc):
                sel = proc == pr
                sig2[sel] = _var(sensors[pr][IN_COLUMN[name]], tf[IN_COLUMN[name]].to_numpy()[sel])
        for c in OUT_COLUMN:
            var[c] += np.asarray(getattr(d, c)) ** 2 * sig2
    return {c: np.sqrt(v) for c, v in var.items()}, true_s


def unresolved_acceleration(camp, data):
    """Mean square, per run, of the true acceleration the extraction's 9-point
    derivative cannot follow even on noise-free speed (the dynamometer's
    once-per-revolution speed ripple is aliased at 2500 rpm and 50 Hz) [rad²/s⁴],
    per running sample.  Its phase is random from run to run, so for the fit it
    is an input error like noise."""
    from motorid.identify.extract import smoothed_acceleration

    tf = camp.true_frame
    out = np.zeros(data.n_running)
    keys = tf["run_id"].astype(str).to_numpy()
    for r in np.unique(data.run_of_sample):
        sel = np.flatnonzero(data.run_of_sample == r)
        rows = np.flatnonzero(keys == data.runs["run"].iloc[r])
        est = smoothed_acceleration(tf["time_s"].to_numpy()[rows], tf["speed_rad_s"].to_numpy()[rows])
        err = tf["acceleration_rad_s2"].to_numpy()[rows] - est
        pos = np.searchsorted(rows, data.frame_index[sel])
        out[sel] = np.mean(err[pos] ** 2)
    return out


def replicate(seed, spec, truth, prots, keep_dataset=False):
    from motorid import model
    from motorid.bench.simulate import simulate_campaign
    from motorid.identify.extract import extract
    from motorid.identify.least_squares import fit_least_squares

    camp = simulate_campaign(prots, spec, truth, seed=seed)
    data = extract(camp.frame, spec)
    ls = fit_least_squares(data, spec)
    brk = np.asarray(data.held_torque) - np.asarray(
        model.predict_breakaway(model.as_jax(truth.params), spec, data.events))
    out = {"values": ls.values, "std": ls.std, "brk": dict(zip(data.event_runs, brk)), "ls": ls}
    if keep_dataset:
        out.update(camp=camp, data=data)
    return out


def _fmt(x, digits=4):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{x:.{digits}g}"


def efficiency(quick: bool, budget_s: float):
    from scipy import stats

    from motorid import design

    spec, truth, prots = _setup()
    n_rep = 10 if quick else 100
    t0 = time.time()
    reps = []
    first = None
    for i in range(n_rep):
        r = replicate(1000 + i, spec, truth, prots, keep_dataset=(i == 0))
        if i == 0:
            first = dict(r)
        r.pop("ls", None)
        reps.append(r)
        if time.time() - t0 > budget_s and i >= 9:
            break
    t_rep = (time.time() - t0) / len(reps)
    n = len(reps)
    names = list(first["ls"].free)
    truth_p = truth.params
    # breakaway channel: within-event scatter of held − predict_breakaway(truth) over replications
    keys = sorted(set().union(*[r["brk"].keys() for r in reps]))
    by_event = {k: np.array([r["brk"][k] for r in reps if k in r["brk"]]) for k in keys}
    dev = np.concatenate([v - v.mean() for v in by_event.values() if v.size > 1])
    dof = sum(v.size - 1 for v in by_event.values() if v.size > 1)
    sigma_brk = float(math.sqrt(np.sum(dev**2) / max(dof, 1)))
    brk_offset = float(np.mean(np.concatenate(list(by_event.values()))))
    sigma, true_s = noise_model_sigma(spec, truth_p, prots, first["camp"], first["data"])
    sigma["breakaway"] = np.full(first["data"].n_events, sigma_brk)
    data0 = first["data"]
    measured = dict(data0.measured, breakaway=data0.held_torque)
    info = design.fisher_information(truth_p, spec, None, sigma, names=names, running=true_s, events=data0.events,
                                     measured=measured)
    crb, _ = design.cramer_rao(info, names)
    # the same bound with the sensors' noise alone (no unresolved acceleration), for the record
    sig0, _ = noise_model_sigma(spec, truth_p, prots, first["camp"], first["data"], unresolved=False)
    sig0["breakaway"] = sigma["breakaway"]
    crb0, _ = design.cramer_rao(design.fisher_information(truth_p, spec, None, sig0, names=names, running=true_s,
                                                          events=data0.events, measured=measured), names)
    vals = np.array([[r["values"][k] for k in names] for r in reps])
    stds = np.array([[r["std"][k] for k in names] for r in reps])
    tv = np.array([truth_p[k] for k in names])
    bias = vals.mean(axis=0) - tv
    emp = vals.std(axis=0, ddof=1)
    crb_v = np.array([crb[k] for k in names])
    ratio = emp / crb_v
    lo_q, hi_q = stats.chi2.ppf([0.95, 0.05], n - 1)
    r_lo, r_hi = ratio * np.sqrt((n - 1) / lo_q), ratio * np.sqrt((n - 1) / hi_q)
    z = np.abs(vals - tv) / stds
    cov68 = (z <= 1.0).mean(axis=0)
    cov95 = (z <= 1.959964).mean(axis=0)
    ls_std = stds.mean(axis=0)
    rows = []
    for j, k in enumerate(names):
        rows.append(f"| {k} | {_fmt(tv[j])} | {_fmt(bias[j], 2)} | {bias[j] / crb_v[j]:+.2f} | {_fmt(emp[j], 3)} | "
                    f"{_fmt(crb_v[j], 3)} | {_fmt(crb0[k], 3)} | **{ratio[j]:.3f}** ({r_lo[j]:.2f}–{r_hi[j]:.2f}) | {_fmt(ls_std[j], 3)} | "
                    f"{100 * cov68[j]:.0f} % | {100 * cov95[j]:.0f} % |")
    se68 = 100 * math.sqrt(0.6827 * 0.3173 / n)
    se95 = 100 * math.sqrt(0.95 * 0.05 / n)
    pooled68 = 100 * cov68.mean()
    pooled95 = 100 * cov95.mean()
    return dict(names=names, n=n, rows=rows, ratio=ratio, r_lo=r_lo, r_hi=r_hi, cov68=cov68, cov95=cov95,
                pooled68=pooled68, pooled95=pooled95, se68=se68, se95=se95, sigma_brk=sigma_brk,
                brk_offset=brk_offset, n_events=data0.n_events, n_running=data0.n_running, t_rep=t_rep,
                bias_z=bias / (emp / math.sqrt(n)), rows_frame=len(first["camp"].frame),
                noise_fit=first["ls"].noise, sigma_med={c: float(np.median(v)) for c, v in sigma.items()})


def sbc(quick: bool, budget_s: float):
    from scipy import stats

    from motorid.bench.truth import Truth
    from motorid.identify.bayes import sample_posterior

    spec, truth, prots = _setup()
    rng = np.random.default_rng(20180101)
    center = dict(truth.params)
    prior = {k: (v, SBC_PRIOR_REL * abs(v)) for k, v in center.items()}
    max_rep = 5 if quick else 400
    ranks, names, t0, conv, secs, sig_brk = [], None, time.time(), 0, [], []
    while len(ranks) < max_rep and (time.time() - t0 < budget_s or len(ranks) < 5):
        draw = {}
        for k, (m, s) in prior.items():
            while True:  # truncated to the positive side for positive parameters
                x = rng.normal(m, s)
                if x > 0 or k.startswith("KL_"):
                    break
            draw[k] = float(x)
        t = Truth(params=draw, mechanisms=(), source="sbc draw")
        r = replicate(int(rng.integers(1 << 30)), spec, t, prots)
        ls = r["ls"]
        sig_brk.append(ls.noise.get("breakaway") or np.nan)
        if names is None:
            names = list(ls.free)
        ts = time.time()
        post = sample_posterior(ls, spec, seed=int(rng.integers(1 << 30)), progress=False, max_seconds=60,
                                prior={k: prior[k] for k in ls.free})
        secs.append(time.time() - ts)
        conv += bool(post.converged)
        s = post.samples()
        pick = s[np.linspace(0, len(s) - 1, SBC_DRAWS).astype(int)]
        ranks.append([int(np.sum(pick[:, post.names.index(k)] < draw[k])) for k in names])
    ranks = np.array(ranks)
    n = len(ranks)
    bins = 5 if n < 60 else 10
    edges = np.linspace(0, SBC_DRAWS + 1, bins + 1)
    rows, pvals = [], []
    for j, k in enumerate(names):
        h, _ = np.histogram(ranks[:, j], bins=edges)
        chi = stats.chisquare(h)
        pvals.append(float(chi.pvalue))
        rows.append(f"| {k} | {' '.join(f'{c:>2d}' for c in h)} | {chi.statistic:.1f} | {chi.pvalue:.2f} |")
    # do the outer ranks (truth outside the central 90 % of the posterior) go with a small fitted breakaway σ?
    sig_brk = np.array(sig_brk)
    low = sig_brk < np.nanmedian(sig_brk)
    outer = (ranks < 0.05 * (SBC_DRAWS + 1)) | (ranks >= 0.95 * (SBC_DRAWS + 1))
    split = {k: (float(outer[low, j].mean()), float(outer[~low, j].mean())) for j, k in enumerate(names)}
    spread = float(np.nanstd(sig_brk) / np.nanmean(sig_brk))
    shape = {}
    for j, k in enumerate(names):
        u = ranks[:, j] / (SBC_DRAWS + 1)
        shape[k] = (float(u.mean()), float(outer[:, j].mean()))
    return dict(names=names, n=n, bins=bins, rows=rows, pvals=np.array(pvals), conv=conv, split=split, shape=shape,
                brk_spread=spread, brk_range=(float(np.nanmin(sig_brk)), float(np.nanmax(sig_brk))),
                sec_post=float(np.mean(secs)), sec_total=time.time() - t0)


def run(quick: bool = False) -> str:
    t_start = time.time()
    eff = efficiency(quick, budget_s=60 if quick else 900)
    cal = sbc(quick, budget_s=40 if quick else 300)
    n = eff["n"]
    worst = int(np.argmax(eff["ratio"]))
    met_eff = bool(np.all(eff["ratio"] <= 1.1))
    met_eff_ci = bool(np.all(eff["r_lo"] <= 1.1))
    dev68 = np.abs(100 * eff["cov68"] - 68.27)
    dev95 = np.abs(100 * eff["cov95"] - 95.0)
    met_cov = bool(np.all(dev68 <= 3) and np.all(dev95 <= 3))
    met_pool = abs(eff["pooled68"] - 68.27) <= 3 and abs(eff["pooled95"] - 95) <= 3
    # Bonferroni over the parameters for the uniformity verdict
    p_min = float(cal["pvals"].min())
    met_sbc = p_min > 0.05 / len(cal["names"])
    cmd = "python benchmarks/run.py --only bench_estimators" + (" --quick" if quick else "")
    L = [
        "## Efficiency and calibration of the estimators",
        "",
        f"Command: `{cmd}` (part of `make bench`).  Machine: see the header; "
        f"{os.cpu_count()} cores, Python {platform.python_version()}.  Study time {time.time() - t_start:.0f} s.",
        "",
        "**Campaign.** The lighter ISO 4392-1 constant-speed and constant-pressure and ISO 4392-2 startability "
        "protocols of `synthetic_data/concealed/protocols/` (their default sensors), the demo motor and truth "
        f"(`synthetic_data/demo/`): {eff['rows_frame']:,} log rows, {eff['n_running']:,} steady running samples "
        f"and {eff['n_events']} breakaway events per campaign.  Each replication is `simulate_campaign(seed=1000+i)` "
        f"→ `extract` → `fit_least_squares`, {eff['t_rep']:.1f} s each.",
        "",
        "**Cramér–Rao bound.** `motorid.design.fisher_information` at the true parameters and the true operating "
        "points (rows of the simulator's `true_frame`), I = Σ J Jᵀ/σ² with J from JAX (forward mode through "
        "`model.predict` / `model.predict_breakaway`).  The σ of each running sample is the sensors' noise "
        "model at the true reading, σ² = noise² + (relative_noise·|x|)² + resolution²/12, plus the noise of the "
        "measured inputs the fit conditions on (port and case pressures, speed, viscosity, and the acceleration "
        "the extraction derives from the noisy speed), carried through the model's derivatives (shaft-angle "
        "quantization, 0.01°, is left out).  The acceleration's error also holds the part of the true "
        "acceleration that a 9-point derivative of even noise-free speed cannot follow: the dynamometer's "
        "once-per-revolution speed ripple, aliased at 2500 rpm and 50 Hz, puts J·α ≈ 0.25 N·m rms into the "
        "torque of the fastest runs, 2-3 times the torque sensor's noise; its phase is random from run to run, "
        "so it enters as input noise (per run, its mean square on the noise-free trajectory).  Without this term "
        "the bound on K_v would be about half as large, and no estimator that takes the acceleration from the "
        "logged speed could reach it.  The held breakaway torque is not a sensor reading but an extracted "
        "quantity (its error comes from locating the onset on a pressure ramp), so its σ is measured: the "
        f"pooled within-event standard deviation of held − predict_breakaway(truth) over the replications, "
        f"σ_brk = {eff['sigma_brk']:.4g} N·m (mean offset {eff['brk_offset']:+.3g} N·m).",
        "",
        f"### Least squares over {n} replications",
        "",
        "| parameter | truth | mean bias | bias/CRB | empirical std | CRB std | CRB std, sensors alone | "
        "ratio std/CRB (90 % CI) | mean LS std | 68 % cover | 95 % cover |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
        *eff["rows"],
        "",
        f"Coverage pooled over parameters: 68 % intervals {eff['pooled68']:.1f} %, 95 % intervals "
        f"{eff['pooled95']:.1f} % (binomial standard error per parameter at {n} replications: "
        f"±{eff['se68']:.1f} and ±{eff['se95']:.1f} points).",
        "",
        f"- Goal *ratio ≤ 1.1 for every parameter*: **{'met' if met_eff else 'not met'}** (largest ratio "
        f"{eff['ratio'][worst]:.3f}, {eff['names'][worst]}; "
        + ("every 90 % interval of the ratio reaches below 1.1)." if met_eff_ci else
           "some 90 % intervals of the ratio lie wholly above 1.1).")
        + f"  An empirical std from {n} replications is itself uncertain by about ±{100 / math.sqrt(2 * (n - 1)):.0f} % "
        "(1σ), hence the interval.",
        f"- Goal *coverage within ±3 points of nominal*: per parameter **{'met' if met_cov else 'not met'}** "
        f"(68 %: {', '.join(f'{100 * c:.0f}' for c in eff['cov68'])}; 95 %: "
        f"{', '.join(f'{100 * c:.0f}' for c in eff['cov95'])}); pooled **{'met' if met_pool else 'not met'}**.  "
        f"At {n} replications one parameter's coverage has a sampling error of ±{eff['se68']:.1f} points (68 %), "
        "so ±3 points per parameter is a bound a perfectly calibrated estimator misses now and then; the pooled "
        "figure is the sharper test.",
        "",
        "### Simulation-based calibration of the posterior (emcee)",
        "",
        f"Truth drawn from a calibration prior, independent Normal(demo value, {100 * SBC_PRIOR_REL:.0f} % of it) "
        "(positive parameters truncated at 0); campaign simulated and fitted as above; posterior sampled by "
        "`sample_posterior(..., prior=…)` with that same prior (the optional calibration-prior argument); "
        f"rank of the truth among L = {SBC_DRAWS} evenly spaced draws of the thinned chain (Talts et al. 2018).  "
        f"{cal['n']} replications in {cal['sec_total']:.0f} s ({cal['sec_post']:.1f} s of sampling each), "
        f"{cal['conv']} of them converged by the sampler's 50 τ rule.  Counts of ranks in {cal['bins']} equal bins "
        "and a χ² test of uniformity per parameter:",
        "",
        "| parameter | rank histogram | χ² | p |",
        "|---|---|---|---|",
        *cal["rows"],
        "",
        f"- Goal *uniform ranks*: **{'met' if met_sbc else 'not met'}** (smallest p = {p_min:.3f}; "
        f"threshold 0.05/{len(cal['names'])} with a Bonferroni correction over the parameters).  "
        f"With {cal['n']} replications a χ² test over {cal['bins']} bins sees a posterior width off by a few tens of %.",
        "",
        "Share of ranks in the outer 10 % (nominal 10 %), replications split at the median of the breakaway σ "
        f"the fit estimated (it ranged {cal['brk_range'][0]:.3f}-{cal['brk_range'][1]:.3f} N·m, relative spread "
        f"{100 * cal['brk_spread']:.0f} %): "
        + "; ".join(f"{k} {100 * a:.0f} % / {100 * b:.0f} %" for k, (a, b) in cal["split"].items())
        + " (small σ_brk / large σ_brk).",
        "",
    ]
    below = [k for k, hi in zip(eff["names"], eff["r_hi"]) if hi < 1.0]
    above = [k for k, lo in zip(eff["names"], eff["r_lo"]) if lo > 1.1]
    if met_eff:
        verdict = "within 1.1."
    elif not above and eff["r_lo"][worst] <= 1.0:
        verdict = (f"above 1.1, but its 90 % interval ({eff['r_lo'][worst]:.2f}–{eff['r_hi'][worst]:.2f}) holds 1.0: "
                   "no parameter's spread is shown to exceed the bound, yet the strict reading of the goal is not "
                   "met by this sample of replications.")
    else:
        verdict = (f"above 1.1; the 90 % intervals of {', '.join(above) or eff['names'][worst]} lie above 1.1: "
                   "for them the estimator is measurably less efficient than the bound.")
    over = [k for k, c in zip(eff["names"], eff["cov68"]) if 100 * c > 68.27 + 2 * eff["se68"]]
    under = [k for k, c in zip(eff["names"], eff["cov68"]) if 100 * c < 68.27 - 2 * eff["se68"]]
    kfs, ks = cal["split"].get("KFS", (0, 0)), cal["split"].get("Ks", (0, 0))
    others = []
    for k, p in zip(cal["names"], cal["pvals"]):
        if p >= 0.05 or k in ("KFS", "Ks"):
            continue
        mean, out = cal["shape"][k]
        if out < 0.06:
            what = f"a hump (outer 10 % holds {100 * out:.0f} %): the posterior is too wide"
        elif out > 0.14:
            what = f"U-shaped (outer 10 % holds {100 * out:.0f} %): the posterior is too narrow"
        else:
            what = "no clear width error"
        if abs(mean - 0.5) > 0.03:
            what += (f", and skewed (mean rank {mean:.2f} of 1): the estimate sits "
                     + ("below" if mean > 0.5 else "above") + " the truth more often than not")
        others.append(f"{k}, {what}")
    confirmed = kfs[0] > kfs[1] and ks[0] > ks[1]
    L += [
        "**Reading the results.**",
        "",
        f"- Efficiency: the largest ratio is {eff['ratio'][worst]:.3f} ({eff['names'][worst]}), {verdict}"
        + (f"  Ratios wholly below 1 ({', '.join(below)}) do not beat the bound: they show that the noise model "
           "used for the bound is conservative for them.  K_v is set by the fastest runs, whose extra torque error "
           "(the aliased once-per-revolution acceleration) is a slow sinusoid within a run, not white noise, and "
           "averages out of a run's mean torque better than white noise of the same size; the bound with the "
           "sensors alone (column 7) is a floor that no estimator taking the acceleration from the logged speed "
           "can reach, and the estimator sits between the two.  K_s and K_FS rest on the breakaway events, whose "
           "σ (the pooled within-event scatter) treats the onset-location error as independent white noise on "
           "the held torque; part of that error moves the extracted onset pressure and angle together with the "
           "held torque, and the model absorbs it." if below else ""),
        f"- Least-squares intervals: pooled coverage {eff['pooled68']:.1f} % / {eff['pooled95']:.1f} % is "
        + ("within" if met_pool else "outside") + " 3 points of nominal."
        + (f"  Over-covering by more than two binomial standard errors: {', '.join(over)} (the fit's σ includes "
           "errors that are not white, as above)." if over else "")
        + (f"  Under-covering by more than two binomial standard errors: {', '.join(under)}." if under else ""),
        "- Posterior calibration: the fit estimates the breakaway σ from only ~30 breakaway residuals (the RMS "
        "with K_FS and K_s taken out of the degrees of freedom, ≈ ±13 % from campaign to campaign; a MAD, used "
        "before, scattered ≈ ±20 %), and the least-squares covariance and the posterior take it as known.  When "
        "it comes out low, the intervals of K_FS and K_s are too narrow and their ranks pile up at the ends "
        "(U-shaped histograms).  "
        + (f"The split above bears this out: K_FS {100 * kfs[0]:.0f} % vs {100 * kfs[1]:.0f} %, K_s "
           f"{100 * ks[0]:.0f} % vs {100 * ks[1]:.0f} % outer ranks with small vs large fitted σ_brk.  "
           if confirmed else "The split above does not show it clearly in this run.  ")
        + "Still to do in the fit: carry σ_brk's uncertainty (Student-t intervals with n − p degrees of "
        "freedom, or σ_brk sampled in the posterior), and find the small positive bias of K_s's rank (the "
        "held torque's mean offset from the model at the truth, +0.001 N·m, points at the onset location)."
        + (("  Other parameters whose ranks are not uniform (p < 0.05): " + "; ".join(others) + ".") if others
           else ""),
        "",
    ]
    return "\n".join(L)


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
