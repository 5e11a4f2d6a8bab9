"""Logs without a shaft angle: fit and diagnose verdicts on the concealed campaigns with the angle removed.

    python benchmarks/run.py --only bench_angle_free [--quick]

A bench with no shaft encoder logs everything but the angle.  Each concealed campaign under
synthetic_data/concealed/ (simulated by motorid's bench, its truth kept apart) is written
again without its ``shaft_angle_deg`` column and given to `motorid.fit` and
`motorid.diagnose` (identify/log_points.py: steady runs and breakaways, the model averaged
over the angle).  Scored: the mechanism ids diagnose names against what the campaign holds
that an angle-free log can show.  Without the angle, a leakage phase and a transducer lag
leave the steady means untouched, and a torque transducer's gain at one back pressure is
K_F's shape: nothing named is the right verdict there.  The clean
campaigns must stay clean.  Also given: the points each log gives and the parameters the fit
identifies from them.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parent.parent
CONCEALED = REPO / "synthetic_data" / "concealed"

#: campaign → the ids an angle-free log can show (phase and lag: none)
CASES = {
    "clean_9_seed101": [], "clean_9_seed102": [], "clean_9_seed103": [], "clean_8_seed104": [],
    "clean_8_seed105": [], "clean_pump_8_seed106": [],
    "hydrodynamic_torque": ["hydrodynamic_torque"], "mixed_lubrication": ["mixed_lubrication"],
    "pump_mode_friction": ["pump_mode_friction"], "film_heating": ["film_heating"],
    "pressure_speed_loss": ["pressure_speed_loss"],
    # a torque gain at one back pressure is K_F's shape without the ripple: an angle-free log cannot show it
    "causes_displacement_error": ["displacement_error"], "causes_torque_meter_gain": [],
    "causes_flow_meter_gain_a": ["flow_meter_gain_a"],
    "causes_leak_phase": [], "causes_sensor_lag_torque": [],
}
QUICK = ("clean_9_seed101", "hydrodynamic_torque", "causes_displacement_error")


def _without_angle(name: str, folder: Path) -> Path:
    files = sorted((CONCEALED / name).glob("*.csv*"))
    frame = pd.concat([pd.read_csv(f) for f in files]).drop(columns=["shaft_angle_deg"])
    path = folder / f"{name}.csv"
    frame.to_csv(path, index=False)
    return path


def run(quick: bool = False) -> str:
    import motorid

    rows, right, alarms, clean = [], 0, 0, 0
    names = QUICK if quick else tuple(CASES)
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            log = _without_angle(name, Path(tmp))
            motor = CONCEALED / name / "motor.toml"
            t0 = time.time()
            fit = motorid.fit([log], motor)
            t_fit = time.time() - t0
            t0 = time.time()
            dg = motorid.diagnose([log], motor)
            t_dg = time.time() - t0
            found = dg.mechanisms
            unexplained = [u.get("channel", "?") for u in dg.document.get("unexplained", [])]
            expected = CASES[name]
            ok = sorted(found) == sorted(expected)
            right += ok
            if not expected:
                clean += 1
                alarms += bool(found)
            par = fit.document["parameters"]
            ident = [k for k, e in par.items() if e.get("identifiable")]
            rows.append(f"| {name} | {', '.join(expected) or '—'} | {', '.join(found) or '—'} | "
                        f"{', '.join(unexplained) or '—'} | {'yes' if ok else '**no**'} | "
                        f"{len(fit.log_points.path.read_text().splitlines()) - 1 if fit.log_points else 0} | "
                        f"{', '.join(ident)} | {t_fit:.0f} s / {t_dg:.0f} s |")
    head = ["## Logs without a shaft angle (bench_angle_free)", "",
            "Made by `python benchmarks/run.py --only bench_angle_free" + (" --quick" if quick else "") + "` "
            "(benchmarks/bench_angle_free.py): each concealed campaign with its shaft-angle column removed, "
            "through `motorid.fit` and `motorid.diagnose` (points per steady run, breakaways at the mean "
            "pressure torque; docs/maps.md).  Expected: what an angle-free log can show (a leakage phase and "
            "a transducer lag leave steady means untouched).",
            "", f"**{right}/{len(names)} verdicts right; false alarms on {alarms} of {clean} campaigns whose "
            f"angle-free log shows nothing.**", "",
            "| campaign | expected | named | unexplained | right | points | identified | fit / diagnose |",
            "|---|---|---|---|---|---:|---|---|"]
    return "\n".join(head + rows) + "\n"


if __name__ == "__main__":
    import sys

    print(run(quick="--quick" in sys.argv))
