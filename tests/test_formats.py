"""DAQ formats and channel maps (issue 20, docs/formats.md): real files written by their own
libraries (scipy.io, h5py, pyarrow, openpyxl, npTDMS, asammdf), read back through a channel
map, give the CSV path's frame to float precision; a fit on the TDMS copy is the CSV's fit;
bad files and bad maps are one line and exit 2."""

import json
import math

import numpy as np
import pandas as pd
import pytest

from conftest import REPO
from motorid.cli import main
from motorid.errors import InputError
from motorid.io.logs import read_logs
from motorid.io.spec import load_motor_spec

DEMO = REPO / "synthetic_data" / "demo"
MOTOR = DEMO / "motor.toml"
PSI = 6894.757293168361
ATM_PSI = 101325.0 / PSI
IN3 = 0.0254 ** 3


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """A small simulated campaign (constant-speed runs of the demo) as the format's CSV,
    runs named by number, and its channels as a foreign bench would log them."""
    df = pd.read_csv(DEMO / "campaign.csv.gz")
    df = df[df["protocol"] == "constant_speed"]
    runs = df["run_id"].drop_duplicates().iloc[::5]
    df = df[df["run_id"].isin(runs)].reset_index(drop=True)
    df["run_id"] = pd.factorize(df["run_id"])[0] + 1
    folder = tmp_path_factory.mktemp("campaign")
    csv = folder / "small.csv"
    df.to_csv(csv, index=False, float_format="%.17g")
    raw = {  # foreign names, units and signs
        "t": df["time_s"].to_numpy(),
        "RunNo": df["run_id"].to_numpy(dtype=float),
        "phi": np.deg2rad(df["shaft_angle_deg"].to_numpy()),
        "n_Motor": -df["speed_rpm"].to_numpy() * 2 * np.pi / 60,  # rad/s, the other direction
        "T_pump": -df["torque_Nm"].to_numpy(),  # torque into the shaft
        "pA_abs": df["p_a_bar"].to_numpy() * 1e5 / PSI + ATM_PSI,  # psia
        "pB": df["p_b_bar"].to_numpy() / 10.0,  # MPa
        "pCase": df["p_case_bar"].to_numpy(),
        "QA": df["q_a_lpm"].to_numpy() / 60000.0,  # m³/s
        "QB": df["q_b_lpm"].to_numpy(),
        "QL": df["q_case_lpm"].to_numpy() / 3.785411784,  # US gal/min
        "Toil": df["oil_temp_C"].to_numpy() + 273.15,
        "mu": df["viscosity_mPas"].to_numpy(),
    }
    return csv, raw, folder


def map_text(prefix="", time_name=None, fmt_lines=""):
    p = prefix
    return f"""{fmt_lines}
[constants]
protocol = "constant_speed"

[channels]
time_s = {{name = "{time_name or p + 't'}", unit = "s"}}
run_id = {{name = "{p}RunNo"}}
shaft_angle_deg = {{name = "{p}phi", unit = "rad"}}
speed_rpm = {{name = "{p}n_Motor", unit = "rad/s", sign = -1}}
torque_Nm = {{name = "{p}T_pump", unit = "N*m", sign = -1}}
p_a_bar = {{name = "{p}pA_abs", unit = "psi", absolute = true}}
p_b_bar = {{name = "{p}pB", unit = "MPa"}}
p_case_bar = {{name = "{p}pCase", unit = "bar"}}
q_a_lpm = {{name = "{p}QA", unit = "m3/s"}}
q_b_lpm = {{name = "{p}QB", unit = "l/min"}}
q_case_lpm = {{name = "{p}QL", unit = "gpm"}}
oil_temp_C = {{name = "{p}Toil", unit = "K"}}
viscosity_mPas = {{name = "{p}mu", unit = "mPa.s"}}
"""


def write_matlab_73(path, arrays: dict, struct: str):
    """A MATLAB v7.3 MAT-file as MATLAB writes it: HDF5 with a 512-byte user block holding
    the MAT header, a struct as a group, column-major arrays (stored with axes reversed)."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as h5:
        g = h5.create_group(struct)
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        for name, value in arrays.items():
            value = np.asarray(value, dtype=float)
            value = value.reshape(-1, 1) if value.ndim == 1 else value  # a column vector
            ds = g.create_dataset(name, data=value.T)
            ds.attrs["MATLAB_class"] = np.bytes_("double")
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created by: motorid tests HDF5 schema 1.00 ."
    with open(path, "r+b") as fh:
        fh.write(header.ljust(116) + b"\0" * 8 + b"\x00\x02" + b"IM")


def write_foreign(kind, raw, folder):
    """Write ``raw`` with the format's own library; return (file, channel-map text)."""
    if kind == "mat5":
        from scipy.io import savemat

        path = folder / "daq_v5.mat"
        savemat(path, {"daq": {k: v.reshape(-1, 1) for k, v in raw.items()}})
        return path, map_text("daq.")
    if kind == "mat73":
        path = folder / "daq_v73.mat"
        write_matlab_73(path, raw, "daq")
        return path, map_text("daq.")
    if kind == "hdf5":
        import h5py

        path = folder / "daq.h5"
        with h5py.File(path, "w") as h5:
            for k, v in raw.items():
                h5.create_dataset(f"bench7/signals/{k}", data=v)
        return path, map_text("", fmt_lines='[file]\ngroup = "bench7/signals"')
    if kind == "parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        path = folder / "daq.parquet"
        pq.write_table(pa.table(raw), path)
        return path, map_text()
    if kind == "xlsx":
        path = folder / "daq.xlsx"
        with pd.ExcelWriter(path, engine="openpyxl") as xw:
            pd.DataFrame({"note": ["bench 7 export"]}).to_excel(xw, sheet_name="Info", index=False)
            pd.DataFrame(raw).to_excel(xw, sheet_name="Data", index=False)
        return path, map_text("", fmt_lines='[file]\nsheet = "Data"')
    if kind == "tdms":
        from nptdms import ChannelObject, TdmsWriter

        path = folder / "daq.tdms"
        with TdmsWriter(str(path)) as w:
            w.write_segment([ChannelObject("Measurement", k, v) for k, v in raw.items()])
        return path, map_text("Measurement/")
    if kind == "mdf":
        from asammdf import MDF, Signal

        path = folder / "daq.mf4"
        mdf = MDF(version="4.10")
        t = raw["t"]
        mdf.append([Signal(v, t, name=k) for k, v in raw.items() if k != "t"])
        mdf.save(path, overwrite=True)
        mdf.close()
        return path, map_text("", time_name="n_Motor@time")
    if kind == "csv_semicolon_comma":
        path = folder / "daq_de.csv"
        table = pd.DataFrame(raw)
        table.to_csv(path, sep=";", decimal=",", index=False, float_format="%.17g")
        return path, map_text()
    raise AssertionError(kind)


KINDS = ["mat5", "mat73", "hdf5", "parquet", "xlsx", "tdms", "mdf", "csv_semicolon_comma"]


def assert_same_frame(got: pd.DataFrame, ref: pd.DataFrame):
    assert len(got) == len(ref)
    for col in ref.columns:
        if col in ("file",):
            continue
        if ref[col].dtype.kind == "f":
            scale = np.nanmax(np.abs(ref[col].to_numpy())) if ref[col].notna().any() else 1.0
            np.testing.assert_allclose(got[col].to_numpy(dtype=float), ref[col].to_numpy(), rtol=1e-12,
                                       atol=1e-13 * scale, err_msg=col)
        else:
            assert got[col].astype(str).tolist() == ref[col].astype(str).tolist(), col


