"""Quickstart: the Python API on the shipped demo campaign.

    python examples/quickstart.py [OUT_FOLDER]

Reads the demo's bench logs, fits the motor's parameters, prints the result,
draws data and model, saves result.json, and reads it back.  The same fit as
``motorid fit synthetic_data/demo/*.csv.gz --motor synthetic_data/demo/motor.toml
--out DIR``, number for number.
"""

import sys
from pathlib import Path

import motorid

DEMO = Path(__file__).resolve().parents[1] / "synthetic_data" / "demo"


def main(out: Path) -> "motorid.FitResult":
    out.mkdir(parents=True, exist_ok=True)
    spec = motorid.load_motor_spec(DEMO / "motor.toml")  # known motor data, SI inside
    logs = sorted(DEMO.glob("*.csv.gz"))

    frame = motorid.read_logs(logs, spec)  # one SI frame: speed_rad_s [rad/s], torque_Nm [N·m], p_a_Pa [Pa], …
    print(f"{len(frame)} samples in {frame['run_id'].nunique()} runs")

    fit = motorid.fit(logs, spec)  # least squares; bayes=True adds the emcee posterior
    print(fit)  # the parameter table, χ²/dof and warnings in words
    print(f"viscous torque coefficient K_v = {fit.params['Kv']:.5g} ± {fit.std['Kv']:.2g} [-]")

    fit.plot().savefig(out / "quickstart.png", dpi=80)  # data and model
    fit.to_json(out / "result.json")  # written whole or not at all
    again = motorid.load_result(out / "result.json")
    assert again.params == fit.params
    # motorid.diagnose(logs, spec) would name any physics the 1992 model leaves out (see docs/diagnosis.md)
    return fit


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("quickstart-out"))
