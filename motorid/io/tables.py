"""Operating-point tables (BENCH_LOG_FORMAT.md, "Operating-point tables"): reading.

One row per steady operating point (an ISO 4409-style loss map or efficiency
test).  A file is a table when its header has no ``time_s`` column.  Units,
suffixes and signs are those of the bench logs; the values are converted to SI
here, at the edge, and nowhere else.

Columns: ``point_id`` (optional text), ``speed_rpm`` (required), ``p_a_bar`` and
``p_b_bar`` or ``dp_bar`` (P_A − P_B, with P_B = 0), ``p_case_bar`` (optional, 0),
the outputs ``torque_Nm``, ``q_a_lpm``, ``q_b_lpm``, ``q_case_lpm`` (each
optional; a fit needs one), ``oil_temp_C`` / ``viscosity_mPas`` (optional; the
spec's ``[oil] temp_C`` where both are absent), ``displacement_cm3`` (per-point
displacement of a variable unit, per revolution), ``n_samples`` and
``<output>_std_<unit>`` (averaging count and spread: relative weights).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motorid.errors import InputError
from motorid.io.efficiency_columns import outputs_from_efficiencies, outputs_from_losses
from motorid.io.logs import (_BY_SI, _PRESSURE_UNITS, _oil_viscosity, _parse_body, _split_header,
                             refuse_fahrenheit_as_celsius)
from motorid.io.table_columns import (_DISPLACEMENT_UNITS, OUTPUTS, _head_text, _header_fields,  # noqa: F401
                                      _map_table_columns, is_table)

#: below this |speed| a point is at rest [rad/s] (0.01 rpm)
STALL_SPEED = 1e-3
#: gauge pressure of a perfect vacuum, with 0.1 bar for a transducer's zero error [Pa]
VACUUM_GAUGE_PA = 1.01325e5 + 1e4
@dataclass
class PointTable:
    """Steady operating points, SI, every array over the points.

    speed ω [rad/s]; p_a, p_b, p_case [Pa gauge]; temperature [°C] (NaN where
    the viscosity column was used); viscosity μ [Pa·s]; displacement D
    [m³/rev] (the spec's where the table gives none); measured : channel →
    mean reading ("torque" [N·m], "q_a", "q_b", "q_case" [m³/s]), NaN where
    absent; relative_sigma : channel → relative σ of each point's mean (from
    ``*_std_*`` / √n_samples, or 1/√n_samples; 1 where the table gives
    neither), normalized to a median of 1; point_id : names; file : source of
    each point; line : its line in the file; recording : the label of the
    recording (test session) each point comes from, where the table has a
    ``recording`` column, else None; temperature_assumed : True where the oil
    temperature was not in the table and was taken from the spec's ``[oil] temp_C``.
    """

    point_id: np.ndarray
    speed: np.ndarray
    p_a: np.ndarray
    p_b: np.ndarray
    p_case: np.ndarray
    temperature: np.ndarray
    viscosity: np.ndarray
    displacement: np.ndarray
    measured: dict
    relative_sigma: dict
    file: np.ndarray
    line: np.ndarray
    has_point_id: bool = False
    weights_from: dict = field(default_factory=dict)  # channel → "std columns" / "n_samples" / "none"
    variable_displacement: bool = False
    recording: np.ndarray | None = None
    temperature_assumed: np.ndarray | None = None
    notes: list = field(default_factory=list)  # what the reader set aside, in words

    def __len__(self) -> int:
        return int(self.speed.size)

    @property
    def dp(self) -> np.ndarray:
        return self.p_a - self.p_b

    def subset(self, mask) -> "PointTable":
        """The points where ``mask`` holds (a bool mask or an index array)."""
        idx = np.arange(len(self))[mask]
        take = lambda a: np.asarray(a)[idx]  # noqa: E731
        return PointTable(take(self.point_id), take(self.speed), take(self.p_a), take(self.p_b),
                          take(self.p_case), take(self.temperature), take(self.viscosity),
                          take(self.displacement), {c: take(v) for c, v in self.measured.items()},
                          {c: take(v) for c, v in self.relative_sigma.items()}, take(self.file),
                          take(self.line), self.has_point_id, dict(self.weights_from), self.variable_displacement,
                          None if self.recording is None else take(self.recording),
                          None if self.temperature_assumed is None else take(self.temperature_assumed),
                          list(self.notes))

    def recordings(self) -> np.ndarray:
        """The recording of each point: the ``recording`` column where the table has one, else its
        file (every point of a one-file table without the column shares one label)."""
        if self.recording is not None:
            return np.asarray(self.recording, dtype=object)
        return np.asarray(self.file, dtype=object)

    def assumed_temperature(self) -> np.ndarray:
        """True at the points whose oil temperature was not recorded (taken from the spec)."""
        if self.temperature_assumed is None:
            return np.zeros(len(self), bool)
        return np.asarray(self.temperature_assumed, bool)

    def channels(self) -> list:
        """Output channels with at least one reading."""
        return [c for c in ("torque", "q_a", "q_b", "q_case") if np.isfinite(self.measured[c]).any()]


def read_table(path, spec=None, require_outputs: bool = True) -> PointTable:
    """Read and validate one operating-point table (CSV or CSV.gz) into SI arrays.

    path : the table file; spec : :class:`motorid.model.MotorSpec` (its oil gives μ
    from ``oil_temp_C``, or from ``[oil] temp_C`` where the table has neither
    column; its displacement where the table has no ``displacement_cm3``);
    require_outputs : a fit needs at least one output column (``motorid predict``
    does not).  Bad input raises :class:`~motorid.errors.InputError`, one line
    naming the file and the column (and line).
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not a table file")
    if not path.exists():
        raise InputError(f"{path}: no such file")
    fields, delim, body, header_line = _header_fields(path)
    found = _map_table_columns(path, fields)
    if require_outputs and not (any(k in found for k in OUTPUTS) or any(k.startswith(("eff:", "loss:")) for k in found)):
        raise InputError(f"{path}: no output column: a table for a fit needs at least one of torque_Nm, q_a_lpm, "
                         f"q_b_lpm, q_case_lpm (or efficiencies: volumetric_efficiency, "
                         f"hydromechanical_efficiency, overall_efficiency, fractions or _pct; or losses: "
                         f"torque_loss_Nm, q_loss_lpm)")
    parse_keys = {k: v for k, v in found.items() if k not in ("point_id", "recording")}
    if "point_id" in found:
        parse_keys["run_id"] = found["point_id"]
    if "recording" in found:  # text, as the protocol column of a log
        parse_keys["protocol"] = found["recording"]
    table = _parse_body(path, body, delim, fields, parse_keys, header_line)
    lines = header_line + 1 + np.arange(len(table))
    numeric = [j for k, (j, _) in parse_keys.items() if k not in ("run_id", "protocol")]
    blank = np.all([table[j].isna().to_numpy() for j in numeric], axis=0)
    table, lines = table.loc[~blank].reset_index(drop=True), lines[~blank]
    n = len(table)
    if n == 0:
        raise InputError(f"{path}: no data rows after the header")

    def column(key):
        j, unit = found[key]
        x = table[j].to_numpy(dtype=float)
        return np.where(np.isinf(x), np.nan, x), j, unit

    def required(key):
        x, j, _ = column(key)
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            raw = table[j].iloc[bad[0]]
            what = "empty cell" if not np.isinf(raw) else f"'{raw:g}' is no reading"
            raise InputError(f"{path}: column '{fields[j]}', line {lines[bad[0]]}: {what} (required)")
        return x

    def convert(key, x):
        conv = _BY_SI[key].units[found[key][1]]
        return conv(x) if callable(conv) else x * conv

    speed = convert("speed_rad_s", required("speed_rad_s"))
    if "dp_Pa" in found:  # the low-pressure port at 0: port A high where ΔP > 0, port B where ΔP < 0
        dp = required("dp_Pa") * _PRESSURE_UNITS[found["dp_Pa"][1]]
        p_a, p_b = np.maximum(dp, 0.0), np.maximum(-dp, 0.0)
    else:
        p_a = convert("p_a_Pa", required("p_a_Pa"))
        p_b = convert("p_b_Pa", required("p_b_Pa"))
    p_case = convert("p_case_Pa", np.nan_to_num(column("p_case_Pa")[0])) if "p_case_Pa" in found else np.zeros(n)
    for key, x in (("p_a_Pa", p_a), ("p_b_Pa", p_b), ("p_case_Pa", p_case)):
        below = np.flatnonzero(x < -VACUUM_GAUGE_PA)
        if below.size and key in found:
            raise InputError(f"{path}: column '{fields[found[key][0]]}', line {lines[below[0]]}: a gauge pressure "
                             f"below vacuum ({x[below[0]] / 1e5:.3g} bar; absolute pressures need a channel map "
                             f"with absolute = true)")

    temperature = np.full(n, np.nan)
    if "oil_temp_C" in found:
        temperature = convert("oil_temp_C", column("oil_temp_C")[0])
        if np.any(temperature < -273.15):
            i = int(np.flatnonzero(temperature < -273.15)[0])
            raise InputError(f"{path}: column '{fields[found['oil_temp_C'][0]]}', line {lines[i]}: "
                             f"temperature below absolute zero")
        if "viscosity_Pa_s" not in found:  # °F under a °C name: a viscosity 7× too low, refused
            refuse_fahrenheit_as_celsius(str(path), fields[found["oil_temp_C"][0]], temperature,
                                         np.ones(n, bool))
    mu = np.full(n, np.nan)
    oil = getattr(spec, "oil", None)
    if "viscosity_Pa_s" in found:
        x, j, unit = column("viscosity_Pa_s")
        if np.any(x <= 0):
            i = int(np.flatnonzero(x <= 0)[0])
            raise InputError(f"{path}: column '{fields[j]}', line {lines[i]}: viscosity must be > 0")
        conv = _BY_SI["viscosity_Pa_s"].units[unit]
        if isinstance(conv, tuple):  # kinematic: needs the density of the spec's oil
            if oil is None:
                raise InputError(f"{path}: column '{fields[j]}' is a kinematic viscosity; a motor spec with an "
                                 f"[oil] table is needed for the density")
            mu = oil.dynamic_from_kinematic(x * conv[1], temperature)
        else:
            mu = x * conv
    gaps = ~np.isfinite(mu)
    if gaps.any():
        t_fill = np.where(np.isfinite(temperature), temperature,
                          np.nan if oil is None or oil.temp_C is None else oil.temp_C)
        missing = gaps & ~np.isfinite(t_fill)
        if missing.any():
            i = int(np.flatnonzero(missing)[0])
            raise InputError(f"{path}: line {lines[i]}: no viscosity_mPas nor oil_temp_C, and the motor spec "
                             f"has no [oil] temp_C to take the oil temperature from")
        if oil is None:
            raise InputError(f"{path}: no viscosity column and no [oil] in the motor spec to derive it from the "
                             f"oil temperature")
        mu = np.where(gaps, _oil_viscosity(spec, np.where(gaps, t_fill, 40.0)), mu)
        assumed = gaps & ~np.isfinite(temperature)
        temperature = np.where(np.isfinite(temperature), temperature, t_fill)
    else:
        assumed = np.zeros(n, bool)

    if "displacement_m3" in found:
        x, j, unit = column("displacement_m3")
        x = np.where(np.isfinite(x), x * _DISPLACEMENT_UNITS[unit], np.nan)
        if np.any(x <= 0):
            i = int(np.flatnonzero(x <= 0)[0])
            raise InputError(f"{path}: column '{fields[j]}', line {lines[i]}: displacement must be > 0")
        if spec is None and np.isnan(x).any():
            raise InputError(f"{path}: column '{fields[j]}' has empty cells and no motor spec gives a displacement")
        displacement = np.where(np.isfinite(x), x, np.nan if spec is None else spec.displacement)
        variable = True
    else:
        if spec is None:
            raise InputError(f"{path}: no displacement_cm3 column and no motor spec")
        displacement = np.full(n, float(spec.displacement))
        variable = False

    measured, rel, how = {}, {}, {}
    counts = None
    if "n_samples" in found:
        counts, j, _ = column("n_samples")
        if np.any(counts[np.isfinite(counts)] < 1):
            i = int(np.flatnonzero(np.isfinite(counts) & (counts < 1))[0])
            raise InputError(f"{path}: column '{fields[j]}', line {lines[i]}: n_samples must be ≥ 1")
    for si, c in OUTPUTS.items():
        measured[c] = convert(si, column(si)[0]) if si in found else np.full(n, np.nan)
        s = np.ones(n)
        how[c] = "none"
        if "std:" + c in found:
            x, j, unit = column("std:" + c)
            conv = _BY_SI[si].units[unit]
            x = x * conv
            if np.any(x[np.isfinite(x)] <= 0):
                i = int(np.flatnonzero(np.isfinite(x) & (x <= 0))[0])
                raise InputError(f"{path}: column '{fields[j]}', line {lines[i]}: a spread must be > 0")
            if np.isfinite(x).any():
                s = np.where(np.isfinite(x), x, np.nanmedian(x))
                how[c] = "std columns"
        if counts is not None:
            s = s / np.sqrt(np.where(np.isfinite(counts), counts, np.nanmedian(counts)))
            how[c] = how[c] + " and n_samples" if how[c] != "none" else "n_samples"
        rel[c] = s / np.median(s)
    if "point_id" in found:
        ids = table[found["point_id"][0]].fillna("").astype(str).str.strip().to_numpy(dtype=object)
        empty = np.flatnonzero(ids == "")
        if empty.size:
            raise InputError(f"{path}: column '{fields[found['point_id'][0]]}', line {lines[empty[0]]}: empty cell")
        has_id = True
    else:
        ids = np.array([f"{path.name}:{k}" for k in lines], dtype=object)
        has_id = False
    notes = []
    if has_id and len(set(ids)) < ids.size:
        names, counts = np.unique(ids, return_counts=True)
        twice = [str(x) for x in names[counts > 1]]
        notes.append(f"{path.name}: point_id {', '.join(repr(x) for x in twice[:3])}"
                     f"{' …' if len(twice) > 3 else ''} names more than one point (fitted as separate points; "
                     "predict refuses repeated ids)")
    effs = {k[4:]: column(k)[0] * found[k][1] for k in found if k.startswith("eff:")}
    if effs:
        if "t" in effs and len(effs) == 1:
            raise InputError(f"{path}: column '{fields[found['eff:t'][0]]}': an overall efficiency alone cannot "
                             f"be split into torque and flow; give the volumetric or the hydromechanical one too")
        for k, x in effs.items():
            if np.isfinite(x).any() and np.nanmedian(x) > 1.5:
                raise InputError(f"{path}: column '{fields[found['eff:' + k][0]]}': efficiencies of "
                                 f"{np.nanmedian(x):.3g} in the median read as fractions: per cent? (name the "
                                 f"column with _pct, or map it with unit = \"%\")")
        derived, words = outputs_from_efficiencies(effs, speed, p_a, p_b, displacement)
        used = False
        for c, x in derived.items():
            fill = ~np.isfinite(measured[c]) & np.isfinite(x)
            if fill.any():
                measured[c] = np.where(fill, x, measured[c])
                used = True
        if used:
            notes += [f"{path.name}: {w}" for w in words]
            power = (p_a - p_b) * speed
            if not (power < 0).any() and not any(k in found for k in OUTPUTS):
                # an efficiency has no sign: a pump's sheet in the pump's own signs reads as a motor's
                notes.append(f"{path.name}: every point read in motor mode (ΔP·ω > 0, motorid's signs); the "
                             "efficiencies carry no sign to check it by: a pump's data sheet in its own signs "
                             "needs a channel map with convention = \"pump\" (docs/formats.md)")
    losses = {k[5:]: column(k)[0] * found[k][1] for k in found if k.startswith("loss:")}
    if losses:
        derived, words = outputs_from_losses(losses, speed, p_a, p_b, displacement)
        for c in derived:
            if np.isfinite(measured[c]).any():
                key = "torque" if c == "torque" else "q"
                raise InputError(f"{path}: column '{fields[found['loss:' + key][0]]}' and another column (a "
                                 f"{c} reading or an efficiency) give the same quantity; keep one")
        measured.update(derived)
        notes += [f"{path.name}: {w}" for w in words]
    stall = np.isfinite(measured["torque"]) & (np.abs(speed) < STALL_SPEED)
    if stall.any():  # a held shaft's torque is anywhere within its static friction: no running law
        measured["torque"] = np.where(stall, np.nan, measured["torque"])
        notes.append(f"{path.name}: {int(stall.sum())} torque reading(s) at zero speed (line {lines[stall][0]} "
                     f"first) set aside: a held shaft's torque lies anywhere within its static friction, which "
                     f"a steady table cannot fit (startability runs do: ISO 4392-2); their flows are kept")
    if "dp_Pa" in found and any(np.isfinite(measured[c]).any() for c in ("q_a", "q_b", "q_case")):
        notes.append(f"{path.name}: the table gives ΔP alone: the low-pressure port is taken at 0 bar gauge "
                     f"(BENCH_LOG_FORMAT.md); the leakage to the case follows the port pressures, so on a map "
                     f"run at a boost pressure give p_a_bar and p_b_bar instead (a channel map may build them "
                     f"from one ΔP channel with offset = the boost)")
    recording = None
    if "recording" in found:
        # an empty cell: a point of no named recording (never given a recording's own viscosity)
        recording = table[found["recording"][0]].fillna("").astype(str).str.strip().to_numpy(dtype=object)
    table = PointTable(ids, speed, p_a, p_b, p_case, temperature, mu, displacement, measured, rel,
                       np.array([str(path)] * n, dtype=object), lines, has_id, how, variable, recording, assumed,
                       notes)
    empty = ~np.any([np.isfinite(measured[c]) for c in measured], axis=0)
    if require_outputs and empty.all():
        raise InputError(f"{path}: no row holds an output reading (torque, a flow, an efficiency or a loss)")
    if require_outputs and empty.any():  # a point with no reading: nothing to fit, not a point of the map
        table = table.subset(~empty)
        table.notes.append(f"{path.name}: {int(empty.sum())} row(s) with no output reading (line "
                           f"{lines[empty][0]} first) set aside")
    return table


