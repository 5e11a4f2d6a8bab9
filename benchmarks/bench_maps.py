"""Loss maps: held-out prediction of motorid and of the classical loss models.

    python benchmarks/run.py --only bench_maps [--quick]

On every operating-point table under real_data/ (with its motor.toml) and on
synthetic 4-quadrant maps simulated with physics beyond the Bartos model (one
catalog mechanism each, at 3× its typical size, plus noise), each model is
fitted and asked to predict points it did not see:

- motorid: the base model (θ-averaged, identify/tables.py);
- motorid + diagnose: the model with the mechanisms that `motorid diagnose`
  selects on the whole table (forward selection by BIC, discrepancy/tables.py)
  and, where diagnose leaves a channel unexplained with an empirical term, that
  term searched again on each fold's training points (discrepancy/table_terms.py);
- ... + kriged model error: the residuals neighbouring training points share,
  kriged to the points held out (identify/kriging.py; nothing far from the
  training points, so extrapolation is the physics'); not yet used by `predict`;
- Wilson, Schlösser, McCandlish–Dorey, Jeong, polynomial map (motorid/comparators/).

Errors (motorid/comparators/evaluate.py): 5-fold held-out RMS, and the RMS when
fitted on the lower 60 % of |ΔP| (or |ω|) and predicting the rest; each in % of
the channel's measured span; where a real table names the recording of each point,
also "1-out": each recording predicted from a fit on the others.  Note that the
mechanism selection itself saw every point (the folds refit its parameters, not
the choice).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
KINDS = (("kfold", "K"), ("extrapolate_pressure", "ΔP"), ("extrapolate_speed", "ω"))
GROUP_COLUMNS = ("recording", "run", "session")  # a table column naming where each point came from


def _synthetic(mech_id, spec, rng):
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.physics.registry import get
    from motorid.io.tables import read_table

    truth = {"Kv": 5000.0, "KF": 3e-3, "KFS": 1.5e-2, "TFc": 3.0, "Ks": 1.0, "KL0": 5e-14, "KL_a1": 0.15,
             "KL_b1": 0.08, "KAB": 2e-14}
    mechs = ()
    if mech_id:
        m = get(mech_id)
        mechs = (m,)
        truth.update({k: 3 * info.typical for k, info in m.parameters.items()})
    g = map_grid([100, 500, 1000, 2000, 3000], [20, 80, 160, 240, 320], 4)
    df = simulate_map(spec, truth, g, mechanisms=mechs, rng=rng,
                      noise={"torque_Nm": 0.3, "q_a_lpm": 0.05, "q_b_lpm": 0.05, "q_case_lpm": 0.02})
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "map.csv"
        df.to_csv(p, index=False)
        return read_table(p, spec)


#: a map put together from three recordings (days), each over its own part of the grid: speeds [rpm],
#: ΔP [bar], quadrants; their oil temperatures are not in the table (the spec assumes 50 °C)
RECORDINGS = (("day1", [100, 500, 1000, 2000, 3000], [20, 80, 160, 240, 320], 4),
              ("day2", [500, 1500, 2500], [40, 120, 200, 280], 2),
              ("day3", [300, 1000, 3000], [60, 160, 300], 4))


def _recordings(temps, spec, rng):
    """The base model's map of :data:`RECORDINGS` at oil temperatures ``temps`` [°C], written without
    a temperature column (a ``recording`` column instead) and read back: (table, recording labels)."""
    import tempfile

    import pandas as pd

    from motorid.bench.maps import map_grid, simulate_map
    from motorid.io.tables import read_table

    truth = {"Kv": 5000.0, "KF": 3e-3, "KFS": 1.5e-2, "TFc": 3.0, "Ks": 1.0, "KL0": 5e-14, "KL_a1": 0.15,
             "KL_b1": 0.08, "KAB": 2e-14}
    parts = []
    for (label, speeds, dps, quadrants), temp in zip(RECORDINGS, temps):
        df = simulate_map(spec, truth, map_grid(speeds, dps, quadrants), temp_C=temp, rng=rng,
                          noise={"torque_Nm": 0.3, "q_a_lpm": 0.05, "q_b_lpm": 0.05, "q_case_lpm": 0.02})
        parts.append(df.drop(columns=["oil_temp_C"]).assign(recording=label, point_id=label + ":" + df["point_id"]))
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "map.csv"
        pd.concat(parts).to_csv(path, index=False)
        table = read_table(path, spec)
    return table, table.recordings()


FOREIGN_MAP = """
# another maker's test report: pump sign, absolute pressures, speed in rad/s
convention = "pump"
[constants]
oil_temp_C = {temp}
[channels]
speed_rpm = {{name = "omega", unit = "rad/s"}}
p_a_bar = {{name = "pA_abs", unit = "bar", absolute = true}}
p_b_bar = {{name = "pB_abs", unit = "bar", absolute = true}}
torque_Nm = {{name = "M_shaft", unit = "N*m"}}
q_a_lpm = {{name = "Q_A", unit = "l/min"}}
q_b_lpm = {{name = "Q_B", unit = "l/min"}}
q_case_lpm = {{name = "Q_L", unit = "l/min"}}
"""


def _foreign(mech_id, rng):
    """A map never tuned on: a 28 cm³/rev 7-piston unit, an uneven grid (50-4500 rpm, 15-380 bar) with
    an 18 bar boost on the low side, 60 °C, four quadrants, written as another maker's .xlsx (pump-sign
    torque and flow, absolute pressures, speed in rad/s) and read through a channel map
    (io/tables.read_mapped_table); the mechanism at 3× its catalog size scaled to this unit."""
    import tempfile

    import pandas as pd

    from motorid.bench.maps import map_grid, simulate_map
    from motorid.io.spec import MotorSpec, OilSpec
    from motorid.io.tables import read_mapped_table
    from motorid.physics.registry import get

    spec = MotorSpec("foreign-28", 7, 28e-6, 0.001, oil=OilSpec(temp_C=60.0))
    truth = {"Kv": 6000.0, "KF": 3e-3, "KFS": 1e-2, "TFc": 0.4, "Ks": 1.0, "KL0": 2e-14, "KL_a1": 0.0,
             "KL_b1": 0.0, "KAB": 8e-15}
    mechs = ()
    if mech_id:
        m = get(mech_id)
        mechs = (m,)
        truth.update({k: 3 * info.typical for k, info in m.parameters.items()})
    grid = map_grid([50, 220, 700, 1300, 2400, 3600, 4500], [15, 45, 110, 190, 280, 380], 4, p_low_bar=18.0)
    df = simulate_map(spec, truth, grid, temp_C=60.0, mechanisms=mechs, rng=rng,
                      noise={"torque_Nm": 0.05, "q_a_lpm": 0.02, "q_b_lpm": 0.02, "q_case_lpm": 0.01})
    rpm = 2 * np.pi / 60
    foreign = pd.DataFrame({"omega": df["speed_rpm"] * rpm, "pA_abs": df["p_a_bar"] + 1.01325,
                            "pB_abs": df["p_b_bar"] + 1.01325, "M_shaft": -df["torque_Nm"], "Q_A": -df["q_a_lpm"],
                            "Q_B": -df["q_b_lpm"], "Q_L": df["q_case_lpm"]})
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "report.xlsx"
        foreign.to_excel(path, index=False)
        (Path(d) / "report.channels.toml").write_text(FOREIGN_MAP.format(temp=60.0))
        return read_mapped_table(path, spec), spec


def _real_maps():
    from motorid.io.tables import is_table, read_table
    from motorid.io.spec import load_motor_spec

    out = []
    for folder in sorted((REPO / "real_data").glob("*")) if (REPO / "real_data").exists() else []:
        motor = folder / "motor.toml"
        if not motor.exists():
            continue
        spec = load_motor_spec(motor)
        tables = [f for f in sorted(folder.glob("*.csv")) if is_table(f)]
        for f in tables:
            import pandas as pd

            head = pd.read_csv(f)
            groups = next((head[c].astype(str).to_numpy() for c in GROUP_COLUMNS if c in head), None)
            out.append((f"{folder.name}/{f.name}", read_table(f, spec), spec, groups))
        if not tables:  # recordings without a shaft angle: the operating points motorid reduces them to
            from motorid.identify.log_points import points_from_logs

            reduced = points_from_logs([folder], spec)
            if reduced is not None:
                import pandas as pd

                head = pd.read_csv(reduced.path)
                groups = head["recording"].astype(str).to_numpy() if "recording" in head else None
                out.append((f"{folder.name}/ (recordings → {len(head)} points by motorid fit)",
                            read_table(reduced.path, spec), spec, groups))
    return out


def _evaluate(name, table, spec, diagnose: bool, groups=None):
    from motorid.comparators import all_comparators
    from motorid.comparators.evaluate import MotoridModel, WithModelError, held_out
    from motorid.discrepancy.tables import diagnose_table

    t0 = time.time()
    base = MotoridModel(spec)
    rows = {"motorid": held_out(base, table, groups=groups),  # what `motorid predict --physics-only` gives
            "motorid + kriged model error": held_out(WithModelError(base), table, groups=groups)}  # predict's
    found = []
    if diagnose:
        from motorid.discrepancy.table_terms import MotoridWithTerms

        dg = diagnose_table(table, spec)
        found = [m.id for m in dg["mechanisms"]] + [f"empirical term ({u['channel']})" for u in dg["unexplained"]]
        if found:  # an empirical term is chosen again on each fold's training points alone
            model = (MotoridWithTerms(spec, dg["mechanisms"], groups=groups) if dg["unexplained"]
                     else MotoridModel(spec, dg["mechanisms"]))
            rows["motorid + diagnose"] = held_out(model, table, groups=groups)
        if found:  # the model error the neighbours share, kriged between the training points (as predict does)
            rows["motorid + diagnose + kriged model error"] = held_out(WithModelError(model), table, groups=groups)
    for m in all_comparators():
        rows[m.name] = held_out(m, table, groups=groups)
    return {"name": name, "rows": rows, "found": found, "seconds": time.time() - t0, "points": len(table),
            "kinds": KINDS + ((("leave_one_group_out", "1-out"),) if groups is not None else ()),
            "channels": [c for c in ("torque", "q_a", "q_case") if np.isfinite(table.measured[c]).any()]}


def _fmt(v):
    return "—" if v is None else f"{v:.2f}"


def _table(res) -> list:
    chans = res["channels"]
    kinds = res["kinds"]
    head = "| model | " + " | ".join(f"{c} {k}" for c in chans for _, k in kinds) + " |"
    lines = [head, "|" + "---|" * (1 + len(kinds) * len(chans))]
    best = {}
    for c in chans:
        for kind, _ in kinds:
            vals = [r.get(kind, {}).get(c, {}).get("percent_of_span") for r in res["rows"].values()]
            vals = [v for v in vals if v is not None]
            best[(c, kind)] = min(vals) if vals else None
    for name, r in res["rows"].items():
        cells = []
        for c in chans:
            for kind, _ in kinds:
                v = r.get(kind, {}).get(c, {}).get("percent_of_span")
                s = _fmt(v)
                cells.append(f"**{s}**" if v is not None and v == best[(c, kind)] else s)
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def _verdict(res) -> str:
    """Does motorid (with what diagnose adds) predict held-out points at least as well as the best
    classical model, and extrapolate better?  Per channel, in words."""
    ours = res["rows"].get("motorid + diagnose", res["rows"]["motorid"])
    others = {k: v for k, v in res["rows"].items() if not k.startswith("motorid")}
    words = []
    for c in res["channels"]:
        for kind, label in res["kinds"]:
            mine = ours.get(kind, {}).get(c, {}).get("percent_of_span")
            theirs = [(v.get(kind, {}).get(c, {}).get("percent_of_span"), k) for k, v in others.items()]
            theirs = [t for t in theirs if t[0] is not None]
            if mine is None or not theirs:
                continue
            best, who = min(theirs)
            if mine > 1.05 * best:
                words.append(f"{c} {label}: motorid {mine:.2f} % vs {who} {best:.2f} %")
    return ("motorid is within 5 % of the best classical model or better everywhere" if not words else
            "worse than the best classical model: " + "; ".join(words))


def run(quick: bool = False) -> str:
    import motorid  # noqa: F401
    from motorid.model import MotorSpec, OilSpec

    spec = MotorSpec("synthetic-map-9", 9, 80e-6, 0.005, oil=OilSpec(temp_C=50.0))
    rng = np.random.default_rng(2026)
    cases = [(f"real: {name}", t, s, True, g) for name, t, s, g in _real_maps()]
    mechs = [None, "hydrodynamic_torque"] if quick else [None, "hydrodynamic_torque", "stribeck_friction",
                                                         "turbulent_leakage", "compressibility_flow",
                                                         "pressure_viscosity", "film_heating"]
    for mid in mechs:
        cases.append((f"synthetic: Bartos{' + ' + mid if mid else ' only'}", _synthetic(mid, spec, rng), spec,
                      not quick or mid is not None, None))
    for temps in ([(50.0, 54.0, 47.0)] if quick else [(50.0, 54.0, 47.0), (50.0, 50.0, 50.0)]):
        t, g = _recordings(temps, spec, rng)
        cases.append((f"synthetic: Bartos, 3 recordings at {', '.join(f'{x:g}' for x in temps)} °C, no temperature "
                      f"column", t, spec, True, g))
    for mid in [None, "film_heating"] if quick else [None, "film_heating", "hydrodynamic_torque"]:
        t, s28 = _foreign(mid, rng)
        cases.append((f"foreign map (28 cm³/rev, pump sign, absolute pressures, .xlsx): Bartos"
                      f"{' + ' + mid if mid else ' only'}", t, s28, True, None))
    out = ["## Loss maps: held-out prediction against the classical loss models", "",
           "Made by `python benchmarks/run.py --only bench_maps" + (" --quick" if quick else "") + "` "
           "(benchmarks/bench_maps.py).  Each cell: RMS of the held-out residual in % of the channel's span; "
           "K: 5-fold; ΔP / ω: fitted on the lower 60 % of |ΔP| / |ω|, predicting the rest.  Bold: the best "
           "of the column; 1-out (real tables with a recording column): each recording predicted from a fit on "
           "the others.  'motorid + diagnose': the model with the catalog mechanisms that diagnose selects on "
           "the table (selection on all points, parameters refitted per fold).  q_b behaves as q_a and is left "
           "out.  Synthetic maps: 4 quadrants, 5 speeds (100-3000 rpm) × 5 ΔP (20-320 bar), noise 0.3 N·m, "
           "0.05 L/min (ports), 0.02 L/min (case); the mechanism at 3× its catalog's typical size.  Foreign maps "
           "(a map never tuned on, issue 20): a 28 cm³/rev 7-piston unit, uneven grid 50-4500 rpm × 15-380 bar, "
           "18 bar boost, 60 °C, noise 0.05 N·m / 0.02 / 0.01 L/min, written as another maker's .xlsx (pump-sign "
           "torque and flow, absolute pressures, rad/s) and read through a channel map.  Recordings: the "
           "Bartos-only map put together from three recordings (days) over parts of the grid (100, 24 and 36 "
           "points), with oil temperatures the table does not hold (spec: 50 °C).", ""]
    if not _real_maps():
        out += ["No operating-point table under real_data/ on this branch.", ""]
    for name, table, s, diag, groups in cases:
        res = _evaluate(name, table, s, diag, groups)
        out += [f"### {name} ({res['points']} points, {res['seconds']:.0f} s)", ""]
        if diag:
            out += [f"diagnose selected: {', '.join(res['found']) or 'nothing'}.  {_verdict(res)}.", ""]
        else:
            out += [_verdict(res) + ".", ""]
        out += _table(res) + [""]
    return "\n".join(out)


if __name__ == "__main__":
    import sys

    print(run(quick="--quick" in sys.argv))
