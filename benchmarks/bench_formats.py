"""DAQ formats: how fast motorid reads each format through a channel map, against the plain CSV.

    python benchmarks/run.py --only bench_formats [--quick]

The demo campaign (synthetic_data/demo) is tiled to N samples (time shifted so that each
copy is a new run), written as the format's CSV and, with foreign channel names, units and
signs, by each format's own library; then each file is read by ``motorid.io.logs.read_logs``
(through a channel map for the foreign ones) and the frame compared with the CSV's. Also
the MBARI recordings of real_data/mbari_f11 (text through their channel map).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

PSI = 6894.757293168361

MAP = """
[constants]
protocol = "constant_speed"
[channels]
time_s = {{name = "{t}", unit = "s"}}
run_id = {{name = "{p}RunNo"}}
shaft_angle_deg = {{name = "{p}phi", unit = "rad"}}
speed_rpm = {{name = "{p}n_Motor", unit = "rad/s", sign = -1}}
torque_Nm = {{name = "{p}T_pump", unit = "N*m", sign = -1}}
p_a_bar = {{name = "{p}pA_abs", unit = "psi", absolute = true}}
p_b_bar = {{name = "{p}pB", unit = "MPa"}}
p_case_bar = {{name = "{p}pCase", unit = "bar"}}
q_a_lpm = {{name = "{p}QA", unit = "m3/s"}}
q_b_lpm = {{name = "{p}QB", unit = "l/min"}}
q_case_lpm = {{name = "{p}QL", unit = "l/min"}}
oil_temp_C = {{name = "{p}Toil", unit = "K"}}
viscosity_mPas = {{name = "{p}mu", unit = "mPa.s"}}
"""


def campaign(n_samples: int) -> pd.DataFrame:
    df = pd.read_csv(REPO / "synthetic_data" / "demo" / "campaign.csv.gz")
    df = df[df["protocol"] == "constant_speed"].reset_index(drop=True)
    codes = pd.factorize(df["run_id"])[0]
    copies = int(np.ceil(n_samples / len(df)))
    parts = []
    for k in range(copies):
        part = df.copy()
        part["run_id"] = codes + 1 + k * (codes.max() + 1)
        parts.append(part)
    return pd.concat(parts, ignore_index=True).iloc[:n_samples]


def foreign(df: pd.DataFrame) -> dict:
    return {
        "t": df["time_s"].to_numpy(), "RunNo": df["run_id"].to_numpy(dtype=float),
        "phi": np.deg2rad(df["shaft_angle_deg"].to_numpy()),
        "n_Motor": -df["speed_rpm"].to_numpy() * 2 * np.pi / 60, "T_pump": -df["torque_Nm"].to_numpy(),
        "pA_abs": df["p_a_bar"].to_numpy() * 1e5 / PSI + 101325.0 / PSI, "pB": df["p_b_bar"].to_numpy() / 10.0,
        "pCase": df["p_case_bar"].to_numpy(), "QA": df["q_a_lpm"].to_numpy() / 60000.0,
        "QB": df["q_b_lpm"].to_numpy(), "QL": df["q_case_lpm"].to_numpy(),
        "Toil": df["oil_temp_C"].to_numpy() + 273.15, "mu": df["viscosity_mPas"].to_numpy(),
    }


def write(kind: str, raw: dict, folder: Path):
    if kind == "TDMS (npTDMS)":
        from nptdms import ChannelObject, TdmsWriter

        path = folder / "daq.tdms"
        with TdmsWriter(str(path)) as w:
            w.write_segment([ChannelObject("Measurement", k, v) for k, v in raw.items()])
        return path, MAP.format(t="Measurement/t", p="Measurement/")
    if kind == "MDF4 (asammdf)":
        from asammdf import MDF, Signal

        path = folder / "daq.mf4"
        mdf = MDF(version="4.10")
        mdf.append([Signal(v, raw["t"], name=k) for k, v in raw.items() if k != "t"])
        mdf.save(path, overwrite=True)
        mdf.close()
        return path, MAP.format(t="n_Motor@time", p="")
    if kind == "HDF5 (h5py)":
        import h5py

        path = folder / "daq.h5"
        with h5py.File(path, "w") as h5:
            for k, v in raw.items():
                h5.create_dataset(f"signals/{k}", data=v)
        return path, MAP.format(t="signals/t", p="signals/")
    if kind == "Parquet (pyarrow)":
        import pyarrow as pa
        import pyarrow.parquet as pq

        path = folder / "daq.parquet"
        pq.write_table(pa.table(raw), path)
        return path, MAP.format(t="t", p="")
    if kind == "MATLAB v5 (scipy)":
        from scipy.io import savemat

        path = folder / "daq.mat"
        savemat(path, {"daq": {k: v.reshape(-1, 1) for k, v in raw.items()}})
        return path, MAP.format(t="daq.t", p="daq.")
    if kind == "CSV ; and decimal comma":
        path = folder / "daq_de.csv"
        pd.DataFrame(raw).to_csv(path, sep=";", decimal=",", index=False, float_format="%.17g")
        return path, MAP.format(t="t", p="")
    raise ValueError(kind)


KINDS = ["TDMS (npTDMS)", "MDF4 (asammdf)", "HDF5 (h5py)", "Parquet (pyarrow)", "MATLAB v5 (scipy)",
         "CSV ; and decimal comma"]


#: a fresh process that reads a file through its map → the samples read (peak RSS measured around it)
_STREAMED = ("from motorid.io.spec import load_motor_spec; from motorid.io.stream import stream_runs; import sys\n"
             "spec = load_motor_spec(sys.argv[2])\n"
             "print(sum(r.n for r in stream_runs([sys.argv[1]], spec, sys.argv[3], progress=False)))")
_WHOLE = ("from motorid.io.spec import load_motor_spec; from motorid.io.logs import read_logs; import sys\n"
          "print(len(read_logs([sys.argv[1]], load_motor_spec(sys.argv[2]), channels=sys.argv[3])))")
#: the formats read in blocks of samples through their channel map (motorid.io.stream.RANGE_FORMATS)
STREAMED_KINDS = ("TDMS (npTDMS)", "MDF4 (asammdf)", "HDF5 (h5py)")


def _memory(path: Path, cmap: Path, motor: Path) -> dict:
    """Peak RSS [MiB] and wall [s] of reading ``path`` streamed and whole, each a fresh process."""
    sys.path.insert(0, str(REPO / "benchmarks"))
    from bench_memory import _measure

    out = {}
    for how, code in (("streamed", _STREAMED), ("whole", _WHOLE)):
        wall, rss, text = _measure([sys.executable, "-c", code, str(path), str(motor), str(cmap)])
        out[how] = (wall, rss, int(text.strip().splitlines()[-1]))
    return out


def run(quick: bool = False) -> str:
    from motorid.io.logs import read_logs
    from motorid.io.spec import load_motor_spec

    spec = load_motor_spec(REPO / "synthetic_data" / "demo" / "motor.toml")
    n = 100_000 if quick else 500_000
    df = campaign(n)
    raw = foreign(df)
    rows = []
    memory = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        csv = folder / "campaign.csv"
        df.to_csv(csv, index=False, float_format="%.17g")
        t0 = time.perf_counter()
        ref = read_logs(csv, spec)
        t_csv = time.perf_counter() - t0
        rows.append(("CSV (the format's own)", csv.stat().st_size, t_csv, 0.0))
        for kind in KINDS:
            path, text = write(kind, raw, folder)
            cmap = folder / f"{path.stem}.toml"
            cmap.write_text(text)
            t0 = time.perf_counter()
            got = read_logs(path, spec, channels=cmap)
            seconds = time.perf_counter() - t0
            worst = 0.0
            for col in ("speed_rad_s", "torque_Nm", "p_a_Pa", "p_b_Pa", "q_a_m3_s", "q_case_m3_s", "viscosity_Pa_s"):
                a, b = got[col].to_numpy(), ref[col].to_numpy()
                scale = np.nanmax(np.abs(b))
                worst = max(worst, float(np.nanmax(np.abs(a - b)) / scale))
            rows.append((kind, path.stat().st_size, seconds, worst))
            if kind in STREAMED_KINDS:
                del got
                memory[kind] = _memory(path, cmap, REPO / "synthetic_data" / "demo" / "motor.toml")
    long_n = 2_000_000 if not quick else 0  # the same at four times the samples: does the memory grow?
    if long_n:
        raw_long = foreign(campaign(long_n))
        with tempfile.TemporaryDirectory() as tmp:
            path, text = write("HDF5 (h5py)", raw_long, Path(tmp))
            del raw_long
            cmap = Path(tmp) / "long.toml"
            cmap.write_text(text)
            memory[f"HDF5 (h5py), {long_n:,} samples"] = _memory(path, cmap, REPO / "synthetic_data" / "demo" /
                                                                 "motor.toml")
    mbari = REPO / "real_data" / "mbari_f11"
    spec_m = load_motor_spec(mbari / "motor.toml")
    t0 = time.perf_counter()
    frame = read_logs(mbari, spec_m)
    t_mbari = time.perf_counter() - t0

    lines = [
        "## DAQ formats through a channel map (bench_formats)",
        "",
        "`python benchmarks/run.py --only bench_formats" + (" --quick`" if quick else "`"),
        "",
        f"The demo campaign's constant-speed runs tiled to {n:,} samples × 14 channels, written by each "
        "format's own library with foreign names, units and signs (rad/s counted the other way, pump-sign "
        "torque, psia, MPa, m³/s, K), read by `read_logs(..., channels=MAP)`; the frame compared with the "
        "CSV's (largest error relative to the channel's range).",
        "",
        "| file | size (MB) | read (s) | samples/s | max rel. error vs CSV |",
        "|---|---:|---:|---:|---:|",
    ]
    for kind, size, seconds, worst in rows:
        lines.append(f"| {kind} | {size / 1e6:.1f} | {seconds:.2f} | {n / seconds:,.0f} | {worst:.1e} |")
    lines += [
        "",
        f"Real recordings: the four MBARI files of `real_data/mbari_f11/` ({len(frame):,} samples, "
        f"whitespace text with a `#` header, gzip, through `channels.toml`) read in {t_mbari:.1f} s.",
        "",
        "Every foreign file goes through one path: its channels become a table in the format's units, "
        "written as a CSV whose floats read back exactly and read by the CSV reader, so the checks are "
        "the same for all formats; the cost of that second pass is the difference between the rows above "
        "and the plain CSV.",
        "",
        "Read in blocks (issue 16): a fit of a long log (cells, above `MOTORID_CELL_ROWS`) takes HDF5, MATLAB "
        "v7.3, TDMS and MDF4 files through their channel map in blocks of "
        "`motorid.io.stream.FOREIGN_BLOCK_ROWS` samples (h5py slices, npTDMS `TdmsFile.open`, asammdf record "
        "ranges), run by run, instead of the whole file.  Each reader a fresh process; peak RSS from the "
        "kernel (`os.wait4`, through bench_memory's small wrapper):",
        "",
        f"({n:,} samples unless the row says otherwise.)",
        "",
        "| file | streamed: peak RSS MiB | wall s | whole file: peak RSS MiB | wall s | streamed ÷ whole, memory |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for kind, m in memory.items():
        (ws, rs, ns), (ww, rw, nw) = m["streamed"], m["whole"]
        assert ns == nw, (kind, ns, nw)
        lines.append(f"| {kind} | {rs:,.0f} | {ws:.1f} | {rw:,.0f} | {ww:.1f} | {rs / rw:.2f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
