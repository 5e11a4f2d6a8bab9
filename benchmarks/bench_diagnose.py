"""Speed and memory of ``motorid diagnose``, side by side with ``motorid fit`` and the old diagnose.

    python benchmarks/run.py --only bench_diagnose [--quick]

A campaign of about 320 k rows (quick: about 75 k) with two concealed effects (Stribeck
friction and compressibility flow, the sizes of synthetic_data/concealed/truths/
stribeck_and_compressibility.toml) is simulated from the repository's protocols with every
sample rate scaled up.  Then, in one session on one machine, each a fresh process timed
by /usr/bin/time (wall seconds, peak resident memory):

1. ``motorid fit`` three times (the first fills the compile cache; the better of runs 2 and 3
   counts);
2. ``motorid diagnose`` three times, the same way;
3. the old diagnose (benchmarks/diagnose_baseline.py: every candidate a full fit on every
   sample, as before issue 16) once, warm (skipped with --quick: it takes minutes);
4. where diagnose's time goes, per step (``Diagnosis.seconds``), in-process;
5. the verdicts of the new diagnose on every concealed campaign of synthetic_data/concealed/
   against its truth (skipped with --quick; the causes_* ones only with BENCH_DIAGNOSE_CAUSES=1).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

from bench_speed import _scaled_protocols  # noqa: E402

CONCEALED = ROOT / "synthetic_data" / "concealed"
CASE = "stribeck_and_compressibility"
SEED = 7


def _timed(cmd, env) -> tuple[float, float, subprocess.CompletedProcess]:
    """(wall s, peak RSS GiB, process) of one fresh process."""
    full = ["/usr/bin/time", "-f", "@@%e %M", *map(str, cmd)]
    proc = subprocess.run(full, capture_output=True, text=True, cwd=ROOT, env=env)
    line = [x for x in proc.stderr.splitlines() if x.startswith("@@")][-1]
    wall, kb = line[2:].split()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} failed ({proc.returncode}):\n{proc.stderr[-2000:]}")
    return float(wall), float(kb) / 2**20, proc


def _simulate(tmp: Path, factor: float, py: str, env) -> tuple[Path, Path, int]:
    protocols = _scaled_protocols(tmp / "protocols", factor)
    motor = tmp / "motor.toml"
    shutil.copy(CONCEALED / CASE / "motor.toml", motor)
    subprocess.run([py, "-m", "motorid", "simulate", "--protocol", str(protocols), "--motor", str(motor),
                    "--truth", str(CONCEALED / "truths" / f"{CASE}.toml"), "--out", str(tmp / "sim"),
                    "--seed", str(SEED)], check=True, cwd=ROOT, env=env, capture_output=True)
    log = tmp / "sim" / "campaign.csv.gz"
    import pandas as pd

    rows = len(pd.read_csv(log, usecols=[0]))
    return log, motor, rows


def _steps(log: Path, motor: Path) -> tuple[dict, list]:
    from motorid.discrepancy.select import diagnose
    from motorid.identify.pipeline import load_campaign
    from motorid.io.spec import load_motor_spec

    spec = load_motor_spec(motor)
    t0 = time.perf_counter()
    _, data = load_campaign([log], spec)
    read = time.perf_counter() - t0
    dg = diagnose(data, spec)
    return {"read and extract": read, **dg.seconds}, [c.mechanism.id for c in dg.accepted]


def _truth_ids(name: str) -> set:
    t = tomllib.loads((CONCEALED / "truths" / f"{name}.toml").read_text())
    return set(t.get("mechanisms", {}))


def _verdicts(py: str, env, tmp: Path) -> list:
    """The verdict on every concealed campaign of synthetic_data/concealed/ (about 24 k rows each);
    the causes_* campaigns (1.3 M rows each, minutes apiece: bench_causes diagnoses them) only with
    BENCH_DIAGNOSE_CAUSES=1."""
    rows = []
    causes = os.environ.get("BENCH_DIAGNOSE_CAUSES") == "1"
    for folder in sorted(p for p in CONCEALED.iterdir() if (p / "campaign.csv.gz").exists()
                         and (causes or not p.name.startswith("causes_"))):
        out = tmp / f"dg_{folder.name}"
        t0 = time.perf_counter()
        proc = subprocess.run([py, "-m", "motorid", "diagnose", str(folder / "campaign.csv.gz"), "--motor",
                               str(folder / "motor.toml"), "--out", str(out), "--force", "--quiet"],
                              capture_output=True, text=True, cwd=ROOT, env=env)
        dt = time.perf_counter() - t0
        if proc.returncode:
            rows.append((folder.name, "—", "error: " + proc.stderr.strip().splitlines()[-1][:80], dt, False))
            continue
        doc = json.loads((out / "diagnosis.json").read_text())
        named = {m["id"] for m in doc["mechanisms"]}
        truth = _truth_ids(folder.name)
        rows.append((folder.name, ", ".join(sorted(truth)) or "none", ", ".join(sorted(named)) or
                     ("unexplained" if doc["mismatch"] else "none"), dt, named == truth or (not named and not truth
                                                                                             and not doc["mismatch"])))
    return rows


def run(quick: bool = False) -> str:
    py = sys.executable
    factor = 1.0 if quick else 4.3
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        env = dict(os.environ, MOTORID_CACHE_DIR=str(tmp / "jaxcache"), MOTORID_QUIET="1")
        log, motor, rows = _simulate(tmp, factor, py, env)
        common = [log, "--motor", motor, "--force", "--quiet"]
        fit = [_timed([py, "-m", "motorid", "fit", *common, "--out", tmp / "fit"], env) for _ in range(3)]
        dg = [_timed([py, "-m", "motorid", "diagnose", *common, "--out", tmp / "dg"], env) for _ in range(3)]
        named = [m["id"] for m in json.loads((tmp / "dg" / "diagnosis.json").read_text())["mechanisms"]]
        base = None
        # BENCH_DIAGNOSE_BASELINE=0 skips the old diagnose (12 minutes on 2 cores): its row is then the
        # last measured one, said so
        if not quick and os.environ.get("BENCH_DIAGNOSE_BASELINE") != "0":
            base = _timed([py, str(HERE / "diagnose_baseline.py"), log, motor, tmp / "base.json"], env)
            base_named = json.loads((tmp / "base.json").read_text())["mechanisms"]
        os.environ["MOTORID_CACHE_DIR"] = env["MOTORID_CACHE_DIR"]
        steps, _ = _steps(log, motor)
        # BENCH_DIAGNOSE_VERDICTS=0 skips the concealed campaigns (minutes)
        verdicts = [] if quick or os.environ.get("BENCH_DIAGNOSE_VERDICTS") == "0" else _verdicts(py, env, tmp)

    fit_w, fit_m = min(f[0] for f in fit[1:]), max(f[1] for f in fit[1:])
    dg_w, dg_m = min(d[0] for d in dg[1:]), max(d[1] for d in dg[1:])
    lines = [
        "## Diagnose at the speed of a fit",
        "",
        "`python benchmarks/run.py --only bench_diagnose` (study: benchmarks/bench_diagnose.py; baseline: "
        "benchmarks/diagnose_baseline.py, the diagnose of before issue 16, run on today's fit functions).",
        "",
        f"Campaign: {rows:,} rows, concealed Stribeck friction + compressibility flow "
        f"(truths/{CASE}.toml), protocols/*.toml with every sample rate × {factor}. Each command a fresh "
        "process; wall time and peak RSS from /usr/bin/time; the better of runs 2 and 3 (run 1 fills the "
        "compile cache). The 2-core machine may be shared: the side-by-side ratios are what counts.",
        "",
        "| command | wall, first run | wall, later run | peak RSS | named |",
        "|---|---:|---:|---:|---|",
        f"| `motorid fit` | {fit[0][0]:.1f} s | {fit_w:.1f} s | {fit_m:.2f} GiB | — |",
        f"| `motorid diagnose` | {dg[0][0]:.1f} s | {dg_w:.1f} s | {dg_m:.2f} GiB | {', '.join(named) or 'none'} |",
    ]
    if base is not None:
        lines.append(f"| old diagnose (baseline) | — | {base[0]:.1f} s | {base[1]:.2f} GiB | "
                     f"{', '.join(base_named) or 'none'} |")
    elif not quick:
        lines.append("| old diagnose (baseline), as last measured (commit d961243, not rerun: "
                     "BENCH_DIAGNOSE_BASELINE=0) | — | 750.5 s | 2.86 GiB | stribeck_friction, compressibility_flow |")
    lines += ["", "| goal | value | |", "|---|---:|---|",
              f"| diagnose wall ≤ 3 × fit wall | {dg_w / fit_w:.2f} × | {'**met**' if dg_w <= 3 * fit_w else '**not met**'} |",
              f"| diagnose peak RSS ≤ 1.5 × fit's | {dg_m / fit_m:.2f} × | {'**met**' if dg_m <= 1.5 * fit_m else '**not met**'} |"]
    if base is not None:
        lines.append(f"| diagnose against the old diagnose | {base[0] / dg_w:.0f} × faster, "
                     f"{base[1] / dg_m:.1f} × less memory | same names: {'yes' if base_named == named else 'NO'} |")
    lines += ["", "### Where diagnose's time goes (in-process, warm)", "", "| step | seconds |", "|---|---:|"]
    lines += [f"| {k} | {v:.2f} |" for k, v in steps.items()]
    if verdicts:
        ok = sum(v[4] for v in verdicts)
        clean = [v for v in verdicts if v[1] == "none"]
        alarms = sum(1 for v in clean if not v[4])
        lines += ["", f"### Verdicts on every concealed campaign ({ok}/{len(verdicts)} exactly right; "
                  f"{alarms} false alarms on {len(clean)} clean campaigns)", "",
                  "| campaign | truth | named | seconds | right |", "|---|---|---|---:|---|"]
        lines += [f"| {n} | {t} | {m} | {s:.1f} | {'yes' if r else 'no'} |" for n, t, m, s, r in verdicts]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
