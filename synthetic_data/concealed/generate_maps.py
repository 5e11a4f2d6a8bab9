"""Regenerate the concealed campaigns of the physics that loss maps show (issue 20).

    python synthetic_data/concealed/generate_maps.py

Like generate.py (same base truths and motors): each campaign folder holds only
``campaign.csv.gz`` and ``motor.toml``; the truth stays in ``truths/NAME.toml``.
Protocols: the ISO 4392-1 constant-speed and constant-pressure plans of
protocols_maps/ (the light ones of protocols/ without the 0.3 rpm runs and without
startability — none of these mechanisms acts at rest — so that a campaign is half
the rows and its diagnosis half the time); the pump-mode cases add the pump-mode
protocol (the dynamometer drives the shaft against ΔP), the only way a loss law that
differs between pump and motor mode can show.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from generate import MOTOR_8, MOTOR_9, truth_text  # noqa: E402

PUMP_PROTOCOL = HERE / "protocols_maps" / "iso4392-1_pump_mode.toml"

# name: (pistons, seed, {mechanism id: {parameter: value}}, with the pump-mode protocol) — modest sizes
CASES = {
    "mixed_lubrication": (9, 21, {"mixed_lubrication": {"C_m": 0.012, "S_m": 3e-9}}, False),
    "pressure_speed_loss": (9, 22, {"pressure_speed_loss": {"C_x": 3e-10}}, False),
    "filling_loss": (9, 23, {"filling_loss": {"C_f": 3e-10}}, False),
    "pump_mode_friction": (8, 24, {"pump_mode_friction": {"dKF": 1.5e-3}}, True),
    "film_heating": (9, 25, {"film_heating": {"c_N": 6e-5}}, False),
    "clean_pump_8_seed106": (8, 106, {}, True),
}


def protocols(pump: bool) -> list[Path]:
    """The running protocols of protocols_maps/, with the pump-mode one where asked."""
    return [HERE / "protocols_maps" / f"iso4392-1_constant_{kind}.toml" for kind in ("pressure", "speed")] + (
        [PUMP_PROTOCOL] if pump else [])


def main(names=None) -> int:
    from motorid.cli import main as motorid

    (HERE / "truths").mkdir(exist_ok=True)
    for name, (pistons, seed, mechs, pump) in CASES.items():
        if names and name not in names:
            continue
        truth = HERE / "truths" / f"{name}.toml"
        truth.write_text(truth_text(pistons, mechs))
        with tempfile.TemporaryDirectory() as tmp:
            motor = Path(tmp) / "motor.toml"
            if pistons == 9:
                shutil.copy(MOTOR_9, motor)
            else:
                motor.write_text(MOTOR_8)
            out = Path(tmp) / "out"
            rc = motorid(["simulate", "--protocol", *map(str, protocols(pump)), "--motor", str(motor),
                          "--truth", str(truth), "--out", str(out), "--seed", str(seed)])
            if rc:
                return rc
            dest = HERE / name
            dest.mkdir(exist_ok=True)
            shutil.copy(out / "campaign.csv.gz", dest / "campaign.csv.gz")
            shutil.copy(out / "motor.toml", dest / "motor.toml")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