@pytest.mark.parametrize("kind", KINDS)
def test_each_format_through_a_channel_map_reads_as_its_csv_twin(kind, campaign, tmp_path):
    csv, raw, _ = campaign
    spec = load_motor_spec(MOTOR)
    if kind == "xlsx":  # openpyxl writes slowly: two runs are enough to show the cells read back
        keep = raw["RunNo"] <= 2
        raw = {k: v[keep] for k, v in raw.items()}
        ref_csv = tmp_path / "ref.csv"
        pd.read_csv(csv)[keep].to_csv(ref_csv, index=False, float_format="%.17g")
        csv = ref_csv
    path, text = write_foreign(kind, raw, tmp_path)
    cmap = tmp_path / "bench7.toml"
    cmap.write_text(text)
    ref = read_logs(csv, spec)
    got = read_logs(path, spec, channels=cmap)
    assert_same_frame(got, ref)
    assert set(got["file"].astype(str)) == {str(path)}
    # the map beside the file is found without --channels
    cmap.rename(tmp_path / "channels.toml")
    assert_same_frame(read_logs(path, spec), ref)


@pytest.mark.parametrize("kind", ["mat73", "hdf5", "tdms", "mdf"])
def test_binary_formats_stream_in_blocks_as_they_read_whole(kind, campaign, tmp_path, monkeypatch):
    """HDF5, MATLAB v7.3, TDMS and MDF4 are read through their channel map in blocks of samples
    (h5py slices, npTDMS TdmsFile.open, asammdf record ranges): run by run, the same SI columns as
    the file read whole, bit for bit; and more than one block was read (memory: one block, one run)."""
    from motorid.io import stream
    from motorid.io.stream import runs_of_frame, stream_runs

    csv, raw, _ = campaign
    spec = load_motor_spec(MOTOR)
    path, text = write_foreign(kind, raw, tmp_path)
    cmap = tmp_path / "bench7.toml"
    cmap.write_text(text)
    monkeypatch.setattr(stream, "FOREIGN_BLOCK_ROWS", 1000)  # a small block: many blocks, runs across them
    plan = stream._foreign_plan(path, cmap)
    assert plan is not None
    blocks = list(plan[2])
    assert len(blocks) == math.ceil(len(raw["t"]) / 1000)
    got = list(stream_runs([path], spec, cmap, progress=False))
    ref = list(runs_of_frame(read_logs(path, spec, channels=cmap)))
    assert [r.run_id for r in got] == [r.run_id for r in ref] and len(got) == len(set(raw["RunNo"]))
    for a, b in zip(got, ref):
        assert a.protocol == b.protocol
        for col, v in b.columns.items():
            np.testing.assert_array_equal(a.columns[col], v, err_msg=f"{kind} {a.run_id} {col}")


def test_decimal_comma_csv_with_the_formats_own_headers_needs_no_map(campaign, tmp_path):
    csv, _, _ = campaign
    spec = load_motor_spec(MOTOR)
    de = tmp_path / "bench_de.csv"
    pd.read_csv(csv).to_csv(de, sep=";", decimal=",", index=False, float_format="%.17g")
    assert "," in de.read_text().splitlines()[1]
    assert_same_frame(read_logs(de, spec), read_logs(csv, spec))


def test_fit_on_the_tdms_copy_is_the_fit_on_the_csv(campaign, tmp_path, capsys):
    csv, raw, _ = campaign
    path, text = write_foreign("tdms", raw, tmp_path)
    cmap = tmp_path / "bench7.toml"
    cmap.write_text(text)
    assert main(["fit", str(csv), "--motor", str(MOTOR), "--out", str(tmp_path / "a")]) == 0
    assert main(["fit", str(path), "--channels", str(cmap), "--motor", str(MOTOR),
                 "--out", str(tmp_path / "b")]) == 0
    capsys.readouterr()
    a = json.loads((tmp_path / "a" / "result.json").read_text())["parameters"]
    b = json.loads((tmp_path / "b" / "result.json").read_text())["parameters"]
    assert a.keys() == b.keys()
    fitted = [k for k in a if a[k]["identifiable"]]
    assert len(fitted) >= 3
    for k in a:
        assert a[k]["identifiable"] == b[k]["identifiable"], k
        if a[k]["identifiable"]:
            assert math.isclose(a[k]["value"], b[k]["value"], rel_tol=1e-8), k
            assert math.isclose(a[k]["std"], b[k]["std"], rel_tol=1e-6), k


# --------------------------------------------------------------------------- gridded maps

