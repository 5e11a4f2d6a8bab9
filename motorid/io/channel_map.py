"""Channel maps: how the channels of a foreign DAQ file become BENCH_LOG_FORMAT columns.

A channel map is a TOML file (schema in docs/formats.md) that names, for each
column of the bench log format (``speed_rpm``, ``p_a_bar``, …), the channel of
the foreign file that holds it, the unit of that channel and its sign, so that a
user maps a bench's files once and reuses the map.  Applying a map to a file's
channels gives a table *in the format's own units* (rpm, bar, L/min, °C, …);
the log reader (motorid/logs.py) then reads that table exactly as it reads a CSV.

Transform of one channel (all optional but the name and, for numbers, the unit):

    x_unit   = scale · raw + offset                 (raw reading → stated unit)
    x_unit  -= atmosphere                           (absolute = true; pressures only)
    x_format = sign · convert(x_unit)               (unit → the column's unit)

and with ``convention = "pump"`` the torque and the port flows are negated once
more (pump sign: torque into the shaft, flow out of the high-pressure port,
BENCH_LOG_FORMAT.md "Operating-point tables").
"""

from __future__ import annotations

import datetime
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from motorid.errors import InputError
from motorid.io.logs import (_ANGLE_UNITS, _FLOW_UNITS, _PRESSURE_UNITS, _SPEED_UNITS, _TEMPERATURE_UNITS,
                          _TIME_UNITS, _TORQUE_UNITS, _VISCOSITY_UNITS, PROTOCOLS, looks_like_a_unit,
                          normalize_header)

_IN3 = 0.0254 ** 3  # m³ per cubic inch
_ATMOSPHERE_PA = 101325.0

# units a channel map knows beyond the log reader's header suffixes
_FLOW = {**_FLOW_UNITS, "in3_s": _IN3, "in3_min": _IN3 / 60.0, "cuin_s": _IN3, "cuin_min": _IN3 / 60.0}
_PRESSURE = {**_PRESSURE_UNITS, "psia": _PRESSURE_UNITS["psi"], "bara": 1e5, "bar_a": 1e5, "atm": _ATMOSPHERE_PA}
_DISPLACEMENT = {"cm3": 1.0, "cm3_rev": 1.0, "cc": 1.0, "cc_rev": 1.0, "ml": 1.0, "ml_rev": 1.0,
                 "in3": _IN3 * 1e6, "in3_rev": _IN3 * 1e6, "m3": 1e6, "m3_rev": 1e6, "m3_rad": 2e6 * math.pi,
                 "l": 1e3, "l_rev": 1e3}
_NONE = {"": 1.0, "1": 1.0, "count": 1.0}
_EFFICIENCY = {"": 1.0, "1": 1.0, "fraction": 1.0, "%": 0.01, "pct": 0.01, "percent": 0.01}
_ABSOLUTE_UNITS = ("psia", "bara", "bar_a")
_GAUGE_UNITS = ("psig", "barg", "bar_g")

# family → (units → factor to SI (or callable/tuple as in motorid.io.logs), SI per format unit)
_FAMILIES = {
    "time": (_TIME_UNITS, 1.0),
    "angle": (_ANGLE_UNITS, math.pi / 180.0),
    "speed": (_SPEED_UNITS, 2.0 * math.pi / 60.0),
    "torque": (_TORQUE_UNITS, 1.0),
    "pressure": (_PRESSURE, 1e5),
    "flow": (_FLOW, 1e-3 / 60.0),
    "temperature": (_TEMPERATURE_UNITS, None),
    "viscosity": (_VISCOSITY_UNITS, 1e-3),
    "displacement": (_DISPLACEMENT, 1.0),
    "count": (_NONE, 1.0),
    "efficiency": (_EFFICIENCY, 1.0),
}

# every column a map may fill: format column → family ("text" for names)
COLUMNS = {
    "time_s": "time", "run_id": "text", "protocol": "text", "point_id": "text",
    "shaft_angle_deg": "angle", "speed_rpm": "speed", "torque_Nm": "torque",
    "p_a_bar": "pressure", "p_b_bar": "pressure", "p_case_bar": "pressure", "dp_bar": "pressure",
    "q_a_lpm": "flow", "q_b_lpm": "flow", "q_case_lpm": "flow",
    "oil_temp_C": "temperature", "viscosity_mPas": "viscosity", "displacement_cm3": "displacement",
    "n_samples": "count", "torque_std_Nm": "torque", "speed_std_rpm": "speed",
    "q_a_std_lpm": "flow", "q_b_std_lpm": "flow", "q_case_std_lpm": "flow",
    # a data sheet's efficiencies (a fraction in the table; io/efficiency_columns.py derives torque and flow)
    "volumetric_efficiency": "efficiency", "hydromechanical_efficiency": "efficiency",
    "overall_efficiency": "efficiency",
    # a loss table's losses, Simscape's convention (io/efficiency_columns.py derives torque and the inlet flow)
    "torque_loss_Nm": "torque", "q_loss_lpm": "flow",
}
LOG_REQUIRED = ("time_s", "run_id", "protocol", "shaft_angle_deg", "speed_rpm", "torque_Nm", "p_a_bar",
                "p_b_bar", "p_case_bar", "q_a_lpm", "q_b_lpm", "q_case_lpm", "oil_temp_C")
