"""`motorid predict RESULT_DIR POINTS --out PRED.csv [--motor SPEC.toml] [--physics-only] [--force]`."""

from __future__ import annotations

from pathlib import Path

from motorid.errors import InputError


def register(sub):
    p = sub.add_parser("predict", help="torque, flows and efficiencies at operating points, with 95 %% bands")
    p.add_argument("result", help="folder written by motorid fit (its result.json)")
    p.add_argument("points", nargs="+", help="operating-point table(s): speed_rpm, p_a_bar/p_b_bar or dp_bar, ...")
    p.add_argument("--out", required=True, help="CSV to write")
    p.add_argument("--motor", default=None, help="motor spec TOML (default: the one stored in result.json)")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.add_argument("--physics-only", action="store_true",
                   help="the fitted model alone: leave out the model error the fit kriged between its table points")
    p.add_argument("--channels", default=None,
                   help="channel-map TOML for points in a foreign format (e.g. a gridded .mat map; docs/formats.md)")
    p.set_defaults(func=run)


def run(args) -> int:
    from motorid.identify.predict import load_result, predict_points, write_predictions
    from motorid.io.tables import read_tables
    from motorid.io.spec import load_motor_spec

    out = Path(args.out)
    if out.exists() and not args.force:
        raise InputError(f"{out} exists; use --force to overwrite it")
    if out.is_dir():
        raise InputError(f"--out {out}: is a folder; give a CSV file name")
    spec = load_motor_spec(args.motor) if args.motor else None
    result = load_result(args.result, spec)
    table = read_tables(args.points, result[1], require_outputs=False, channels=args.channels)
    frame = predict_points(result, table, physics_only=args.physics_only)
    write_predictions(frame, out)
    kriged = [c[:-len("_model_error")] for c in frame.columns if c.endswith("_model_error")]
    print(f"wrote {out} ({len(frame)} points; bands: _lo95/_hi95 confidence of the model's value, "
          f"_pi_lo95/_pi_hi95 prediction of a new reading" +
          (f"; {', '.join(kriged)} include the fit's kriged model error (the _model_error columns; "
           "--physics-only leaves it out)" if kriged else "") + ")")
    return 0
