"""`motorid fit LOG... --motor SPEC.toml --out DIR [--bayes] [--force] [--report]`: a thin layer over
:func:`motorid.api.fit`."""

from __future__ import annotations

from pathlib import Path

from motorid.cli._common import add_campaign_arguments, check_logs_exist, check_output
from motorid.errors import InputError


def register(sub):
    p = sub.add_parser("fit", help="identify the motor parameters from bench logs")
    add_campaign_arguments(p, "bench log CSV or CSV.gz files (BENCH_LOG_FORMAT.md)")
    p.add_argument("--out", required=True, help="output folder for result.json")
    p.add_argument("--bayes", action="store_true", help="also sample the posterior with emcee")
    p.add_argument("--force", action="store_true", help="overwrite an existing result")
    p.add_argument("--report", action="store_true", help="also write report.html")
    p.add_argument("--harmonics", type=int, default=None, help="order M of the K_L(θ) Fourier series")
    p.add_argument("--seed", type=int, default=0, help="seed of the sampler")
    p.set_defaults(func=run)


def run(args) -> int:
    from motorid import api
    from motorid.io.results import RESULT_FILE

    out = Path(args.out)
    check_output(out, args.force)
    if args.harmonics is not None and not 0 <= args.harmonics <= 10:
        raise InputError(f"--harmonics must be between 0 and 10, got {args.harmonics}")
    spec = api.load_motor_spec(args.motor)
    check_logs_exist(args.logs)
    from motorid.io.tables import split_logs_and_tables

    logs, tables = split_logs_and_tables(args.logs, args.channels)
    from motorid.cli.tables import reduce_angle_free_logs

    # logs without a shaft angle: their operating points, with the rest (identify/log_points.py)
    logs, more = reduce_angle_free_logs(args, logs, spec, out)
    tables = tables + more
    if tables:  # operating-point tables (no time column): cli/tables.py
        from motorid.cli.tables import run_table_fit

        return run_table_fit(args, logs, tables, spec)
    result = api.fit(args.logs, spec, bayes=args.bayes, harmonics=args.harmonics, seed=args.seed,
                     motor_path=args.motor, channels=args.channels)
    result.save(out)
    from motorid.cli.tables import drop_stale_points

    drop_stale_points(out, result.log_points)
    print(result)
    print(f"wrote {out / RESULT_FILE}")
    if args.report:
        print(f"wrote {result.write_report(out)}")
    return 0