TABLE_OUTPUTS = ("torque_Nm", "q_a_lpm", "q_b_lpm", "q_case_lpm")
EFFICIENCY_OUTPUTS = ("volumetric_efficiency", "hydromechanical_efficiency", "overall_efficiency",
                      "torque_loss_Nm", "q_loss_lpm")  # outputs derived from efficiencies or losses
PUMP_SIGN = ("torque_Nm", "q_a_lpm", "q_b_lpm")  # negated by convention = "pump"
LOSS_OUTPUTS = ("torque_loss_Nm", "q_loss_lpm")  # Simscape's convention: refused with convention = "pump"
FORMATS = ("csv", "text", "mat", "hdf5", "parquet", "xlsx", "tdms", "mdf")

_TOP_KEYS = {"file", "convention", "channels", "constants", "absent", "extra", "grid"}
_FILE_KEYS = {"format", "sheet", "header_row", "skip_rows", "delimiter", "decimal", "group"}
#: a file with no run column: a pause of more than this many median time steps, and of RUN_GAP_S
#: seconds, starts a new run; so does a time that falls back by more than RUN_RESTART_STEPS steps
RUN_GAP_STEPS, RUN_GAP_S, RUN_RESTART_STEPS = 20.0, 1.0, 5.0

_CHANNEL_KEYS = {"name", "unit", "sign", "scale", "offset", "absolute", "atmosphere", "sample_rate_Hz"}


@dataclass
class Channel:
    """One mapped column: the foreign channel ``name`` and its transform to the format's unit."""

    column: str
    name: str
    unit: str | None = None  # normalized unit
    sign: float = 1.0
    scale: float = 1.0
    offset: float = 0.0
    atmosphere: float = 0.0  # subtracted, in the channel's unit (absolute pressures)
    rate_Hz: float | None = None  # time_s only: no channel, the time of sample i is i / rate [s]

    def convert(self, raw: np.ndarray, pump: bool) -> np.ndarray:
        """Raw channel readings → values in the format column's unit (eq. in the module doc)."""
        x = self.scale * np.asarray(raw, dtype=float) + self.offset - self.atmosphere
        family = COLUMNS[self.column]
        units, si_per_format = _FAMILIES[family]
        conv = units[self.unit]
        if callable(conv):  # temperature → °C
            x = conv(x)
        elif isinstance(conv, tuple):  # kinematic viscosity → cSt, converted by the log reader
            x = x * conv[1] / 1e-6
        else:
            x = x * (conv / si_per_format)  # 1 exactly where the unit is the column's own
        flip = -1.0 if (pump and self.column in PUMP_SIGN) else 1.0
        return self.sign * flip * x


