"""Foreign loss maps through the table path (issue 20).

- A gridded 2-D MATLAB loss map (axis vectors × matrices, as a lab saves an ISO 4409 map)
  given with a channel map reaches the *table* reader, through ``api.fit`` and through
  ``motorid fit --channels`` alike; files written by scipy.io (v5) and h5py (v7.3).
- A map never seen (another size and piston count, another grid, pump-sign torque and
  flow, absolute pressures with a boost pressure on the low side, speed in rad/s, an
  Excel file) fits within the margins of the maps the tool was built on: parameters
  within 4 σ of the truth, held-out (5-fold) error at the noise level.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from motorid import api
from motorid.bench.maps import map_grid, simulate_map
from motorid.cli import main
from motorid.comparators.evaluate import MotoridModel, held_out
from motorid.io.spec import MotorSpec, OilSpec
from test_formats import write_matlab_73

RPM = 2 * np.pi / 60
#: the margins every table test holds (test_tables.py): truth within 4 σ; held-out RMS at the noise
SIGMAS = 4.0


def _check_recovered(values: dict, std: dict, truth: dict, names):
    for k in names:
        assert std[k] and abs(values[k] - truth[k]) < SIGMAS * std[k], (k, values[k], std[k], truth[k])


# --------------------------------------------------------------------------- a gridded .mat map

SPEC_80 = MotorSpec("grid-80", 9, 80e-6, 0.005, oil=OilSpec(temp_C=50.0))
TRUTH_80 = {"Kv": 4000.0, "KF": 2e-3, "KFS": 1.2e-2, "TFc": 2.0, "Ks": 1.5, "KL0": 6e-14, "KL_a1": 0.0,
            "KL_b1": 0.0, "KAB": 3e-14}
SPEEDS = np.array([100.0, 300.0, 600.0, 1000.0, 1500.0, 2000.0, 2500.0, 3000.0])  # rpm
DPS = np.array([20.0, 60.0, 100.0, 150.0, 200.0, 250.0, 300.0])  # bar

GRID_MAP = """
convention = "pump"
[constants]
oil_temp_C = 50.0
[grid]
axes = ["speed_rpm", "dp_bar"]
[channels]
speed_rpm = {name = "map.n", unit = "rpm"}
dp_bar = {name = "map.dp", unit = "bar"}
torque_Nm = {name = "map.T", unit = "N*m"}
q_a_lpm = {name = "map.Q", unit = "l/min"}
q_case_lpm = {name = "map.Qc", unit = "l/min"}
"""


def _gridded_map(rng):
    """One quadrant (motor mode) over SPEEDS × DPS as matrices in the pump sign: torque into the shaft,
    flow out of the high-pressure port (negated), case drain as is; one cell the bench never reached."""
    df = simulate_map(SPEC_80, TRUTH_80, map_grid(SPEEDS, DPS, quadrants=1), noise={
        "torque_Nm": 0.2, "q_a_lpm": 0.05, "q_b_lpm": 0.05, "q_case_lpm": 0.02}, rng=rng)
    shape = (SPEEDS.size, DPS.size)  # map_grid: speed outer, ΔP inner
    t = -df["torque_Nm"].to_numpy().reshape(shape).copy()
    q = -df["q_a_lpm"].to_numpy().reshape(shape).copy()
    qc = df["q_case_lpm"].to_numpy().reshape(shape).copy()
    t[-1, -1] = q[-1, -1] = qc[-1, -1] = np.nan
    return {"n": SPEEDS, "dp": DPS, "T": t, "Q": q, "Qc": qc}


@pytest.mark.parametrize("version", ["v5", "v7.3"])
def test_gridded_mat_map_with_channels_is_fitted_as_a_table(version, tmp_path, capsys):
    arrays = _gridded_map(np.random.default_rng(5 if version == "v5" else 6))
    path = tmp_path / "A6VM_map.mat"
    if version == "v5":
        from scipy.io import savemat

        savemat(path, {"map": arrays})
    else:
        write_matlab_73(path, arrays, "map")
    (tmp_path / "map.toml").write_text(GRID_MAP)
    motor = tmp_path / "motor.toml"
    motor.write_text(SPEC_80.to_toml())
    if version == "v5":  # the library: api.fit takes the map as motorid fit does
        res = api.fit([path], SPEC_80, channels=tmp_path / "map.toml")
        doc = res.document
        assert doc["inputs"]["tables"] == [str(path)] and doc["inputs"]["logs"] == []
    else:  # the command line
        rc = main(["fit", str(path), "--channels", str(tmp_path / "map.toml"), "--motor", str(motor),
                   "--out", str(tmp_path / "r"), "--quiet"])
        assert rc == 0, capsys.readouterr().err
        doc = json.loads((tmp_path / "r" / "result.json").read_text())
        # and motorid predict reads the same map through the same channel map
        rc = main(["predict", str(tmp_path / "r"), str(path), "--channels", str(tmp_path / "map.toml"),
                   "--out", str(tmp_path / "pred.csv")])
        assert rc == 0, capsys.readouterr().err
        pred = pd.read_csv(tmp_path / "pred.csv")
        measured = -arrays["T"].ravel()  # motor sign, row-major as the [grid] reads it
        measured = measured[np.isfinite(measured)]
        assert len(pred) == measured.size
        assert np.sqrt(np.mean((pred["torque_Nm"] - measured) ** 2)) < 1.3 * 0.2  # the map's noise
    assert doc["table"]["points"] == SPEEDS.size * DPS.size - 1
    p = doc["parameters"]
    for k in ("KFS", "Ks", "KL_a1"):
        assert not p[k]["identifiable"]  # a steady map has no breakaway and no shaft angle
    _check_recovered({k: v["value"] for k, v in p.items()}, {k: v["std"] for k, v in p.items()}, TRUTH_80,
                     ("Kv", "KF", "TFc", "KL0"))
    assert "polynomial map" in doc["comparison"]["models"]


def test_gridded_map_whose_channel_map_names_time_is_refused_in_one_line(tmp_path, capsys):
    from scipy.io import savemat

    arrays = _gridded_map(np.random.default_rng(1))
    savemat(tmp_path / "m.mat", {"map": arrays})
    (tmp_path / "map.toml").write_text(GRID_MAP.replace('q_case_lpm = {name = "map.Qc", unit = "l/min"}',
                                                        'time_s = {name = "map.Qc", unit = "s"}'))
    motor = tmp_path / "motor.toml"
    motor.write_text(SPEC_80.to_toml())
    rc = main(["fit", str(tmp_path / "m.mat"), "--channels", str(tmp_path / "map.toml"), "--motor", str(motor),
               "--out", str(tmp_path / "r"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "Traceback" not in err and "map.toml" in err
    assert not (tmp_path / "r").exists()


# --------------------------------------------------------------------------- a map never seen

SPEC_28 = MotorSpec("foreign-28", 7, 28e-6, 0.001, oil=OilSpec(temp_C=60.0))
# a 28 cm³/rev unit: torque losses scale with D (K_v, K_F are per unit displacement), T_Fc with the size
TRUTH_28 = {"Kv": 6000.0, "KF": 3e-3, "KFS": 1e-2, "TFc": 0.4, "Ks": 1.0, "KL0": 2e-14, "KL_a1": 0.0,
            "KL_b1": 0.0, "KAB": 8e-15}
FOREIGN_MAP = """
# another maker's test report: pump sign, absolute pressures, speed in rad/s, Excel
convention = "pump"
[constants]
oil_temp_C = 60.0
[channels]
speed_rpm = {name = "omega", unit = "rad/s"}
p_a_bar = {name = "pA_abs", unit = "bar", absolute = true}
p_b_bar = {name = "pB_abs", unit = "bar", absolute = true}
torque_Nm = {name = "M_shaft", unit = "N*m"}
q_a_lpm = {name = "Q_A", unit = "l/min"}
q_b_lpm = {name = "Q_B", unit = "l/min"}
q_case_lpm = {name = "Q_L", unit = "l/min"}
"""


def test_a_map_never_seen_fits_within_the_same_margins(tmp_path):
    """Another size (28 cm³/rev, 7 pistons), an uneven grid (50-4500 rpm, 15-380 bar), a boost of
    18 bar on the low side, four quadrants, pump-sign torque and flow, absolute pressures in an
    .xlsx: the truth comes back within 4 σ and the held-out error is the noise."""
    rng = np.random.default_rng(2028)
    grid = map_grid([50, 220, 700, 1300, 2400, 3600, 4500], [15, 45, 110, 190, 280, 380], 4, p_low_bar=18.0)
    noise = {"torque_Nm": 0.05, "q_a_lpm": 0.02, "q_b_lpm": 0.02, "q_case_lpm": 0.01}
    df = simulate_map(SPEC_28, TRUTH_28, grid, temp_C=60.0, noise=noise, rng=rng)
    atm = 1.01325
    foreign = pd.DataFrame({"omega": df["speed_rpm"] * RPM, "pA_abs": df["p_a_bar"] + atm,
                            "pB_abs": df["p_b_bar"] + atm, "M_shaft": -df["torque_Nm"], "Q_A": -df["q_a_lpm"],
                            "Q_B": -df["q_b_lpm"], "Q_L": df["q_case_lpm"]})
    path = tmp_path / "report.xlsx"
    foreign.to_excel(path, index=False)  # openpyxl
    (tmp_path / "report.channels.toml").write_text(FOREIGN_MAP)
    res = api.fit([path], SPEC_28)  # the map beside the file
    t = res.identification.table
    np.testing.assert_allclose(t.p_a / 1e5, df["p_a_bar"], atol=1e-9)  # gauge again
    np.testing.assert_allclose(t.measured["torque"], df["torque_Nm"], atol=1e-12)  # motor sign again
    p = res.document["parameters"]
    _check_recovered({k: v["value"] for k, v in p.items()}, {k: v["std"] for k, v in p.items()}, TRUTH_28,
                     ("Kv", "KF", "TFc", "KL0", "KAB"))
    h = held_out(MotoridModel(SPEC_28), t)
    si = {"torque": noise["torque_Nm"], "q_a": noise["q_a_lpm"] / 6e4, "q_case": noise["q_case_lpm"] / 6e4}
    for c, s in si.items():
        for kind in ("kfold", "extrapolate_pressure", "extrapolate_speed"):
            assert h[kind][c]["rms"] < 1.3 * s, (c, kind, h[kind][c]["rms"], s)


# --------------------------------------------------------------------------- coordinate matrices

def test_a_four_quadrant_map_with_coordinate_matrices_for_axes(tmp_path, capsys):
    """A lab's .mat holds the map as four equal matrices (as MATLAB's meshgrid writes them): ΔP signed
    over the rows (-300 … 300 bar, port B high below 0), speed signed in rad/s over the columns, the
    shaft turning the other way from the format's, torque, and flow in m³/s counted the other way.
    Every cell is one point (no outer product of 'vectors' of 10⁴ cells: that took all the memory),
    the zero-speed torques are set aside, and the truth comes back within 4 σ."""
    from scipy.io import savemat

    dps = np.array([-300.0, -200.0, -120.0, -60.0, 0.0, 60.0, 120.0, 200.0, 300.0])  # bar, signed
    rpm = np.array([-3000.0, -1800.0, -900.0, -300.0, 0.0, 300.0, 900.0, 1800.0, 3000.0])
    P, N = np.meshgrid(dps, rpm, indexing="ij")
    grid = np.column_stack([N.ravel(), np.maximum(P.ravel(), 0.0), np.maximum(-P.ravel(), 0.0)])
    noise = {"torque_Nm": 0.2, "q_a_lpm": 0.05}
    df = simulate_map(SPEC_80, TRUTH_80, grid, noise=noise, rng=np.random.default_rng(44))
    shape = P.shape
    savemat(tmp_path / "lab_map.mat", {
        "P_4Q": P * 1e5, "w_4Q": -N.reshape(shape) * RPM,
        "T_4Q": df["torque_Nm"].to_numpy().reshape(shape),
        "Q_4Q": -df["q_a_lpm"].to_numpy().reshape(shape) / 6e4})
    (tmp_path / "lab.toml").write_text("""
