"""`make bench`: every study, each writing its section; results.md assembles them.

    python benchmarks/run.py [--only NAME ...] [--quick]

Each study is a module in benchmarks/ with ``run(quick: bool) -> str`` returning
a Markdown section (tables with the command that made them).  Sections are kept
in benchmarks/sections/NAME.md, so one study can be re-run alone and the others
stay in results.md.
"""

from __future__ import annotations

import argparse
import datetime as dt
import importlib
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
STUDIES = ["bench_speed", "bench_discrepancy", "bench_estimators", "bench_design", "bench_scaling", "bench_foreign",
           "bench_fleet", "bench_export", "bench_causes", "bench_maps", "bench_formats", "bench_mapphysics",
           "bench_memory", "bench_memory_hdf5", "bench_diagnose", "bench_angle_free", "bench_real_maps"]


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = ""
    try:
        for line in open("/proc/meminfo"):
            if line.startswith("MemTotal"):
                mem = f", {int(line.split()[1]) / 2**20:.0f} GiB"
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores{mem}, Python {platform.python_version()}, {platform.system()}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", nargs="*", default=None,
                    help="run only these studies (none: just reassemble results.md from the sections)")
    ap.add_argument("--quick", action="store_true", help="smaller studies, for a smoke run")
    a = ap.parse_args(argv)
    sys.path.insert(0, str(HERE))
    (HERE / "sections").mkdir(exist_ok=True)
    for name in (STUDIES if a.only is None else a.only):
        t0 = time.time()
        print(f"== {name}", flush=True)
        section = importlib.import_module(name).run(quick=a.quick)
        (HERE / "sections" / f"{name}.md").write_text(section.rstrip() + "\n")
        print(f"   {time.time() - t0:.0f} s", flush=True)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=HERE).stdout.strip()
    parts = [
        "# motorid benchmarks",
        "",
        f"Made by `make bench` (`python benchmarks/run.py`) on {dt.date.today().isoformat()}, "
        f"commit {commit or '?'}.  Machine: {machine()}.  Each section names the command that "
        "made its numbers; ratios compare motorid with a baseline run side by side in the same process "
        "or session.",
        "",
    ]
    for name in STUDIES:
        p = HERE / "sections" / f"{name}.md"
        if p.exists():
            parts += [p.read_text(), ""]
    (HERE / "results.md").write_text("\n".join(parts))
    print(f"wrote {HERE / 'results.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