@dataclass
class ChannelMap:
    """A validated channel map (see docs/formats.md)."""

    path: str
    channels: dict = field(default_factory=dict)  # column → Channel
    constants: dict = field(default_factory=dict)  # column → value in the format unit / text
    attributes: dict = field(default_factory=dict)  # column → the file's (or each run group's) attribute
    absent: tuple = ()
    extra: dict = field(default_factory=dict)  # output column → foreign channel name
    grid_axes: tuple = ()
    pump: bool = False
    file: dict = field(default_factory=dict)

    @property
    def is_log(self) -> bool:
        """Time series (a ``time_s`` channel) rather than an operating-point table."""
        return "time_s" in self.channels

    def output_column(self, column: str) -> str:
        """Name of the column written for ``column`` (a kinematic viscosity goes as cSt)."""
        ch = self.channels.get(column)
        if column == "viscosity_mPas" and ch is not None and isinstance(_VISCOSITY_UNITS.get(ch.unit), tuple):
            return "viscosity_cSt"
        return column

    def apply(self, source, file_label: str, rows: tuple | None = None) -> pd.DataFrame:
        """Foreign channels (``source.get(name)``) → a table with the format's columns and units;
        ``rows`` (start, stop): those samples alone (a source with ``length``; no [grid])."""
        columns: dict = {}
        n = None
        first = None
        self.runs_cut_by_time = False  # set below where this file's runs are cut by its time track
        grid = self._grid(source, file_label) if self.grid_axes else None
        read = (lambda name: source.get(name)) if rows is None else (lambda name: source.get(name, *rows))  # noqa: E731
        order = sorted(self.channels.items(), key=lambda kv: kv[0] != "time_s")  # the time track first
        t_ref = None
        for col, ch in order:
            if ch.rate_Hz is not None:  # a time track from the sample rate: once the length is known
                continue
            raw = grid[col] if grid is not None else read(ch.name)
            raw = np.asarray(raw)
            if grid is None and raw.ndim != 1:
                raw = np.squeeze(raw)
                if raw.ndim != 1:
                    raise InputError(f"{file_label}: channel '{ch.name}' ({col} in {self.path}) has shape "
                                     f"{np.shape(raw)}, not one value per sample (a 2-D map needs [grid])")
            if col == "time_s" and grid is None and rows is None:
                t_ref = _seconds_of(raw, ch)
            if n is None:
                n, first = raw.shape[0], (col, ch.name)
            elif raw.shape[0] != n:
                resampled = _onto_time_base(source, ch, col, raw, t_ref, rows, self.channels["time_s"].name
                                            if "time_s" in self.channels else None)
                if resampled is None:
                    raise InputError(f"{file_label}: channel '{ch.name}' ({col}) has {raw.shape[0]} samples but "
                                     f"'{first[1]}' ({first[0]}) has {n}; resample them to one time base")
                raw = resampled
            if COLUMNS[col] == "text":
                columns[col] = _text(raw)
            else:
                columns[self.output_column(col)] = ch.convert(_numeric(raw, file_label, ch, rows[0] if rows else 0),
                                                              self.pump)
        if n is None:
            raise InputError(f"{self.path}: [channels] maps no channel")
        clock = self.channels.get("time_s")
        if clock is not None and clock.rate_Hz is not None:
            columns["time_s"] = ((rows[0] if rows else 0) + np.arange(n, dtype=float)) / clock.rate_Hz
        for col, value in self.constants.items():
            columns[col] = np.full(n, value, dtype=object if isinstance(value, str) else float)
        for col, attr in self.attributes.items():
            columns[col] = self._attribute_column(source, file_label, col, attr, n)
        for col in self.absent:
            columns[col] = np.full(n, np.nan)
        if "run_id" not in columns and self.is_log and hasattr(source, "sample_groups"):
            named = next(ch.name for ch in self.channels.values() if ch.rate_Hz is None)
            columns["run_id"] = source.sample_groups(named)  # a group per run: the group's name
        elif "run_id" not in columns and self.is_log:
            columns["run_id"] = self._runs_by_time(_stem(file_label), columns["time_s"], rows)
            self.runs_cut_by_time = True  # and then by set point (io/set_points.py)
        elif "run_id" not in columns and "point_id" not in columns:
            columns["run_id"] = np.full(n, _stem(file_label), dtype=object)
        for out, name in self.extra.items():
            raw = np.asarray(read(name))
            columns[out] = np.squeeze(raw) if raw.ndim > 1 else raw
        frame = pd.DataFrame(columns)
        if grid is not None:  # cells where the map holds no measurement
            outputs = [self.output_column(c) for c in TABLE_OUTPUTS + EFFICIENCY_OUTPUTS if c in self.channels]
            frame = frame[frame[outputs].notna().any(axis=1)].reset_index(drop=True)
        return frame

    def _attribute_column(self, source, file_label: str, col: str, attr: str, n: int) -> np.ndarray:
        """A column from an attribute: each run group's (a group per run), else the file's."""
        where = f"{file_label}: [constants] {col} = {{attribute = \"{attr}\"}}"
        if hasattr(source, "sample_attribute"):
            named = next(ch.name for ch in self.channels.values() if ch.rate_Hz is None)
            values = source.sample_attribute(attr, named)
        elif hasattr(source, "attribute"):
            values = np.full(n, source.attribute(attr), dtype=object)
        else:
            raise InputError(f"{where}: this file type holds no attributes (HDF5 and TDMS do)")
        if len(values) != n:
            raise InputError(f"{where}: the groups' channels have {len(values)} samples, the file {n}")
        if COLUMNS[col] == "text":
            return _text(np.asarray([str(v).strip() for v in values], dtype=object))
        try:
            numbers = np.asarray(values, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"{where}: '{values[0]}' is not a number") from None
        return numbers  # in the column's own unit, as a constant

    def _runs_by_time(self, stem: str, t: np.ndarray, rows) -> np.ndarray:
        """Run names for a file that maps no run column: a new run wherever the time track starts
        again (falls back by more than :data:`RUN_RESTART_STEPS` median steps) or pauses for more
        than :data:`RUN_GAP_STEPS` of them and :data:`RUN_GAP_S`, as a bench that logs its runs one
        after another into one file does; repeated stamps, a little backward jitter, a slower rate
        later in the file and an empty time cell start none.  The first run is named after the
        file, the next ``<file>#2``, …; blocks of a stream (``rows``) carry on from the block before."""
        t = np.asarray(t, dtype=float)
        if rows is None or rows[0] == 0:
            self._run_state = (None, 1, None)
        last, run, step = self._run_state
        if t.size == 0:
            return np.empty(0, dtype=object)
        filled = pd.Series(t).ffill().to_numpy()  # an empty cell: measured from the last time there was
        if last is not None:
            filled = np.where(np.isnan(filled), last, filled)
        prev = np.r_[filled[0] if last is None else last, filled[:-1]]
        dt = filled - prev
        if step is None:
            positive = dt[dt > 0]
            step = float(np.median(positive)) if positive.size else None
        breaks = np.zeros(t.size, bool)
        if step is not None:
            breaks = (dt < -RUN_RESTART_STEPS * step) | (dt > max(RUN_GAP_STEPS * step, RUN_GAP_S))
        if last is None:
            breaks[0] = False
        number = run + np.cumsum(breaks)
        tail = filled[np.isfinite(filled)]
        self._run_state = (float(tail[-1]) if tail.size else last, int(number[-1]), step)
        names = np.array([stem if k == 1 else f"{stem}#{k}" for k in range(1, int(number[-1]) + 1)],
                         dtype=object)
        return names[number - 1]

    def _grid(self, source, file_label: str) -> dict:
        """Gridded map: axis vectors × matrices → one entry per grid point (row-major, 'ij').

        The axes may also be given as coordinate matrices of the outputs' shape (MATLAB's
        ``meshgrid``/``ndgrid`` form: each cell's speed and pressure written out)."""
        raw = [np.asarray(source.get(self.channels[a].name)) for a in self.grid_axes]
        matrices = [np.squeeze(r).ndim == 2 for r in raw]
        if any(matrices):
            if not all(matrices) or np.squeeze(raw[0]).shape != np.squeeze(raw[1]).shape:
                raise InputError(f"{file_label}: [grid] axes '{self.channels[self.grid_axes[0]].name}' "
                                 f"{raw[0].shape} and '{self.channels[self.grid_axes[1]].name}' {raw[1].shape}: "
                                 "give two vectors, or two coordinate matrices of one shape")
            mesh = [np.squeeze(r) for r in raw]
            shape = mesh[0].shape
        else:
            axes = [np.ravel(r) for r in raw]
            shape = tuple(a.size for a in axes)
            mesh = np.meshgrid(*axes, indexing="ij")
        out = {a: m.ravel() for a, m in zip(self.grid_axes, mesh)}
        for col, ch in self.channels.items():
            if col in self.grid_axes:
                continue
            value = np.asarray(source.get(ch.name))
            if value.shape != shape:
                squeezed = np.squeeze(value)
                hint = " (transposed: swap the two [grid] axes)" if squeezed.shape == shape[::-1] else ""
                if squeezed.shape != shape:
                    raise InputError(f"{file_label}: '{ch.name}' ({col}) has shape {value.shape}, the grid "
                                     f"{' × '.join(self.grid_axes)} needs {shape}{hint}")
                value = squeezed
            out[col] = value.ravel()
        return out


