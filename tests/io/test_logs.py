"""Reading bench logs: units at the edge, validation with one-line messages, missing cells."""

import gzip

import numpy as np
import pandas as pd
import pytest

from motorid.io import logs
from motorid.errors import InputError
from motorid.model import MotorSpec, OilSpec

SPEC = MotorSpec("test-9", pistons=9, displacement=80e-6, inertia=0.005, oil=OilSpec())
NO_OIL = MotorSpec("test-9", pistons=9, displacement=80e-6, oil=None)

HEADER = ("time_s,run_id,protocol,shaft_angle_deg,speed_rpm,torque_Nm,p_a_bar,p_b_bar,p_case_bar,"
          "q_a_lpm,q_b_lpm,q_case_lpm,oil_temp_C,viscosity_mPas")
ROWS = [
    "0.0,R1,constant_speed,10,60,50,100,5,1,5.0,-4.9,0.1,45,30",
    "0.1,R1,constant_speed,46,60,51,101,5,1,5.0,-4.9,0.1,45,30",
    "0.2,R1,constant_speed,82,60,52,102,5,1,5.0,-4.9,0.1,45,30",
    "0.0,R2,startability,5,0,20,50,5,1,0.0,0.0,0.0,45,30",
    "0.1,R2,startability,5,0,20,51,5,1,0.0,0.0,0.0,45,30",
]


