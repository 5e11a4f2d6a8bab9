"""Fleets (issue 17): throughput on Dask against the plain loop, and the population model's recovery.

    python benchmarks/run.py --only bench_fleet [--quick]

1. Throughput: N simulated campaigns (the repository's ISO 4392-1/-2 protocols,
   every third run) fitted by the plain sequential loop in one process, and by
   `motorid fleet fit`'s path (motorid.fleet.fitting.fit_fleet: an embedded
   LocalCluster of 1 and 2 worker processes, one thread each, store and
   fleet.json included); campaigns per minute, wall clock.
2. The issue's fleet through the real pipeline: 12 motors of one type whose
   Kv, KF, KL0 and KAB are drawn from a known log-normal population, one of
   them out of family (K_L0 × 4), three re-tested 9 months later with K_L0 up
   30-60 %: population recovered within its intervals, flags, trends.
3. Recovery over many simulated fleets on per-motor estimates with known
   truth (no fits, so hundreds of fleets): coverage of the 95 % intervals of
   μ and τ, family-wise false-flag rate, detection rate against the outlier's size.
"""

from __future__ import annotations

import datetime as dt
import json
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
PROTOCOLS = ROOT / "protocols"
BASE = {"Kv": 5000.0, "KF": 3e-3, "KFS": 1.5e-2, "TFc": 3.0, "Ks": 1.0, "KL0": 5e-14, "KL_a1": 0.15,
        "KL_b1": 0.08, "KAB": 2e-14}
SPREAD = {"Kv": 0.10, "KF": 0.10, "KL0": 0.15, "KAB": 0.10}  # population τ on the log scale


def _spec():
    from motorid.model import MotorSpec, OilSpec

    return MotorSpec(name="A2FM-80", pistons=9, displacement=80e-6, inertia=0.005, oil=OilSpec())


def _draw(rng):
    return {k: v * math.exp(rng.normal(0, SPREAD[k])) if k in SPREAD else v for k, v in BASE.items()}


def _load():
    try:
        return os.getloadavg()[0]
    except OSError:
        return float("nan")


def throughput(root: Path, n: int) -> dict:
    from motorid import __version__
    from motorid.fleet.campaigns import campaign_key, read_campaign
    from motorid.fleet.fitting import fit_fleet
    from motorid.fleet.simulated import small_protocols, write_simulated_campaign
    from motorid.fleet.tasks import fit_campaign_task, map_local

    prots = small_protocols(PROTOCOLS, every=3)
    rng = np.random.default_rng(17)
    spec = _spec()
    folders = [write_simulated_campaign(root / f"T{i:02d}", _draw(rng), prots, spec, f"T-{i:02d}",
                                        dt.date(2026, 1, 1), seed=100 + i) for i in range(n)]
    options = {"harmonics": None, "diagnose": False}
    jobs = []
    for f in folders:
        c = read_campaign(f)
        jobs.append({"campaign": c, "options": options, "key": campaign_key(c, options, __version__)})
    out = {"n": n, "load_before": _load()}
    t0 = time.time()
    res = map_local(fit_campaign_task, jobs)
    out["sequential_s"] = time.time() - t0
    assert all(isinstance(r, dict) for r in res), res
    for w in (1, 2):
        d = root / f"fleet_w{w}"
        t0 = time.time()
        run = fit_fleet(folders, d, workers=w, progress=False)
        out[f"dask{w}_s"] = time.time() - t0
        out[f"dask{w}_pids"] = len(set(run.workers.values()))
        assert len(run.fitted) == n, run.failed
    out["load_after"] = _load()
    return out


def issue_fleet(root: Path) -> dict:
    """12 motors, one out of family, three worn and re-tested: fitted with fit_fleet (2 workers)."""
    from motorid.fleet.fitting import fit_fleet
    from motorid.fleet.simulated import small_protocols, write_simulated_campaign

    prots = small_protocols(PROTOCOLS, every=3)
    rng = np.random.default_rng(2026)
    spec = _spec()
    d0, d1 = dt.date(2025, 6, 1), dt.date(2026, 3, 1)
    motors = {f"SN-{1000 + i}": _draw(rng) for i in range(12)}
    motors["SN-1011"]["KL0"] *= 4.0  # out of family
    worn = {"SN-1000": 0.3, "SN-1001": 0.45, "SN-1002": 0.6}  # K_L0 growth over the 9 months
    folders = []
    for i, (s, p) in enumerate(motors.items()):
        folders.append(write_simulated_campaign(root / f"{s}_{d0}", p, prots, spec, s, d0, seed=200 + i))
    for i, (s, g) in enumerate(worn.items()):
        p = dict(motors[s], KL0=motors[s]["KL0"] * (1 + g))
        folders.append(write_simulated_campaign(root / f"{s}_{d1}", p, prots, spec, s, d1, seed=300 + i))
    t0 = time.time()
    fit_fleet(folders, root / "fleet", workers=2, progress=False)
    seconds = time.time() - t0
    doc = json.loads((root / "fleet" / "fleet.json").read_text())
    pop = json.loads((root / "fleet" / "population.json").read_text())["types"]["A2FM-80"]
    return {"doc": doc, "pop": pop, "seconds": seconds, "worn": worn, "motors": motors}


