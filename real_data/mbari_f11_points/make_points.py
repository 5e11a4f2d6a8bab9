"""Quasi-steady operating points from the MBARI recordings → points.csv (an operating-point table).

    python real_data/mbari_f11_points/make_points.py   # rewrites real_data/mbari_f11_points/points.csv

The recordings are continuous wave-like motions, not steady runs. A point here is the mean
of the samples of one recording that fall in one cell of a (speed, ΔP) grid — 250 rpm by
10 bar — while the shaft turns (|n| ≥ 200 rpm) and barely accelerates (|dn/dt| < 300 rpm/s,
so that an inertia of even 1e-3 kg·m² adds under 0.03 N·m), with at least 25 samples
(0.5 s) in the cell. Torque and flows are those of ../mbari_f11/channels.toml (torque from generator
current, flow from ram speed: PROVENANCE.md). Columns as BENCH_LOG_FORMAT.md "Operating-point
tables", plus ``recording`` (the source file, for leave-one-recording-out tests) and
``accel_rpm_s`` (the cell's mean dn/dt, what inertia could add to its torque).

A cell whose means break the first law is left out (:func:`passive`): a motor delivers power
at its shaft only from the oil it takes in, so a point where the unit gives power out at
both its shaft (T·ω > 0) and its ports ((p_A − p_B)·q_A < 0) is not a steady point of the
unit (a transient the binning did not remove, or pressures read away from the ports).  The
rule has no threshold and is applied before any fit; it drops 2 of the 107 cells (both in 2021.07.26, near 700 rpm).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
RECORDINGS = HERE.parent / "mbari_f11"  # the recordings and their channels.toml
SPEED_BIN_RPM = 250.0
DP_BIN_BAR = 10.0
MIN_SPEED_RPM = 200.0
MAX_ACCEL_RPM_S = 300.0
MIN_SAMPLES = 25


def quasi_steady_points(frame: pd.DataFrame) -> pd.DataFrame:
    """Canonical SI frame of the recordings → one row per (recording, speed cell, ΔP cell)."""
    rows = []
    for run, g in frame.groupby("run", observed=True, sort=True):
        t = g["time_s"].to_numpy()
        n = g["speed_rad_s"].to_numpy() * 60.0 / (2.0 * np.pi)
        accel = np.gradient(n, t)
        dp = (g["p_a_Pa"] - g["p_b_Pa"]).to_numpy() / 1e5
        keep = (np.abs(n) >= MIN_SPEED_RPM) & (np.abs(accel) < MAX_ACCEL_RPM_S)
        cells = pd.DataFrame({
            "ns": np.floor(n / SPEED_BIN_RPM), "dps": np.floor(dp / DP_BIN_BAR),
            "speed_rpm": n, "p_a_bar": g["p_a_Pa"].to_numpy() / 1e5, "p_b_bar": g["p_b_Pa"].to_numpy() / 1e5,
            "torque_Nm": g["torque_Nm"].to_numpy(), "q_a_lpm": g["q_a_m3_s"].to_numpy() * 60000.0,
            "q_b_lpm": g["q_b_m3_s"].to_numpy() * 60000.0, "accel_rpm_s": accel,
        })[keep]
        for (_, _), c in cells.groupby(["ns", "dps"], sort=True):
            if len(c) < MIN_SAMPLES:
                continue
            rows.append({
                "point_id": f"{run}:{len(rows) + 1}", "recording": str(run),
                **{k: c[k].mean() for k in ("speed_rpm", "p_a_bar", "p_b_bar", "torque_Nm", "q_a_lpm", "q_b_lpm")},
                "n_samples": len(c), "torque_std_Nm": c["torque_Nm"].std(ddof=1),
                "accel_rpm_s": c["accel_rpm_s"].mean(),
            })
    return pd.DataFrame(rows)


def passive(points: pd.DataFrame) -> np.ndarray:
    """True where the point does not give power out at both shaft and ports (the first law):
    not (T·ω > 0 and (p_A − p_B)·q_A < 0)."""
    shaft_out = points["torque_Nm"] * points["speed_rpm"] > 0
    ports_out = (points["p_a_bar"] - points["p_b_bar"]) * points["q_a_lpm"] < 0
    return ~(shaft_out & ports_out).to_numpy()


def main() -> Path:
    from motorid.io.logs import read_logs
    from motorid.io.spec import load_motor_spec

    spec = load_motor_spec(RECORDINGS / "motor.toml")
    points = quasi_steady_points(read_logs(RECORDINGS, spec))
    ok = passive(points)
    for pid in points.loc[~ok, "point_id"]:
        print(f"left out {pid}: power out at both the shaft and the ports (first law)")
    points = points[ok]
    out = HERE / "points.csv"
    points.to_csv(out, index=False, float_format="%.6g", lineterminator="\n")
    print(f"wrote {out}: {len(points)} points from {points['recording'].nunique()} recordings")
    return out


if __name__ == "__main__":
    main()