def concat_tables(tables: list) -> PointTable:
    """Several tables as one (each point keeps its file and line)."""
    if len(tables) == 1:
        return tables[0]
    cat = lambda name: np.concatenate([getattr(t, name) for t in tables])  # noqa: E731
    chans = ("torque", "q_a", "q_b", "q_case")
    how = {c: "/".join(sorted({t.weights_from.get(c, "none") for t in tables})) for c in chans}
    # relative σ of different tables are not on one scale: each was normalized to its own median
    return PointTable(cat("point_id"), cat("speed"), cat("p_a"), cat("p_b"), cat("p_case"), cat("temperature"),
                      cat("viscosity"), cat("displacement"),
                      {c: np.concatenate([t.measured[c] for t in tables]) for c in chans},
                      {c: np.concatenate([t.relative_sigma[c] for t in tables]) for c in chans},
                      cat("file"), cat("line"), all(t.has_point_id for t in tables), how,
                      any(t.variable_displacement for t in tables),
                      # a table without the column: its file names its recording
                      None if all(t.recording is None for t in tables) else
                      np.concatenate([t.recordings() for t in tables]),
                      np.concatenate([t.assumed_temperature() for t in tables]),
                      [note for t in tables for note in t.notes])


def _table_map(channels):
    """The channel map (path or ChannelMap) as a ChannelMap, or None."""
    if channels is None:
        return None
    from motorid.io.channel_map import ChannelMap, load_channel_map

    return channels if isinstance(channels, ChannelMap) else load_channel_map(channels)


