"""`motorid export RESULT_DIR --format fmu|simscape|python --out PATH`."""

from __future__ import annotations

from pathlib import Path


def register(sub):
    p = sub.add_parser("export", help="the identified motor as an FMU, Simscape loss tables or a Python module")
    p.add_argument("result_dir", help="folder of a fit (result.json; diagnosis.json beside it is included)")
    p.add_argument("--format", required=True, choices=("fmu", "simscape", "python"), dest="fmt")
    p.add_argument("--out", required=True, help="the .fmu file, the tables' folder, or the .py file")
    p.add_argument("--motor", help="motor spec TOML, where the one result.json names cannot be found")
    p.add_argument("--no-diagnosis", action="store_true", help="leave out the mechanisms of diagnosis.json")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.add_argument("--displacement", type=float, metavar="CM3",
                   help="a variable unit's setting to export at [cm3/rev] (a fit of a table with a displacement "
                        "column; default: the spec's)")
    p.add_argument("--assume", action="append", default=[], metavar="KEY=VALUE",
                   help="a value (SI, as in result.json) for a parameter the fit did not determine, e.g. "
                        "--assume KFS=0.012 --assume Ks=0.8 for a map, which holds no breakaway; repeatable")
    g = p.add_argument_group("simscape tables")
    g.add_argument("--temperature", type=float, default=40.0, help="oil temperature of the tables [°C] (40)")
    g.add_argument("--max-pressure", type=float, default=350.0, help="largest |p_A − p_B| [bar] (350)")
    g.add_argument("--max-speed", type=float, default=3000.0, help="largest |speed| [rpm] (3000)")
    g.add_argument("--low-pressure", type=float, default=0.0, help="low-side port pressure [bar gauge] (0)")
    g.add_argument("--case-pressure", type=float, default=0.0, help="case pressure [bar gauge] (0)")
    p.set_defaults(func=run_export)


def run_export(args) -> int:
    import math

    from motorid.errors import InputError
    from motorid.export import export
    from motorid.export.simscape import BAR, RPM

    out = Path(args.out)
    if out.exists() and not args.force:
        raise InputError(f"{out} exists; use --force to overwrite it")
    options = {}
    if args.fmt == "simscape":
        for name in ("temperature", "max_pressure", "max_speed", "low_pressure", "case_pressure"):
            if not math.isfinite(getattr(args, name)):
                raise InputError(f"--{name.replace('_', '-')} must be finite")
        options = {"temperature": args.temperature + 273.15, "max_pressure": args.max_pressure * BAR,
                   "max_speed": args.max_speed * RPM, "p_low": args.low_pressure * BAR,
                   "p_case": args.case_pressure * BAR}
    assume = {}
    for item in args.assume:
        key, sep, text = item.partition("=")
        key = key.strip()
        try:
            value = float(text) if sep and key else math.nan
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise InputError(f"--assume {item}: expected KEY=VALUE with a finite number, e.g. --assume KFS=0.012")
        if key in assume:
            raise InputError(f"--assume {key}: given twice ({assume[key]!r} and {value!r}); keep one")
        assume[key] = value  # a value below a parameter's bound is refused with the result read (export/source.py)
    displacement = None if args.displacement is None else args.displacement * 1e-6
    path = export(args.result_dir, args.fmt, out, motor=args.motor, diagnosis=not args.no_diagnosis,
                  assume=assume, displacement=displacement, **options)
    print(f"wrote {path}")
    return 0
