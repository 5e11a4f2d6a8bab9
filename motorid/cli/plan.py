"""`motorid plan LOG... --motor SPEC.toml`: the extra bench runs that would shrink the worst uncertainty most
(a thin layer over :func:`motorid.experiment_design.suggest_runs`)."""

from __future__ import annotations

import json

from motorid.cli._common import add_campaign_arguments, check_logs_exist
from motorid.errors import InputError


def register(sub):
    p = sub.add_parser("plan", help="suggest the extra bench runs that would shrink the worst uncertainty most")
    add_campaign_arguments(p)
    p.add_argument("--top", type=int, default=5, help="how many runs to suggest (default 5)")
    p.add_argument("--parameter", default=None, help="the parameter to improve (default: the worst-determined)")
    p.add_argument("--json", action="store_true", help="print the plan as JSON")
    p.set_defaults(func=run)


def run(args) -> int:
    from motorid.experiment_design import format_plan, suggest_runs
    from motorid.identify.least_squares import fit_least_squares
    from motorid.identify.pipeline import load_campaign
    from motorid.io.spec import load_motor_spec

    if args.top < 1:
        raise InputError(f"--top must be at least 1, got {args.top}")
    spec = load_motor_spec(args.motor)
    check_logs_exist(args.logs)
    _, dataset = load_campaign(args.logs, spec, args.channels)
    ls = fit_least_squares(dataset, spec)
    plan = suggest_runs(ls, dataset, spec, top=args.top, parameter=args.parameter)
    if args.json:
        doc = {"worst": plan["worst"], "std_now": plan["std_now"],
               "suggestions": [s.as_dict() for s in plan["suggestions"]], "unidentified": plan["unidentified"]}
        print(json.dumps(doc, indent=1, default=float))
    else:
        print(format_plan(plan, ls))
    return 0
