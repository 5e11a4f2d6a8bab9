"""`motorid report DIR [--logs LOG...] [--motor SPEC.toml]`: write DIR/report.html from DIR/result.json."""

from __future__ import annotations

from pathlib import Path

from motorid.cli import subcommand
from motorid.errors import InputError


@subcommand
def register(sub):
    p = sub.add_parser("report", help="write a self-contained report.html beside a result.json",
                       description="Write DIR/report.html from DIR/result.json (and DIR/chain.npz, "
                                   "DIR/diagnosis.json where present). The campaign named in result.json is "
                                   "re-read and the model evaluated at the fitted parameters; nothing is refitted.")
    p.add_argument("dir", help="result folder of `motorid fit`")
    p.add_argument("--logs", nargs="+", metavar="LOG", help="bench logs, where they moved since the fit")
    p.add_argument("--motor", metavar="SPEC.toml", help="motor spec, where it moved since the fit")
    p.set_defaults(func=run_report)


def run_report(args) -> int:
    from motorid.identify.cli import check_logs_exist
    from motorid.report.html import write_report

    out = Path(args.dir)
    if not out.is_dir():
        raise InputError(f"{out}: no such folder")
    check_logs_exist(args.logs or [])
    existed = (out / "report.html").exists()
    from motorid.report.maps import is_table_result, rerender_map_report

    if is_table_result(out):  # a fit with operating-point tables: report/maps.py
        path = rerender_map_report(out, motor=args.motor)
    else:
        path = write_report(out, logs=args.logs, motor=args.motor)
    print(f"{'replaced' if existed else 'wrote'} {path}")
    return 0