def split_channel_map(channels) -> tuple:
    """(map for the tables, map for the logs) from one ``channels`` argument (path or ChannelMap):
    a map that names ``time_s`` is for logs, one that does not is for tables; (None, None) for None."""
    cmap = _table_map(channels)
    if cmap is None:
        return None, None
    return (None, cmap) if cmap.is_log else (cmap, None)


def _table_map_beside(path):
    """The channel map beside ``path`` (:func:`~motorid.io.formats.find_channel_map`) where it is a
    table's; None where there is none or it maps ``time_s`` (the map of the logs in that folder: a
    table of points to predict beside a bench's logs was refused for it)."""
    from motorid.io.formats import find_channel_map

    found = find_channel_map(path)
    cmap = _table_map(found) if found is not None else None
    return None if cmap is None or cmap.is_log else cmap


def read_mapped_table(path, spec=None, channels=None, require_outputs: bool = True) -> PointTable:
    """A foreign operating-point map (a .mat with a [grid], HDF5, Parquet, xlsx, TDMS, MDF4, any
    delimited text) read through its channel map (``channels``: path or ChannelMap; None: the map
    beside the file) into a :class:`PointTable`.  The mapped channels become a table in the
    format's columns and units, written as a CSV whose floats read back exactly, and read by
    :func:`read_table`: the same checks as for a table written by hand; errors name ``path``."""
    import re
    import tempfile

    from motorid.io.formats import _write_exact_csv, find_channel_map, standard_table

    path = Path(path)
    cmap = _table_map(channels if channels is not None else find_channel_map(path))
    if cmap is not None and cmap.is_log:
        if channels is None:  # found beside it: the map of the logs in that folder, not of this table
            cmap = None
        else:
            raise InputError(f"{path}: its channel map {cmap.path} maps time_s: a time series, not an "
                             f"operating-point table")
    frame = standard_table(path, cmap)
    with tempfile.TemporaryDirectory(prefix="motorid-") as tmp:
        twin = Path(tmp) / (path.name + ".csv")
        _write_exact_csv(frame, twin)
        try:
            table = read_table(twin, spec, require_outputs)
        except InputError as exc:
            msg = str(exc).replace(str(twin), str(path))
            msg = re.sub(r"\bline (\d+)", lambda m: f"row {int(m.group(1)) - 1}", msg)
            raise InputError(msg + (f" (read through {cmap.path})" if cmap is not None else "")) from None
    table.file = np.full(len(table), str(path), dtype=object)
    table.notes = [n.replace(twin.name, path.name) for n in table.notes]  # the user's file, not the twin
    return table


