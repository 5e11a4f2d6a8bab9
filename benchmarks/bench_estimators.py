"""Efficiency and calibration of the estimators (issue 7).

    python benchmarks/run.py --only bench_estimators [--quick]

1. Cramér–Rao bound of every parameter of a standard campaign (the lighter
   ISO 4392-1/-2 protocols of synthetic_data/concealed/protocols, demo truth),
   from the Fisher information of the noise model at the truth
   (:func:`motorid.experiment_design.fisher_information`); then N replications (new
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
N_REP = 400  # least-squares replications (±2.3 points binomial error on a 68 % coverage)
N_DIAG = 40  # of them also refitted for the diagnosis (true viscosity; readings as read; shaft order 1)


def _setup():
    import motorid  # noqa: F401
    from motorid.bench.protocols import load_protocol
    from motorid.bench.truth import load_truth
    from motorid.io.spec import load_motor_spec

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
    the port and case pressures, speed, the acceleration the fit takes from the
    noisy speed by a 9-point quadratic derivative, and the viscosity in runs
    whose readings the extraction uses as read; where it smooths them the
    viscosity is a nuisance curve per run, :func:`viscosity_nuisance_bound`).
    Also returns the true-operating-point Samples."""
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
            if name == "viscosity":
                sig2 = np.where(_smoothed_runs(data)[data.run_of_sample], 0.0, sig2)
        for c in OUT_COLUMN:
            var[c] += np.asarray(getattr(d, c)) ** 2 * sig2
    return {c: np.sqrt(v) for c, v in var.items()}, true_s


def _smoothed_runs(data):
    """Which runs' viscosity the extraction replaced by a curve in time."""
    return data.runs["viscosity_degree"].to_numpy() >= 0


def viscosity_nuisance_bound(spec, truth_params, names, prots, camp, data, sigma, true_s, info):
    """Cramér–Rao bound with each smoothed run's viscosity a nuisance curve.

    Where the extraction smooths a run's viscometer readings, the bound's model
    is: the run's true viscosity is a Chebyshev polynomial in time of the degree
    the extraction chose (coefficients c_r unknown), the viscometer reads it with
    its noise model, and the running channels see it through the model.  Joint
    Fisher information of (β, c): I_ββ = ``info`` (outputs), I_βc = Σ J (g X)ᵀ/σ²,
    I_cc = Σ (g X)(g X)ᵀ/σ² + Xᵀ X/σ_μ², with J = ∂channel/∂β and g =
    ∂channel/∂μ per sample and X the run's basis; the bound on β is the Schur
    complement's inverse.  Returns (crb dict, Fisher matrix of β)."""
    import jax
    import jax.numpy as jnp

    from motorid import experiment_design as design, model
    from motorid.identify.types import VISCOSITY_MODES

    smoothed = _smoothed_runs(data)
    if not smoothed.any() or data.viscosity_error is None:
        return design.cramer_rao(info, names)[0], info
    sensors = {p.procedure: p.sensors.channels for p in prots}
    proc = data.runs["protocol"].to_numpy()[data.run_of_sample]
    tf = camp.true_frame.iloc[data.frame_index]
    held = {k: v for k, v in truth_params.items() if k not in names}
    values = {k: jnp.asarray(float(truth_params[k])) for k in names}

    def f(v, mu):
        out = model.predict(model.as_jax({**held, **v}), spec, true_s._replace(viscosity=mu))
        return {c: getattr(out, c) for c in OUT_COLUMN}

    mu0 = jnp.asarray(true_s.viscosity)
    J = jax.jacfwd(f, argnums=0)(values, mu0)
    _, g = jax.jvp(lambda m: f(values, m), (mu0,), (jnp.ones_like(mu0),))
    ve = data.viscosity_error
    r_of = data.run_of_sample
    u = (np.asarray(true_s.time) - ve.center[r_of]) / ve.half_span[r_of]
    degree = data.runs["viscosity_degree"].to_numpy()
    basis = np.polynomial.chebyshev.chebvander(u, VISCOSITY_MODES - 1)
    runs = np.flatnonzero(smoothed)
    cols = [(r, k) for r in runs for k in range(int(degree[r]) + 1)]
    p, q = len(names), len(cols)
    I_bc, I_cc = np.zeros((p, q)), np.zeros((q, q))
    col_of = {rk: i for i, rk in enumerate(cols)}
    sig_mu2 = np.zeros(data.n_running)
    for pr in np.unique(proc):
        sel = proc == pr
        sig_mu2[sel] = _var(sensors[pr]["viscosity_Pa_s"], tf["viscosity_Pa_s"].to_numpy()[sel])
    for r in runs:
        sel = np.flatnonzero(r_of == r)
        d = int(degree[r]) + 1
        X = basis[sel, :d]
        idx = [col_of[(r, k)] for k in range(d)]
        block = X.T @ (X / sig_mu2[sel, None])  # the viscometer's readings
        for c in OUT_COLUMN:
            m = data.measured[c][sel]
            w = np.where(np.isfinite(m), 1.0 / np.asarray(sigma[c])[sel] ** 2, 0.0)
            gc = np.asarray(g[c])[sel]
            GX = X * gc[:, None]
            Jc = np.stack([np.asarray(J[c][k])[sel] for k in names], axis=1)
            I_bc[:, idx] += Jc.T @ (GX * w[:, None])
            block += GX.T @ (GX * w[:, None])
        I_cc[np.ix_(idx, idx)] = block
    schur = info - I_bc @ np.linalg.solve(I_cc, I_bc.T)
    schur = 0.5 * (schur + schur.T)
    return design.cramer_rao(schur, names)[0], schur