def _grid_map():
    speed = np.array([500.0, 1000.0, 2000.0, 3000.0])  # rpm
    dp = np.array([50.0, 200.0, 350.0])  # bar
    torque = np.outer(np.ones(4), dp) * 80e-6 * 1e5 / (2 * np.pi) * 0.95 - 0.002 * speed[:, None]
    flow = (speed[:, None] * 80e-3) * (1 + 1e-4 * dp[None, :])  # L/min
    torque[3, 2] = np.nan
    flow[3, 2] = np.nan  # a point the bench did not reach
    return speed, dp, torque, flow


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
"""


@pytest.mark.parametrize("version", ["v5", "v7.3"])
def test_gridded_mat_loss_map_gives_one_row_per_point(version, tmp_path):
    from motorid.io.channel_map import load_channel_map
    from motorid.io.formats import standard_table

    speed, dp, torque, flow = _grid_map()
    path = tmp_path / "map.mat"
    if version == "v5":
        from scipy.io import savemat

        savemat(path, {"map": {"n": speed, "dp": dp, "T": torque, "Q": flow}})
    else:
        write_matlab_73(path, {"n": speed, "dp": dp, "T": torque, "Q": flow}, "map")
    (tmp_path / "map.toml").write_text(GRID_MAP)
    table = standard_table(path, load_channel_map(tmp_path / "map.toml"))
    rows = [(s, d, torque[i, j], flow[i, j]) for i, s in enumerate(speed) for j, d in enumerate(dp)
            if not np.isnan(torque[i, j])]
    assert len(table) == len(rows) == 11
    np.testing.assert_array_equal(table["speed_rpm"], [r[0] for r in rows])
    np.testing.assert_array_equal(table["dp_bar"], [r[1] for r in rows])
    # pump convention: torque into the shaft and flow out of the high-pressure port, negated
    np.testing.assert_allclose(table["torque_Nm"], [-r[2] for r in rows], rtol=1e-15)
    np.testing.assert_allclose(table["q_a_lpm"], [-r[3] for r in rows], rtol=1e-15)
    assert (table["oil_temp_C"] == 50.0).all()
    # a transposed matrix is named, with the fix
    bad = tmp_path / "map_t.mat"
    from scipy.io import savemat

    savemat(bad, {"map": {"n": speed, "dp": dp, "T": torque.T, "Q": flow}})
    with pytest.raises(InputError, match=r"map\.T.*transposed"):
        standard_table(bad, load_channel_map(tmp_path / "map.toml"))


def test_a_square_grid_read_with_its_axes_swapped_is_refused_naming_the_axes(tmp_path):
    """A square grid (as many speeds as pressures) cannot tell its axes apart by shape: read the wrong
    way round its flows contradict the swept flow, and the refusal blamed a unit alone (a second reader);
    it now names the [grid] axes too."""
    from scipy.io import savemat

    from motorid.io.tables import read_tables

    speed = np.linspace(500.0, 3000.0, 4)  # rpm
    dp = np.linspace(50.0, 350.0, 4)  # bar
    torque = np.outer(np.ones(4), dp) * 80e-6 * 1e5 / (2 * np.pi) * 0.95
    flow = np.outer(speed, np.ones(4)) * 80e-3 * 1.02  # L/min
    path = tmp_path / "map.mat"
    savemat(path, {"map": {"n": speed, "dp": dp, "T": torque.T, "Q": flow.T}})  # the maker's rows: ΔP
    (tmp_path / "map.toml").write_text(GRID_MAP.replace('convention = "pump"\n', ""))
    with pytest.raises(InputError, match=r"\[grid\] axes in the wrong order"):
        read_tables([path], load_motor_spec(MOTOR), channels=tmp_path / "map.toml")


def test_a_square_torque_only_grid_read_with_its_axes_swapped_is_refused(tmp_path):
    """Without a flow to contradict the swept flow, a square torque map read the wrong way round
    had every ideal-machine ratio in range (the torque's mean slope on the misread ΔP near 1) and
    was fitted with exit 0: K_F 9× the truth, K_v and T_Fc at zero (a new user's 8 × 8 .mat map of
    a 250 cm³/rev radial-piston motor).  Read right, the same file passes."""
    from scipy.io import savemat

    from motorid.io.tables import read_tables
    from motorid.io.table_checks import MIN_PRESSURE_SHARE, _torque_follows_pressure

    speed = np.linspace(20.0, 300.0, 8)  # rpm: numbers like the pressures' own
    dp = np.linspace(25.0, 300.0, 8)  # bar
    D = 80e-6
    omega = speed * 2 * np.pi / 60
    loss = 0.006 * D * np.outer(2 * dp * 1e5, np.ones(8)) / (2 * np.pi) + 0.02 * np.outer(np.ones(8), omega) + 2.0
    torque = D * np.outer(dp * 1e5, np.ones(8)) / (2 * np.pi) - loss  # the maker's rows: ΔP
    path = tmp_path / "map.mat"
    savemat(path, {"map": {"n": speed, "dp": dp, "T": torque}})
    text = GRID_MAP.replace('convention = "pump"\n', "").replace('q_a_lpm = {name = "map.Q", unit = "l/min"}\n', "")
    (tmp_path / "map.toml").write_text(text)
    with pytest.raises(InputError, match=r"torque does not follow the pressure torque.*\[grid\] axes in the wrong order"):
        read_tables([path], load_motor_spec(MOTOR), channels=tmp_path / "map.toml")
    # the same grid declared the right way round passes
    (tmp_path / "right.toml").write_text(text.replace('axes = ["speed_rpm", "dp_bar"]', 'axes = ["dp_bar", "speed_rpm"]'))
    table = read_tables([path], load_motor_spec(MOTOR), channels=tmp_path / "right.toml")
    assert len(table) == 64
    # what the check measures: read right the pressure torque explains nearly all, swapped nearly none
    ideal = D * np.outer(dp * 1e5, np.ones(8)).ravel() / (2 * np.pi)
    share, n = _torque_follows_pressure(torque.ravel(), ideal, np.outer(np.ones(8), omega).ravel())
    assert share > 0.99 and n == 64
    swapped, _ = _torque_follows_pressure(torque.T.ravel(), ideal, np.outer(np.ones(8), omega).ravel())
    assert swapped < MIN_PRESSURE_SHARE


# --------------------------------------------------------------------------- bad files, bad maps

def _cli_fails(args, capsys):
    rc = main([str(a) for a in args])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    return err


@pytest.mark.parametrize("suffix", [".tdms", ".mf4", ".parquet", ".h5", ".mat", ".xlsx"])
def test_corrupt_file_is_one_line_exit_2(suffix, campaign, tmp_path, capsys):
    _, _, _ = campaign
    path = tmp_path / f"broken{suffix}"
    path.write_bytes(bytes(range(256)) * 7)
    cmap = tmp_path / "m.toml"
    cmap.write_text(map_text())
    err = _cli_fails(["fit", path, "--channels", cmap, "--motor", MOTOR, "--out", tmp_path / "r"], capsys)
    assert str(path) in err and "cannot read" in err
    assert not (tmp_path / "r").exists()


def test_missing_channel_names_file_and_channel(campaign, tmp_path, capsys):
    _, raw, _ = campaign
    raw = {k: v for k, v in raw.items() if k != "QL"}
    path, text = write_foreign("tdms", raw, tmp_path)
    cmap = tmp_path / "m.toml"
    cmap.write_text(text)
    err = _cli_fails(["fit", path, "--channels", cmap, "--motor", MOTOR, "--out", tmp_path / "r"], capsys)
    assert str(path) in err and "'Measurement/QL'" in err and "Measurement/QB" in err


@pytest.mark.parametrize("edit,words", [
    (("unit = \"gpm\"", "unit = \"furlongs/fortnight\""), ["[channels] q_case_lpm", "unknown flow unit"]),
    (("[channels]", "[channels]\nspeed = {name = \"x\", unit = \"rpm\"}"), ["[channels] speed", "unknown column"]),
    (("[constants]", "colour = \"red\"\n[constants]"), ["unknown key 'colour'"]),
    (("q_case_lpm = {name = \"QL\", unit = \"gpm\"}", ""), ["[channels] q_case_lpm", "missing"]),
    (("sign = -1}", "sign = 2}"), ["[channels] speed_rpm", "sign must be 1 or -1"]),
    (("unit = \"MPa\"}", "unit = \"MPa\", absolute = \"yes\"}"), ["[channels] p_b_bar", "absolute"]),
    (("protocol = \"constant_speed\"", "protocol = \"wobble\""), ["protocol", "wobble"]),
])
def test_bad_channel_map_is_one_line_naming_file_and_key(edit, words, campaign, tmp_path, capsys):
    csv, raw, _ = campaign
    path, text = write_foreign("parquet", raw, tmp_path)
    assert edit[0] in text
    cmap = tmp_path / "bench7.toml"
    cmap.write_text(text.replace(edit[0], edit[1], 1))
    err = _cli_fails(["fit", path, "--channels", cmap, "--motor", MOTOR, "--out", tmp_path / "r"], capsys)
    assert str(cmap) in err
    for w in words:
        assert w in err


# --------------------------------------------------------------------------- real recordings

MBARI = REPO / "real_data" / "mbari_f11"
MBARI_POINTS = REPO / "real_data" / "mbari_f11_points"


def test_mbari_recording_reads_through_its_map_with_physical_signs():
    """The MBARI F11-5 recordings (real_data/mbari_f11): through channels.toml the port-A
    pressure drives positive speed, flow from ram speed is the displacement flow within a few
    per cent, and torque from generator current tracks ΔP·V/2π with an efficiency below one."""
    spec = load_motor_spec(MBARI / "motor.toml")
    f = read_logs(MBARI / "FrictionIDMovesWithBiasCurr.exp.gz", spec)
    assert len(f) == 20001 and np.allclose(np.diff(f["time_s"]), 0.02)
    assert f["theta_rad"].isna().all() and f["q_case_m3_s"].isna().all()
    w = f["speed_rad_s"].to_numpy()
    run = np.abs(w) > 300 * 2 * np.pi / 60
    dp = (f["p_a_Pa"] - f["p_b_Pa"]).to_numpy()
    ideal_torque = dp * spec.displacement / (2 * np.pi)
    torque = f["torque_Nm"].to_numpy()
    slope, _ = np.polyfit(ideal_torque[run], torque[run], 1)
    assert np.corrcoef(ideal_torque[run], torque[run])[0, 1] > 0.95
    assert 0.6 < slope < 0.95  # torque efficiency, generator friction and current-to-torque included
    ideal_flow = w * spec.displacement / (2 * np.pi)
    ratio = np.median(f["q_a_m3_s"].to_numpy()[run] / ideal_flow[run])
    assert 0.95 < ratio < 1.05
    np.testing.assert_allclose(f["q_b_m3_s"], -f["q_a_m3_s"])
    # points.csv (make_points.py) holds this recording's quasi-steady points, as made from it
    import importlib.util

    spec_mod = importlib.util.spec_from_file_location("make_points", MBARI_POINTS / "make_points.py")
    make_points = importlib.util.module_from_spec(spec_mod)
    spec_mod.loader.exec_module(make_points)
    mine = make_points.quasi_steady_points(f)
    shipped = pd.read_csv(MBARI_POINTS / "points.csv")
    assert make_points.passive(shipped).all()  # no shipped point gives power out at shaft and ports alike
    backwards = pd.DataFrame({"torque_Nm": [0.8, 0.8], "speed_rpm": [700, 700], "p_a_bar": [1, 15],
                              "p_b_bar": [15, 1], "q_a_lpm": [0.5, 0.5]})
    assert make_points.passive(backwards).tolist() == [False, True]
    shipped = shipped[shipped["recording"] == "FrictionIDMovesWithBiasCurr"].reset_index(drop=True)
    assert len(mine) == len(shipped) >= 10
    for col in ("speed_rpm", "p_a_bar", "p_b_bar", "torque_Nm", "q_a_lpm"):
        np.testing.assert_allclose(shipped[col], mine[col], rtol=1e-5, atol=1e-5, err_msg=col)
    # the first release of the 2022-01-28 test logged the lower pressure negated; its own map flips it
    g = read_logs(MBARI / "original_sign" / "2022.01.28T16.46.31.exp.gz", spec)
    h = read_logs(MBARI / "2022.01.28T16.46.31_new.exp.gz", spec)
    n = len(h)
    np.testing.assert_allclose(g["p_b_Pa"].to_numpy()[:n], h["p_b_Pa"].to_numpy(), atol=1e-9)


# ----------------------------------------------------------------------------- a new user's bench files
# (found by trying motorid as a new user would, 2026-11-26)

def test_a_plain_csv_log_with_its_own_names_is_a_log_under_its_map(campaign, tmp_path):
    """A ','-separated log whose columns a channel map names (its time column 't', which reads as no
    time column) was taken for an operating-point table and refused ('missing speed_rpm'), both under
    --channels and with the map beside it; a native table given with the logs' map stays a table."""
    from motorid.io.tables import split_logs_and_tables

    csv, raw, _ = campaign
    spec = load_motor_spec(MOTOR)
    path = tmp_path / "bench.csv"
    pd.DataFrame(raw).to_csv(path, index=False, float_format="%.17g")
    cmap = tmp_path / "bench7.toml"
    cmap.write_text(map_text())
    table = tmp_path / "points.csv"
    pd.DataFrame({"speed_rpm": [100.0, 200.0, 300.0], "p_a_bar": [100.0] * 3, "p_b_bar": [0.0] * 3,
                  "torque_Nm": [10.0, 11.0, 12.0]}).to_csv(table, index=False)
    assert split_logs_and_tables([path, table], cmap) == ([path], [table])
    assert_same_frame(read_logs(path, spec, channels=cmap), read_logs(csv, spec))
    cmap.rename(tmp_path / "bench.channels.toml")  # beside the file
    assert split_logs_and_tables([path], None) == ([path], [])
    assert_same_frame(read_logs(path, spec), read_logs(csv, spec))


@pytest.mark.parametrize("unit,factor", [("lbf*in", 0.1129848290276167), ("lbf·ft", 1.3558179483314004),
                                         ("in.lbf", 0.1129848290276167), ("ft-lb", 1.3558179483314004)])
def test_torque_in_the_units_makers_write_reads(unit, factor, campaign, tmp_path):
    """'lbf*in' normalizes to 'lbfin' (the separator dropped): it was refused as an unknown unit."""
    csv, raw, _ = campaign
    spec = load_motor_spec(MOTOR)
    raw = dict(raw, T_pump=raw["T_pump"] / factor)
    path = tmp_path / "bench.parquet"
    pd.DataFrame(raw).to_parquet(path)
    cmap = tmp_path / "map.toml"
    cmap.write_text(map_text().replace('unit = "N*m", sign = -1', f'unit = "{unit}", sign = -1'))
    np.testing.assert_allclose(read_logs(path, spec, channels=cmap)["torque_Nm"], read_logs(csv, spec)["torque_Nm"],
                               rtol=1e-12, atol=1e-12)


def test_a_psia_channel_is_absolute_without_saying_so_and_a_contradiction_is_refused(campaign, tmp_path):
    """unit = "psia" with no 'absolute' key was read as gauge (1.013 bar high: K_L0 64 σ off)."""
    csv, raw, _ = campaign
    spec = load_motor_spec(MOTOR)
    path = tmp_path / "bench.parquet"
    pd.DataFrame(raw).to_parquet(path)
    cmap = tmp_path / "map.toml"
    cmap.write_text(map_text().replace('unit = "psi", absolute = true', 'unit = "psia"'))
    np.testing.assert_allclose(read_logs(path, spec, channels=cmap)["p_a_Pa"], read_logs(csv, spec)["p_a_Pa"],
                               rtol=1e-12, atol=1e-4)
    cmap.write_text(map_text().replace('unit = "psi", absolute = true', 'unit = "psia", absolute = false'))
    with pytest.raises(InputError, match=r"map.toml: \[channels\] p_a_bar: unit .psia. is an absolute pressure"):
        read_logs(path, spec, channels=cmap)


def test_a_timestamp_time_channel_reads_as_seconds(campaign, tmp_path):
    """A datetime64 time track (as NI and MDF loggers write it) was read as raw microsecond counts
    taken for seconds: time steps of 10 000 s, no warning."""
    csv, raw, _ = campaign
    spec = load_motor_spec(MOTOR)
    start = np.datetime64("2026-03-01T08:00:00", "us")
    stamps = start + (raw["t"] * 1e6).round().astype("timedelta64[us]")
    path = tmp_path / "bench.parquet"
    pd.DataFrame(dict(raw, t=stamps)).to_parquet(path)
    _time_reads_as_seconds_and_not_as_ms(path, csv, spec, tmp_path, r"holds timestamps")


def _time_reads_as_seconds_and_not_as_ms(path, csv, spec, folder, refusal: str):
    """``path``'s time channel 't', mapped with unit = "s", steps as the CSV twin's time; mapped as ms,
    refused in one line matching ``refusal``."""
    cmap = folder / "map.toml"
    cmap.write_text(map_text())
    got, ref = read_logs(path, spec, channels=cmap), read_logs(csv, spec)
    np.testing.assert_allclose(np.diff(got["time_s"]), np.diff(ref["time_s"]), atol=2e-6)
    cmap.write_text(map_text().replace('time_s = {name = "t", unit = "s"}', 'time_s = {name = "t", unit = "ms"}'))
    with pytest.raises(InputError, match=r"channel 't' \(time_s\) " + refusal):
        read_logs(path, spec, channels=cmap)


def test_a_map_of_a_time_series_that_forgot_time_is_refused(campaign, tmp_path):
    """With run_id, protocol and shaft angle mapped but no time_s the map was taken for a loss map's,
    and a time series was fitted as operating points (exit 0)."""
    from motorid.io.channel_map import load_channel_map

    cmap = tmp_path / "map.toml"
    cmap.write_text(map_text().replace('time_s = {name = "t", unit = "s"}\n', ""))
    with pytest.raises(InputError, match=r"maps shaft_angle_deg, which only a time series has, but no time_s"):
        load_channel_map(cmap)


@pytest.mark.parametrize("segments", [1, 4])
def test_a_tdms_file_cut_short_is_refused_in_one_line(segments, campaign, tmp_path, capsys):
    """A TDMS file cut inside its last segment (a DAQ stopped mid-write): npTDMS reads it "to the end
    of the file" with two warning lines, and motorid fitted the part it got (exit 0); now one line."""
    from nptdms import ChannelObject, TdmsWriter

    _, raw, _ = campaign
    path = tmp_path / "cut.tdms"
    n = len(raw["t"])
    with TdmsWriter(str(path)) as w:
        for part in np.array_split(np.arange(n), segments):
            w.write_segment([ChannelObject("Measurement", k, np.asarray(v, float)[part]) for k, v in raw.items()])
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * 0.6)])
    cmap = tmp_path / "map.toml"
    cmap.write_text(map_text(prefix="Measurement/"))
    with pytest.raises(InputError, match=r"cut.tdms: cut short: its last segment holds \d+ of the \d+ samples "
                                         r"its header announces"):
        read_logs(path, load_motor_spec(MOTOR), channels=cmap)
    assert "nptdms" not in capsys.readouterr().err


