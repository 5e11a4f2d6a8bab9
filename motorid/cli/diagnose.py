"""`motorid diagnose LOG... --motor SPEC.toml --out DIR`: a thin layer over :func:`motorid.api.diagnose`."""

from __future__ import annotations

import sys
from pathlib import Path

from motorid.cli._common import add_campaign_arguments, check_logs_exist, check_output
from motorid.errors import InputError


def register(sub):
    p = sub.add_parser("diagnose", help="locate model-data mismatch, name the missing physics, refit")
    add_campaign_arguments(p)
    p.add_argument("--out", required=True, help="output folder for diagnosis.json")
    p.add_argument("--force", action="store_true", help="overwrite an existing diagnosis")
    p.add_argument("--alpha", type=float, default=1e-3, help="family-wise false-alarm rate of the structure tests")
    p.add_argument("--min-evidence", type=float, default=10.0, help="ΔBIC a mechanism must earn")
    p.set_defaults(func=run)


def run(args) -> int:
    from motorid import api
    from motorid.io.results import DIAGNOSIS_FILE

    out = Path(args.out)
    check_output(out, args.force, files=(DIAGNOSIS_FILE,))
    spec = api.load_motor_spec(args.motor)
    check_logs_exist(args.logs)
    if not 0 < args.alpha < 1:
        raise InputError(f"--alpha must be between 0 and 1, got {args.alpha}")
    from motorid.io.tables import split_logs_and_tables

    logs, tables = split_logs_and_tables(args.logs, args.channels)
    from motorid.cli.tables import reduce_angle_free_logs

    # logs without a shaft angle: their operating points, with the rest (identify/log_points.py)
    logs, more = reduce_angle_free_logs(args, logs, spec, out, say=True)
    tables = tables + more
    if tables:  # operating-point tables: cli/tables.py
        from motorid.cli.tables import run_table_diagnose

        return run_table_diagnose(args, logs, tables, spec)
    show = sys.stderr.isatty()
    result = api.diagnose(args.logs, spec, alpha=args.alpha, min_evidence=args.min_evidence, motor_path=args.motor,
                          channels=args.channels,
                          progress=(lambda m: print(f"  {m}", file=sys.stderr)) if show else None)
    result.save(out)
    from motorid.cli.tables import drop_stale_points

    drop_stale_points(out, result.log_points)
    print(result)
    print(f"wrote {out / DIAGNOSIS_FILE}")
    write_refit(out, args, spec, [m["id"] for m in result.document.get("mechanisms", [])], result.refit)
    return 0


def write_refit(out: Path, args, spec, mechanisms: list, refit=None) -> None:
    """result.json beside diagnosis.json: the fit of the same logs with the mechanisms diagnose named, so
    that `motorid predict`, `report` and `export` take the diagnosed model (a fit, as `motorid fit` writes
    it; an empirical term of an unexplained entry is not in it): ``refit``, diagnose's own final fit,
    where given, else fitted here.  Tables: cli/tables.py."""
    from motorid import api
    from motorid.io.results import RESULT_FILE

    if refit is None:
        refit = api.fit(args.logs, spec, mechanisms=mechanisms, motor_path=args.motor, channels=args.channels)
    refit.document["fit"]["from_diagnose"] = True
    target = refit_folder(out)
    refit.save(target)
    say_refit(target / RESULT_FILE, mechanisms)


def say_refit(path: Path, mechanisms) -> None:
    print(f"wrote {path} (the fit " + (f"with {', '.join(mechanisms)}" if mechanisms else "of the 1992 model alone")
          + "; predict, report and export take it)")


def refit_folder(out: Path) -> Path:
    """Where diagnose writes its refit's result.json: ``out``, unless a result.json of `motorid fit` is
    there already (fit and diagnose into one folder, then `motorid report` on both): then ``out/diagnosed``."""
    import json

    from motorid.io.results import RESULT_FILE

    existing = out / RESULT_FILE
    if existing.exists():
        try:
            ours = json.loads(existing.read_text()).get("fit", {}).get("from_diagnose", False)
        except (ValueError, OSError):
            ours = False
        if not ours:
            return out / "diagnosed"
    return out