def unresolved_acceleration(camp, data):
    """Mean square, per run, of the true acceleration that the extraction's own
    estimate (``acceleration.running_acceleration``: the shaft-locked speed ripple
    resolved in θ, the rest by a 9-point derivative) misses even on noise-free
    speed [rad²/s⁴], per running sample.  Its phase is random from run to run,
    so for the fit it is an input error like noise."""
    from motorid.identify.acceleration import running_acceleration

    tf = camp.true_frame
    out = np.zeros(data.n_running)
    keys = tf["run_id"].astype(str).to_numpy()
    for r in np.unique(data.run_of_sample):
        sel = np.flatnonzero(data.run_of_sample == r)
        rows = np.flatnonzero(keys == data.runs["run"].iloc[r])
        pos = np.searchsorted(rows, data.frame_index[sel])
        steady = np.zeros(rows.size, bool)
        steady[pos] = True
        est = running_acceleration(tf["time_s"].to_numpy()[rows], tf["speed_rad_s"].to_numpy()[rows],
                                   np.mod(tf["theta_rad"].to_numpy()[rows], 2 * np.pi), steady)
        err = tf["acceleration_rad_s2"].to_numpy()[rows] - est
        out[sel] = np.mean(err[pos] ** 2)
    return out


def mirror_pairs(data):
    """Breakaway events of the two directions at the same shaft angle (within 3°)
    and the same |P_A − P_B| (within 15 %): [(key of the + event, key of the − one)]."""
    ev = data.events
    th = np.asarray(ev.theta)
    dp = np.asarray(ev.p_a - ev.p_b)
    d = np.asarray(ev.direction)
    keys = list(data.event_runs)
    used, out = set(), []
    for i in np.flatnonzero(d > 0):
        for j in np.flatnonzero(d < 0):
            if j in used:
                continue
            dth = abs(math.degrees(math.remainder(float(th[i] - th[j]), 2 * math.pi)))
            if dth < 3.0 and abs(abs(dp[j]) - abs(dp[i])) < 0.15 * abs(dp[i]):
                used.add(j)
                out.append((keys[i], keys[j]))
                break
    return out


def replicate(seed, spec, truth, prots, keep_dataset=False, diagnose=False):
    import dataclasses

    from motorid import model
    from motorid.bench.simulate import simulate_campaign
    from motorid.identify.extract import ExtractSettings, extract
    from motorid.identify.least_squares import fit_least_squares
    from motorid.identify.results import interval_dof

    camp = simulate_campaign(prots, spec, truth, seed=seed)
    data = extract(camp.frame, spec)
    ls = fit_least_squares(data, spec)
    brk = np.asarray(data.held_torque) - np.asarray(
        model.predict_breakaway(model.as_jax(truth.params), spec, data.events))
    out = {"values": ls.values, "std": ls.std, "dof": interval_dof(ls), "brk": dict(zip(data.event_runs, brk)),
           "pairs": mirror_pairs(data), "ls": ls,
           "brk_design": dict(zip(data.event_runs, zip(np.asarray(data.events.p_a + data.events.p_b).tolist(),
                                                       np.asarray(data.events.direction).tolist())))}
    if diagnose:
        # the same logs (1) fitted with the true viscosity as the input (no viscometer error at
        # all), (2) extracted with the viscometer's readings used as read (no smoothing), (3)
        # extracted with only the first shaft order of the speed ripple resolved
        tf = camp.true_frame.iloc[data.frame_index]
        d1 = dataclasses.replace(data, running=data.running._replace(viscosity=tf["viscosity_Pa_s"].to_numpy()),
                                 viscosity_error=None)
        d2 = extract(camp.frame, spec, ExtractSettings(smooth_viscosity=False))
        d3 = extract(camp.frame, spec, ExtractSettings(shaft_orders=(1,)))
        out["diag"] = {}
        for key, d in (("true_viscosity", d1), ("viscosity_as_read", d2), ("shaft_order_1", d3)):
            f = fit_least_squares(d, spec)
            out["diag"][key] = ({k: f.values[k] for k in ls.free}, {k: f.std[k] for k in ls.free})
    if keep_dataset:
        out.update(camp=camp, data=data)
    return out


def efficiency_task(job: dict) -> dict:
    """One efficiency replication (a task for motorid.fleet.map_tasks): ``replicate`` at
    ``job["seed"]``, returned without its fit object (small and picklable)."""
    spec, truth, prots = _setup()
    r = replicate(job["seed"], spec, truth, prots, diagnose=job["diagnose"])
    r.pop("ls", None)
    return r


def sbc_task(job: dict) -> dict:
    """One SBC replication (a task for motorid.fleet.map_tasks): simulate at the prior draw
    ``job["draw"]``, fit, sample the posterior; returns the ranks of the draw among SBC_DRAWS
    thinned posterior samples and the few numbers the study tabulates (no fit objects)."""
    from motorid.bench.truth import Truth
    from motorid.identify.bayes import sample_posterior

    spec, _, prots = _setup()
    draw, prior = job["draw"], job["prior"]
    r = replicate(job["seed"], spec, Truth(params=draw, mechanisms=(), source="sbc draw"), prots)
    ls = r["ls"]
    ts = time.time()
    post = sample_posterior(ls, spec, seed=job["post_seed"], progress=False, max_seconds=60,
                            prior={k: prior[k] for k in ls.free})
    sec = time.time() - ts
    s = post.samples()
    pick = s[np.linspace(0, len(s) - 1, SBC_DRAWS).astype(int)]
    return {"brk": r["brk"], "pairs": r["pairs"], "brk_design": r["brk_design"],
            "sigma_brk": ls.noise.get("breakaway"), "free": list(ls.free),
            "z": [(ls.values[k] - draw[k]) / ls.std[k] for k in ("KFS", "Ks")],
            "sec_post": sec, "breakaway_noise": post.breakaway_noise, "converged": bool(post.converged),
            "ranks": {k: int(np.sum(pick[:, post.names.index(k)] < draw[k])) for k in ls.free}}


SCHEDULER_ENV = "MOTORID_BENCH_SCHEDULER"