@pytest.mark.parametrize("edit,words", [
    (('unit = "rad/s", sign = -1', 'unit = "rpm", sign = -1'), "as for a speed in rad/s read as rpm"),
    (('time_s = {name = "t", unit = "s"}', 'time_s = {name = "t", unit = "ms"}'), "as for a time in s read as ms"),
])
def test_a_unit_mistake_the_shaft_angle_contradicts_is_refused(edit, words, campaign, tmp_path, capsys):
    """A speed logged in rad/s mapped as rpm (or a time in s mapped as ms) is a valid unit, and was
    fitted silently (K_v 528 instead of 5000): the shaft angle's own rate says otherwise."""
    _, raw, _ = campaign
    path = tmp_path / "bench.parquet"
    pd.DataFrame(raw).to_parquet(path)
    cmap = tmp_path / "map.toml"
    cmap.write_text(map_text().replace(*edit))
    err = _cli_fails(["fit", str(path), "--channels", str(cmap), "--motor", str(MOTOR), "--out",
                      str(tmp_path / "out")], capsys)
    assert "the shaft angle advances at" in err and words in err


@pytest.mark.parametrize("kind", ["xlsx", "csv"])
def test_a_units_row_under_the_header_is_skipped(kind, tmp_path):
    """Makers' sheets put the units in the row under the names ('rpm', 'bar', …): it was read as the
    first point ('rpm' is not a number); [file] skip_rows = 1 leaves it out."""
    from motorid.io.tables import read_tables

    spec = load_motor_spec(MOTOR)
    rows = [["n", "pA", "pB", "M"], ["rpm", "bar", "bar", "N·m"], [1000, 150, 0, 170.5], [2000, 250, 0, 290.25]]
    if kind == "xlsx":
        from openpyxl import Workbook

        wb = Workbook()
        for r in rows:
            wb.active.append(r)
        path = tmp_path / "maker.xlsx"
        wb.save(path)
    else:
        path = tmp_path / "maker.csv"
        path.write_text("\n".join(";".join(str(v).replace(".", ",") for v in r) for r in rows) + "\n")
    cmap = tmp_path / "maker.toml"
    cmap.write_text('[file]\nskip_rows = 1\n[constants]\noil_temp_C = 50.0\n[channels]\n'
                    'speed_rpm = {name = "n", unit = "rpm"}\n'
                    'p_a_bar = {name = "pA", unit = "bar"}\np_b_bar = {name = "pB", unit = "bar"}\n'
                    'torque_Nm = {name = "M", unit = "N*m"}\n')
    table = read_tables([path], spec, channels=cmap)
    np.testing.assert_allclose(table.measured["torque"], [170.5, 290.25])
    np.testing.assert_allclose(table.speed, np.array([1000, 2000]) * 2 * np.pi / 60)


