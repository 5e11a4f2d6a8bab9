"""`motorid fit LOG... --motor SPEC.toml --out DIR [--bayes] [--force] [--report]`."""

from __future__ import annotations

import sys
from pathlib import Path

from motorid.cli import subcommand
from motorid.errors import InputError


@subcommand
def register(sub):
    p = sub.add_parser("fit", help="identify the motor parameters from bench logs")
    p.add_argument("logs", nargs="+", help="bench log CSV or CSV.gz files, or operating-point tables (BENCH_LOG_FORMAT.md)")
    p.add_argument("--motor", required=True, help="motor spec TOML")
    p.add_argument("--out", required=True, help="output folder for result.json")
    p.add_argument("--bayes", action="store_true", help="also sample the posterior with emcee")
    p.add_argument("--force", action="store_true", help="overwrite an existing result")
    p.add_argument("--report", action="store_true", help="also write report.html")
    p.add_argument("--harmonics", type=int, default=None, help="order M of the K_L(θ) Fourier series")
    p.add_argument("--seed", type=int, default=0, help="seed of the sampler")
    p.set_defaults(func=run_fit)


def check_output(out: Path, force: bool, files=("result.json",)):
    for name in files:
        if (out / name).exists() and not force:
            raise InputError(f"{out / name} exists; use --force to overwrite it")
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a folder")


def check_logs_exist(logs) -> None:
    for log in logs:
        if not Path(log).exists():
            raise InputError(f"{log}: no such file")


def run_fit(args) -> int:
    from motorid.identify.least_squares import FitOptions
    from motorid.identify.pipeline import identify
    from motorid.identify.results import CHAIN_FILE, RESULT_FILE, result_document, write_chain, write_json_atomic
    from motorid.spec import load_motor_spec

    out = Path(args.out)
    check_output(out, args.force)
    if args.harmonics is not None and not 0 <= args.harmonics <= 10:
        raise InputError(f"--harmonics must be between 0 and 10, got {args.harmonics}")
    spec = load_motor_spec(args.motor)
    check_logs_exist(args.logs)
    from motorid.io.tables import split_logs_and_tables

    logs, tables = split_logs_and_tables(args.logs)
    if tables:  # operating-point tables (no time column): motorid/identify/table_pipeline.py
        from motorid.identify.table_pipeline import run_table_fit

        return run_table_fit(args, logs, tables, spec)
    res = identify(args.logs, spec, bayes=args.bayes, options=FitOptions(harmonics=args.harmonics),
                   seed=args.seed)
    inputs = {"logs": [str(p) for p in args.logs], "motor": str(args.motor)}
    doc = result_document(res.ls, spec, res.dataset, res.bayes, inputs, res.seconds, res.priors)
    doc["motor_spec"] = spec.to_toml()  # motorid predict needs nothing else
    out.mkdir(parents=True, exist_ok=True)
    if res.bayes is not None:
        write_chain(res.bayes, out / CHAIN_FILE)
    write_json_atomic(doc, out / RESULT_FILE)
    print(format_summary(doc))
    print(f"wrote {out / RESULT_FILE}")
    if args.report:
        from motorid.report.html import write_report

        path = write_report(out, identification=res, spec=spec)
        print(f"wrote {path}")
    return 0


def format_summary(doc: dict) -> str:
    lines = [f"{'parameter':<8} {'value':>12} {'std':>10}  {'unit':<5} identifiable"]
    for k, e in doc["parameters"].items():
        if e["identifiable"]:
            lines.append(f"{k:<8} {e['value']:>12.5g} {e['std']:>10.3g}  {e['unit']:<5} yes")
        else:
            lines.append(f"{k:<8} {'—':>12} {'—':>10}  {e['unit']:<5} no: {e.get('reason', '')}")
    fit = doc["fit"]
    lines.append(f"χ²/dof = {fit['reduced_chi2']:.3f}; outliers rejected: "
                 + ", ".join(f"{c} {n}" for c, n in fit["outliers"].items()))
    for w in fit["warnings"]:
        lines.append(f"warning: {w}")
    if "mcmc" in doc:
        m = doc["mcmc"]
        lines.append(f"emcee: {m['steps']} steps × {m['walkers']} walkers, converged: {m['converged']}")
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(0)