def _stem(label: str) -> str:
    name = Path(label).name
    for suffix in (".gz",):
        name = name[: -len(suffix)] if name.endswith(suffix) else name
    return name.rsplit(".", 1)[0] if "." in name else name


def _text(raw: np.ndarray) -> np.ndarray:
    """Names from a channel: numbers as '1', not '1.0'; bytes decoded."""
    out = []
    for v in raw.tolist():
        if isinstance(v, bytes):
            v = v.decode("utf-8", "replace")
        if isinstance(v, float) and v.is_integer():
            v = int(v)
        out.append("" if v is None or (isinstance(v, float) and math.isnan(v)) else str(v).strip())
    return np.array(out, dtype=object)


def _seconds_of(raw: np.ndarray, ch: Channel) -> np.ndarray | None:
    """The mapped time track in seconds (None where it is not plain numbers)."""
    if raw.dtype.kind not in "fiu":
        return None
    return np.asarray(raw, float) * _TIME_UNITS[ch.unit] if ch.unit in _TIME_UNITS else None


def _onto_time_base(source, ch: Channel, col: str, raw: np.ndarray, t_ref, rows, time_name=None):
    """A channel recorded at another rate than the time track (an MDF4 recorder's channel groups: the
    pressures at 1 kHz, the speed at 100 Hz, the temperature at 1 Hz) → its values at the time track's
    instants, from its own time stamps (``<name>@time``): linear for numbers, the last value for text.
    A source of a group per run (TDMS or HDF5 ``group = "*"``) is taken group by group, each group's
    stamps against its own time track.  None where the source has no time stamps for it, or the whole
    file is not being read."""
    if t_ref is None or rows is not None or ch.name.endswith("@time"):
        return None
    try:
        t_own = np.asarray(source.get(ch.name + "@time"), dtype=float)
    except (InputError, KeyError, ValueError, TypeError, AttributeError):
        return None
    if t_own.shape != raw.shape or t_own.size < 2:
        return None
    if hasattr(source, "sample_groups") and time_name is not None:
        ref_groups, own_groups = source.sample_groups(time_name), source.sample_groups(ch.name)
        if ref_groups.shape != t_ref.shape or own_groups.shape != raw.shape:
            return None
        out = np.empty(t_ref.shape, dtype=object if COLUMNS[col] == "text" or raw.dtype.kind not in "fiub"
                       else float)
        for g in pd.unique(ref_groups):
            mine, theirs = own_groups == g, ref_groups == g
            piece = _interpolated(t_own[mine], raw[mine], t_ref[theirs], col)
            if piece is None:
                return None
            out[theirs] = piece
        return out
    return _interpolated(t_own, raw, t_ref, col)


