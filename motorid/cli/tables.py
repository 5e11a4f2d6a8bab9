"""`motorid fit` and `motorid diagnose` when operating-point tables are given (alone or with logs).

The commands in cli/fit.py and cli/diagnose.py hand over here when any given file is a table (no time column).
"""

from __future__ import annotations

from pathlib import Path

from motorid.errors import InputError
from motorid.discrepancy.tables import diagnose_tables, diagnosis_table_document
from motorid.identify.table_pipeline import identify_tables, table_inputs, table_result_document


def reduce_angle_free_logs(args, logs, spec, out: Path, say: bool = False) -> tuple[list, list]:
    """The logs that hold no shaft angle → their operating points, a CSV in a temporary folder until the
    command succeeds (:func:`place_points` moves it into ``out``) → (logs for the log fit, [that CSV]);
    where every log holds an angle: (logs, [])."""
    from motorid.identify.log_points import reduce_logs_without_angle
    from motorid.io.tables import split_channel_map

    if not logs:
        return logs, []
    _, log_map = split_channel_map(getattr(args, "channels", None))
    kept, reduced = reduce_logs_without_angle(logs, spec, log_map)
    if reduced is None:
        return logs, []
    if say:  # (a fit says it in its warnings)
        print(reduced.summary())
        for note in reduced.notes:
            print(f"  {note}")
    args.reduced_logs = list(reduced.sources)
    args.log_points = reduced
    return kept, [reduced.path]


def drop_stale_points(out: Path, reduced) -> None:
    """Remove a points_from_logs.csv an earlier run left in ``out`` (--force) where this run made none:
    the folder must not show points its result.json was not fitted on."""
    from motorid.identify.log_points import POINTS_FILE

    stale = out / POINTS_FILE
    if reduced is None and stale.exists():
        stale.unlink()


def place_points(args, doc: dict, out: Path) -> None:
    """Move the operating points of :func:`reduce_angle_free_logs` into ``out`` and say in ``doc`` where they
    came from (:meth:`~motorid.identify.log_points.LogPoints.annotate`)."""
    reduced = getattr(args, "log_points", None)
    if reduced is not None:
        reduced.move_into(doc, out)
        reduced.annotate(doc, args.reduced_logs)


def run_table_fit(args, logs, tables, spec) -> int:
    """The `motorid fit` command when tables are given."""
    from motorid.comparators.evaluate import compare
    from motorid.cli._common import check_output
    from motorid.identify.results import RESULT_FILE, write_json_atomic
    from motorid.report.summary import format_fit as format_summary

    if getattr(args, "bayes", False):
        raise InputError("--bayes is not available with operating-point tables, nor with logs fitted as their "
                         "points (the least-squares covariance is reported)")
    out = Path(args.out)
    check_output(out, args.force)
    tf = identify_tables(logs, tables, spec, harmonics=args.harmonics, channels=getattr(args, "channels", None))
    comparison = compare(tf.table, spec) if len(tf.table) >= 10 else None
    inputs = table_inputs(logs, tables, str(args.motor), getattr(args, "channels", None))
    doc = table_result_document(tf, spec, inputs, comparison)
    place_points(args, doc, out)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(doc, out / RESULT_FILE)
    drop_stale_points(out, getattr(args, "log_points", None))
    print(format_summary(doc))
    if comparison is not None:
        print(format_comparison(comparison))
    else:
        print(f"no held-out comparison: {len(tf.table)} points, and the K-fold and extrapolation splits need at "
              "least 10 (each fold must leave points to fit on)")
    print(f"wrote {out / RESULT_FILE}")
    if getattr(args, "report", False):
        from motorid.report.maps import write_map_report

        path = write_map_report(out, doc, tf, spec)
        print(f"wrote {path}")
    return 0


def format_comparison(comparison: dict) -> str:
    """A text table of the held-out errors (% of each channel's span)."""
    lines = ["held-out RMS error, % of span (K-fold | extrapolation in ΔP | in speed):"]
    width = max([26] + [len(name) for name in comparison["models"]])
    for name, res in comparison["models"].items():
        cells = []
        for c in ("torque", "q_a", "q_b", "q_case"):
            vals = [res.get(k, {}).get(c, {}).get("percent_of_span") for k in
                    ("kfold", "extrapolate_pressure", "extrapolate_speed")]
            if any(v is not None for v in vals):
                cells.append(f"{c} " + "|".join("—" if v is None else f"{v:.2f}" for v in vals))
        lines.append(f"  {name:<{width}} " + "  ".join(cells))
    return "\n".join(lines)


# ----------------------------------------------------------------------------- diagnose


def diagnosed_result_document(dg: dict, spec, inputs: dict) -> dict:
    """result.json of a table diagnosis: its final fit and held-out comparison, for predict, report and
    export.  A viscosity per recording describes the recordings, not the motor: a new point is predicted
    at the recordings' mean viscosity, which is the model without it (physics/recording_temperature.py),
    so it is left out of ``fit.mechanisms`` with a warning."""
    from motorid.physics.registry import CATALOG

    result = table_result_document(dg["fit"], spec, inputs, dg["comparison"])
    result["fit"]["from_diagnose"] = True
    left = [m for m in result["fit"].get("mechanisms", []) if m not in CATALOG]
    if left:
        result["fit"]["mechanisms"] = [m for m in result["fit"]["mechanisms"] if m in CATALOG]
        result["fit"].setdefault("warnings", []).append(
            f"{', '.join(left)} (diagnose) describes the table's recordings, not the motor: its parameters are "
            f"fitted here, and a new point is predicted without it, at the recordings' mean viscosity")
    return result


def run_table_diagnose(args, logs, tables, spec) -> int:
    """The `motorid diagnose` command when tables are given (with logs: the joint fit's BIC)."""
    import sys

    from motorid.cli._common import check_output
    from motorid.identify.results import write_json_atomic
    out = Path(args.out)
    check_output(out, args.force, files=("diagnosis.json",))
    show = sys.stderr.isatty()
    dg = diagnose_tables(logs, tables, spec, min_evidence=args.min_evidence, channels=getattr(args, "channels", None),
                         progress=(lambda m: print(f"  {m}", file=sys.stderr)) if show else None)
    doc = diagnosis_table_document(dg, spec)
    doc["inputs"] = table_inputs(logs, tables, str(args.motor), getattr(args, "channels", None))
    place_points(args, doc, out)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(doc, out / "diagnosis.json")
    drop_stale_points(out, getattr(args, "log_points", None))
    if doc["selection"].get("points_note"):
        print(doc["selection"]["points_note"])
    if not doc["mismatch"]:
        print("no mechanism earns its place on the table (ΔBIC below --min-evidence)")
    for m in doc["mechanisms"]:
        print(f"found {m['id']} ({m['name']})")
        if m.get("description"):
            print(f"  {m['description']}")
    for u in doc["unexplained"]:
        print(f"unexplained: {u['description']}")
    if doc["comparison"]:
        print(format_comparison(doc["comparison"]))
    print(f"wrote {out / 'diagnosis.json'}")
    # result.json: the fit with what diagnose kept (its own fit and held-out comparison), for predict,
    # report and export
    from motorid.cli.diagnose import refit_folder, say_refit

    result = diagnosed_result_document(dg, spec, doc["inputs"])
    target = refit_folder(out)
    target.mkdir(parents=True, exist_ok=True)
    write_json_atomic(result, target / "result.json")
    say_refit(target / "result.json", result["fit"]["mechanisms"])
    return 0