def test_a_workbook_of_numbers_stored_as_text_with_decimal_commas(tmp_path):
    """A German workbook whose cells are text ('-2,0', '1.002,5'): [file] decimal = "," reads them as
    numbers (it was accepted and ignored: "'-2,0' is not a number"); a column of other text is left as
    it is, and without the key the text is refused as before."""
    from openpyxl import Workbook

    from motorid.io.tables import read_tables

    spec = load_motor_spec(MOTOR)
    wb = Workbook()
    for r in (["n", "pA", "pB", "M", "Bem"], ["1.000", "150,0", "0", "170,5", "ok"], ["-2.000,5", "250", "0", "-290,25", "ok"]):
        wb.active.append(r)
    path = tmp_path / "messung.xlsx"
    wb.save(path)
    text = ('[constants]\noil_temp_C = 50.0\n[channels]\nspeed_rpm = {name = "n", unit = "rpm"}\n'
            'p_a_bar = {name = "pA", unit = "bar"}\np_b_bar = {name = "pB", unit = "bar"}\n'
            'torque_Nm = {name = "M", unit = "N*m"}\n')
    cmap = tmp_path / "messung.toml"
    cmap.write_text('[file]\ndecimal = ","\n' + text)
    table = read_tables([path], spec, channels=cmap)
    np.testing.assert_allclose(table.measured["torque"], [170.5, -290.25])
    np.testing.assert_allclose(table.speed, np.array([1000.0, -2000.5]) * 2 * np.pi / 60)
    cmap.write_text(text)
    with pytest.raises(InputError, match="not a number"):
        read_tables([path], spec, channels=cmap)


@pytest.mark.parametrize("kind", ["hdf5", "csv"])
def test_a_time_track_from_the_sample_rate(kind, campaign, tmp_path, monkeypatch):
    """A DAQ that stores its samples at a fixed rate and no time channel (HDF5 with an 'fs' attribute,
    a CSV of values): time_s = {sample_rate_Hz = …} gives sample i the time i / rate, whole or in blocks."""
    import h5py

    from motorid.io import stream

    csv, raw, _ = campaign
    spec = load_motor_spec(MOTOR)
    first = raw["RunNo"] == raw["RunNo"][0]  # one run at its own constant rate
    raw = {k: v[first] for k, v in raw.items()}
    rate = 1.0 / float(np.median(np.diff(raw["t"])))
    rest = {k: v for k, v in raw.items() if k != "t"}
    if kind == "hdf5":
        path = tmp_path / "daq.h5"
        with h5py.File(path, "w") as h5:
            for k, v in rest.items():
                h5.create_dataset(k, data=np.asarray(v, float))
    else:
        path = tmp_path / "daq.csv"
        pd.DataFrame(rest).to_csv(path, index=False, float_format="%.17g")
    cmap = tmp_path / "map.toml"
    cmap.write_text(map_text().replace('time_s = {name = "t", unit = "s"}',
                                       f"time_s = {{sample_rate_Hz = {rate!r}}}"))
    got = read_logs(path, spec, channels=cmap)
    np.testing.assert_allclose(got["time_s"].to_numpy(), np.arange(len(got)) / rate, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got["time_s"].to_numpy() - got["time_s"].iloc[0], raw["t"] - raw["t"][0], atol=1e-6)
    if kind == "hdf5":  # the same in blocks
        monkeypatch.setattr(stream, "FOREIGN_BLOCK_ROWS", 1000)
        runs = list(stream.stream_runs([path], spec, channels=cmap, progress=False))
        t = np.concatenate([r.columns["time_s"] for r in runs])
        np.testing.assert_allclose(np.sort(t), np.arange(len(got)) / rate, atol=1e-9)
    cmap.write_text(map_text().replace('time_s = {name = "t", unit = "s"}',
                                       'time_s = {sample_rate_Hz = 100, unit = "s"}'))
    with pytest.raises(InputError, match="sample_rate_Hz stands alone"):
        read_logs(path, spec, channels=cmap)


@pytest.mark.parametrize("form", ["zone", "text", "day_first"])
def test_date_times_with_a_zone_or_as_text_read_as_seconds(form, campaign, tmp_path):
    """Time-zone-aware stamps (pandas keeps them as objects) were read as raw µs counts, 10⁶ times the
    run's length, with exit 0; wall-clock text ('2026-03-14 10:22:01.125', or day first with a
    decimal comma, as a German DAQ export writes it) was refused as not a number."""
    csv, raw, _ = campaign
    spec = load_motor_spec(MOTOR)
    stamps = pd.Timestamp("2026-03-14 10:22:01", tz="Europe/Berlin") + pd.to_timedelta(raw["t"], unit="s")
    if form == "zone":
        path = tmp_path / "bench.parquet"
        pd.DataFrame(dict(raw, t=stamps)).to_parquet(path)
    else:
        text = stamps.strftime("%Y-%m-%d %H:%M:%S.%f" if form == "text" else "%d.%m.%Y %H:%M:%S,%f")
        path = tmp_path / "bench.txt"
        pd.DataFrame(dict(raw, t=text)).to_csv(path, index=False, sep=";" if form == "day_first" else ",",
                                               float_format="%.17g")
    _time_reads_as_seconds_and_not_as_ms(path, csv, spec, tmp_path, r"holds (date-times|timestamps)")


def test_runs_logged_one_after_another_without_a_run_column_are_told_apart_by_the_time(campaign, tmp_path):
    """A file that maps no run column was one run: 21 constant-speed set points from 3 to 2500 rpm
    fitted as one, K_v 38σ off (exit 0).  A pause in the time track (here 5 s) or a time that starts
    again begins a new run; the runs are those of the file with run numbers."""
    csv, raw, _ = campaign
    spec = load_motor_spec(MOTOR)
    ref = read_logs(csv, spec)
    run = raw["RunNo"]
    starts = np.r_[True, run[1:] != run[:-1]]
    which = np.cumsum(starts) - 1  # each sample's run, 0, 1, …
    from_zero = raw["t"] - raw["t"][np.flatnonzero(starts)][which]  # each run's clock from 0
    for t_form in ("pause", "restart"):
        t = from_zero
        if t_form == "pause":  # one clock, 5 s between the end of a run and the start of the next
            ends = np.array([from_zero[which == k].max() for k in range(which[-1] + 1)])
            t = from_zero + np.r_[0.0, np.cumsum(ends[:-1] + 5.0)][which]
        path = tmp_path / f"{t_form}.parquet"
        pd.DataFrame(dict(raw, t=t)).drop(columns=["RunNo"]).to_parquet(path)
        cmap = tmp_path / "map.toml"
        cmap.write_text(map_text().replace('run_id = {name = "RunNo"}\n', ""))
        got = read_logs(path, spec, channels=cmap)
        assert got["run_id"].nunique() == ref["run_id"].nunique() == np.unique(run).size
        assert list(pd.factorize(got["run_id"])[0]) == list(pd.factorize(ref["run_id"].astype(str))[0])
        assert got["run_id"].iloc[0] == t_form and f"{t_form}#2" in set(got["run_id"])