def _bench_client():
    """A Dask client for the replications, kept open for a whole study: of the cluster at
    ``$MOTORID_BENCH_SCHEDULER`` when set, else of an embedded LocalCluster (one process per core)."""
    from motorid.fleet.tasks import dask_client

    return dask_client(os.environ.get(SCHEDULER_ENV) or None)


def _map(client, func, jobs: list, desc: str) -> list:
    """``[func(j) for j in jobs]`` as tasks on ``client``; a failed task stops the study with
    its one-line error."""
    from motorid.fleet import map_tasks

    out = map_tasks(func, jobs, client=client, desc=desc)
    for job, r in zip(jobs, out):
        if not isinstance(r, dict):
            raise RuntimeError(f"{desc}: task with seed {job['seed']} failed: {r}")
    return out


def _fmt(x, digits=4):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{x:.{digits}g}"


def efficiency(quick: bool, budget_s: float):
    from scipy import stats

    from motorid import experiment_design as design

    spec, truth, prots = _setup()
    n_rep = 10 if quick else N_REP
    n_diag = 5 if quick else N_DIAG
    t0 = time.time()
    # replication 0 runs here (its fit, campaign and dataset feed the tables below); the rest run
    # as tasks on Dask (motorid.fleet.map_tasks), in batches so that the time budget keeps its
    # meaning: stop once the budget is spent and at least 10 replications are done
    first = replicate(1000, spec, truth, prots, keep_dataset=True, diagnose=(0 < n_diag))
    reps = [{k: v for k, v in first.items() if k != "ls"}]
    with _bench_client() as client:
        batch = max(1, sum(client.nthreads().values()))
        i = 1
        while i < n_rep and (time.time() - t0 <= budget_s or len(reps) < 10):
            jobs = [{"seed": 1000 + j, "diagnose": j < n_diag} for j in range(i, min(n_rep, i + batch))]
            reps += _map(client, efficiency_task, jobs, "efficiency replications")
            i += len(jobs)
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
    # mirrored events (same angle and load, opposite directions): correlation of their
    # deviations from their own means over the replications, and of their means (frozen part)
    pairs = first["pairs"]
    dev_pairs = [(r["brk"][a] - by_event[a].mean(), r["brk"][b] - by_event[b].mean())
                 for r in reps for a, b in pairs if a in r["brk"] and b in r["brk"]]
    rho_fixed = float(np.corrcoef(np.array(dev_pairs).T)[0, 1]) if len(dev_pairs) > 3 else math.nan
    means = np.array([(by_event[a].mean(), by_event[b].mean()) for a, b in pairs if a in by_event and b in by_event])
    frozen = float(np.sqrt(np.mean(means**2))) if means.size else math.nan
    sigma, true_s = noise_model_sigma(spec, truth_p, prots, first["camp"], first["data"])
    data0 = first["data"]
    # each event's own σ: the held torque compares with pressures read at the onset, whose error
    # grows with the reading, so the scatter grows with the port pressures; a variance
    # a + b·(P_A² + P_B²) fitted to the per-event variances over the replications (unweighted:
    # weights from the noisy variances themselves would pull the fit low)
    ev_keys = list(data0.event_runs)
    ev_var = np.array([by_event[k].var(ddof=1) for k in ev_keys])
    ev_x2 = np.asarray(data0.events.p_a) ** 2 + np.asarray(data0.events.p_b) ** 2
    A = np.c_[np.ones_like(ev_x2), ev_x2 / np.median(ev_x2)]
    coef = np.linalg.lstsq(A, ev_var, rcond=None)[0]
    brk_model = np.sqrt(np.clip(A @ coef, 1e-12, None))
    sigma["breakaway"] = brk_model
    measured = dict(data0.measured, breakaway=data0.held_torque)
    info = design.fisher_information(truth_p, spec, None, sigma, names=names, running=true_s, events=data0.events,
                                     measured=measured)
    crb, _ = viscosity_nuisance_bound(spec, truth_p, names, prots, first["camp"], data0, sigma, true_s, info)
    # the same bound with the sensors' noise alone (no unresolved acceleration), for the record
    sig0, _ = noise_model_sigma(spec, truth_p, prots, first["camp"], first["data"], unresolved=False)
    sig0["breakaway"] = sigma["breakaway"]
    sig1 = dict(sigma, breakaway=np.full(data0.n_events, sigma_brk))
    crb_pooled, _ = viscosity_nuisance_bound(spec, truth_p, names, prots, first["camp"], data0, sig1, true_s,
                                             design.fisher_information(truth_p, spec, None, sig1, names=names,
                                                                       running=true_s, events=data0.events,
                                                                       measured=dict(data0.measured,
                                                                                     breakaway=data0.held_torque)))
    info0 = design.fisher_information(truth_p, spec, None, sig0, names=names, running=true_s, events=data0.events,
                                      measured=measured)
    crb0, _ = viscosity_nuisance_bound(spec, truth_p, names, prots, first["camp"], data0, sig0, true_s, info0)
    vals = np.array([[r["values"][k] for k in names] for r in reps])
    stds = np.array([[r["std"][k] for k in names] for r in reps])
    tv = np.array([truth_p[k] for k in names])
    bias = vals.mean(axis=0) - tv
    emp = vals.std(axis=0, ddof=1)
    crb_v = np.array([crb[k] for k in names])
    ratio = emp / crb_v
    lo_q, hi_q = stats.chi2.ppf([0.95, 0.05], n - 1)
    r_lo, r_hi = ratio * np.sqrt((n - 1) / lo_q), ratio * np.sqrt((n - 1) / hi_q)
    from motorid.identify.results import interval_factor

    # intervals as result.json gives them: Student-t with the effective dof of each standard error
    dofs = np.array([[r["dof"].get(k, math.inf) for k in names] for r in reps])
    f68 = np.vectorize(lambda d: interval_factor(d, 0.6827))(dofs)
    f95 = np.vectorize(lambda d: interval_factor(d, 0.95))(dofs)
    z = np.abs(vals - tv) / stds
    cov68 = (z <= f68).mean(axis=0)
    cov95 = (z <= f95).mean(axis=0)
    cov68_normal = (z <= 1.0).mean(axis=0)
    cov95_normal = (z <= 1.959964).mean(axis=0)
    ls_std = stds.mean(axis=0)
    nu = np.median(dofs, axis=0)
    rows = []
    for j, k in enumerate(names):
        rows.append(f"| {k} | {_fmt(tv[j])} | {_fmt(bias[j], 2)} | {bias[j] / crb_v[j]:+.2f} | {_fmt(emp[j], 3)} | "
                    f"{_fmt(crb_v[j], 3)} | {_fmt(crb0[k], 3)} | **{ratio[j]:.3f}** ({r_lo[j]:.2f}–{r_hi[j]:.2f}) | {_fmt(ls_std[j], 3)} | "
                    f"{'∞' if not math.isfinite(nu[j]) else f'{nu[j]:.0f}'} | "
                    f"{100 * cov68[j]:.1f} % | {100 * cov95[j]:.1f} % |")
    # diagnosis: the first replications refitted with true viscosity / shaft-resolved acceleration
    diag = {}
    dreps = [r for r in reps if "diag" in r]
    for key in ("true_viscosity", "viscosity_as_read", "shaft_order_1"):
        if not dreps:
            break
        dv = np.array([[r["diag"][key][0][k] for k in names] for r in dreps])
        ds = np.array([[r["diag"][key][1][k] for k in names] for r in dreps])
        bv = np.array([[r["values"][k] for k in names] for r in dreps])
        bs = np.array([[r["std"][k] for k in names] for r in dreps])
        diag[key] = {k: dict(base_bias=float(bv[:, j].mean() - tv[j]), base_emp=float(bv[:, j].std(ddof=1)),
                             base_ls=float(bs[:, j].mean()), bias=float(dv[:, j].mean() - tv[j]),
                             emp=float(dv[:, j].std(ddof=1)), ls=float(ds[:, j].mean()))
                     for j, k in enumerate(names)}
    se68 = 100 * math.sqrt(0.6827 * 0.3173 / n)
    se95 = 100 * math.sqrt(0.95 * 0.05 / n)
    pooled68 = 100 * cov68.mean()
    pooled95 = 100 * cov95.mean()
    return dict(names=names, n=n, rows=rows, ratio=ratio, r_lo=r_lo, r_hi=r_hi, cov68=cov68, cov95=cov95,
                cov68_normal=cov68_normal, cov95_normal=cov95_normal, nu=nu, diag=diag, n_diag=len(dreps),
                bias_crb=bias / crb_v, emp=emp, crb=crb_v, ls_std=ls_std,
                pooled68=pooled68, pooled95=pooled95, se68=se68, se95=se95, sigma_brk=sigma_brk,
                brk_sigma_range=(float(brk_model.min()), float(brk_model.max())),
                brk_psum_range=(float(np.min(np.asarray(data0.events.p_a + data0.events.p_b))),
                                float(np.max(np.asarray(data0.events.p_a + data0.events.p_b)))),
                crb_pooled={k: crb_pooled[k] for k in ("KFS", "Ks") if k in crb_pooled},
                brk_offset=brk_offset, n_events=data0.n_events, rho_fixed=rho_fixed, frozen=frozen,
                n_pairs=len(pairs), zstd_fixed={k: float(np.std((vals[:, j] - tv[j]) / stds[:, j]))
                                                for j, k in enumerate(names) if k in ("KFS", "Ks")}, n_running=data0.n_running, t_rep=t_rep,
                bias_z=bias / (emp / math.sqrt(n)), rows_frame=len(first["camp"].frame),
                noise_fit=first["ls"].noise, sigma_med={c: float(np.median(v)) for c, v in sigma.items()})