def _interpolated(t_own: np.ndarray, raw: np.ndarray, t_ref: np.ndarray, col: str):
    """``raw`` stamped ``t_own`` at the instants ``t_ref`` (linear; the last value for text), the first
    and last value held beyond its stamps; None where its stamps are too few or run backwards."""
    if t_own.size < 1 or np.any(np.diff(t_own) < 0):
        return None
    if COLUMNS[col] == "text" or raw.dtype.kind not in "fiub":
        idx = np.clip(np.searchsorted(t_own, t_ref, side="right") - 1, 0, t_own.size - 1)
        return raw[idx]
    return np.interp(t_ref, t_own, raw.astype(float))


def _numeric(raw: np.ndarray, file_label: str, ch: Channel, offset: int = 0) -> np.ndarray:
    if raw.dtype.kind in "fiub":
        return raw.astype(float)
    if raw.dtype.kind in "mM":  # a timestamp (as NI and MDF loggers write the time track): seconds
        if ch.column != "time_s" or ch.unit != "s":
            raise InputError(f"{file_label}: channel '{ch.name}' ({ch.column}) holds timestamps: map it as "
                             f"time_s with unit = \"s\" (it is read as seconds)")
        seconds = raw.astype("m8[ns]" if raw.dtype.kind == "m" else "M8[ns]").astype(np.int64) / 1e9
        return np.where(np.isnat(raw), np.nan, seconds)
    if ch.column == "time_s" and raw.dtype.kind in "OUS":
        stamps = _timestamps(raw.ravel(), file_label, ch, offset)
        if stamps is not None:
            return stamps
    values = pd.to_numeric(pd.Series(raw.ravel()), errors="coerce").to_numpy(dtype=float)
    bad = np.flatnonzero(np.isnan(values) & ~pd.isna(pd.Series(raw.ravel())).to_numpy())
    if bad.size:
        hint = (" (a units row under the header? [file] skip_rows = 1 leaves it out)"
                if offset + bad[0] == 0 and looks_like_a_unit(raw.ravel()[bad[0]]) else "")
        raise InputError(f"{file_label}: channel '{ch.name}' ({ch.column}), sample {offset + bad[0] + 1}: "
                         f"'{raw.ravel()[bad[0]]}' is not a number{hint}")
    return values


