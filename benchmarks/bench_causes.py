"""The real causes of a mismatch (issue 15): spec errors, transducers, physics in no catalog.

    python benchmarks/run.py --only bench_causes [--quick]

1. Every concealed-cause campaign shipped in synthetic_data/concealed/causes_*
   (generator: synthetic_data/concealed/generate_causes.py) is diagnosed and
   scored against its truth: named right (exactly its named causes), named
   wrong (another or an extra one), missed; for the effects in no catalog,
   "honest" means a mismatch, nothing named, and an unexplained entry (with the
   empirical term proposed, if any).
2. Sizes (full run only): each new cause re-simulated at several sizes and new
   seeds, and clean campaigns for the false-alarm rate.
3. The foreign bench's n12_offsets_gains campaign (benchmarks/foreign_bench.py):
   what diagnose names there now.
"""

from __future__ import annotations

import math
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CONCEALED = ROOT / "synthetic_data" / "concealed"
sys.path.insert(0, str(CONCEALED))

import generate_causes as gc  # noqa: E402

from motorid.discrepancy.select import diagnose, diagnosis_document  # noqa: E402
from motorid.identify.pipeline import load_campaign  # noqa: E402
from motorid.io.spec import load_motor_spec  # noqa: E402

#: study row → (shipped case giving pistons, seed and protocols; kind; channel or mechanism; parameter; sizes).
#: Other forms of a cause (a gain, a zero on another meter, a lag on another transducer) are rows of their own;
#: "extra" rows scale an effect in no catalog, "offset" rows a constant meter zero, "offset_sd" rows the
#: per-run zero offsets.
SIZES = {
    "displacement_error": ("displacement_error", "physics", "displacement_error", "eps", (-0.005, -0.01)),
    "flow_meter_gain_case": ("flow_meter_gain_case", "gain", "q_case", None, (-0.01, -0.02)),
    "flow_meter_gain_b": ("flow_meter_gain_a", "gain", "q_b", None, (0.005, 0.01)),
    "torque_meter_gain": ("torque_meter_gain", "gain", "torque", None, (0.003, 0.005)),
    "sensor_lag_torque": ("sensor_lag_torque", "lag", "torque", None, (0.5e-3, 1e-3)),
    "sensor_lag_q_a": ("sensor_lag_q_a", "lag", "q_a", None, (0.5e-3,)),
    "sensor_lag_q_b": ("sensor_lag_q_a", "lag", "q_b", None, (0.5e-3, 1e-3)),
    "per_run_offset_torque": ("per_run_offsets", "offset_sd", "torque", None, (0.1, 0.25)),
    "flow_meter_offset_a": ("flow_meter_offset_a", "offset", "q_a", None, (3e-7, -6e-7)),
    "flow_meter_offset_b": ("flow_meter_offset_case", "offset", "q_b", None, (4e-7,)),
    "flow_meter_offset_case": ("flow_meter_offset_case", "offset", "q_case", None, (1e-7, -2e-7)),
    "extra_torque_order3_dp": ("extra_torque_order3_dp", "extra", "torque_order3_dp", None, (1e-8,)),
    "extra_case_leak_pa_pb": ("extra_case_leak_pa_pb", "extra", "case_leak_pa_pb", None, (2.5e-20,)),
    # the catalog's churning law ∝ ω|ω| fits it closely: named only if its shape check is blind
    "extra_torque_cubic_speed": ("extra_torque_cubic_speed", "extra", "torque_cubic_speed", None, (4e-8,)),
    # true rotor inertia / the spec's: 2× is below what steady runs show (expected: clean, read "missed")
    "inertia_error": ("inertia_error", "inertia", "factor", None, (6.0, 2.0)),
}
#: the quick setting: the newest causes (constant meter zeros) and per-run zeros, one seed each
QUICK_SHIPPED = ("causes_offsets_and_gain", "causes_clean_9_seed214")
QUICK_SIZES = ("flow_meter_offset_b", "flow_meter_offset_case", "per_run_offset_torque")


def _diagnose(folder: Path) -> tuple[dict, float]:
    spec = load_motor_spec(folder / "motor.toml")
    start = time.perf_counter()
    _, ds = load_campaign([folder / "campaign.csv.gz"], spec)
    doc = diagnosis_document(diagnose(ds, spec), spec)
    return doc, time.perf_counter() - start


