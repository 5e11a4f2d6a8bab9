"""Peak memory of `motorid fit` on an HDF5 log read through a channel map, against its rows.

    python benchmarks/run.py --only bench_memory_hdf5 [--quick]

bench_memory's campaigns (the demo protocols with the running sample rates scaled up
to 1 and 10 M rows; quick: 0.3 and 1 M) written as a DAQ would write them to HDF5:
one 1-D dataset per channel under ``daq/``, in the channel's own unit, run and
protocol as text datasets, converted from the CSV in blocks (pyarrow's streaming CSV
reader → h5py appends), never held whole.  Each fit is a fresh process, through a
channel map (``--channels``); above ``MOTORID_CELL_ROWS`` (500 k rows) motorid reads
the HDF5 file in blocks of ``motorid.io.stream.FOREIGN_BLOCK_ROWS`` samples and fits
from shaft-angle cells.  Peak RSS from the kernel (bench_memory's wrapper process).
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_memory as bm  # noqa: E402

UNITS = {"time_s": "s", "shaft_angle_deg": "deg", "speed_rpm": "rpm", "torque_Nm": "N*m", "p_a_bar": "bar",
         "p_b_bar": "bar", "p_case_bar": "bar", "q_a_lpm": "l/min", "q_b_lpm": "l/min", "q_case_lpm": "l/min",
         "oil_temp_C": "C", "viscosity_mPas": "mPa*s"}
TEXT = ("run_id", "protocol")


def to_hdf5(csv: Path, h5: Path) -> Path:
    """The CSV log → an HDF5 file of 1-D datasets ``daq/<column>`` (appended block by block) and its
    channel map beside it → the map's path."""
    import h5py
    import pyarrow as pa
    import pyarrow.csv as pa_csv

    text_types = {c: pa.string() for c in TEXT}
    reader = pa_csv.open_csv(str(csv), convert_options=pa_csv.ConvertOptions(column_types=text_types),
                             read_options=pa_csv.ReadOptions(block_size=1 << 24))
    with h5py.File(h5, "w") as f:
        g = f.create_group("daq")
        sets = {}
        for batch in reader:
            n = batch.num_rows
            for name, col in zip(batch.schema.names, batch.columns):
                if name not in sets:
                    dtype = h5py.string_dtype("utf-8") if name in TEXT else "f8"
                    sets[name] = g.create_dataset(name, shape=(0,), maxshape=(None,), dtype=dtype, chunks=(65536,))
                ds = sets[name]
                start = ds.shape[0]
                ds.resize((start + n,))
                if name in TEXT:
                    ds[start:] = np.asarray(col.to_pylist(), dtype=object)
                else:
                    ds[start:] = col.to_numpy(zero_copy_only=False).astype(float)
    cmap = h5.with_suffix(".channels.toml")
    lines = ['[file]', 'group = "daq"', "", "[channels]"]
    lines += [f'{c} = {{name = "{c}"}}' for c in TEXT]
    lines += [f'{c} = {{name = "{c}", unit = "{u}"}}' for c, u in UNITS.items()]
    cmap.write_text("\n".join(lines) + "\n")
    return cmap


def run(quick: bool = False) -> str:
    sizes = [300_000, 1_000_000] if quick else [1_000_000, 10_000_000]
    truth = tomllib.load(open(bm.TRUTH, "rb"))["parameters"]
    py = sys.executable
    env = dict(os.environ, MOTORID_QUIET="1")
    env.setdefault("MOTORID_CACHE_DIR", str(Path(tempfile.gettempdir()) / "motorid-bench-memory-cache"))
    rows_out = []
    with tempfile.TemporaryDirectory(prefix="motorid-h5mem-") as tmp:
        tmp = Path(tmp)
        warm_csv, _ = bm.make_campaign(tmp / "warm", 300_000)
        warm = tmp / "warm" / "log.h5"
        warm_map = to_hdf5(warm_csv, warm)
        bm._measure([py, "-m", "motorid", "fit", warm, "--channels", warm_map, "--motor", bm.MOTOR, "--out",
                     tmp / "warm-out", "--force", "--quiet"], dict(env, MOTORID_CELL_ROWS="1"))
        for size in sizes:
            t0 = time.perf_counter()
            csv, rows = bm.make_campaign(tmp / f"c{size}", size)
            h5 = tmp / f"c{size}" / "log.h5"
            cmap = to_hdf5(csv, h5)
            csv.unlink()
            made = time.perf_counter() - t0
            print(f"   {rows:,} rows → {h5.stat().st_size / 2**20:.0f} MB HDF5 in {made:.0f} s", flush=True)
            out = tmp / f"out{size}"
            wall, rss, _ = bm._measure([py, "-m", "motorid", "fit", h5, "--channels", cmap, "--motor", bm.MOTOR,
                                        "--out", out, "--force", "--quiet"], env)
            import json

            doc = json.loads((out / "result.json").read_text())
            z, zname = bm._worst_z(doc, truth)
            rows_out.append((rows, h5.stat().st_size / 2**20, rss, wall, z, zname, doc["fit"]["reduced_chi2"]))
            h5.unlink()
    (r1, *_), (rN, *_) = rows_out[0], rows_out[-1]
    growth = rows_out[-1][2] / rows_out[0][2] - 1.0
    lines = [
        "## Memory: `motorid fit` on an HDF5 log through a channel map (bench_memory_hdf5)",
        "",
        "`python benchmarks/run.py --only bench_memory_hdf5` (study: benchmarks/bench_memory_hdf5.py). "
        "bench_memory's campaigns written as a DAQ writes HDF5 (one dataset per channel under `daq/`, run and "
        "protocol as text), fitted with `motorid fit log.h5 --channels log.channels.toml` in a fresh process "
        "(streamed in blocks of 65 536 samples above 500 k rows, fitted from shaft-angle cells); peak RSS from "
        "the kernel, compile cache warm.",
        "",
        "| goal | measured | |",
        "|---|---|---|",
        f"| peak RSS at {rN / 1e6:.1f} M rows < 1.5 GiB | {rows_out[-1][2]:,.0f} MiB | "
        f"{'✓' if rows_out[-1][2] < 1536 else '✗'} |",
        f"| growth from {r1 / 1e6:.1f} M to {rN / 1e6:.1f} M rows < 10 % | {100 * growth:+.1f} % | "
        f"{'✓' if growth < 0.10 else '✗'} |",
        "",
        "| rows | HDF5 MB | peak RSS MiB | wall s | worst \\|value − truth\\|/std | χ²/dof |",
        "|---:|---:|---:|---:|---|---:|",
    ]
    lines += [f"| {r:,} | {mb:.0f} | {rss:,.0f} | {wall:.1f} | {z:.2f} ({zn}) | {chi:.3f} |"
              for r, mb, rss, wall, z, zn, chi in rows_out]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