def _timestamps(raw: np.ndarray, file_label: str, ch: Channel, offset: int) -> np.ndarray | None:
    """A time track of date-times → seconds (since 1970, UTC), or None where it holds numbers.

    Time-zone-aware stamps (pandas keeps them as objects) and wall-clock text ("2026-03-14
    10:22:01.125", ISO 8601, or day first "14.03.2026 10:22:01,125") are both taken; a zone
    shifts every stamp alike, so only differences matter.  Text that is a number is left to the
    numeric path."""
    series = pd.Series(raw)
    present = series[series.notna() & (series.astype(str).str.strip() != "")]
    if present.empty:
        return None
    first = present.iloc[0]
    if isinstance(first, (bytes, np.bytes_)):
        series = series.map(lambda v: v.decode("utf-8", "replace") if isinstance(v, (bytes, np.bytes_)) else v)
        present = series[series.notna()]
        first = present.iloc[0]
    if isinstance(first, str):
        if not pd.isna(pd.to_numeric(first.strip().replace(",", "."), errors="coerce")):
            return None
        text = series.astype(str).str.strip()
        day_first = bool(re.match(r"^\d{1,2}\.\d{1,2}\.\d{4}", first.strip()))
        if day_first:  # 14.03.2026 10:22:01,125: the decimal comma of the seconds → a point
            text = text.str.replace(r"(\d{2}:\d{2}:\d{2}),(\d+)", r"\1.\2", regex=True)
        try:
            stamps = pd.to_datetime(text.where(series.notna()), utc=True, dayfirst=day_first, format="mixed")
        except (ValueError, TypeError):
            bad = next((i for i, v in enumerate(text) if pd.isna(pd.to_datetime(v, errors="coerce",
                                                                                dayfirst=day_first))), 0)
            raise InputError(f"{file_label}: channel '{ch.name}' (time_s), sample {offset + bad + 1}: "
                             f"'{raw[bad]}' is neither a number nor a date-time") from None
    elif isinstance(first, (pd.Timestamp, datetime.datetime, np.datetime64)):
        try:
            stamps = pd.to_datetime(series, utc=True)
        except (ValueError, TypeError) as exc:
            raise InputError(f"{file_label}: channel '{ch.name}' (time_s): timestamps pandas cannot read "
                             f"({exc})") from None
    else:
        return None
    if ch.unit != "s":
        raise InputError(f"{file_label}: channel '{ch.name}' (time_s) holds date-times: map it with "
                         f"unit = \"s\" (it is read as seconds)")
    ns = stamps.to_numpy(dtype="datetime64[ns]")
    return np.where(np.isnat(ns), np.nan, ns.astype(np.int64) / 1e9)


# --------------------------------------------------------------------------- loading

def _check_keys(where: str, table: dict, allowed: set):
    for key in table:
        if key not in allowed:
            raise InputError(f"{where}: unknown key '{key}' (allowed: {', '.join(sorted(allowed))})")


