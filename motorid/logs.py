"""Bench logs (BENCH_LOG_FORMAT.md): the canonical SI table, writing, and reading.

Inside motorid a log is a ``pandas.DataFrame`` with the canonical SI columns of
:data:`SI_COLUMNS`.  Units are converted here, at the edge, and nowhere else.
"""

from __future__ import annotations

import gzip
import io
import os
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

# canonical SI column  ← file column in the format's own units, factor to SI
FORMAT_COLUMNS = {
    "time_s": ("time_s", 1.0),
    "theta_rad": ("shaft_angle_deg", np.pi / 180.0),
    "speed_rad_s": ("speed_rpm", 2.0 * np.pi / 60.0),
    "torque_Nm": ("torque_Nm", 1.0),
    "p_a_Pa": ("p_a_bar", 1e5),
    "p_b_Pa": ("p_b_bar", 1e5),
    "p_case_Pa": ("p_case_bar", 1e5),
    "q_a_m3_s": ("q_a_lpm", 1e-3 / 60.0),
    "q_b_m3_s": ("q_b_lpm", 1e-3 / 60.0),
    "q_case_m3_s": ("q_case_lpm", 1e-3 / 60.0),
    "oil_temp_C": ("oil_temp_C", 1.0),
    "viscosity_Pa_s": ("viscosity_mPas", 1e-3),
}
SI_COLUMNS = ["run_id", "protocol", *FORMAT_COLUMNS]
PROTOCOLS = ("constant_speed", "constant_pressure", "startability", "constant_flow", "constant_torque")

# printf formats that keep more digits than any bench sensor resolves
_FORMATS = {
    "time_s": "%.6f", "shaft_angle_deg": "%.6f", "speed_rpm": "%.7g", "torque_Nm": "%.7g",
    "p_a_bar": "%.7g", "p_b_bar": "%.7g", "p_case_bar": "%.7g", "q_a_lpm": "%.7g",
    "q_b_lpm": "%.7g", "q_case_lpm": "%.7g", "oil_temp_C": "%.5f", "viscosity_mPas": "%.7g",
}


def to_format_units(frame: pd.DataFrame, full_precision: bool = False) -> pd.DataFrame:
    """Canonical SI frame → frame with the format's column names and units."""
    out = pd.DataFrame({"time_s": frame["time_s"].to_numpy(), "run_id": frame["run_id"].to_numpy(),
                        "protocol": frame["protocol"].to_numpy()})
    for si, (col, factor) in FORMAT_COLUMNS.items():
        if si == "time_s" or si not in frame:
            continue
        values = frame[si].to_numpy(dtype=float) / factor
        if si == "theta_rad":
            values = np.mod(values, 360.0)
        out[col] = values
    return out


def write_log(frame: pd.DataFrame, path, full_precision: bool = False) -> Path:
    """Write a canonical SI frame as a bench log CSV (``.csv`` or ``.csv.gz``).

    The file is written whole or not at all (temporary file, then rename); a
    ``.gz`` file is byte-reproducible (no timestamp in the gzip header).
    full_precision : write every float with 17 significant digits (round-trip).
    """
    path = Path(path)
    table = to_format_units(frame)
    buf = io.StringIO()
    if full_precision:
        table.to_csv(buf, index=False, float_format="%.17g", lineterminator="\n")
    else:
        for col, fmt in _FORMATS.items():
            if col in table:
                vals = table[col].to_numpy(dtype=float)
                table[col] = np.where(np.isnan(vals), "", np.char.mod(fmt, vals))
        table.to_csv(buf, index=False, lineterminator="\n")
    data = buf.getvalue().encode()
    if path.name.endswith(".gz"):
        raw = io.BytesIO()
        with gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as gz:
            gz.write(data)
        data = raw.getvalue()
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path
