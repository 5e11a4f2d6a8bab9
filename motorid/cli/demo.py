"""`motorid demo` (what `make demo` runs): fit the shipped synthetic campaign and write its report.

    motorid demo [--out reports/demo] [--no-bayes]

Runs ``motorid fit synthetic_data/demo/*.csv.gz --motor synthetic_data/demo/motor.toml
--out reports/demo --bayes --force --report`` from the repository root, so that
``result.json`` names its inputs by paths relative to the root (``motorid report
reports/demo`` then works from there), and prints where the files are.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from motorid.errors import InputError

ROOT = Path(__file__).resolve().parents[2]
CAMPAIGN = Path("synthetic_data") / "demo"
OUT = Path("reports") / "demo"


def campaign_logs(folder: Path) -> list[Path]:
    """The bench logs of the demo campaign (``*.csv.gz`` and ``*.csv``), sorted."""
    return sorted(list(folder.glob("*.csv.gz")) + list(folder.glob("*.csv")))


def register(sub):
    p = sub.add_parser("demo", help="fit the shipped demo campaign and write its report (make demo)",
                       description=__doc__.splitlines()[0])
    p.add_argument("--out", default=str(OUT), help=f"output folder, relative to the repository root ({OUT})")
    p.add_argument("--no-bayes", action="store_true", help="least squares only (skip the emcee posterior)")
    p.set_defaults(func=run)


def run(args) -> int:
    from motorid.cli.commands import main

    if not (ROOT / CAMPAIGN / "motor.toml").exists():
        raise InputError(f"{ROOT / CAMPAIGN} holds no demo campaign (motor.toml); run it from a clone of the repository")
    here = Path.cwd()
    os.chdir(ROOT)  # the fit records its inputs relative to the repository root
    try:
        logs = campaign_logs(CAMPAIGN)
        if not logs:
            raise InputError(f"no bench log (*.csv.gz, *.csv) in {ROOT / CAMPAIGN}; regenerate it "
                             f"with the command in {CAMPAIGN / 'README.md'}")
        cmd = ["fit", *map(str, logs), "--motor", str(CAMPAIGN / "motor.toml"), "--out", args.out, "--force",
               "--report"] + ([] if args.no_bayes else ["--bayes"])
        print("motorid " + " ".join(cmd), flush=True)
        t0 = time.perf_counter()
        rc = main(cmd)
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