def synthetic_recovery(n_fleets: int, k: int = 12) -> dict:
    from motorid.fleet.population import analyse_type, fit_population

    rng = np.random.default_rng(5)
    cov = {"mu": 0, "tau": 0}
    false_fleets = 0
    for _ in range(n_fleets):
        theta = rng.normal(math.log(5e-14), 0.15, k)
        rel = rng.uniform(0.01, 0.05, k)
        est = np.exp(theta + rng.normal(0, rel))
        serials = [f"m{i}" for i in range(k)]
        pop = fit_population("A", "KL0", serials, est, rel * est)
        cov["mu"] += pop.mu_ci95[0] <= math.log(5e-14) <= pop.mu_ci95[1]
        cov["tau"] += pop.tau_ci95[0] <= 0.15 <= pop.tau_ci95[1]
        # clean fleet, four parameters judged together (M·P = 48 tests)
        ests = {}
        for p, sd in SPREAD.items():
            th = rng.normal(0.0, sd, k)
            r = rng.uniform(0.01, 0.05, k)
            v = BASE[p] * np.exp(th + rng.normal(0, r))
            ests[p] = (serials, v, r * v)
        _, ver = analyse_type("A", ests)
        false_fleets += any(v.out_of_family for v in ver)
    detect = {}
    for factor in (1.5, 2.0, 3.0, 4.0):
        hits = 0
        n = max(20, n_fleets // 4)
        for _ in range(n):
            ests = {}
            for p, sd in SPREAD.items():
                th = rng.normal(0.0, sd, k)
                if p == "KL0":
                    th[0] += math.log(factor)
                r = rng.uniform(0.01, 0.05, k)
                v = BASE[p] * np.exp(th + rng.normal(0, r))
                ests[p] = ([f"m{i}" for i in range(k)], v, r * v)
            _, ver = analyse_type("A", ests)
            hits += any(v.out_of_family and v.serial == "m0" and v.parameter == "KL0" for v in ver)
        detect[factor] = (hits, n)
    return {"n": n_fleets, "k": k, "cov": cov, "false": false_fleets, "detect": detect}


def run(quick: bool = False) -> str:
    t0 = time.time()
    root = Path(tempfile.mkdtemp(prefix="bench_fleet_"))
    try:
        tp = throughput(root / "tp", 6 if quick else 12)
        fl = issue_fleet(root / "issue")
        rec = synthetic_recovery(100 if quick else 400)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return render(tp, fl, rec, quick, time.time() - t0)


def render(tp, fl, rec, quick, seconds) -> str:
    n = tp["n"]
    rate = {k: 60 * n / tp[f"{k}_s"] for k in ("sequential", "dask1", "dask2")}
    L = ["## Fleets: throughput on Dask, population recovery",
         "",
         "Command: `python benchmarks/run.py --only bench_fleet`" + (" (quick)" if quick else "") + ".  "
         f"{n} simulated campaigns (repository protocols ISO 4392-1/-2, every third run, about 26 k rows each), "
         f"os.cpu_count() = {os.cpu_count()}, load average {tp['load_before']:.1f} before and "
         f"{tp['load_after']:.1f} after (the machine is shared: timings are of that moment).",
         "",
         "| path | wall s | campaigns / min | × sequential |",
         "|---|---|---|---|",
         f"| plain sequential loop, one process (fit only) | {tp['sequential_s']:.1f} | {rate['sequential']:.1f} | 1.00 |"]
    for w in (1, 2):
        L.append(f"| `fleet fit` on LocalCluster, {w} worker{'s' if w > 1 else ''} "
                 f"(cluster start, store, fleet.json included; {tp[f'dask{w}_pids']} worker pid(s) used) | "
                 f"{tp[f'dask{w}_s']:.1f} | {rate[f'dask{w}']:.1f} | {rate[f'dask{w}'] / rate['sequential']:.2f} |")
    L += ["", "Each worker process pays its own start (imports, JAX compile from the on-disk cache); "
              "past that, throughput grows with the worker processes the cores can run.  On a cluster, "
              "`--scheduler tcp://…` adds machines the same way.", ""]
    doc, pop = fl["doc"], fl["pop"]
    motors = {m["serial"]: m for m in doc["motors"]}
    L += [f"### The issue's fleet through `fleet fit` (15 campaigns, 2 workers, {fl['seconds']:.0f} s)", "",
          "12 motors of A2FM-80; Kv, KF, KL0, KAB drawn log-normal about the demo values with τ = "
          + ", ".join(f"{k} {v}" for k, v in SPREAD.items())
          + "; SN-1011 has K_L0 × 4 (out of family); SN-1000/1001/1002 re-tested 9 months later with K_L0 "
            "+30/+45/+60 %.", "",
          "| parameter | true μ (log) | μ̂ [95 %] | true τ | τ̂ [95 %] | motors in fit | left out |",
          "|---|---|---|---|---|---|---|"]
    for p in ("Kv", "KF", "KL0", "KAB"):
        e = pop[p]
        mu = math.log(BASE[p])
        ok_mu = e["mu_ci95"][0] <= mu <= e["mu_ci95"][1]
        ok_tau = e["tau_ci95"][0] <= SPREAD[p] <= e["tau_ci95"][1]
        L.append(f"| {p} | {mu:.4f} | {e['mu']:.4f} [{e['mu_ci95'][0]:.4f}, {e['mu_ci95'][1]:.4f}] "
                 f"{'✓' if ok_mu else '✗'} | {SPREAD[p]} | {e['tau']:.3f} [{e['tau_ci95'][0]:.3f}, "
                 f"{e['tau_ci95'][1]:.3f}] {'✓' if ok_tau else '✗'} | {e['n']} | {', '.join(e['excluded']) or '—'} |")
    L += ["", "(The worn motors enter the population at their latest, worn, test; τ of K_L0 carries that.)", ""]
    flagged = {s: [f"{o['parameter']} (p = {o['probability']:.6f})" for o in m["out_of_family"]]
               for s, m in motors.items() if m["out_of_family"]}
    L.append("Out of family: " + ("; ".join(f"{s}: {', '.join(v)}" for s, v in flagged.items()) or "none") + ".")
    L += ["", "| motor | K_L0 per year (SI/a) [95 %] | true | verdict | other parameters |", "|---|---|---|---|---|"]
    for s, g in fl["worn"].items():
        tr = {t["parameter"]: t for t in motors[s]["trends"]}
        k = tr["KL0"]
        true = g * fl["motors"][s]["KL0"] / ((dt.date(2026, 3, 1) - dt.date(2025, 6, 1)).days / 365.25)
        others = ", ".join(f"{p} {t['verdict']}" for p, t in tr.items() if p != "KL0" and t["verdict"] != "stable")
        L.append(f"| {s} | {k['per_year']:.4g} [{k['ci95'][0]:.4g}, {k['ci95'][1]:.4g}] | {true:.4g} | "
                 f"{k['verdict']} | {others or 'all stable'} |")
    L += ["", f"Failed: {len(doc['failed'])}.", ""]
    c = rec["cov"]
    L += [f"### Recovery over {rec['n']} simulated fleets of {rec['k']} motors (per-motor estimates, 1-5 % errors)", "",
          f"- coverage of the 95 % interval of μ (HKSJ): {100 * c['mu'] / rec['n']:.1f} %; of τ (REML profile): "
          f"{100 * c['tau'] / rec['n']:.1f} % (binomial ±{100 * 1.96 * math.sqrt(0.05 * 0.95 / rec['n']):.1f} points)",
          f"- clean fleets with any out-of-family flag (4 parameters × 12 motors, family-wise α = 1 %): "
          f"{rec['false']}/{rec['n']}",
          "- detection of one motor's K_L0 moved by a factor (τ = 0.15): "
          + ", ".join(f"×{f:g}: {h}/{n}" for f, (h, n) in rec["detect"].items()),
          "", f"Study time {seconds:.0f} s."]
    return "\n".join(L)


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