def sbc(quick: bool, budget_s: float):
    from scipy import stats

    spec, truth, prots = _setup()
    rng = np.random.default_rng(20180101)
    center = dict(truth.params)
    prior = {k: (v, SBC_PRIOR_REL * abs(v)) for k, v in center.items()}
    max_rep = 5 if quick else 600
    ranks, names, t0, conv, secs, sig_brk, brk_mode = [], None, time.time(), 0, [], [], set()
    pair_res, zs, res_rows, design, pairs0 = [], [], [], None, None
    # the draws and seeds come from rng in the same order as the one-at-a-time loop did; the
    # replications run as tasks on Dask in batches, until the budget is spent (at least 5)
    jobs = []
    for _ in range(max_rep):
        draw = {}
        for k, (m, s) in prior.items():
            while True:  # truncated to the positive side for positive parameters
                x = rng.normal(m, s)
                if x > 0 or k.startswith("KL_"):
                    break
            draw[k] = float(x)
        rep_seed = int(rng.integers(1 << 30))
        jobs.append({"draw": draw, "seed": rep_seed, "post_seed": int(rng.integers(1 << 30)), "prior": prior})
    results = []
    with _bench_client() as client:
        batch = max(1, sum(client.nthreads().values()))
        while len(results) < max_rep and (time.time() - t0 < budget_s or len(results) < 5):
            results += _map(client, sbc_task, jobs[len(results):len(results) + batch], "SBC replications")
    for r in results:
        sb = r["sigma_brk"] or np.nan
        pair_res += [(r["brk"][a] / sb, r["brk"][b] / sb) for a, b in r["pairs"]]
        res_rows.append({k: v / sb for k, v in r["brk"].items()})
        design = design or r["brk_design"]
        pairs0 = pairs0 or r["pairs"]
        zs.append(r["z"])
        sig_brk.append(r["sigma_brk"] or np.nan)
        if names is None:
            names = list(r["free"])
        secs.append(r["sec_post"])
        brk_mode.add(r["breakaway_noise"])
        conv += r["converged"]
        ranks.append([r["ranks"][k] for k in names])
    ranks = np.array(ranks)
    n = len(ranks)
    # how much the events' correlated errors widen K_FS's and K_s's true spread: the covariance
    # of the residuals at the truth over the replications, projected on the least-squares
    # weights of the two breakaway-only columns (D·ΣP·dir, dir), against independent events
    keys = sorted(design) if design else []
    full = [row for row in res_rows if all(k in row for k in keys)]
    widen = {}
    if len(full) > 10 and keys:
        Rm = np.array([[row[k] for k in keys] for row in full])
        C = np.cov(Rm.T)
        X = np.array([[design[k][0] * design[k][1] / 1e7, design[k][1]] for k in keys])
        W = X @ np.linalg.inv(X.T @ X)
        idx = {k: i for i, k in enumerate(keys)}
        Cp = np.diag(np.diag(C))
        for a, b in pairs0 or []:
            i, j = idx[a], idx[b]
            Cp[i, j] = Cp[j, i] = C[i, j]
        s2 = float(np.mean(np.diag(C)))
        for col, k in enumerate(("KFS", "Ks")):
            w = W[:, col]
            widen[k] = (float(np.sqrt(w @ C @ w / (s2 * (w @ w)))), float(np.sqrt(w @ Cp @ w / (s2 * (w @ w)))))
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
                sec_post=float(np.mean(secs)), sec_total=time.time() - t0, brk_mode=", ".join(sorted(brk_mode)),
                widen=widen, n_full=len(full),
                rho_sbc=float(np.corrcoef(np.array(pair_res).T)[0, 1]) if len(pair_res) > 3 else math.nan,
                zstd_sbc=dict(zip(("KFS", "Ks"), np.std(np.array(zs), axis=0).tolist())) if zs else {},
                zout_sbc=dict(zip(("KFS", "Ks"), np.mean(np.abs(np.array(zs)) > 1.645, axis=0).tolist())) if zs else {})


