"""Regenerate the concealed-physics campaigns (issue 6) from their truth files.

    python synthetic_data/concealed/generate.py

Each campaign folder holds only what the tool reads: ``campaign.csv.gz`` and
``motor.toml``.  The truth (base parameters and the concealed mechanism) stays
in ``truths/NAME.toml``, which the tool is never given.  Protocols: the lighter
copies in ``protocols/`` of the repository's ISO 4392-1/-2 plans.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
BASE = """[parameters]
Kv = {Kv}
KF = {KF}
KFS = {KFS}
TFc = {TFc}
Ks = {Ks}
KL0 = {KL0}
KL_a1 = {KL_a1}
KL_b1 = {KL_b1}
KAB = {KAB}
"""
ODD = dict(Kv=5000.0, KF=0.003, KFS=0.015, TFc=3.0, Ks=1.0, KL0=5e-14, KL_a1=0.15, KL_b1=0.08, KAB=2e-14)
EVEN = dict(Kv=3000.0, KF=0.002, KFS=0.01, TFc=2.0, Ks=1.5, KL0=3e-14, KL_a1=-0.1, KL_b1=0.2, KAB=1e-14)
MOTOR_9 = HERE.parent / "demo" / "motor.toml"
MOTOR_8 = """[motor]
name = "concealed-8"
pistons = 8
displacement_cm3 = 60.0
inertia_kg_m2 = 0.004

[oil]
name = "ISO VG 46 mineral oil"
nu40_cSt = 46.0
nu100_cSt = 6.8
density15_kg_m3 = 875.0
"""

# name: (pistons, seed, {mechanism id: {parameter: value}})  — modest sizes
CASES = {
    "stribeck_friction": (9, 11, {"stribeck_friction": {"T_s": 2.0, "K_p": 0.002, "w_s": 0.5}}),
    "hydrodynamic_torque": (9, 12, {"hydrodynamic_torque": {"C_h": 3e-5}}),
    "turbulent_leakage": (9, 13, {"turbulent_leakage": {"C_t": 4e-10}}),
    "compressibility_flow": (9, 14, {"compressibility_flow": {"C_c": 3e-15}}),
    "misalignment_ripple": (9, 15, {"misalignment_ripple": {"A1": 0.6, "B1": -0.3, "A2": 0.0, "B2": 0.4}}),
    "torque_offset": (9, 16, {"torque_offset": {"T0": 0.8}}),
    "stribeck_and_compressibility": (8, 17, {"stribeck_friction": {"T_s": 1.5, "K_p": 0.002, "w_s": 0.4},
                                             "compressibility_flow": {"C_c": 3e-15}}),
    "clean_9_seed101": (9, 101, {}),
    "clean_9_seed102": (9, 102, {}),
    "clean_9_seed103": (9, 103, {}),
    "clean_8_seed104": (8, 104, {}),
    "clean_8_seed105": (8, 105, {}),
}


def truth_text(pistons: int, mechanisms: dict) -> str:
    text = BASE.format(**(ODD if pistons % 2 else EVEN))
    for mid, values in mechanisms.items():
        text += f"\n[mechanisms.{mid}]\n" + "".join(f"{k} = {v!r}\n" for k, v in values.items())
    return text


def main() -> int:
    from motorid.cli import main as motorid

    (HERE / "truths").mkdir(exist_ok=True)
    for name, (pistons, seed, mechs) in CASES.items():
        truth = HERE / "truths" / f"{name}.toml"
        truth.write_text(truth_text(pistons, mechs))
        with tempfile.TemporaryDirectory() as tmp:
            motor = Path(tmp) / "motor.toml"
            if pistons == 9:
                shutil.copy(MOTOR_9, motor)
            else:
                motor.write_text(MOTOR_8)
            out = Path(tmp) / "out"
            rc = motorid(["simulate", "--protocol", str(HERE / "protocols"), "--motor", str(motor),
                          "--truth", str(truth), "--out", str(out), "--seed", str(seed)])
            if rc:
                return rc
            dest = HERE / name
            dest.mkdir(exist_ok=True)
            shutil.copy(out / "campaign.csv.gz", dest / "campaign.csv.gz")
            shutil.copy(out / "motor.toml", dest / "motor.toml")
    return 0


if __name__ == "__main__":
    sys.exit(main())