def read_tables(paths, spec=None, require_outputs: bool = True, channels=None) -> PointTable:
    """Read one or several tables (see :func:`read_table`) as one; a file in a foreign format,
    or any file where ``channels`` (a channel map for tables) is given, through
    :func:`read_mapped_table`."""
    from motorid.io.formats import find_channel_map, needs_foreign_reader
    from motorid.io.logs import refuse_repeats

    refuse_repeats(paths, "table")
    out = []
    for p in paths:
        if channels is not None or needs_foreign_reader(p) or _table_map_beside(p) is not None:
            out.append(read_mapped_table(p, spec, channels, require_outputs))
        else:
            out.append(read_table(p, spec, require_outputs))
        if require_outputs:
            from motorid.io.table_checks import check_against_ideal

            try:
                check_against_ideal(out[-1], p)
            except InputError as exc:
                cmap = _table_map(channels if channels is not None else find_channel_map(p))
                if cmap is not None and cmap.grid_axes:  # a square grid cannot tell its axes apart by shape
                    raise InputError(f"{exc}; or the [grid] axes in the wrong order (axes = "
                                     f"{list(cmap.grid_axes)!r}: the first indexes the matrices' rows)") from None
                raise
    return concat_tables(out)


def split_logs_and_tables(paths, channels=None) -> tuple[list, list]:
    """Files given on the command line → (bench logs, operating-point tables); folders are
    expanded to their ``*.csv`` / ``*.csv.gz`` files.  A file is a table when its header
    has no time column, or when ``channels`` (a channel-map path or ChannelMap) maps no
    ``time_s`` (an operating-point map such as a gridded .mat): then every file is a table."""
    cmap = _table_map(channels)
    if cmap is not None and not cmap.is_log:
        files = []
        for p in map(Path, paths):
            if p.is_dir():
                from motorid.io.formats import data_files_in

                found = data_files_in(p)
                if not found:
                    raise InputError(f"{p}: directory holds no file motorid reads")
                files += found
            elif not p.exists():
                raise InputError(f"{p}: no such file")
            else:
                files.append(p)
        return [], files
    files = []
    for p in paths:
        p = Path(p)
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.is_file() and
                           (q.name.endswith(".csv") or q.name.endswith(".csv.gz")))
            if not found:  # a folder of DAQ files, under one channels.toml or a <stem>.channels.toml each
                from motorid.io.formats import data_files_in

                found = data_files_in(p)
            if not found:
                raise InputError(f"{p}: directory holds no file motorid reads (.csv, .csv.gz, or a DAQ file: "
                                 f".tdms, .mf4, .mat, .h5, .parquet, .xlsx)")
            files += found
        elif not p.exists():
            raise InputError(f"{p}: no such file")
        else:
            files.append(p)
    logs, tables = [], []
    for f in files:
        (tables if _is_table_file(f, cmap) else logs).append(f)
    return logs, tables


def _is_table_file(path, cmap=None) -> bool:
    """Whether ``path`` is an operating-point table.  Under a channel map (``cmap``, the one given,
    else the one beside the file: formats.find_channel_map, which the log reader applies too): a
    table where the map has no time_s; with time_s a bench log, unless the file is delimited text
    whose header holds neither the map's time channel nor a time column (a native table given with
    the logs' map).  Without a map: :func:`is_table` (its header has no time column)."""
    from motorid.io.formats import SUFFIXES, _suffix, find_channel_map, needs_foreign_reader

    if cmap is None:
        beside = find_channel_map(path)
        cmap = _table_map(beside) if beside is not None else None
    if cmap is None:
        return is_table(path)
    if not cmap.is_log:
        return True
    if SUFFIXES.get(_suffix(Path(path))) not in ("csv", "text") or needs_foreign_reader(path) or cmap.file:
        return False  # (a map that says how to read the text, e.g. its header row: its file is its log)
    try:
        fields = [f.strip() for f in _split_header(Path(path), _head_text(Path(path)))[0]]
    except (OSError, InputError, IndexError):
        return False  # the log reader says what is wrong with it
    clock = cmap.channels["time_s"]
    return clock.rate_Hz is None and clock.name.strip() not in fields and is_table(path)
