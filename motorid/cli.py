"""The ``motorid`` command line.

Every user error becomes one line on stderr and exit status 2; no traceback.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

from motorid.errors import InputError


def _cmd_ripple_table(args) -> int:
    from motorid.physics.kinematics import ripple_coefficients

    rows = []
    for n in range(args.min_pistons, args.max_pistons + 1):
        c1, c2, sigma = ripple_coefficients(n, points=args.points)
        rows.append({"pistons": n, "C1": c1, "C2": c2, "sigma": sigma})
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    families = [("Table 1: n = 2k+1", lambda n: n % 2 == 1),
                ("Table 2: n = 4k-2", lambda n: n % 4 == 2),
                ("Table 3: n = 4k", lambda n: n % 4 == 0)]
    for title, keep in families:
        print(title)
        print(f"{'pistons':>8} {'C1':>12} {'C2':>12} {'2πσ/DΔP':>12}")
        for r in rows:
            if keep(r["pistons"]):
                print(f"{r['pistons']:>8} {r['C1']:>12.4e} {r['C2']:>12.4e} {r['sigma']:>12.4e}")
        print()
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="motorid", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    rt = sub.add_parser("ripple-table", help="the report's Tables 1-3 (C1, C2, σ) from the exact model")
    rt.add_argument("--json", action="store_true", help="print a JSON list of {pistons, C1, C2, sigma}")
    rt.add_argument("--min-pistons", type=int, default=2)
    rt.add_argument("--max-pistons", type=int, default=20)
    rt.add_argument("--points", type=int, default=500, help="samples over one ripple (report: 500)")
    rt.set_defaults(func=_cmd_ripple_table)

    for register in _REGISTRARS:
        register(sub)
    return p


_REGISTRARS: list = []


def subcommand(register):
    """Decorator: modules add their subcommands to the parser through this list."""
    _REGISTRARS.append(register)
    return register


def _load_subcommands():
    import importlib

    for mod in ("motorid.bench.cli", "motorid.identify.cli", "motorid.report.cli",
                "motorid.discrepancy.cli", "motorid.design", "motorid.identify.predict_cli"):
        try:
            importlib.import_module(mod)
        except ModuleNotFoundError as exc:
            if exc.name != mod:
                raise


def main(argv=None) -> int:
    _load_subcommands()
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"motorid {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"motorid {args.command}: interrupted", file=sys.stderr)
        return 130


def console() -> None:
    """The ``motorid`` command: :func:`main`, then a prompt exit.

    Everything is written and closed by then; ``os._exit`` skips the interpreter's
    teardown of JAX and XLA (a fifth of a second that the user would wait for nothing).
    """
    rc = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(rc)


if __name__ == "__main__":
    console()