def write(tmp_path, text, name="log.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def good_text(header=HEADER, rows=ROWS):
    return "\n".join([header, *rows]) + "\n"


def si_frame(n=50, run="R1", protocol="constant_speed", seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    return pd.DataFrame({
        "run_id": run, "protocol": protocol, "time_s": t,
        "theta_rad": np.mod(3.0 * t + 0.2, 2 * np.pi), "speed_rad_s": 3.0 + 0.01 * rng.standard_normal(n),
        "torque_Nm": 40.0 + rng.standard_normal(n), "p_a_Pa": 1e7 + 1e4 * rng.standard_normal(n),
        "p_b_Pa": np.full(n, 5e5), "p_case_Pa": np.full(n, 1e5), "q_a_m3_s": np.full(n, 1e-4),
        "q_b_m3_s": np.full(n, -0.98e-4), "q_case_m3_s": np.full(n, 2e-6), "oil_temp_C": np.full(n, 45.0),
        "viscosity_Pa_s": np.full(n, 0.03),
    })


def _insert(row, position, value):
    fields = row.split(",")
    return ",".join(fields[:position] + [value] + fields[position:])


def one_line(exc_info):
    msg = str(exc_info.value)
    assert "\n" not in msg and msg.strip() == msg
    return msg


# ------------------------------------------------------------------ round trip, gzip


def test_round_trip_through_write_log_gives_the_si_frame(tmp_path):
    frame = si_frame()
    path = logs.write_log(frame, tmp_path / "a.csv", full_precision=True)
    back = logs.read_log(path)
    assert list(back.columns[: len(logs.SI_COLUMNS)]) == logs.SI_COLUMNS
    assert {"file", "run"} <= set(back.columns)
    for col in logs.SI_COLUMNS[2:]:
        np.testing.assert_allclose(back[col], frame[col], rtol=1e-12, atol=1e-15, err_msg=col)
    assert (back["run"] == "R1").all() and (back["file"] == str(path)).all()


def test_gzip_read_by_suffix_and_by_magic_bytes(tmp_path):
    frame = si_frame()
    gz = logs.write_log(frame, tmp_path / "a.csv.gz")
    assert gz.read_bytes()[:2] == b"\x1f\x8b"
    disguised = tmp_path / "b.csv"  # gzip data under a plain name
    disguised.write_bytes(gz.read_bytes())
    for path in (gz, disguised):
        back = logs.read_log(path)
        np.testing.assert_allclose(back["p_a_Pa"], frame["p_a_Pa"], rtol=1e-6)


# ------------------------------------------------------------------ units, headers


def test_other_units_are_converted_to_si(tmp_path):
    header = (" Speed [rad/s] ,p_b_psi,P_A_PSI,shaft_angle_rad,time_s,run_id,protocol,torque_lbf_ft,"
              "p_case_kPa,q_a_gpm,q_b_m3_s,q_case_cm3_s,oil_temp_K,viscosity_cP,operator")
    rows = ["2.5,72.5,1450,7.0,0.0,R1,Constant Speed,10,100,2,-1e-4,3,318.15,30,ann",
            "2.5,72.5,1450,-0.5,0.5,R1,constant_speed,10,100,2,-1e-4,3,318.15,30,ann"]
    f = logs.read_log(write(tmp_path, good_text(header, rows)))
    psi = 6894.757293168361
    np.testing.assert_allclose(f["speed_rad_s"], 2.5)
    np.testing.assert_allclose(f["p_a_Pa"], 1450 * psi)
    np.testing.assert_allclose(f["p_b_Pa"], 72.5 * psi)
    np.testing.assert_allclose(f["p_case_Pa"], 1e5)
    np.testing.assert_allclose(f["q_a_m3_s"], 2 * 3.785411784e-3 / 60)  # US gallons per minute
    np.testing.assert_allclose(f["q_b_m3_s"], -1e-4)
    np.testing.assert_allclose(f["q_case_m3_s"], 3e-6)
    np.testing.assert_allclose(f["oil_temp_C"], 45.0)
    np.testing.assert_allclose(f["viscosity_Pa_s"], 0.03)
    np.testing.assert_allclose(f["torque_Nm"], 13.558179483314004)
    np.testing.assert_allclose(f["theta_rad"], [7.0 - 2 * np.pi, 2 * np.pi - 0.5])  # wrapped to [0, 2π)
    assert (f["protocol"] == "constant_speed").all()
    assert list(f["operator"]) == ["ann", "ann"]  # extra column kept


def test_more_units_of_flow_time_and_speed(tmp_path):
    header = (HEADER.replace("q_a_lpm", "q_a_l_h").replace("q_b_lpm", "q_b_m3_min").replace("q_case_lpm", "q_case_dm3_min")
              .replace("time_s", "time_us").replace("speed_rpm", "speed_Hz"))
    f = logs.read_log(write(tmp_path, good_text(header, ROWS)))
    np.testing.assert_allclose(f["q_a_m3_s"].iloc[0], 5e-3 / 3600)
    np.testing.assert_allclose(f["q_b_m3_s"].iloc[0], -4.9 / 60)
    np.testing.assert_allclose(f["q_case_m3_s"].iloc[0], 0.1e-3 / 60)
    np.testing.assert_allclose(f["time_s"].iloc[:3], [0.0, 1e-7, 2e-7])
    np.testing.assert_allclose(f["speed_rad_s"].iloc[0], 60 * 2 * np.pi)


def test_extra_columns_may_repeat_and_are_ignored(tmp_path):
    f = logs.read_log(write(tmp_path, good_text(HEADER + ",note,note", [r + ",a,b" for r in ROWS])))
    assert list(f["note"]) == ["a"] * len(ROWS) and list(f["note.16"]) == ["b"] * len(ROWS)
    assert list(f.columns[: len(logs.SI_COLUMNS)]) == logs.SI_COLUMNS


def test_rpm_degrees_fahrenheit_milliseconds_and_kinematic_viscosity(tmp_path):
    header = (HEADER.replace("oil_temp_C", "oil_temp_F").replace("viscosity_mPas", "viscosity_cSt")
              .replace("time_s", "Time (ms)").replace("p_case_bar", "p_case_mbar"))
    rows = [r.replace(",45,30", ",113,40").replace(",1,", ",700,") for r in ROWS]
    f = logs.read_log(write(tmp_path, good_text(header, rows)), SPEC)
    np.testing.assert_allclose(f["time_s"].iloc[:3], [0.0, 1e-4, 2e-4])
    np.testing.assert_allclose(f["p_case_Pa"], 0.7e5)
    np.testing.assert_allclose(f["speed_rad_s"].iloc[0], 2 * np.pi)
    np.testing.assert_allclose(f["theta_rad"].iloc[1], np.radians(46))
    np.testing.assert_allclose(f["oil_temp_C"], 45.0)
    from motorid.physics.oil import density

    np.testing.assert_allclose(f["viscosity_Pa_s"], 40e-6 * float(density(45.0, 875.0)))
    with pytest.raises(InputError) as exc:
        logs.read_log(write(tmp_path, good_text(header, rows), "k.csv"), NO_OIL)
    assert "k.csv" in one_line(exc) and "viscosity_cSt" in str(exc.value)


def test_comment_lines_semicolons_and_crlf(tmp_path):
    text = "# exported by BenchPro 7\r\n" + good_text().replace(",", ";").replace("\n", "\r\n")
    f = logs.read_log(write(tmp_path, text))
    assert len(f) == len(ROWS)
    np.testing.assert_allclose(f["p_a_Pa"].iloc[:3], [100e5, 101e5, 102e5])


# ------------------------------------------------------------------ missing cells, viscosity


def test_rows_with_missing_cells_are_kept(tmp_path):
    rows = list(ROWS)
    rows[1] = "0.1,R1,constant_speed,46,60,,101,5,1,NaN,-4.9,,45,30"
    f = logs.read_log(write(tmp_path, good_text(rows=rows)))
    assert len(f) == len(ROWS)
    assert np.isnan(f["torque_Nm"].iloc[1]) and np.isnan(f["q_a_m3_s"].iloc[1])
    assert np.isnan(f["q_case_m3_s"].iloc[1])
    assert f["p_a_Pa"].iloc[1] == 101e5 and f["torque_Nm"].iloc[0] == 50


def test_viscosity_from_temperature_and_the_oil(tmp_path):
    header = HEADER.replace(",viscosity_mPas", "")
    rows = [r.rsplit(",", 1)[0] for r in ROWS]
    rows[0] = rows[0].replace(",45", ",60")
    f = logs.read_log(write(tmp_path, good_text(header, rows)), SPEC)
    expected = np.asarray(SPEC.oil.viscosity(f["oil_temp_C"].to_numpy()))
    np.testing.assert_allclose(f["viscosity_Pa_s"], expected)
    assert f["viscosity_Pa_s"].iloc[0] < f["viscosity_Pa_s"].iloc[1]  # hotter oil is thinner
    assert 0.005 < f["viscosity_Pa_s"].iloc[1] < 0.1
    with pytest.raises(InputError) as exc:
        logs.read_log(write(tmp_path, good_text(header, rows), "noviscosity.csv"))
    assert "noviscosity.csv" in one_line(exc) and "viscosity" in str(exc.value)


def test_empty_viscosity_cells_are_filled_from_temperature(tmp_path):
    rows = list(ROWS)
    rows[2] = rows[2].rsplit(",", 1)[0] + ","
    f = logs.read_log(write(tmp_path, good_text(rows=rows)), SPEC)
    assert f["viscosity_Pa_s"].iloc[0] == pytest.approx(0.03)
    assert f["viscosity_Pa_s"].iloc[2] == pytest.approx(float(SPEC.oil.viscosity(45.0)))
    g = logs.read_log(write(tmp_path, good_text(rows=rows), "b.csv"))  # no spec: stays missing
    assert np.isnan(g["viscosity_Pa_s"].iloc[2]) and len(g) == len(ROWS)


# ------------------------------------------------------------------ bad input


def bad(tmp_path, text, name="bad.csv", spec=None):
    path = tmp_path / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(InputError) as exc:
        logs.read_log(path, spec)
    msg = one_line(exc)
    assert name in msg
    return msg


def test_missing_required_column_is_named(tmp_path):
    header = HEADER.replace(",q_case_lpm", "")
    rows = [",".join(r.split(",")[:11] + r.split(",")[12:]) for r in ROWS]
    msg = bad(tmp_path, good_text(header, rows))
    assert "missing required column" in msg and "q_case_lpm" in msg


def test_column_with_unknown_unit_is_pointed_at(tmp_path):
    msg = bad(tmp_path, good_text(HEADER.replace("speed_rpm", "speed_furlongs"), ROWS))
    assert "speed_rpm" in msg and "speed_furlongs" in msg


def test_text_in_numeric_column_names_column_and_line(tmp_path):
    rows = list(ROWS)
    rows[2] = rows[2].replace(",52,", ",oops,")
    msg = bad(tmp_path, good_text(rows=rows))
    assert "torque_Nm" in msg and "line 4" in msg and "oops" in msg


def test_time_not_increasing_within_a_run_names_the_run(tmp_path):
    rows = list(ROWS)
    rows[2] = rows[2].replace("0.2,R1", "0.1,R1", 1)
    msg = bad(tmp_path, good_text(rows=rows))
    assert "run 'R1'" in msg and "line 4" in msg and "increasing" in msg


def test_time_restarting_in_a_new_run_is_fine(tmp_path):
    f = logs.read_log(write(tmp_path, good_text()))
    assert list(f["run"].unique()) == ["R1", "R2"]


def test_unknown_protocol_names_run_and_protocol(tmp_path):
    rows = [r.replace("startability", "spin_test") for r in ROWS]
    msg = bad(tmp_path, good_text(rows=rows))
    assert "spin_test" in msg and "run 'R2'" in msg and "startability" in msg


def test_empty_and_header_only_files(tmp_path):
    assert "empty" in bad(tmp_path, "", "empty.csv")
    assert "empty" in bad(tmp_path, "\n\n  \n", "blank.csv")
    assert "no data rows" in bad(tmp_path, HEADER + "\n", "header.csv")


def test_binary_and_unreadable_files(tmp_path):
    rng = np.random.default_rng(1)
    assert "binary" in bad(tmp_path, bytes(rng.integers(0, 256, 4096, dtype=np.uint8)), "noise.csv")
    assert "gzip" in bad(tmp_path, b"\x1f\x8b\x08\x00garbage-not-deflate", "broken.csv.gz")
    with pytest.raises(InputError) as exc:
        logs.read_log(tmp_path / "nowhere.csv")
    assert "nowhere.csv" in one_line(exc) and "cannot read" in str(exc.value)


def test_a_copy_in_another_unit_beside_the_formats_column_is_an_extra_column(tmp_path):
    """BENCH_LOG_FORMAT.md: extra columns are kept and ignored; the format's own column wins,
    wherever it stands."""
    for header, rows in ((HEADER + ",p_a_psi,time_ms", [r + ",1450,7" for r in ROWS]),
                         ("p_a_psi," + HEADER, ["1450," + r for r in ROWS])):
        f = logs.read_log(write(tmp_path, good_text(header, rows), "copy.csv"))
        np.testing.assert_allclose(f["p_a_Pa"].iloc[:3], [100e5, 101e5, 102e5])
        np.testing.assert_allclose(f["time_s"].iloc[:3], [0.0, 0.1, 0.2])
        assert [float(x) for x in f["p_a_psi"]] == [1450.0] * len(ROWS)  # kept as read


def test_same_quantity_in_two_units_names_both_columns(tmp_path):
    header = HEADER.replace("p_a_bar", "p_a_kPa") + ",p_a_psi"
    rows = [r + ",1450" for r in ROWS]
    msg = bad(tmp_path, good_text(header, rows))
    assert "'p_a_kPa'" in msg and "'p_a_psi'" in msg
    msg = bad(tmp_path, good_text(HEADER + ", P_A_BAR ", [r + ",100" for r in ROWS]), "twice.csv")
    assert "p_a_bar" in msg.lower() and "twice" in msg


def test_empty_time_or_run_cell_is_an_error(tmp_path):
    rows = list(ROWS)
    rows[1] = rows[1].replace("0.1,R1", ",R1", 1)
    assert "time_s" in bad(tmp_path, good_text(rows=rows)) 
    rows = list(ROWS)
    rows[1] = rows[1].replace("0.1,R1", "0.1,", 1)
    assert "run_id" in bad(tmp_path, good_text(rows=rows), "norun.csv")


def test_impossible_values_are_refused(tmp_path):
    rows = [r.replace(",45,30", ",45,-3") for r in ROWS]
    assert "viscosity" in bad(tmp_path, good_text(rows=rows))
    rows = [r.replace(",45,30", ",-300,30") for r in ROWS]
    assert "absolute zero" in bad(tmp_path, good_text(rows=rows), "cold.csv")


def test_impossible_oil_in_the_spec_is_refused(tmp_path):
    header = HEADER.replace(",viscosity_mPas", "")
    rows = [r.rsplit(",", 1)[0] for r in ROWS]
    thick = MotorSpec("odd", pistons=9, displacement=80e-6, oil=OilSpec(nu40_cSt=5.0, nu100_cSt=46.0))
    with pytest.raises(InputError) as exc:
        logs.read_log(write(tmp_path, good_text(header, rows)), thick)
    assert "'odd' [oil]" in one_line(exc) and "nu100_cSt" in str(exc.value)


def test_cli_turns_a_bad_log_into_exit_status_2(tmp_path, capsys):
    from motorid.cli import main

    spec = tmp_path / "motor.toml"
    spec.write_text(SPEC.to_toml())
    log = write(tmp_path, good_text(HEADER.replace("torque_Nm", "torque_lbf_ft,torque_kNm"),
                                    [_insert(r, 6, "0.05") for r in ROWS]), "twotorques.csv")
    assert main(["fit", str(log), "--motor", str(spec), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "twotorques.csv" in err and "torque_kNm" in err and "Traceback" not in err


def test_ragged_row_is_a_parse_error_with_the_file_line(tmp_path):
    rows = list(ROWS)
    rows[3] = rows[3] + ",1,2"
    msg = bad(tmp_path, good_text(rows=rows))
    assert "line 5" in msg


# ------------------------------------------------------------------ campaigns


def test_read_logs_makes_run_keys_unique_across_files(tmp_path):
    a = logs.write_log(pd.concat([si_frame(run="R1"), si_frame(run="A2")]), tmp_path / "a.csv")
    b = logs.write_log(si_frame(run="R1"), tmp_path / "b.csv.gz")
    f = logs.read_logs([a, b])
    assert set(f["run"]) == {"a.csv:R1", "b.csv.gz:R1", "A2"}
    assert set(f["file"]) == {str(a), str(b)}
    assert len(f) == 150
    assert set(logs.read_logs(tmp_path)["run"]) == set(f["run"])  # a directory reads its logs
    with pytest.raises(InputError) as exc:
        logs.read_logs([a, a])
    assert "a.csv" in one_line(exc) and "twice" in str(exc.value)
    with pytest.raises(InputError):
        logs.read_logs([])


def test_bad_file_in_a_campaign_is_named(tmp_path):
    a = logs.write_log(si_frame(), tmp_path / "good.csv")
    b = write(tmp_path, good_text(rows=[r.replace("constant_speed", "warp") for r in ROWS]), "second.csv")
    with pytest.raises(InputError) as exc:
        logs.read_logs([a, b])
    assert "second.csv" in one_line(exc) and "warp" in str(exc.value)


def test_header_normalization():
    assert logs.normalize_header(" P_A [bar] ") == "p_a_bar"
    assert logs.normalize_header("Oil Temp (°C)") == "oil_temp_degc"
    assert logs.normalize_header("torque [N·m]") == "torque_nm"
    assert logs.normalize_header("q_case [l/min]") == "q_case_l_min"
    assert logs.normalize_header("viscosity_mPa.s") == "viscosity_mpas"