def test_a_log_with_no_temperature_takes_the_specs_assumed_one_and_says_so(campaign, tmp_path, capsys):
    """No oil temperature and no viscosity: every parameter was 'not identifiable' with wrong reasons
    ('no running-torque samples', notes of 'no steady speed (median nan rad/s)').  With [oil] temp_C in
    the spec it stands for every sample, and the fit says it was assumed; without, one line."""
    csv, raw, _ = campaign
    path = tmp_path / "bench.parquet"
    pd.DataFrame(raw).drop(columns=["Toil", "mu"]).to_parquet(path)
    cmap = tmp_path / "map.toml"
    cmap.write_text(map_text(fmt_lines='absent = ["oil_temp_C", "viscosity_mPas"]')
                    .replace('oil_temp_C = {name = "Toil", unit = "K"}\n', "")
                    .replace('viscosity_mPas = {name = "mu", unit = "mPa.s"}\n', ""))
    spec_text = MOTOR.read_text()
    assert "temp_C" not in spec_text
    (tmp_path / "none.toml").write_text(spec_text)
    (tmp_path / "t40.toml").write_text(spec_text.replace("[oil]", "[oil]\ntemp_C = 40.0"))
    out = _cli_fails(["fit", str(path), "--channels", str(cmap), "--motor", str(tmp_path / "none.toml"),
                      "--out", str(tmp_path / "r0")], capsys)
    assert "no oil temperature and no viscosity in this log" in out and "[oil] temp_C" in out
    assert main(["fit", str(path), "--channels", str(cmap), "--motor", str(tmp_path / "t40.toml"),
                 "--out", str(tmp_path / "r1"), "--quiet"]) == 0
    doc = json.loads((tmp_path / "r1" / "result.json").read_text())
    assert all(p["identifiable"] for k, p in doc["parameters"].items() if k in ("Kv", "KL0"))
    assert any("spec's assumed [oil] temp_C = 40 °C" in w for w in doc["fit"]["warnings"])


def test_a_log_without_a_needed_input_says_which_not_a_nan_speed(campaign, tmp_path):
    from motorid.identify.least_squares import fit_least_squares
    from motorid.identify.pipeline import load_campaign

    csv, raw, _ = campaign
    path = tmp_path / "bench.parquet"
    pd.DataFrame(raw).drop(columns=["phi"]).to_parquet(path)
    cmap = tmp_path / "map.toml"
    cmap.write_text(map_text(fmt_lines='absent = ["shaft_angle_deg"]')
                    .replace('shaft_angle_deg = {name = "phi", unit = "rad"}\n', ""))
    spec = load_motor_spec(MOTOR)
    _, ds = load_campaign([path], spec, cmap)
    assert all("none holds a shaft angle" in n for n in ds.notes if n.startswith("run "))
    ls = fit_least_squares(ds, spec)
    assert "running runs left out: missing a shaft angle" in ls.reasons["Kv"]


def test_a_folder_of_daq_files_each_with_its_own_map_is_read_as_the_files(campaign, tmp_path):
    """A folder of .tdms files, each with <stem>.channels.toml beside it: 'directory holds no .csv or
    .csv.gz file', though the same files listed one by one fitted."""
    from motorid.io.tables import split_logs_and_tables

    _, raw, _ = campaign
    folder = tmp_path / "bench7"
    folder.mkdir()
    run = raw["RunNo"]
    for r in np.unique(run)[:3]:
        part = {k: v[run == r] for k, v in raw.items()}
        path, text = write_foreign("tdms", part, folder)
        stem = f"run_{int(r):03d}"
        path.rename(folder / f"{stem}.tdms")
        (folder / f"{stem}.channels.toml").write_text(text)
    logs, tables = split_logs_and_tables([folder])
    assert [p.name for p in logs] == ["run_001.tdms", "run_002.tdms", "run_003.tdms"] and tables == []
    frame = read_logs(logs, load_motor_spec(MOTOR))
    assert frame["run_id"].nunique() == 3
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match=r"directory holds no file motorid reads \(.csv, .csv.gz, or a DAQ"):
        split_logs_and_tables([tmp_path / "empty"])


def test_run_numbers_that_start_again_for_each_protocol_are_runs_of_their_protocol(tmp_path):
    """Run 1 of the constant-speed test and run 1 of the startability test in one log were refused
    ("run '1' has several protocols"): a run is now its protocol and its number."""
    df = pd.read_csv(DEMO / "campaign.csv.gz")
    ref = read_logs(DEMO / "campaign.csv.gz", load_motor_spec(MOTOR))
    per_protocol = df.groupby("protocol", sort=False)["run_id"].transform(lambda r: pd.factorize(r)[0] + 1)
    df.assign(run_id=per_protocol).to_csv(tmp_path / "renumbered.csv", index=False, float_format="%.17g")
    got = read_logs(tmp_path / "renumbered.csv", load_motor_spec(MOTOR))
    assert got["run_id"].nunique() == ref["run_id"].nunique() > df["protocol"].nunique()
    assert set(got["run_id"].astype(str)) >= {"constant_speed:1", "startability:1"}
    np.testing.assert_array_equal(pd.factorize(got["run_id"])[0], pd.factorize(ref["run_id"])[0])


def test_mdf_channel_groups_at_different_rates_are_read_on_the_time_tracks_instants(campaign, tmp_path):
    """A recorder writes each rate as its own channel group (pressures fast, speed slower, temperature
    at 1/100 of the rate): 'has N samples but … resample them to one time base' and no way to map it.
    Each channel is taken at the time track's instants from its own time stamps."""
    from asammdf import MDF, Signal

    _, raw, _ = campaign
    run = raw["RunNo"]
    one = {k: v[run == run[0]] for k, v in raw.items()}
    t = one["t"] - one["t"][0]
    path = tmp_path / "multirate.mf4"
    mdf = MDF(version="4.10")
    fast = [k for k in one if k not in ("t", "n_Motor", "Toil")]
    mdf.append([Signal(one[k], t, name=k) for k in fast])
    mdf.append([Signal(one["n_Motor"][::4], t[::4], name="n_Motor")])
    mdf.append([Signal(one["Toil"][::50], t[::50], name="Toil")])
    mdf.save(path, overwrite=True)
    mdf.close()
    cmap = tmp_path / "map.toml"
    cmap.write_text(map_text("", time_name="pA_abs@time"))
    spec = load_motor_spec(MOTOR)
    got = read_logs(path, spec, channels=cmap)
    pd.DataFrame(one).to_parquet(tmp_path / "whole.parquet")
    ref = read_logs(tmp_path / "whole.parquet", spec, channels=_whole_map(tmp_path))
    assert len(got) == len(ref) == t.size
    np.testing.assert_allclose(got["p_a_Pa"], ref["p_a_Pa"], rtol=1e-12)
    speed_err = np.abs(got["speed_rad_s"].to_numpy() - ref["speed_rad_s"].to_numpy())
    assert np.median(speed_err) < 0.01 * np.abs(ref["speed_rad_s"]).median() + 1e-9  # interpolated
    assert np.abs(got["oil_temp_C"] - ref["oil_temp_C"]).max() < 1.0


def _whole_map(folder):
    path = folder / "whole.toml"
    path.write_text(map_text())
    return path


