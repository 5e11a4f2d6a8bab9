"""`motorid diagnose LOG... --motor SPEC.toml --out DIR`."""

from __future__ import annotations

import sys
from pathlib import Path

from motorid.cli import subcommand


@subcommand
def register(sub):
    p = sub.add_parser("diagnose", help="locate model-data mismatch, name the missing physics, refit")
    p.add_argument("logs", nargs="+", help="bench log CSV or CSV.gz files")
    p.add_argument("--motor", required=True, help="motor spec TOML")
    p.add_argument("--out", required=True, help="output folder for diagnosis.json")
    p.add_argument("--force", action="store_true", help="overwrite an existing diagnosis")
    p.add_argument("--alpha", type=float, default=1e-3, help="family-wise false-alarm rate of the structure tests")
    p.add_argument("--min-evidence", type=float, default=10.0, help="ΔBIC a mechanism must earn")
    p.set_defaults(func=run_diagnose)


def run_diagnose(args) -> int:
    import io

    import numpy as np

    from motorid._atomic import write_bytes_atomic
    from motorid.discrepancy.select import diagnose, diagnosis_document, residual_arrays
    from motorid.identify.cli import check_logs_exist, check_output
    from motorid.identify.pipeline import load_campaign
    from motorid.identify.results import write_json_atomic
    from motorid.spec import load_motor_spec
    from motorid.errors import InputError

    out = Path(args.out)
    check_output(out, args.force, files=("diagnosis.json",))
    spec = load_motor_spec(args.motor)
    check_logs_exist(args.logs)
    if not 0 < args.alpha < 1:
        raise InputError(f"--alpha must be between 0 and 1, got {args.alpha}")
    from motorid.io.tables import split_logs_and_tables

    logs, tables = split_logs_and_tables(args.logs)
    if tables:  # operating-point tables: motorid/identify/table_pipeline.py
        from motorid.identify.table_pipeline import run_table_diagnose

        return run_table_diagnose(args, logs, tables, spec)
    _, dataset = load_campaign(args.logs, spec)
    show = sys.stderr.isatty()
    dg = diagnose(dataset, spec, alpha=args.alpha, min_evidence=args.min_evidence,
                  progress=(lambda m: print(f"  {m}", file=sys.stderr)) if show else None)
    doc = diagnosis_document(dg, spec)
    doc["inputs"] = {"logs": [str(p) for p in args.logs], "motor": str(args.motor)}
    out.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    np.savez_compressed(buf, **residual_arrays(dg, dataset))
    write_bytes_atomic(out / "diagnosis_residuals.npz", buf.getvalue())
    write_json_atomic(doc, out / "diagnosis.json")
    print(format_diagnosis(doc))
    print(f"wrote {out / 'diagnosis.json'}")
    return 0


def format_diagnosis(doc: dict) -> str:
    if not doc["mismatch"]:
        return "no mismatch: the residuals of every channel are consistent with the noise"
    lines = []
    for m in doc["mechanisms"]:
        lines.append(f"found {m['id']} ({m['name']}): {m['where']}")
        lines.append(f"  {m['explanation']}")
        for k, p in m["parameters"].items():
            if p["value"] is not None:
                lines.append(f"  {k} = {p['value']:.4g} ± {(p['std'] or 0):.2g} {p['unit']}")
    for u in doc["unexplained"]:
        lines.append(f"unexplained: {u['where']}")
    for c, v in doc["channels"].items():
        if v["residual_rms_before"] is not None:
            lines.append(f"{c}: residual RMS {v['residual_rms_before']:.4g} → {v['residual_rms_after']:.4g} "
                         f"(noise {v['noise']:.4g}) [SI]")
    return "\n".join(lines)