[constants]
oil_temp_C = 50.0
[grid]
axes = ["dp_bar", "speed_rpm"]
[channels]
dp_bar    = {name = "P_4Q", unit = "Pa"}
speed_rpm = {name = "w_4Q", unit = "rad/s", sign = -1}
torque_Nm = {name = "T_4Q", unit = "N*m"}
q_a_lpm   = {name = "Q_4Q", unit = "m3/s", sign = -1}
""")
    motor = tmp_path / "motor.toml"
    motor.write_text(SPEC_80.to_toml())
    args = ["fit", str(tmp_path / "lab_map.mat"), "--channels", str(tmp_path / "lab.toml"), "--motor", str(motor),
            "--out", str(tmp_path / "r"), "--quiet"]
    assert main(args) == 0, capsys.readouterr().err
    doc = json.loads((tmp_path / "r" / "result.json").read_text())
    assert doc["table"]["points"] == P.size
    p = doc["parameters"]
    _check_recovered({k: v["value"] for k, v in p.items()}, {k: v["std"] for k, v in p.items()}, TRUTH_80,
                     ("Kv", "KF", "TFc", "KL0"))
    # one axis a matrix, the other a vector: refused in one line naming both
    savemat(tmp_path / "bad.mat", {"P_4Q": P * 1e5, "w_4Q": rpm * RPM, "T_4Q": np.zeros(shape),
                                   "Q_4Q": np.zeros(shape)})
    capsys.readouterr()
    assert main(["fit", str(tmp_path / "bad.mat"), *args[2:6], "--out", str(tmp_path / "r2"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "P_4Q" in err and "w_4Q" in err and "bad.mat" in err
    assert not (tmp_path / "r2").exists()


def test_loss_tables_in_simscape_convention_give_back_the_motor_that_made_them(tmp_path, capsys):
    """Loss tables as a Simscape user holds them (Simscape's tabulated-loss convention:
    T = DΔP/2π − T_loss, Q_hp = ±(Dω/2π + Q_loss) at the high-pressure port), here written by ``motorid export --format simscape``
    from a map fit: read through a channel map (loss columns, [grid] axes as row vectors), fitted,
    they give back that fit's parameters; a table with a loss column and the same reading is refused."""
    from test_export import fitted_map

    _, first_fit, df = fitted_map(tmp_path, quadrants=4, seed=8)
    motor = tmp_path / "motor.toml"
    assert main(["export", str(first_fit), "--format", "simscape", "--out", str(tmp_path / "ss"),
                 "--temperature", "45", "--max-speed", "2500"]) == 0
    (tmp_path / "ss.toml").write_text(
        '[constants]\noil_temp_C = 45.0\n[grid]\naxes = ["dp_bar", "speed_rpm"]\n[channels]\n'
        'dp_bar = {name = "pressure_drop_Pa", unit = "Pa"}\n'
        'speed_rpm = {name = "shaft_speed_rad_s", unit = "rad/s"}\n'
        'torque_loss_Nm = {name = "torque_loss_Nm", unit = "N*m"}\n'
        'q_loss_lpm = {name = "volumetric_loss_m3_s", unit = "m3/s"}\n'
        'q_case_lpm = {name = "case_flow_m3_s", unit = "m3/s"}\n')
    capsys.readouterr()
    assert main(["fit", str(tmp_path / "ss" / "simscape_losses.mat"), "--channels", str(tmp_path / "ss.toml"),
                 "--motor", str(motor), "--out", str(tmp_path / "f2")]) == 0
    assert "±(Dω/2π + Q_loss)" in capsys.readouterr().out
    first = json.loads((first_fit / "result.json").read_text())["parameters"]
    again = json.loads((tmp_path / "f2" / "result.json").read_text())["parameters"]
    for k in ("Kv", "KF", "TFc", "KL0", "KAB"):
        assert again[k]["value"] == pytest.approx(first[k]["value"], rel=1e-6, abs=0), k
    # a loss in a pump's convention is not what the loss columns mean: refused, naming the column
    (tmp_path / "pump.toml").write_text("convention = \"pump\"\n" + (tmp_path / "ss.toml").read_text())
    assert main(["fit", str(tmp_path / "ss" / "simscape_losses.mat"), "--channels", str(tmp_path / "pump.toml"),
                 "--motor", str(motor), "--out", str(tmp_path / "f4")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "torque_loss_Nm" in err and "Simscape's convention" in err
    # the same quantity twice: a loss column and the reading it derives
    df.assign(torque_loss_Nm=1.0).to_csv(tmp_path / "both.csv", index=False)
    assert main(["fit", str(tmp_path / "both.csv"), "--motor", str(motor), "--out", str(tmp_path / "f3")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "torque_loss_Nm" in err and "keep one" in err