def test_a_tdms_file_with_a_group_per_run_reads_every_group_as_a_run(campaign, tmp_path):
    """NI loggers often write a test as one group per run: 'channel … is in several groups; write it as
    group/…', and following that read one run.  [file] group = "*" reads every group, each a run named
    after it, with each group's waveform timing."""
    from nptdms import ChannelObject, GroupObject, TdmsWriter

    csv, raw, _ = campaign
    run = raw["RunNo"]
    path = tmp_path / "groups.tdms"
    with TdmsWriter(str(path)) as w:
        for r in np.unique(run)[:4]:
            sel = run == r
            step = float(np.median(np.diff(raw["t"][sel])))  # each run at its own rate
            group = f"Run {int(r):03d}"
            w.write_segment([GroupObject(group)] + [
                ChannelObject(group, k, v[sel], properties={"wf_increment": step, "wf_start_offset": 0.0})
                for k, v in raw.items() if k not in ("t", "RunNo")])
    cmap = tmp_path / "map.toml"
    cmap.write_text(map_text(time_name="n_Motor@time", fmt_lines='[file]\ngroup = "*"')
                    .replace('run_id = {name = "RunNo"}\n', ""))
    got = read_logs(path, load_motor_spec(MOTOR), channels=cmap)
    assert list(pd.unique(got["run_id"].astype(str))) == ["Run 001", "Run 002", "Run 003", "Run 004"]
    keep = np.isin(run, np.unique(run)[:4])
    np.testing.assert_allclose(got["p_b_Pa"], raw["pB"][keep] * 1e6, rtol=1e-12)
    t0 = np.concatenate([raw["t"][run == r] - raw["t"][run == r][0] for r in np.unique(run)[:4]])
    np.testing.assert_allclose(got["time_s"], t0, atol=1e-6)


def test_a_tdms_group_per_run_with_a_slow_channel_is_read_group_by_group(campaign, tmp_path):
    """A group per run, and in each group the oil temperature at a tenth of the rate (its own
    wf_increment; every group's clock starts at 5 s): 'T has N samples but … resample them to one time
    base', though the docs say channels at other rates are taken at the time track's instants.  Each
    group's slow channel is taken against that group's own time track."""
    from nptdms import ChannelObject, GroupObject, TdmsWriter

    _, raw, _ = campaign
    run = raw["RunNo"]
    runs = np.unique(run)[:3]
    path = tmp_path / "groups.tdms"
    with TdmsWriter(str(path)) as w:
        for r in runs:
            sel = run == r
            step = float(np.median(np.diff(raw["t"][sel])))
            group = f"Run {int(r):03d}"
            fast = {"wf_increment": step, "wf_start_offset": 5.0}
            slow = {"wf_increment": 10 * step, "wf_start_offset": 5.0}
            w.write_segment([GroupObject(group)] + [
                ChannelObject(group, k, v[sel][::10] if k == "Toil" else v[sel],
                              properties=slow if k == "Toil" else fast)
                for k, v in raw.items() if k not in ("t", "RunNo")])
    cmap = tmp_path / "map.toml"
    cmap.write_text(map_text(time_name="n_Motor@time", fmt_lines='[file]\ngroup = "*"')
                    .replace('run_id = {name = "RunNo"}\n', ""))
    got = read_logs(path, load_motor_spec(MOTOR), channels=cmap)
    keep = np.isin(run, runs)
    assert len(got) == keep.sum()
    whole = pd.DataFrame({k: v[keep] for k, v in raw.items()})
    whole.to_parquet(tmp_path / "whole.parquet")
    ref = read_logs(tmp_path / "whole.parquet", load_motor_spec(MOTOR), channels=_whole_map(tmp_path))
    np.testing.assert_allclose(got["p_a_Pa"], ref["p_a_Pa"], rtol=1e-12)
    err = np.abs(got["oil_temp_C"].to_numpy() - ref["oil_temp_C"].to_numpy())
    assert err.max() < 1.0  # the slow temperature interpolated, in each run from its own first sample
    # and not shifted by a run: each group's temperature comes from that group
    for r in runs:
        g = got["run_id"].astype(str) == f"Run {int(r):03d}"
        assert abs(got.loc[g, "oil_temp_C"].mean() - ref.loc[g.to_numpy(), "oil_temp_C"].mean()) < 0.5


def test_an_hdf5_file_with_a_group_per_run_and_its_protocol_as_an_attribute(campaign, tmp_path):
    """A logger that writes each run as an HDF5 group, with the test it belongs to as the group's
    attribute (h5py, as such loggers write it): [file] group = "runs/*" reads every group under /runs
    as a run named after it, and [constants] protocol = {attribute = "test"} takes each group's
    attribute; the oil temperature from the file's root attribute where a group has none."""
    import h5py

    _, raw, _ = campaign
    run = raw["RunNo"]
    path = tmp_path / "groups.h5"
    with h5py.File(path, "w") as h5:
        h5.attrs["oil_temperature"] = 41.5
        for k, r in enumerate(np.unique(run)[:3]):
            g = h5.create_group(f"runs/R{int(r):02d}")
            g.attrs["test"] = np.bytes_("constant_speed" if k < 2 else "constant pressure")
            sel = run == r
            for name, v in raw.items():
                if name not in ("RunNo", "Toil", "mu"):
                    g.create_dataset(name, data=v[sel] - (raw["t"][sel][0] if name == "t" else 0.0))
    text = (map_text(fmt_lines='[file]\ngroup = "runs/*"').replace('run_id = {name = "RunNo"}\n', "")
            .replace('protocol = "constant_speed"', 'protocol = {attribute = "test"}\noil_temp_C = {attribute = '
                     '"oil_temperature"}')
            .replace('oil_temp_C = {name = "Toil", unit = "K"}\n', "")
            .replace('viscosity_mPas = {name = "mu", unit = "mPa.s"}\n', ""))
    cmap = tmp_path / "map.toml"
    cmap.write_text(text)
    got = read_logs(path, load_motor_spec(MOTOR), channels=cmap)
    names = list(pd.unique(got["run_id"].astype(str)))
    assert names == [f"R{int(r):02d}" for r in np.unique(run)[:3]]
    protocols = got.groupby(got["run_id"].astype(str), observed=True)["protocol"].first().astype(str)
    assert protocols[names[0]] == "constant_speed" and protocols[names[2]] == "constant_pressure"
    np.testing.assert_allclose(got["oil_temp_C"], 41.5)
    keep = np.isin(run, np.unique(run)[:3])
    np.testing.assert_allclose(got["p_b_Pa"], raw["pB"][keep] * 1e6, rtol=1e-12)
    # an attribute the groups do not hold: one line naming the group and the attribute
    cmap.write_text(text.replace('attribute = "test"', 'attribute = "mode"'))
    with pytest.raises(InputError, match=r"group 'R\d+' has no attribute 'mode'"):
        read_logs(path, load_motor_spec(MOTOR), channels=cmap)


def test_a_tdms_file_property_gives_a_constant_and_a_csv_has_no_attributes(campaign, tmp_path):
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    _, raw, _ = campaign
    sel = raw["RunNo"] == raw["RunNo"][0]
    path = tmp_path / "one.tdms"
    with TdmsWriter(str(path)) as w:
        w.write_segment([RootObject(properties={"Test type": "constant_speed"}), GroupObject("Data")]
                        + [ChannelObject("Data", k, v[sel]) for k, v in raw.items()])
    text = map_text().replace('protocol = "constant_speed"', 'protocol = {attribute = "Test type"}')
    cmap = tmp_path / "map.toml"
    cmap.write_text(text)
    got = read_logs(path, load_motor_spec(MOTOR), channels=cmap)
    assert (got["protocol"].astype(str) == "constant_speed").all() and len(got) == int(sel.sum())
    csv = tmp_path / "one.csv"
    pd.DataFrame({k: v[sel] for k, v in raw.items()}).to_csv(csv, index=False)
    with pytest.raises(InputError, match="holds no attributes"):
        read_logs(csv, load_motor_spec(MOTOR), channels=cmap)


