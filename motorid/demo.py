"""`make demo`: fit the shipped synthetic campaign and write its report.

    python -m motorid.demo [--out reports/demo] [--no-bayes]

Runs ``motorid fit synthetic_data/demo/*.csv.gz --motor synthetic_data/demo/motor.toml
--out reports/demo --bayes --force --report`` from the repository root, so that
``result.json`` names its inputs by paths relative to the root (``motorid report
reports/demo`` then works from there), and prints where the files are.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CAMPAIGN = Path("synthetic_data") / "demo"
OUT = Path("reports") / "demo"


def campaign_logs(folder: Path) -> list[Path]:
    """The bench logs of the demo campaign (``*.csv.gz`` and ``*.csv``), sorted."""
    return sorted(list(folder.glob("*.csv.gz")) + list(folder.glob("*.csv")))


def main(argv=None) -> int:
    from motorid.cli import main as cli_main

    ap = argparse.ArgumentParser(prog="python -m motorid.demo", description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(OUT), help=f"output folder, relative to the repository root ({OUT})")
    ap.add_argument("--no-bayes", action="store_true", help="least squares only (skip the emcee posterior)")
    args = ap.parse_args(argv)

    if not (ROOT / CAMPAIGN / "motor.toml").exists():
        print(f"motorid demo: error: {ROOT / CAMPAIGN} holds no demo campaign (motor.toml); "
              "run it from a clone of the repository", file=sys.stderr)
        return 2
    here = Path.cwd()
    os.chdir(ROOT)  # the fit records its inputs relative to the repository root
    try:
        logs = campaign_logs(CAMPAIGN)
        if not logs:
            print(f"motorid demo: error: no bench log (*.csv.gz, *.csv) in {ROOT / CAMPAIGN}; regenerate it "
                  f"with the command in {CAMPAIGN / 'README.md'}", file=sys.stderr)
            return 2
        cmd = ["fit", *map(str, logs), "--motor", str(CAMPAIGN / "motor.toml"), "--out", args.out, "--force",
               "--report"] + ([] if args.no_bayes else ["--bayes"])
        print("motorid " + " ".join(cmd), flush=True)
        t0 = time.perf_counter()
        rc = cli_main(cmd)
        seconds = time.perf_counter() - t0
    finally:
        os.chdir(here)
    if rc:
        return rc
    out = (ROOT / args.out).resolve()
    print()
    print(f"demo done in {seconds:.0f} s:")
    print(f"  report  {out / 'report.html'}")
    print(f"  result  {out / 'result.json'}")
    if (out / "chain.npz").exists() and not args.no_bayes:
        print(f"  chain   {out / 'chain.npz'}")
    print(f"open the report in a browser, e.g.  xdg-open {out / 'report.html'}  (or open it on macOS)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