def _number(where: str, value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{where}: {what} must be a finite number, got {value!r}")
    return float(value)


def _unit(where: str, column: str, unit) -> str | None:
    family = COLUMNS[column]
    if family == "text":
        if unit is not None:
            raise InputError(f"{where}: '{column}' is a name and takes no unit")
        return None
    if unit is None:
        if family == "count":
            return ""
        raise InputError(f"{where}: 'unit' is required (e.g. unit = \"{column.rsplit('_', 1)[-1]}\")")
    if not isinstance(unit, str):
        raise InputError(f"{where}: unit must be text, got {unit!r}")
    norm = normalize_header(unit)
    units = _FAMILIES[family][0]
    if norm not in units:
        known = ", ".join(sorted(u for u in units if u)[:12])
        raise InputError(f"{where}: unknown {family} unit '{unit}' (known: {known}, …)")
    return norm


def _channel(where: str, column: str, spec) -> Channel:
    if isinstance(spec, str):
        spec = {"name": spec}
    if not isinstance(spec, dict):
        raise InputError(f"{where}: expected a channel name or a table {{name = ..., unit = ...}}, got {spec!r}")
    _check_keys(where, spec, _CHANNEL_KEYS)
    if "sample_rate_Hz" in spec:  # a time track the file does not store: sample i at i / rate
        if column != "time_s" or set(spec) != {"sample_rate_Hz"}:
            raise InputError(f"{where}: sample_rate_Hz stands alone, for time_s only (time_s = "
                             "{sample_rate_Hz = 1000.0})")
        rate = _number(where, spec["sample_rate_Hz"], "sample_rate_Hz")
        if rate <= 0:
            raise InputError(f"{where}: sample_rate_Hz must be > 0, got {rate!r}")
        return Channel(column=column, name="", unit="s", rate_Hz=rate)
    name = spec.get("name")
    if not isinstance(name, str) or not name.strip():
        raise InputError(f"{where}: 'name' (the channel in the file) is required")
    unit = _unit(where, column, spec.get("unit"))
    ch = Channel(column=column, name=name.strip(), unit=unit)
    if COLUMNS[column] == "text":
        extra = set(spec) - {"name"}
        if extra:
            raise InputError(f"{where}: '{column}' is a name; '{sorted(extra)[0]}' does not apply")
        return ch
    if "sign" in spec:
        sign = spec["sign"]
        if isinstance(sign, bool) or sign not in (1, -1):
            raise InputError(f"{where}: sign must be 1 or -1, got {sign!r}")
        ch.sign = float(sign)
    if "scale" in spec:
        ch.scale = _number(where, spec["scale"], "scale")
    if "offset" in spec:
        ch.offset = _number(where, spec["offset"], "offset")
    # a unit that says absolute (psia, bara) is absolute; one that says gauge (psig, barg) is not
    says = None if column == "dp_bar" else "absolute" if unit in _ABSOLUTE_UNITS else \
        "gauge" if unit in _GAUGE_UNITS else None
    absolute = spec.get("absolute", says == "absolute")
    if not isinstance(absolute, bool):
        raise InputError(f"{where}: absolute must be true or false, got {absolute!r}")
    if says is not None and absolute != (says == "absolute"):
        article = "an" if says == "absolute" else "a"
        raise InputError(f"{where}: unit '{spec.get('unit')}' is {article} {says} pressure, but absolute = "
                         f"{'true' if absolute else 'false'}")
    if "atmosphere" in spec and not absolute:
        raise InputError(f"{where}: 'atmosphere' needs absolute = true")
    if absolute:
        if COLUMNS[column] != "pressure" or column == "dp_bar":
            raise InputError(f"{where}: absolute = true applies to port and case pressures only")
        default = _ATMOSPHERE_PA / _PRESSURE[unit]
        ch.atmosphere = _number(where, spec.get("atmosphere", default), "atmosphere")
    return ch


def parse_channel_map(doc: dict, path: str) -> ChannelMap:
    """Validate a parsed channel-map TOML document; every problem names ``path`` and the key."""
    _check_keys(path, doc, _TOP_KEYS)
    cmap = ChannelMap(path=path)
    file = doc.get("file", {})
    if not isinstance(file, dict):
        raise InputError(f"{path}: [file] must be a table")
    _check_keys(f"{path}: [file]", file, _FILE_KEYS)
    if "format" in file and file["format"] not in FORMATS:
        raise InputError(f"{path}: [file] format: unknown format {file['format']!r} (one of {', '.join(FORMATS)})")
    for key in ("sheet", "delimiter", "group"):
        if key == "sheet" and isinstance(file.get(key), list) and file[key] \
                and all(isinstance(v, str) for v in file[key]):
            continue  # several sheets of one workbook, read one after another
        if key in file and (isinstance(file[key], bool) or not isinstance(file[key], (str, int))):
            raise InputError(f"{path}: [file] {key}: expected text, got {file[key]!r}"
                             + (" (or a list of sheet names, or \"*\" for every sheet)" if key == "sheet" else ""))
    if file.get("decimal", ".") not in (".", ","):
        raise InputError(f"{path}: [file] decimal: '.' or ',', got {file['decimal']!r}")
    if "header_row" in file and (isinstance(file["header_row"], bool) or not isinstance(file["header_row"], int)
                                 or file["header_row"] < 1):
        raise InputError(f"{path}: [file] header_row: a line number ≥ 1, got {file['header_row']!r}")
    if "skip_rows" in file and (isinstance(file["skip_rows"], bool) or not isinstance(file["skip_rows"], int)
                                or file["skip_rows"] < 0):
        raise InputError(f"{path}: [file] skip_rows: a number of rows ≥ 0, got {file['skip_rows']!r}")
    cmap.file = dict(file)
    convention = doc.get("convention", "motor")
    if convention not in ("motor", "pump"):
        raise InputError(f"{path}: convention: 'motor' or 'pump', got {convention!r}")
    cmap.pump = convention == "pump"

    channels = doc.get("channels")
    if not isinstance(channels, dict) or not channels:
        raise InputError(f"{path}: [channels] is required: one entry per column, e.g. "
                         f"speed_rpm = {{name = \"n_Motor\", unit = \"1/min\"}}")
    for column, spec in channels.items():
        where = f"{path}: [channels] {column}"
        if column not in COLUMNS:
            raise InputError(f"{where}: unknown column (one of {', '.join(COLUMNS)}; other channels go "
                             f"under [extra])")
        if cmap.pump and column in LOSS_OUTPUTS:
            raise InputError(f"{where}: a loss column follows Simscape's convention in every quadrant "
                             f"(T = DΔP/2π − T_loss), not a pump's: leave convention = \"pump\" out, or give the "
                             f"loss its sign with sign = -1")
        cmap.channels[column] = _channel(where, column, spec)

    constants = doc.get("constants", {})
    if not isinstance(constants, dict):
        raise InputError(f"{path}: [constants] must be a table")
    for column, value in constants.items():
        where = f"{path}: [constants] {column}"
        if column not in COLUMNS:
            raise InputError(f"{where}: unknown column (one of {', '.join(COLUMNS)})")
        if column in cmap.channels:
            raise InputError(f"{where}: also mapped in [channels]; keep one")
        if isinstance(value, dict):  # {attribute = "name"}: the file's attribute, or each run group's
            _check_keys(where, value, {"attribute"})
            name = value.get("attribute")
            if not isinstance(name, str) or not name.strip():
                raise InputError(f"{where}: attribute: expected the attribute's name, got {name!r}")
            cmap.attributes[column] = name.strip()
            continue
        if COLUMNS[column] == "text":
            if not isinstance(value, (str, int)) or isinstance(value, bool) or str(value).strip() == "":
                raise InputError(f"{where}: expected a name, got {value!r}")
            value = str(value).strip()
        else:
            value = _number(where, value, "the value (in the column's own unit)")
        cmap.constants[column] = value
    proto = cmap.constants.get("protocol")
    if proto is not None and proto not in PROTOCOLS:
        raise InputError(f"{path}: [constants] protocol: unknown protocol {proto!r} (one of {', '.join(PROTOCOLS)})")

    absent = doc.get("absent", [])
    if not isinstance(absent, list) or not all(isinstance(a, str) for a in absent):
        raise InputError(f"{path}: absent: a list of column names, got {absent!r}")
    for column in absent:
        if column not in COLUMNS or COLUMNS[column] == "text":
            raise InputError(f"{path}: absent: unknown sensor column '{column}'")
        if column in cmap.channels or column in cmap.constants or column in cmap.attributes:
            raise InputError(f"{path}: absent: '{column}' is also mapped; keep one")
    cmap.absent = tuple(absent)

    extra = doc.get("extra", {})
    if not isinstance(extra, dict):
        raise InputError(f"{path}: [extra] must be a table of column = \"channel name\"")
    for out, name in extra.items():
        if out in COLUMNS:
            raise InputError(f"{path}: [extra] {out}: a format column; map it under [channels]")
        if not isinstance(name, str) or not name.strip():
            raise InputError(f"{path}: [extra] {out}: expected the channel's name, got {name!r}")
        cmap.extra[out] = name.strip()

    grid = doc.get("grid")
    if grid is not None:
        if not isinstance(grid, dict):
            raise InputError(f"{path}: [grid] must be a table with axes = [column, column]")
        _check_keys(f"{path}: [grid]", grid, {"axes"})
        axes = grid.get("axes")
        if not (isinstance(axes, list) and len(axes) == 2 and len(set(axes)) == 2
                and all(isinstance(a, str) for a in axes)):
            raise InputError(f"{path}: [grid] axes: two distinct column names, got {axes!r}")
        for a in axes:
            if a not in cmap.channels:
                raise InputError(f"{path}: [grid] axes: '{a}' is not mapped under [channels]")
            if COLUMNS[a] == "text":
                raise InputError(f"{path}: [grid] axes: '{a}' is a name, not a number")
        if cmap.is_log:
            raise InputError(f"{path}: [grid] is for operating-point maps; a map with time_s is a time series")
        cmap.grid_axes = tuple(axes)

    _check_complete(cmap)
    return cmap


def _check_complete(cmap: ChannelMap):
    given = set(cmap.channels) | set(cmap.constants) | set(cmap.absent) | set(cmap.attributes)
    only_logs = [c for c in ("protocol", "shaft_angle_deg") if c in cmap.channels]
    if not cmap.is_log and only_logs:
        raise InputError(f"{cmap.path}: [channels] maps {', '.join(only_logs)}, which only a time series has, but "
                         "no time_s: map the time channel for a bench log (or leave those out for an "
                         "operating-point table)")
    if cmap.is_log:
        missing = [c for c in LOG_REQUIRED if c not in given and c != "run_id"]
        if missing:
            raise InputError(f"{cmap.path}: [channels] {missing[0]}: missing (a time series needs "
                             f"{', '.join(LOG_REQUIRED)}; map each under [channels], give it under "
                             f"[constants], or list it in absent = [...]"
                             + (f"; also missing: {', '.join(missing[1:])})" if missing[1:] else ")"))
        return
    needed = ["speed_rpm"] + (["dp_bar"] if "dp_bar" in given else ["p_a_bar", "p_b_bar"])
    missing = [c for c in needed if c not in given]
    if missing:
        raise InputError(f"{cmap.path}: [channels] {missing[0]}: missing (an operating-point table needs "
                         f"speed_rpm and p_a_bar, p_b_bar or dp_bar; with no time_s the map is a table)")
    if not any(c in cmap.channels for c in TABLE_OUTPUTS + EFFICIENCY_OUTPUTS):
        raise InputError(f"{cmap.path}: [channels]: an operating-point table needs one output "
                         f"({', '.join(TABLE_OUTPUTS)}, or efficiencies or losses: {', '.join(EFFICIENCY_OUTPUTS)})")


def load_channel_map(path) -> ChannelMap:
    """Read and validate a channel-map TOML file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{path}: cannot read channel map ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: channel map is not UTF-8 text") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML ({exc})") from None
    return parse_channel_map(doc, str(path))