def test_a_matlab_char_matrix_reads_as_one_text_per_row(tmp_path):
    """MATLAB v7.3 stores a char matrix (run names, one per row, padded) as uint16 codes with the axes
    reversed: each row is one text, not the whole matrix run together."""
    import h5py

    from motorid.io.formats import open_source

    names = ["run_01", "run_02", "run_10"]
    codes = np.array([[ord(c) for c in n] for n in names], dtype=np.uint16)  # 3 × 6, as MATLAB holds it
    path = tmp_path / "chars.mat"
    with h5py.File(path, "w", userblock_size=512) as h5:
        ds = h5.create_dataset("run", data=codes.T)
        ds.attrs["MATLAB_class"] = np.bytes_("char")
        one = h5.create_dataset("single", data=np.array([[ord(c) for c in "abc"]], dtype=np.uint16).T)  # 'abc'
        one.attrs["MATLAB_class"] = np.bytes_("char")
        col = h5.create_dataset("letters", data=np.array([[ord("x")], [ord("y")]], dtype=np.uint16).T)  # 2 × 1
        col.attrs["MATLAB_class"] = np.bytes_("char")
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created by: motorid tests HDF5 schema 1.00 ."
    with open(path, "r+b") as fh:
        fh.write(header.ljust(116) + b"\0" * 8 + b"\x00\x02" + b"IM")
    src = open_source(path)
    assert list(src.get("run")) == names
    assert str(src.get("single")) == "abc"  # a row of chars is one text
    assert list(src.get("letters")) == ["x", "y"]  # a column of chars: one text per row
    src.close()


def test_a_table_in_parquet_or_xlsx_with_the_formats_own_columns_needs_no_map(tmp_path):
    """BENCH_LOG_FORMAT.md: a file with no time_s column is an operating-point table, whatever it is
    written in.  A loss map saved by pandas as Parquet (pyarrow) and as .xlsx (openpyxl) is read as a
    table — not refused as a log without time_s — and reads as its CSV twin; a Parquet log with time_s
    stays a log."""
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.io.tables import read_tables, split_logs_and_tables
    from motorid.model import MotorSpec, OilSpec

    spec = MotorSpec("map-9", 9, 80e-6, 0.005, oil=OilSpec(temp_C=50.0))
    truth = {"Kv": 5000.0, "KF": 3e-3, "KFS": 1.5e-2, "TFc": 3.0, "Ks": 1.0, "KL0": 5e-14, "KL_a1": 0.15,
             "KL_b1": 0.08, "KAB": 2e-14}
    df = simulate_map(spec, truth, map_grid([100, 1000], [50, 200], 2), rng=np.random.default_rng(0),
                      noise={"torque_Nm": 0.3, "q_a_lpm": 0.05, "q_b_lpm": 0.05, "q_case_lpm": 0.02})
    df.to_csv(tmp_path / "map.csv", index=False, float_format="%.17g")
    df.to_parquet(tmp_path / "map.parquet", index=False)
    df.to_excel(tmp_path / "map.xlsx", index=False, engine="openpyxl")
    pd.DataFrame({"time_s": [0.0, 0.1], "speed_rpm": [1.0, 1.0]}).to_parquet(tmp_path / "log.parquet", index=False)
    files = [tmp_path / n for n in ("map.parquet", "map.xlsx", "log.parquet")]
    logs, tables = split_logs_and_tables(files)
    assert tables == files[:2] and logs == files[2:]
    want = read_tables([tmp_path / "map.csv"], spec)
    for f in files[:2]:
        got = read_tables([f], spec)
        for c in ("torque", "q_a", "q_b", "q_case"):
            np.testing.assert_allclose(got.measured[c], want.measured[c], rtol=1e-12, err_msg=f"{f.name} {c}")
        np.testing.assert_allclose(got.speed, want.speed, rtol=1e-12)


def test_a_makers_wide_data_sheet_reads_through_a_grid_of_its_rows_columns_and_cells(tmp_path):
    """A data sheet as makers print it — rows of pressure, a header row of speeds, a block of torques (one
    sheet), flows on a second sheet — read through [grid] with "@rows", "@columns", "@cells" (a sheet
    named before '!'), gives the long table's points; a header that is no number and a text cell are
    refused in one line naming them."""
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.io.tables import read_tables
    from motorid.model import MotorSpec, OilSpec

    spec = MotorSpec("map-9", 9, 80e-6, 0.005, oil=OilSpec(temp_C=50.0))
    truth = {"Kv": 5000.0, "KF": 3e-3, "KFS": 1.5e-2, "TFc": 3.0, "Ks": 1.0, "KL0": 5e-14, "KL_a1": 0.15,
             "KL_b1": 0.08, "KAB": 2e-14}
    speeds, dps = [500, 1000, 2000], [50, 100, 200, 300]
    long = simulate_map(spec, truth, map_grid(speeds, dps, 1), rng=np.random.default_rng(0),
                        noise={"torque_Nm": 0.3, "q_a_lpm": 0.05, "q_b_lpm": 0.05, "q_case_lpm": 0.02})
    long = long.assign(dp=long.p_a_bar - long.p_b_bar).sort_values(["dp", "speed_rpm"])
    wide = {c: long.pivot(index="dp", columns="speed_rpm", values=c) for c in ("torque_Nm", "q_a_lpm")}
    sheet = lambda c: wide[c].rename(columns=lambda v: f"{v:g}").rename_axis("p [bar]").reset_index()  # noqa: E731
    sheet("torque_Nm").to_csv(tmp_path / "torque.csv", index=False)
    with pd.ExcelWriter(tmp_path / "sheet.xlsx", engine="openpyxl") as book:
        sheet("torque_Nm").to_excel(book, sheet_name="Torque", index=False)
        sheet("q_a_lpm").to_excel(book, sheet_name="Flow", index=False)
    grid = '[constants]\noil_temp_C = 50.0\n[grid]\naxes = ["dp_bar", "speed_rpm"]\n'
    (tmp_path / "torque.channels.toml").write_text(
        grid + '[channels]\ndp_bar = {name = "@rows", unit = "bar"}\nspeed_rpm = {name = "@columns", unit = "rpm"}\n'
        'torque_Nm = {name = "@cells", unit = "N*m"}\n')
    (tmp_path / "sheet.channels.toml").write_text(
        '[file]\nsheet = "*"\n' + grid + '[channels]\ndp_bar = {name = "Torque!@rows", unit = "bar"}\n'
        'speed_rpm = {name = "Torque!@columns", unit = "rpm"}\ntorque_Nm = {name = "Torque!@cells", unit = "N*m"}\n'
        'q_a_lpm = {name = "Flow!@cells", unit = "l/min"}\n')
    for name, channels in (("torque.csv", ("torque",)), ("sheet.xlsx", ("torque", "q_a"))):
        t = read_tables([tmp_path / name], spec)
        assert len(t) == len(long)
        order = np.lexsort((t.speed, t.dp))
        np.testing.assert_allclose(t.speed[order] * 30 / np.pi, long.speed_rpm, rtol=1e-12)
        np.testing.assert_allclose(t.dp[order] * 1e-5, long.dp, rtol=1e-12)
        np.testing.assert_allclose(t.measured["torque"][order], long.torque_Nm, rtol=1e-9)
        if "q_a" in channels:
            np.testing.assert_allclose(t.measured["q_a"][order] * 6e4, long.q_a_lpm, rtol=1e-9)
    bad = sheet("torque_Nm").rename(columns={"1000": "1000 rpm"})
    bad.to_csv(tmp_path / "torque.csv", index=False)
    with pytest.raises(InputError, match=r"torque\.csv: header '1000 rpm' of the wide sheet is not a number"):
        read_tables([tmp_path / "torque.csv"], spec)
    bad = sheet("torque_Nm").astype(object)
    bad.iloc[2, 2] = "n.a."
    bad.to_csv(tmp_path / "torque.csv", index=False)
    with pytest.raises(InputError, match=r"torque\.csv: wide sheet, column '1000', row 3: 'n\.a\.' is not a number"):
        read_tables([tmp_path / "torque.csv"], spec)
    # without a map, the refusal says what the sheet looks like and how to read it
    sheet("torque_Nm").to_csv(tmp_path / "plain.csv", index=False)
    with pytest.raises(InputError, match=r"plain\.csv: missing required column 'speed_rpm'.*a wide data sheet.*@cells"):
        read_tables([tmp_path / "plain.csv"], spec)
