"""Fit time and peak memory against campaign size (issue 7).

    python benchmarks/run.py --only bench_scaling [--quick]

Campaigns of 10 k … 3 M log rows are the same ISO 4392-1/-2 runs (the lighter
protocols of synthetic_data/concealed/protocols, demo motor and truth) logged at
higher sample rates: every run keeps its set point and duration, and the rate is
multiplied so the campaign reaches the size.  Each campaign is simulated and
written as a CSV log by one subprocess; a fresh subprocess then reads it
(``read_logs``), extracts the steady samples and breakaway events
(``extract``) and fits (``fit_least_squares``), timing each step; its peak
resident memory is ``getrusage(RUSAGE_SELF).ru_maxrss``.

    python benchmarks/bench_scaling.py make ROWS PATH     # write a campaign log
    python benchmarks/bench_scaling.py fit PATH           # time read/extract/fit, print JSON
"""

from __future__ import annotations

import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

HERE = Path(__file__).resolve()
ROOT = HERE.parent.parent
PROTOCOL_DIR = ROOT / "synthetic_data" / "concealed" / "protocols"
TRUTH = ROOT / "synthetic_data" / "demo" / "truth.toml"
MOTOR = ROOT / "synthetic_data" / "demo" / "motor.toml"
BASE_ROWS = 24_937  # rows of the campaign at the protocols' own rates
SIZES = [10_000, 30_000, 100_000, 300_000, 1_000_000, 3_000_000]
QUICK_SIZES = [10_000, 30_000, 100_000, 300_000]


def make(rows: int, path: str) -> None:
    from motorid.bench.protocols import load_protocol
    from motorid.bench.simulate import simulate_campaign
    from motorid.bench.truth import load_truth
    from motorid.io.logs import write_log
    from motorid.io.spec import load_motor_spec

    spec = load_motor_spec(MOTOR)
    truth = load_truth(TRUTH)
    f = rows / BASE_ROWS
    prots = []
    for p in sorted(PROTOCOL_DIR.glob("*.toml")):
        pr = load_protocol(p)
        prots.append(replace(pr, runs=tuple(replace(r, sample_rate=r.sample_rate * f) for r in pr.runs)))
    camp = simulate_campaign(prots, spec, truth, seed=7)
    write_log(camp.frame, path)
    print(len(camp.frame))


def fit(path: str) -> None:
    t0 = time.perf_counter()
    import motorid  # noqa: F401
    from motorid.identify.extract import extract
    from motorid.identify.least_squares import fit_least_squares
    from motorid.io.logs import read_logs
    from motorid.io.spec import load_motor_spec

    spec = load_motor_spec(MOTOR)
    t_import = time.perf_counter() - t0
    t = time.perf_counter()
    frame = read_logs([path], spec)
    t_read = time.perf_counter() - t
    t = time.perf_counter()
    data = extract(frame, spec)
    t_extract = time.perf_counter() - t
    t = time.perf_counter()
    ls = fit_least_squares(data, spec)
    t_fit = time.perf_counter() - t
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux → MiB
    print(json.dumps({"rows": len(frame), "samples": data.n_running, "events": data.n_events,
                      "cells": int(ls.problem.n_cells), "import": t_import, "read": t_read, "extract": t_extract,
                      "fit": t_fit, "rss_mib": rss, "converged": ls.converged,
                      "Kv": ls.values["Kv"], "Kv_std": ls.std["Kv"]}))


def _py(*args, timeout=900):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, str(HERE), *args], capture_output=True, text=True, env=env,
                         timeout=timeout, cwd=ROOT)
    if out.returncode != 0:
        raise RuntimeError(f"bench_scaling {' '.join(args)} failed:\n{out.stderr[-3000:]}")
    return out.stdout.strip().splitlines()[-1]