def _verdict(doc: dict, truth: dict) -> str:
    named = sorted(m["id"] for m in doc["mechanisms"])
    expected = sorted(truth.get("mechanisms", {}))
    extra = bool(truth.get("extra")) or bool(truth.get("per_run_offset"))  # no catalog mechanism: honest = unexplained
    if extra and expected:  # named causes and per-run offsets together: right names, the offsets left unexplained
        if set(named) - set(expected):
            return "named wrong"
        return ("named right" if named == expected else "partly named" if named else "honest (unexplained)") + (
            " (+ unexplained)" if doc["unexplained"] else "")
    if extra:
        if named:
            return "named wrong"
        return "honest (unexplained)" if doc["mismatch"] and doc["unexplained"] else "missed"
    if not expected:
        return "clean" if not doc["mismatch"] else "false alarm"
    if named == expected:
        return "named right" + (" (+ unexplained)" if doc["unexplained"] else "")
    if set(named) - set(expected):
        return "named wrong"
    return "missed" if not named else "partly named"


def _row(name, doc, seconds, verdict) -> str:
    found = ", ".join(f"{m['id']}" for m in doc["mechanisms"]) or "—"
    terms = [u["empirical_term"]["formula"] for u in doc["unexplained"] if u.get("empirical_term")]
    left = f"{len(doc['unexplained'])}" + (f": `{terms[0]}`" if terms else "")
    refused = ", ".join(r["id"] for r in doc.get("refused_stand_ins", [])) or "—"
    return f"| `{name}` | {verdict} | {found} | {refused} | {left} | {seconds:.0f} |"