STORE = ROOT / ".cache" / "bench_estimators.pkl"  # the last study's figures, to re-render the text


def run(quick: bool = False) -> str:
    import pickle

    t_start = time.time()
    eff = efficiency(quick, budget_s=60 if quick else 420)
    cal = sbc(quick, budget_s=40 if quick else 480)
    seconds = time.time() - t_start
    STORE.parent.mkdir(parents=True, exist_ok=True)
    STORE.write_bytes(pickle.dumps({"eff": eff, "cal": cal, "quick": quick, "seconds": seconds}))
    return render(eff, cal, quick, seconds)


def render(eff: dict, cal: dict, quick: bool, seconds: float) -> str:
    """The section's text from the study's figures (``python benchmarks/bench_estimators.py
    --render`` re-renders the last study without running it again)."""
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
        f"{os.cpu_count()} cores, Python {platform.python_version()}.  Study time {seconds:.0f} s.",
        "",
        "**Campaign.** The lighter ISO 4392-1 constant-speed and constant-pressure and ISO 4392-2 startability "
        "protocols of `synthetic_data/concealed/protocols/` (their default sensors), the demo motor and truth "
        f"(`synthetic_data/demo/`): {eff['rows_frame']:,} log rows, {eff['n_running']:,} steady running samples "
        f"and {eff['n_events']} breakaway events per campaign.  Each replication is `simulate_campaign(seed=1000+i)` "
        f"→ `extract` → `fit_least_squares`, {eff['t_rep']:.1f} s each.",
        "",
        "**Cramér–Rao bound.** `motorid.experiment_design.fisher_information` at the true parameters and the true operating "
        "points (rows of the simulator's `true_frame`), I = Σ J Jᵀ/σ² with J from JAX (forward mode through "
        "`model.predict` / `model.predict_breakaway`).  The σ of each running sample is the sensors' noise "
        "model at the true reading, σ² = noise² + (relative_noise·|x|)² + resolution²/12, plus the noise of the "
        "measured inputs the fit conditions on (port and case pressures, speed, and the acceleration "
        "the extraction derives from the noisy speed), carried through the model's derivatives (shaft-angle "
        "quantization, 0.01°, is left out).  The viscosity is a nuisance: where the extraction smooths a run's "
        "viscometer readings (every running run here), the bound's model has the run's true viscosity a "
        "Chebyshev polynomial in time of the degree the extraction chose, read by the viscometer with its noise "
        "model and seen by the running channels through the model; the bound is the inverse of the Schur "
        "complement of the joint Fisher information of (parameters, polynomial coefficients) "
        "(`viscosity_nuisance_bound`).  The acceleration's error also holds the part of the true "
        "acceleration that a 9-point derivative of even noise-free speed cannot follow: the dynamometer's "
        "once-per-revolution speed ripple, aliased at 2500 rpm and 50 Hz, puts J·α ≈ 0.25 N·m rms into the "
        "torque of the fastest runs, 2-3 times the torque sensor's noise; its phase is random from run to run, "
        "so it enters as input noise (per run, its mean square on the noise-free trajectory).  Without this term "
        "the bound on K_v would be about half as large, and no estimator that takes the acceleration from the "
        "logged speed could reach it.  The held breakaway torque is not a sensor reading but an extracted "
        "quantity (its error comes from locating the onset on a pressure ramp and from the pressures read "
        "there), so its σ is measured, per event: the standard deviation of held − predict_breakaway(truth) "
        "over the replications grows with the port pressures (a transducer's error grows with its reading), "
        "and a variance a + b·(P_A² + P_B²) fitted to the events' variances gives each event its σ: "
        f"{eff['brk_sigma_range'][0]:.4f}–{eff['brk_sigma_range'][1]:.4f} N·m from "
        f"{eff['brk_psum_range'][0] / 1e5:.0f} to {eff['brk_psum_range'][1] / 1e5:.0f} bar of P_A + P_B "
        f"(pooled {eff['sigma_brk']:.4f} N·m; mean offset {eff['brk_offset']:+.3g} N·m).  With the pooled σ "
        "for every event instead the bound would be "
        + ", ".join(f"{k} {v:.3g}" for k, v in eff.get("crb_pooled", {}).items()) + ".",
        "",
        f"### Least squares over {n} replications",
        "",
        "Intervals as `result.json` gives them (`motorid.identify.results.interval_dof` / `interval_factor`): "
        "value ± q·std with q the Student-t quantile at the standard error's effective degrees of freedom "
        "(Welch–Satterthwaite over the share of its variance that scales with the breakaway σ, which rests on "
        "n − 2 event residuals; the running channels' σ are taken as exact, ν = ∞, normal quantiles).",
        "",
        "| parameter | truth | mean bias | bias/CRB | empirical std | CRB std | CRB std, sensors alone | "
        "ratio std/CRB (90 % CI) | mean LS std | interval dof (median) | 68 % cover | 95 % cover |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
        *eff["rows"],
        "",
        f"Coverage pooled over parameters: 68 % intervals {eff['pooled68']:.1f} %, 95 % intervals "
        f"{eff['pooled95']:.1f} % (binomial standard error per parameter at {n} replications: "
        f"±{eff['se68']:.1f} and ±{eff['se95']:.1f} points).  With normal quantiles for every parameter instead "
        "(the intervals before the t-quantiles): "
        + ", ".join(f"{k} {100 * a:.1f}/{100 * b:.1f}" for k, a, b in
                    zip(eff["names"], eff["cov68_normal"], eff["cov95_normal"])
                    if math.isfinite(eff["nu"][eff["names"].index(k)]))
        + " % (68/95; parameters with finite dof only).",
        "",
        f"- Goal *ratio ≤ 1.1 for every parameter*: **{'met' if met_eff else 'not met'}** (largest ratio "
        f"{eff['ratio'][worst]:.3f}, {eff['names'][worst]}; "
        + ("every 90 % interval of the ratio reaches below 1.1)." if met_eff_ci else
           "some 90 % intervals of the ratio lie wholly above 1.1).")
        + f"  An empirical std from {n} replications is itself uncertain by about ±{100 / math.sqrt(2 * (n - 1)):.0f} % "
        "(1σ), hence the interval.",
        f"- Goal *coverage within ±3 points of nominal*: per parameter **{'met' if met_cov else 'not met'}** "
        f"(68 %: {', '.join(f'{100 * c:.1f}' for c in eff['cov68'])}; 95 %: "
        f"{', '.join(f'{100 * c:.1f}' for c in eff['cov95'])}); pooled **{'met' if met_pool else 'not met'}**.  "
        f"At {n} replications one parameter's coverage has a sampling error of ±{eff['se68']:.1f} points (68 %) "
        f"and ±{eff['se95']:.1f} (95 %).",
        "",
    ]
    # diagnosis of K_v and the leakage coefficients on the first replications
    dg = eff["diag"]
    if dg:
        L += [
            f"### Diagnosis: the viscosity and the acceleration ({eff['n_diag']} of the replications refitted)",
            "",
            "The same logs fitted again (1) with the true viscosity as the input (no viscometer error at all), "
            "(2) extracted with `ExtractSettings(smooth_viscosity=False)`: the viscometer's readings (0.3 % "
            "relative noise) used as read, as before the extraction smoothed them, (3) extracted with "
            "`ExtractSettings(shaft_orders=(1,))`: only the first shaft order of the speed ripple resolved in θ.",
            "",
            "| parameter | fit | mean bias | empirical std | mean LS std | empirical/LS |",
            "|---|---|---|---|---|---|",
        ]
        labels = (("true_viscosity", "true viscosity"), ("viscosity_as_read", "viscosity as read"),
                  ("shaft_order_1", "shaft order 1 only"))
        for k in ("Kv", "KL0", "KL_a1", "KL_b1", "KAB"):
            if k not in dg["true_viscosity"]:
                continue
            b0 = dg["true_viscosity"][k]
            L.append(f"| {k} | as fitted | {_fmt(b0['base_bias'], 2)} | {_fmt(b0['base_emp'], 3)} | "
                     f"{_fmt(b0['base_ls'], 3)} | {b0['base_emp'] / b0['base_ls']:.2f} |")
            for key, label in labels:
                if (key == "shaft_order_1") != (k == "Kv"):
                    continue
                c = dg[key][k]
                L.append(f"| {k} | {label} | {_fmt(c['bias'], 2)} | {_fmt(c['emp'], 3)} | {_fmt(c['ls'], 3)} | "
                         f"{c['emp'] / c['ls']:.2f} |")
        L.append("")
    L += [
        "### Simulation-based calibration of the posterior (emcee)",
        "",
        f"Truth drawn from a calibration prior, independent Normal(demo value, {100 * SBC_PRIOR_REL:.0f} % of it) "
        "(positive parameters truncated at 0); campaign simulated and fitted as above; posterior sampled by "
        "`sample_posterior(..., prior=…)` with that same prior (the optional calibration-prior argument), the breakaway σ integrated out (p(σ) ∝ 1/σ); "
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
    zf, zsb, zo = eff["zstd_fixed"], cal["zstd_sbc"], cal["zout_sbc"]
    L += [
        "**The breakaway events of the two directions.**  The startability runs come in mirrored pairs (same shaft "
        f"angle and load, opposite directions; {eff['n_pairs']} pairs of {eff['n_events']} events).  Correlation of "
        "the two events' held − predict_breakaway(truth): at the fixed truth, of their deviations from their own "
        f"means over the replications, {eff['rho_fixed']:+.2f} (each event's mean, its frozen part, is "
        f"{eff['frozen']:.3f} N·m rms against σ_brk {eff['sigma_brk']:.3f}); over the SBC replications, where "
        f"the truth varies, in units of the fit's σ_brk, {cal['rho_sbc']:+.2f}.  Spread of (LS value − truth)/LS "
        "std, nominal 1: at the fixed truth "
        + ", ".join(f"{k} {v:.2f}" for k, v in zf.items())
        + "; over the SBC truths "
        + ", ".join(f"{k} {v:.2f}" for k, v in zsb.items())
        + " (|z| > 1.645: " + ", ".join(f"{k} {100 * v:.0f} %" for k, v in zo.items()) + ", nominal 10 %).  "
        + ("Covariance of the SBC residuals at the truth (in σ_brk, over the replications), projected on the "
           "least-squares weights of the breakaway-only columns (D·ΣP·dir for K_FS, dir for K_s), against 30 "
           "independent events: std × "
           + ", ".join(f"{k} {a:.2f} (mirrored pairs' covariances alone {b:.2f})" for k, (a, b) in cal["widen"].items())
           + f", from {cal['n_full']} replications (± ≈ {1 / math.sqrt(2 * max(cal['n_full'] - 1, 1)):.2f})."
           if cal.get("widen") else ""),
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
    elif not above:
        verdict = (f"above 1.1; its 90 % interval ({eff['r_lo'][worst]:.2f}–{eff['r_hi'][worst]:.2f}) reaches "
                   "below 1.1 but not down to 1.0: the estimator is probably a little less efficient than the bound "
                   "for it.")
    else:
        verdict = (f"above 1.1; the 90 % intervals of {', '.join(above)} lie above 1.1: "
                   "for them the estimator is measurably less efficient than the bound.")
    over = [k for k, c in zip(eff["names"], eff["cov68"]) if 100 * c > 68.27 + 2 * eff["se68"]]
    under = [k for k, c in zip(eff["names"], eff["cov68"]) if 100 * c < 68.27 - 2 * eff["se68"]]
    kfs, ks = cal["split"].get("KFS", (0, 0)), cal["split"].get("Ks", (0, 0))
    shapes = []
    for k, p in zip(cal["names"], cal["pvals"]):
        if p >= 0.05:
            continue
        mean, out = cal["shape"][k]
        if out < 0.06:
            what = f"a hump (outer 10 % holds {100 * out:.0f} %): the posterior is too wide"
        elif out > 0.14:
            what = f"U-shaped (outer 10 % holds {100 * out:.0f} %): the posterior is too narrow"
        else:
            what = f"no clear width error (outer 10 % holds {100 * out:.0f} %)"
        if abs(mean - 0.5) > 0.03:
            what += (f", skewed (mean rank {mean:.2f} of 1): the estimate sits "
                     + ("below" if mean > 0.5 else "above") + " the truth more often than not")
        shapes.append(f"{k} (p = {p:.3f}), {what}")
    bias_of = dict(zip(eff["names"], eff["bias_crb"]))
    kv_d = dg.get("shaft_order_1", {}).get("Kv") if dg else None
    raw = dg.get("viscosity_as_read", {}) if dg else {}
    tru = dg.get("true_viscosity", {}) if dg else {}
    L += [
        "**Reading the results.**",
        "",
        f"- Efficiency: the largest ratio is {eff['ratio'][worst]:.3f} ({eff['names'][worst]}), {verdict}"
        + (f"  Ratios wholly below 1 ({', '.join(below)}) do not beat a true bound: they show that the noise "
           "model used for the bound is conservative for them." if below else ""),
        "- K_v: the fast runs' speed carries the dynamometer's once-per-revolution ripple, aliased at 2500 rpm "
        "and 50 Hz; a plain derivative of the sampled speed turns it into a false J·α of 0.25 N·m rms in their "
        "torque (2-3 times the torque sensor's noise).  The extraction resolves a shaft-locked speed ripple in θ "
        "(`acceleration.running_acceleration`: shaft orders 1 and 2, fitted per steady run and differentiated "
        "through θ, the rest by the 9-point derivative); the bound's column 6 adds what that estimate still "
        "misses on noise-free speed, column 7 leaves it out.  The orders are taken lowest first, each where "
        "Akaike's test passes (F ≥ 2) and the sampling does not fold it onto an order kept, or near 0 Hz: the "
        "former rule kept an order only where F ≥ 30 and fell back to the plain derivative where orders 1 and "
        "2 aliased together (1000 rpm at 50 Hz), and a dynamometer's slow speed wander then left real ripples "
        "unresolved; K_v's spread over the bound was 1.10 with it"
        + (f"; resolving order 1 alone gives K_v's spread {kv_d['base_emp']:.2f} → {kv_d['emp']:.2f} and "
           f"standard error {kv_d['base_ls']:.2f} → {kv_d['ls']:.2f} (diagnosis table)" if kv_d else "") + ".",
        "- The viscosity and the leakage coefficients: the leakage flows go as 1/μ, and a viscometer's noise "
        "(0.3 % per reading here) multiplies them sample by sample.  Used as read, it biases K_L0 low "
        "(errors in variables, E[K̂_L0]/K_L0 ≈ 1 − 2σ_rel²) and scatters the K_L(θ) harmonics beyond their "
        "bound.  The extraction now replaces each steady run's readings by a Chebyshev curve in time "
        "(`viscosity.smooth_viscosity`; degree by a residual-variance test, kept only where the rest is white), "
        "and the fit carries the curve's run-level error, common to the run's samples, into the covariance "
        "(`FitResult.covariance_viscosity`, the two-step plug-in term) and the posterior (each draw convolved "
        "with it)."
        + ("  Diagnosis table, as fitted against readings used as read: "
           + "; ".join(f"{k} spread {tru[k]['base_emp']:.3g} vs {raw[k]['emp']:.3g}, bias {tru[k]['base_bias']:.2g} "
                       f"vs {raw[k]['bias']:.2g}, empirical/LS {tru[k]['base_emp'] / tru[k]['base_ls']:.2f} vs "
                       f"{raw[k]['emp'] / raw[k]['ls']:.2f}"
                       for k in ("KL0", "KL_a1", "KL_b1", "KAB") if k in raw and k in tru)
           + f" (±{100 / math.sqrt(2 * max(eff['n_diag'] - 1, 1)):.0f} % on a spread from {eff['n_diag']} "
           "replications).  With the true viscosity: "
           + ", ".join(f"{k} {tru[k]['emp']:.3g}" for k in ("KL0", "KL_a1", "KL_b1", "KAB") if k in tru)
           + ": what is left above that is the run-level error of the curves, which no estimator that learns "
           "the viscosity from the viscometer can avoid, and which the bound counts." if raw and tru else "")
        + "  A second, smaller bias of the same 1/μ: the fit averages the samples of a run and shaft-angle bin "
        "(taken at different times) into cells, and the cells held the plain mean of their viscosities; the "
        "leakage goes as 1/μ, so a cell's model leakage came out too small by var(μ)/μ² (Jensen), and K_L0 and "
        "K_AB too large: by +0.24 and +0.10 bound-widths in the previous run of this study (K_L0's posterior "
        "ranks skewed, p = 0.003), on noise-free data with realistic weights by 4.3·10⁻¹⁹ (K_L0).  The cells "
        "now hold the harmonic mean: "
        + ", ".join(f"{k} {bias_of[k]:+.2f}" for k in ("KL0", "KAB") if k in bias_of)
        + " bound-widths here.",
        f"- Least-squares intervals: pooled coverage {eff['pooled68']:.1f} % / {eff['pooled95']:.1f} % is "
        + ("within" if met_pool else "outside") + " 3 points of nominal."
        + (f"  Over-covering by more than two binomial standard errors: {', '.join(over)}." if over else "")
        + (f"  Under-covering by more than two binomial standard errors: {', '.join(under)}." if under else "")
        + "  The t-quantiles change only K_FS and K_s (median ν "
        + ", ".join(f"{k} {eff['nu'][eff['names'].index(k)]:.0f}" for k in ("KFS", "Ks") if k in eff["names"]
                    and math.isfinite(eff["nu"][eff["names"].index(k)]))
        + "); every other parameter's ν is effectively infinite.",
        "- Posterior calibration: the posterior integrates the breakaway σ out under p(σ) ∝ 1/σ (the "
        f"sampler's default; here: {cal['brk_mode']}), the right treatment of a noise level known from ~28 "
        "degrees of freedom; outer ranks with small vs large fitted σ_brk: "
        f"K_FS {100 * kfs[0]:.0f} % vs {100 * kfs[1]:.0f} %, K_s {100 * ks[0]:.0f} % vs {100 * ks[1]:.0f} % "
        "(nominal 10 %).  K_FS and K_s rest on the breakaway events alone; how the onsets are placed is what "
        "their calibration rests on.  At 25 Hz the shaft meets the dynamometer's 10 rpm limit within a sample "
        "or two, so `breakaway.find_breakaway` places an onset with fewer than two growth samples from the angle "
        "the shaft turned (the speed's integral).  Where the first moving sample is already on the limit, the "
        "angle leaves the unseen time to reach it, u_s: the middle of what it allows was late by 2.6 ± 2.5 ms "
        "over those events (a third of them), K_FS +0.15 bound-widths and its posterior ranks skewed "
        "(p < 0.001) in an earlier run of this study.  Just after breakaway the shaft accelerates at "
        "(static − kinetic friction)/inertia, a line in P_A + P_B; the campaign's other events give it "
        "(Theil-Sen, then least squares), and with it u_s = W/a and the onset (`onset_angle.place_limited_onset`): "
        "−0.02 ± 0.06 ms.  (The simulator's angle after breakaway had to become trapezoidal too: semi-implicit "
        "Euler put the shaft half a step ahead, which read as a 0.25 ms early onset.)  The pressure at an onset "
        "comes from a line through as many readings as best predict the next one (the supply ripple is followed "
        "where it matters), and where the events scatter more than their variance model follows, a sandwich "
        "widens K_FS and K_s (`covariance.breakaway_sandwich`; here by a few %).  Now: σ_brk "
        f"{eff['sigma_brk']:.3f} N·m, frozen part {eff['frozen']:.3f} N·m rms (of which ≈ "
        f"{eff['sigma_brk'] / math.sqrt(max(n, 1)):.3f} is the {n}-replication mean's own noise), mirrored-pair "
        f"correlation {eff['rho_fixed']:+.2f} at the fixed truth and {cal['rho_sbc']:+.2f} over the SBC truths; "
        "the events' σ grows with the port pressures read at the onset (in the bound, "
        f"{eff['brk_sigma_range'][0]:.3f} to {eff['brk_sigma_range'][1]:.3f} N·m over the loads), which the fit "
        "models as σ_i² = σ₀²(1 + γ (P_A² + P_B²)/median) (`noise.breakaway_noise`); K_FS's bias "
        f"{bias_of.get('KFS', float('nan')):+.2f} bound-widths, coverage "
        f"{100 * eff['cov68'][eff['names'].index('KFS')]:.1f} % at 68 %."
        + (("  Ranks not uniform at p < 0.05: " + "; ".join(shapes) + ".") if shapes else
           "  Every parameter's ranks pass at p ≥ 0.05."),
        "",
    ]
    return "\n".join(L)


if __name__ == "__main__":
    if "--render" in sys.argv:
        import pickle

        stored = pickle.loads(STORE.read_bytes())
        text = render(stored["eff"], stored["cal"], stored["quick"], stored["seconds"])
        (Path(__file__).resolve().parent / "sections" / "bench_estimators.md").write_text(text.rstrip() + "\n")
        print(text)
    else:
        print(run(quick="--quick" in sys.argv))
