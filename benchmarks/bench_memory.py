"""Peak memory of `motorid fit` against the rows of the log, and reading against pandas.read_csv.

    python benchmarks/run.py --only bench_memory [--quick]

A long high-rate recording: the demo protocols on the demo motor and truth, the
running protocols' sample rates scaled up so that one CSV log holds about 0.3, 1, 3
and 10 M rows (quick: 0.3 and 1 M) — the same 180 runs each time, longer and
denser, as a bench logging faster would give.  The startability protocol stays at
bench_speed's rates (4.3×).  The log is simulated run by run (the simulator holds
a whole protocol in memory otherwise) and appended to one plain CSV in a
temporary folder, never in the repository.

Each command runs as a fresh process; its peak resident memory is the kernel's
(``os.wait4`` → ``ru_maxrss``), its wall time process start to exit:

1. ``motorid fit LOG --motor M --out DIR --quiet`` as a user runs it (above
   ``MOTORID_CELL_ROWS``, 500 k rows, it streams the log and fits from cells), and
   the same with the per-sample path forced (``MOTORID_CELL_ROWS`` = 10¹²; not at 10 M
   rows, where it would need several GiB);
2. reading alone: motorid's streamed reader (every run handed on, SI, checked),
   motorid's whole-file reader (``read_logs``), and ``pandas.read_csv`` of the file.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DEMO = ROOT / "synthetic_data" / "demo"
MOTOR = DEMO / "motor.toml"
TRUTH = DEMO / "truth.toml"
START_FACTOR = 4.3  # startability at bench_speed's rates
START_ROWS = 112_000  # rows of the startability runs at those rates
SEED = 1


def _protocol_pieces(dest: Path, running_factor: float) -> list[Path]:
    """protocols/*.toml with their sample rates scaled (running × ``running_factor``, startability
    × 4.3), each running protocol split by direction so that no piece passes the simulator's
    plan limit."""
    dest.mkdir(parents=True, exist_ok=True)
    out = []
    for p in sorted((ROOT / "protocols").glob("*.toml")):
        text = p.read_text()
        factor = START_FACTOR if "startability" in p.name else running_factor

        def scale(m):
            v = m.group(2).strip()
            if v.startswith("["):
                nums = [float(x) * factor for x in v.strip("[]").split(",") if x.strip()]
                return m.group(1) + "[" + ", ".join(f"{x:.2f}" for x in nums) + "]"
            return m.group(1) + f"{float(v) * factor:.2f}"

        text = re.sub(r"^(sample_rate_Hz\s*=\s*)([^#\n]*)", scale, text, flags=re.M)
        if "startability" in p.name:
            (dest / p.name).write_text(text)
            out.append(dest / p.name)
            continue
        for d in ("positive", "negative"):
            piece = re.sub(r"^directions\s*=.*$", f'directions = ["{d}"]', text, flags=re.M)
            target = dest / f"{p.stem}-{d[:3]}.toml"
            target.write_text(piece)
            out.append(target)
    return out


def make_campaign(dest: Path, rows: int, seed: int = SEED) -> tuple[Path, int]:
    """One CSV log of about ``rows`` rows in ``dest`` (see the module doc) → (path, rows written)."""
    from motorid.bench.protocols import load_protocol
    from motorid.bench.simulate import simulate_campaign
    from motorid.bench.truth import load_truth
    from motorid.io.logs import _FORMATS, to_format_units
    from motorid.io.spec import load_motor_spec

    spec, truth = load_motor_spec(MOTOR), load_truth(TRUTH)
    # rows the running protocols plan at factor 1; the startability runs end soon after breakaway,
    # before their plan's pressure limit: 112 k rows at 4.3× (the bench_speed campaign)
    factor = max((rows - START_ROWS) / _plan_rows(dest / "p1", 1.0)["running"], 1.0)
    pieces = _protocol_pieces(dest / "protocols", factor)
    log = dest / f"campaign-{rows // 1000}k.csv"
    written, k = 0, 0
    with open(log, "w") as fh:
        for path in pieces:
            proto = load_protocol(path)
            name = path.stem
            for plan in proto.runs:
                one = dataclasses.replace(proto, runs=(plan,), name=name)
                camp = simulate_campaign([one], spec, truth, seed=seed * 100_000 + k)
                k += 1
                table = to_format_units(camp.frame)
                del camp
                for col, fmt in _FORMATS.items():
                    if col in table:
                        vals = table[col].to_numpy(dtype=float)
                        table[col] = np.where(np.isnan(vals), "", np.char.mod(fmt, vals))
                table.to_csv(fh, header=written == 0, index=False, lineterminator="\n")
                written += len(table)
    return log, written


def _plan_rows(dest: Path, factor: float) -> dict:
    """Rows the demo protocols plan at sample rates × ``factor`` (startability, running)."""
    from motorid.bench.protocols import _expected_samples, load_protocol

    out = {"start": 0.0, "running": 0.0}
    for p in _protocol_pieces(dest, factor):
        proto = load_protocol(p)
        n = sum(_expected_samples(proto.procedure, plan, proto.timing) for plan in proto.runs)
        out["start" if proto.procedure == "startability" else "running"] += n
    return out


#: runs the command from a small process and prints its peak RSS [KiB] and wall time [s] last on stderr.
#: Linux keeps a process's peak RSS across exec, so a command forked straight from this (large)
#: process would report at least this process's RSS; forked from the small wrapper it does not.
_WRAP = ("import os, subprocess, sys, time\n"
         "t0 = time.perf_counter(); p = subprocess.Popen(sys.argv[1:])\n"
         "_, status, usage = os.wait4(p.pid, 0)\n"
         "print(f'@peak {usage.ru_maxrss} {time.perf_counter() - t0}', file=sys.stderr)\n"
         "sys.exit(os.waitstatus_to_exitcode(status))")


def _measure(cmd: list, env: dict | None = None) -> tuple[float, float, str]:
    """Run ``cmd`` as a fresh process → (wall [s], peak RSS [MiB], stdout)."""
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.run([sys.executable, "-c", _WRAP, *map(str, cmd)], stdout=out, stderr=err, cwd=ROOT,
                              env=env)
        out.seek(0)
        err.seek(0)
        text, errors = out.read().decode(errors="replace"), err.read().decode(errors="replace")
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} failed ({proc.returncode}):\n{errors[-2000:]}")
    _, kib, wall = errors.strip().splitlines()[-1].split()
    return float(wall), float(kib) / 1024.0, text


_READERS = {
    "motorid streamed (runs handed on, SI)": (
        "from motorid.io.spec import load_motor_spec; from motorid.io.stream import stream_runs; import sys\n"
        "spec = load_motor_spec(sys.argv[2]); n = sum(r.n for r in stream_runs([sys.argv[1]], spec, progress=False))\n"
        "print(n)"),
    "motorid whole-file (read_logs)": (
        "from motorid.io.spec import load_motor_spec; from motorid.io.logs import read_logs; import sys\n"
        "print(len(read_logs([sys.argv[1]], load_motor_spec(sys.argv[2]))))"),
    "pandas.read_csv": "import pandas, sys; print(len(pandas.read_csv(sys.argv[1])))",
    "imports only (python, pandas, pyarrow)": "import pandas, pyarrow.csv; print(0)",
}


def _fit(log: Path, out: Path, env: dict) -> tuple[float, float, dict]:
    py = sys.executable
    wall, rss, _ = _measure([py, "-m", "motorid", "fit", str(log), "--motor", str(MOTOR), "--out", str(out),
                             "--force", "--quiet"], env)
    return wall, rss, json.loads((out / "result.json").read_text())


def _worst_z(doc: dict, truth: dict) -> tuple[float, str]:
    worst, name = 0.0, ""
    for k, e in doc["parameters"].items():
        if e.get("identifiable") and e.get("std") and k in truth:
            z = abs(e["value"] - truth[k]) / e["std"]
            if z > worst:
                worst, name = z, k
    return worst, name


def run(quick: bool = False) -> str:
    sizes = [300_000, 1_000_000] if quick else [300_000, 1_000_000, 3_000_000, 10_000_000]
    exact_sizes = {s for s in sizes if s <= 3_000_000}
    truth = tomllib.load(open(TRUTH, "rb"))["parameters"]
    py = sys.executable
    env = dict(os.environ, MOTORID_QUIET="1")
    env.setdefault("MOTORID_CACHE_DIR", str(Path(tempfile.gettempdir()) / "motorid-bench-memory-cache"))
    exact_env = dict(env, MOTORID_CELL_ROWS=str(10**12))
    fit_rows, read_rows = [], []
    with tempfile.TemporaryDirectory(prefix="motorid-memory-") as tmp:
        tmp = Path(tmp)
        # warm the compile cache once, so that every size pays the same (cache loading, not compiling)
        warm, _ = make_campaign(tmp / "warm", 300_000)
        _fit(warm, tmp / "warm-out", env)
        _fit(warm, tmp / "warm-out", dict(env, MOTORID_CELL_ROWS="1"))
        for size in sizes:
            t0 = time.perf_counter()
            log, rows = make_campaign(tmp / f"c{size}", size)
            gen_s = time.perf_counter() - t0
            mb = log.stat().st_size / 2**20
            print(f"   {rows:,} rows ({mb:.0f} MB) simulated in {gen_s:.0f} s", flush=True)
            wall, rss, doc = _fit(log, tmp / f"out{size}", env)
            z, zname = _worst_z(doc, truth)
            path = "cells" if rows > 500_000 else "per sample"
            ex = ("", "")
            if size in exact_sizes:
                ewall, erss, _ = _fit(log, tmp / f"exact{size}", exact_env)
                ex = (f"{erss:,.0f}", f"{ewall:.1f}")
            print(f"   fit: {wall:.1f} s, {rss:.0f} MiB ({path}); per sample: {ex}", flush=True)
            fit_rows.append((rows, mb, path, rss, wall, ex, z, zname, doc["fit"]["reduced_chi2"]))
            for name, code in _READERS.items():
                w, r, _ = _measure([py, "-c", code, str(log), str(MOTOR)], env)
                read_rows.append((rows, name, w, r))
            log.unlink()
    base = next(r for r in fit_rows if r[0] >= 900_000)
    top = fit_rows[-1]
    growth = top[3] / base[3] - 1.0
    ok = lambda b: "✓" if b else "✗"  # noqa: E731
    lines = [
        "## Memory: `motorid fit` against the rows of the log; reading against pandas",
        "",
        "(study: benchmarks/bench_memory.py; `python benchmarks/run.py --only bench_memory`.) "
        "One CSV log per size: the demo protocols with the running protocols' sample rates scaled up "
        "(the same 180 runs, longer and denser; startability at 4.3×), simulated run by run. "
        "Each command a fresh process; peak RSS from the kernel (`os.wait4`), wall time start to exit, "
        "compile cache warm. Above 500 k rows (`MOTORID_CELL_ROWS`) `motorid fit` streams the log and "
        "fits from shaft-angle cells (docs/large-logs.md); \"per sample\" forces today's path.",
        "",
        "| goal | measured | |",
        "|---|---|---|",
        f"| peak RSS of `motorid fit` at {top[0]/1e6:.1f} M rows < 1.5 GiB | {top[3]:,.0f} MiB | {ok(top[3] < 1536)} |",
        f"| growth from {base[0]/1e6:.1f} M to {top[0]/1e6:.1f} M rows < 10 % | {100 * growth:+.1f} % | "
        f"{ok(growth < 0.10)} |",
        "",
        "| rows | CSV MB | fit path | peak RSS MiB | wall s | per-sample path: peak RSS MiB | wall s | "
        "worst \\|value − truth\\|/std | χ²/dof |",
        "|---:|---:|---|---:|---:|---:|---:|---|---:|",
    ]
    for rows, mb, path, rss, wall, ex, z, zname, chi in fit_rows:
        lines.append(f"| {rows:,} | {mb:,.0f} | {path} | {rss:,.0f} | {wall:.1f} | {ex[0] or '—'} | {ex[1] or '—'} | "
                     f"{z:.2f} ({zname}) | {chi:.3f} |")
    lines += ["", "Reading alone (fresh process each; rows/s over the whole process):", "",
              "| rows | reader | wall s | peak RSS MiB |", "|---:|---|---:|---:|"]
    for rows, name, w, r in read_rows:
        lines.append(f"| {rows:,} | {name} | {w:.1f} | {r:,.0f} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