def _shipped(quick: bool) -> list[str]:
    lines = ["| campaign | verdict | named | stand-ins refused | unexplained (empirical term) | s |",
             "|---|---|---|---|---|---|"]
    counts: dict = {}
    for folder in sorted(p for p in CONCEALED.glob("causes_*") if p.is_dir() and (p / "campaign.csv.gz").exists()
                         and (not quick or p.name in QUICK_SHIPPED)):
        truth = tomllib.loads((CONCEALED / "truths" / f"{folder.name}.toml").read_text())
        doc, sec = _diagnose(folder)
        v = _verdict(doc, truth)
        counts[v.split(" (")[0]] = counts.get(v.split(" (")[0], 0) + 1
        lines.append(_row(folder.name, doc, sec, v))
        print(lines[-1], flush=True)
    return lines + ["", "Totals: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))]


def _sizes(quick: bool) -> list[str]:
    lines = ["| cause | size | seed | verdict | named | unexplained |", "|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for cause, (base, kind, what, param, sizes) in SIZES.items():
            if quick and cause not in QUICK_SIZES:
                continue
            pistons, seed = gc.CASES[base][:2]
            for size in sizes[:1] if quick else sizes:
                for s in (seed + 1000,) if quick else (seed + 1000, seed + 2000):
                    if kind == "physics":
                        case = (pistons, s, {what: {param: size}}, {}, {})
                    elif kind == "extra":
                        case = (pistons, s, {}, {}, {what: size})
                    else:
                        case = (pistons, s, {}, {kind: {what: size}}, {}, *gc.CASES[base][5:])
                    name = f"{cause}_{size:g}_{s}"
                    gc.CASES[name] = case
                    folder = gc.make(name, Path(tmp), Path(tmp) / "truths")
                    truth = tomllib.loads((Path(tmp) / "truths" / f"causes_{name}.toml").read_text())
                    doc, _ = _diagnose(folder)
                    named = ", ".join(m["id"] for m in doc["mechanisms"]) or "—"
                    left = ", ".join(u["channel"] for u in doc["unexplained"]) or "—"
                    lines.append(f"| `{cause}` | {size:g} | {s} | {_verdict(doc, truth)} | {named} | {left} |")
                    print(lines[-1], flush=True)
        for s in (301,) if quick else (301, 302, 303, 304):
            name = f"clean_{s}"
            gc.CASES[name] = (9 if s % 2 else 8, s, {}, {}, {})
            folder = gc.make(name, Path(tmp), Path(tmp) / "truths")
            doc, _ = _diagnose(folder)
            lines.append(f"| clean | — | {s} | {'false alarm' if doc['mismatch'] else 'clean'} | "
                         f"{', '.join(m['id'] for m in doc['mechanisms']) or '—'} | "
                         f"{', '.join(u['channel'] for u in doc['unexplained']) or '—'} |")
            print(lines[-1], flush=True)
    return lines


def drawn_value(pid: str, cal: dict, displacement: float):
    """The value a named spec or sensor parameter should take on a foreign-bench campaign, from its
    drawn calibration (manifest.json), as the model sees it: a torque zero shifted by the pressure
    zeros through the ideal torque D/2π·ΔP; a port meter's gain relative to the speed's (the swept
    flow D·ω is computed from the measured speed); a flow meter's zero as drawn; None where no drawn
    quantity maps to it."""
    off, gain = cal.get("offset", {}), cal.get("gain", {})
    if pid == "torque_offset.T0":
        return off.get("torque", 0.0) - displacement / (2 * math.pi) * (off.get("pa", 0.0) - off.get("pb", 0.0))
    if pid == "torque_meter_gain.g":
        return gain.get("torque", 1.0) - 1.0
    if pid in ("flow_meter_gain_a.g", "flow_meter_gain_b.g"):
        k = "qa" if pid.endswith("_a.g") else "qb"
        return gain.get(k, 1.0) / gain.get("omega", 1.0) - 1.0
    if pid == "flow_meter_gain_case.g":
        return gain.get("qc", 1.0) - 1.0
    if pid.startswith("flow_meter_offset_"):
        return off.get({"a": "qa", "b": "qb", "case": "qc"}[pid.split(".")[0].rsplit("_", 1)[1]], 0.0)
    return None


def _foreign() -> list[str]:
    import json

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "n12"
        subprocess.run([sys.executable, str(ROOT / "benchmarks" / "foreign_bench.py"), "make", "n12_offsets_gains",
                        str(out)], check=True, capture_output=True)
        spec = load_motor_spec(out / "motor.toml")
        cal = json.loads((out / "manifest.json").read_text())["calibration"]
        start = time.perf_counter()
        _, ds = load_campaign(sorted((out / "logs").iterdir()), spec)
        doc = diagnosis_document(diagnose(ds, spec), spec)
        sec = time.perf_counter() - start
    named = ", ".join(m["id"] for m in doc["mechanisms"]) or "nothing"
    refused = ", ".join(r["id"] for r in doc.get("refused_stand_ins", [])) or "none"
    lines = [f"`n12_offsets_gains` (0.05 % gain errors on torque, pressures, flows and speed, and small zero offsets "
             f"on every channel): mismatch {doc['mismatch']}; named {named}; stand-ins refused: {refused}; "
             f"{len(doc['unexplained'])} channel(s) left unexplained ({sec:.0f} s)."]
    rows = []
    for m in doc["mechanisms"]:
        for pid, p in m["parameters"].items():
            drawn = drawn_value(pid, cal, spec.displacement)
            if drawn is None or p.get("value") is None:
                continue
            z = (p["value"] - drawn) / p["std"] if p.get("std") else float("nan")
            rows.append(f"| `{pid}` | {p['value']:.4g} ± {p['std']:.2g} | {drawn:.4g} | {z:+.1f} |")
    if rows:
        lines += ["", "Named values against the drawn calibration (as the model sees it: `drawn_value`):", "",
                  "| parameter | fitted | drawn | (fitted − drawn)/std |", "|---|---:|---:|---:|"] + rows
    return lines


def run(quick: bool = False) -> str:
    lines = ["## The real causes of a mismatch (issue 15)", "",
             "`motorid diagnose` on the concealed-cause campaigns (spec errors, transducer gains and lags, "
             "and zeros, and effects in no catalog; truths kept apart, `synthetic_data/concealed/generate_causes.py`).", ""]
    if quick:
        lines += ["Quick setting (`--quick`): the campaigns of the causes added last, one seed per size, one "
                  "clean campaign; the full run diagnoses every shipped campaign, two seeds per size, four clean "
                  "campaigns and the foreign bench.", ""]
    lines += _shipped(quick)
    lines += ["", "Other sizes, seeds and forms of a cause, and clean campaigns (false alarms):", ""] + _sizes(quick)
    lines += ["", "`inertia_error` at 2 (a true J twice the spec's) is read `missed`: in steady runs its torque "
              "ripple stays below a third of the torque noise, so no structure is located and nothing is named "
              "(docs/diagnosis-causes.md, Inertia); the detection limit, not a wrong name."]
    if not quick:
        lines += ["", "The foreign bench:", ""] + _foreign()
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