def run(quick: bool = False) -> str:
    sizes = QUICK_SIZES if quick else SIZES
    results = []
    t_start = time.time()
    with tempfile.TemporaryDirectory(prefix="motorid-scaling-") as tmp:
        for rows in sizes:
            path = str(Path(tmp) / f"campaign_{rows}.csv")
            _py("make", str(rows), path)
            r = json.loads(_py("fit", path))
            r["file_mib"] = os.path.getsize(path) / 2**20
            os.unlink(path)
            results.append(r)
            print(f"   {rows:>9,} rows: read {r['read']:.1f} s, extract {r['extract']:.1f} s, fit {r['fit']:.1f} s, "
                  f"{r['rss_mib']:.0f} MiB", flush=True)
    cmd = "python benchmarks/run.py --only bench_scaling" + (" --quick" if quick else "")
    lines = [
        "## Scaling: fit time and memory against campaign size",
        "",
        f"Command: `{cmd}` (part of `make bench`).  Machine: see the header; {os.cpu_count()} cores, "
        f"Python {platform.python_version()}.  Study time {time.time() - t_start:.0f} s.",
        "",
        "The same ISO 4392-1/-2 campaign (lighter protocols of `synthetic_data/concealed/protocols/`, demo motor "
        "and truth) logged at higher sample rates: each run keeps its set point and duration, the rates are "
        "multiplied to reach the size.  One subprocess simulates it and writes the CSV log (uncompressed); a fresh "
        "subprocess reads it (`read_logs`), extracts (`extract`) and fits (`fit_least_squares`); peak RSS is "
        "that process's `ru_maxrss` (Python, JAX and the compiled functions included).  Times are single runs in a fresh "
        "process each; XLA compiles come from motorid's persistent compile cache (`~/.cache/motorid/jax`) when "
        "an earlier run left them there.",
        "",
        "| log rows | steady samples | events | fit cells | file MiB | read s | extract s | fit s | "
        "read+extract+fit s | µs/row (all) | peak RSS MiB | K_v ± std |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        tot = r["read"] + r["extract"] + r["fit"]
        lines.append(f"| {r['rows']:,} | {r['samples']:,} | {r['events']} | {r['cells']:,} | {r['file_mib']:.1f} | "
                     f"{r['read']:.2f} | {r['extract']:.2f} | {r['fit']:.2f} | {tot:.2f} | "
                     f"{1e6 * tot / r['rows']:.1f} | {r['rss_mib']:.0f} | {r['Kv']:.1f} ± {r['Kv_std']:.2f} |")
    a, b = results[-2], results[-1]
    tot = lambda r: r["read"] + r["extract"] + r["fit"]  # noqa: E731
    slope_all = (tot(b) - tot(a)) / (b["rows"] - a["rows"]) * 1e6
    growth = (tot(b) / tot(a)) / (b["rows"] / a["rows"])
    fit_growth = (b["fit"] / a["fit"]) / (b["rows"] / a["rows"])
    mem_total = 0
    try:
        mem_total = int(open("/proc/meminfo").read().split("MemTotal:")[1].split()[0]) / 1024
    except (OSError, IndexError, ValueError):
        pass
    lines += [
        "",
        f"- Linearity: from {a['rows']:,} to {b['rows']:,} rows ({b['rows'] / a['rows']:.1f}×) read+extract+fit "
        f"grew {tot(b) / tot(a):.2f}× ({growth:.2f} of proportional; marginal cost {slope_all:.1f} µs/row), the "
        f"fit alone {b['fit'] / a['fit']:.2f}× ({fit_growth:.2f} of proportional).  The fit works on shaft-angle "
        "cells per run (at most 192 per piston pitch), so once the cells are full its optimizer no longer grows "
        "with the rows; what grows is the per-sample work (cell means, residuals, noise re-estimation), linear "
        "in the rows.  Small campaigns are dominated by fixed costs (JAX dispatch, compiles or compile-cache loads).",
        f"- Memory at {b['rows']:,} rows: peak RSS {b['rss_mib']:.0f} MiB"
        + (f", {100 * b['rss_mib'] / mem_total:.0f} % of this machine's {mem_total / 1024:.0f} GiB" if mem_total else "")
        + f" ({1024 * 1024 * (b['rss_mib'] - results[0]['rss_mib']) / max(b['rows'] - results[0]['rows'], 1):.0f} "
        "bytes per extra row, reading included).",
        *([f"- Precision: K_v's standard error went {a['Kv_std']:.2f} → {b['Kv_std']:.2f} from {a['rows']:,} to "
           f"{b['rows']:,} rows, not down by √{b['rows'] / a['rows']:.0f}.  More rows here means a higher sample "
           "rate over the same runs, and the extraction's acceleration is a derivative over a fixed number of "
           "samples (9): at kHz rates it amplifies the speed sensor's noise (σ_α ∝ σ_ω·rate), and J·α brings that "
           "into the torque residual of the fast runs (at ~1 M rows a 31-sample window gave K_v ± 0.73 "
           "instead of ± 1.2).  Not changed: at 2 kHz and 2500 rpm most of the acceleration is real, the "
           "pistons' torque ripple moving the shaft (J·std α ≈ 0.25 N·m), which a window fixed in time "
           "would smooth away, and a noise-driven choice of the window needs the torque's white noise, "
           "which that same ripple hides from a difference estimate.  Resolving the speed ripple at the "
           "piston orders (as orders 1 and 2 are now) would free the window to grow; that is open."]
          if b["Kv_std"] > 0.8 * a["Kv_std"] else []),
        "- Goal *close to linear, 3 M rows comfortably in memory*: "
        + ("**met**." if (not quick and growth < 1.3 and (not mem_total or b["rss_mib"] < 0.5 * mem_total))
           else "**see the table** (quick run: up to 300 k rows only)." if quick else "**not met**."),
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    if len(sys.argv) >= 2 and sys.argv[1] == "make":
        make(int(sys.argv[2]), sys.argv[3])
    elif len(sys.argv) >= 2 and sys.argv[1] == "fit":
        fit(sys.argv[2])
    else:
        print(run(quick="--quick" in sys.argv))
