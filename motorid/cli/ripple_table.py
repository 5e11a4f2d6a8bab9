"""`motorid ripple-table`: the report's Tables 1-3 (C1, C2, σ) from the exact model
(a thin layer over :func:`motorid.physics.kinematics.ripple_coefficients`)."""

from __future__ import annotations

import json


def register(sub):
    rt = sub.add_parser("ripple-table", help="the report's Tables 1-3 (C1, C2, σ) from the exact model")
    rt.add_argument("--json", action="store_true", help="print a JSON list of {pistons, C1, C2, sigma}")
    rt.add_argument("--min-pistons", type=int, default=2)
    rt.add_argument("--max-pistons", type=int, default=20)
    rt.add_argument("--points", type=int, default=500, help="samples over one ripple (report: 500)")
    rt.set_defaults(func=run)


def run(args) -> int:
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
