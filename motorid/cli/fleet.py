"""`motorid fleet fit|table|report`: thin over motorid.fleet (docs/fleet.md)."""

from __future__ import annotations

import sys

def register(sub):
    p = sub.add_parser("fleet", help="many motors and test dates: fit on Dask, store, population, wear trends")
    fs = p.add_subparsers(dest="fleet_command", required=True)

    f = fs.add_parser("fit", help="fit every campaign folder as a Dask task into FLEET_DIR")
    f.add_argument("campaigns", nargs="+", help="campaign folders (logs, motor.toml, campaign.toml)")
    f.add_argument("--out", required=True, help="the fleet folder (store, fleet.json, campaigns/)")
    f.add_argument("--scheduler", default=None, help="address of a running Dask scheduler, tcp://host:port "
                                                      "(default: an embedded LocalCluster)")
    f.add_argument("--workers", type=int, default=None, help="worker processes of the embedded cluster "
                                                             "(default: one per core)")
    f.add_argument("--diagnose", action="store_true", help="also run the discrepancy search on each campaign")
    f.add_argument("--harmonics", type=int, default=None, help="order M of the K_L(θ) Fourier series")
    f.add_argument("--quiet", action="store_true", help="no progress bar")
    f.set_defaults(func=run_fleet_fit)

    t = fs.add_parser("table", help="print the fleet store (one row per campaign and parameter)")
    t.add_argument("fleet_dir")
    t.add_argument("--sql", default=None, help="a DuckDB query over the views `fleet` and `failed`")
    t.add_argument("--csv", action="store_true", help="CSV instead of aligned text")
    t.set_defaults(func=run_fleet_table)

    r = fs.add_parser("report", help="write FLEET_DIR/fleet_report.html")
    r.add_argument("fleet_dir")
    r.set_defaults(func=run_fleet_report)


def run_fleet_fit(args) -> int:
    from motorid.fleet.fitting import describe_run, fit_fleet

    progress = False if args.quiet else None
    run = fit_fleet(args.campaigns, args.out, scheduler=args.scheduler, workers=args.workers,
                    diagnose=args.diagnose, harmonics=args.harmonics, progress=progress)
    print(describe_run(run, args.out))
    return 0


def run_fleet_table(args) -> int:
    from motorid.fleet.store import failures, query

    df = query(args.fleet_dir, args.sql)
    if args.csv:
        sys.stdout.write(df.to_csv(index=False))
        return 0
    print(df.to_string(index=False, float_format=lambda x: f"{x:.6g}") if len(df) else "(no rows)")
    if args.sql is None:
        for f in failures(args.fleet_dir):
            print(f"failed {f['campaign']}: {f['error']}")
    return 0


def run_fleet_report(args) -> int:
    from motorid.fleet.report import write_fleet_report

    print(f"wrote {write_fleet_report(args.fleet_dir)}")
    return 0
