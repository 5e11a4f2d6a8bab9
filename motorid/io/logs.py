"""Bench logs (BENCH_LOG_FORMAT.md): the canonical SI table, writing, and reading.

Inside motorid a log is a ``pandas.DataFrame`` with the canonical SI columns of
:data:`SI_COLUMNS`.  Units are converted here, at the edge, and nowhere else.
"""

from __future__ import annotations

import csv
import gzip
import io
import os
import re
import zlib
from pathlib import Path

import numpy as np
import pandas as pd
from pandas.api.types import union_categoricals

from motorid._atomic import write_bytes_atomic
from motorid.errors import InputError
from motorid.units import FORMAT_COLUMNS, SI_COLUMNS  # noqa: F401  (re-exported)
from motorid.units import (M3_PER_US_GALLON, M3S_PER_LPM, NM_PER_LBF_FT, PA_PER_BAR, PA_PER_PSI, RAD_PER_DEG,
                           RAD_S_PER_RPM)

VISCOSITY_FROM_OIL = "viscosity_from_oil_model"  # frame column: True where μ came from oil_temp_C and the spec
TEMPERATURE_ASSUMED = "oil_temp_assumed"  # frame column: True where the spec's [oil] temp_C stood for the log's


#: a median oil temperature above this [°C], where the viscosity is to come from it, is refused as a
#: probable °F column (mineral hydraulic oil runs below about 90 °C; ISO 4409 tests at 50 °C): 50 °C
#: read as 122 "°C" gives a viscosity 7× too low, and K_v 7× too high with exit 0
HOT_OIL_C = 110.0


def refuse_fahrenheit_as_celsius(where: str, column: str, temperature, derived) -> None:
    """One line where the oil temperatures from which viscosities are ``derived`` (a mask over
    ``temperature`` [°C]) lie above :data:`HOT_OIL_C` in the median: °F read as °C, most likely.
    Oil that truly runs this hot is read with its viscosity given (``viscosity_mPas``)."""
    t = np.asarray(temperature, dtype=float)[np.asarray(derived, bool)]
    t = t[np.isfinite(t)]
    if not t.size or float(np.median(t)) <= HOT_OIL_C:
        return
    hot = float(np.median(t))
    raise InputError(f"{where}: column '{column}': oil at {hot:.0f} °C in the median, hotter than hydraulic oil "
                     f"is run: °F under a °C name ({(hot - 32) * 5 / 9:.0f} °C if so)? Name the column oil_temp_F "
                     f"(in a channel map: unit = \"F\"); oil truly this hot: give its viscosity too (viscosity_mPas)")


def assumed_temperature(temp, mu, oil, where: str):
    """A log (or a block of one) that holds neither an oil temperature nor a viscosity takes the spec's
    [oil] temp_C for every sample → (temperatures [°C], assumed: bool); one line where the spec has none."""
    temp = np.asarray(temp, dtype=float)
    if temp.size == 0 or not (np.isnan(temp).all() and np.isnan(np.asarray(mu, dtype=float)).all()):
        return temp, False
    t_spec = getattr(oil, "temp_C", None) if oil is not None else None
    if t_spec is None:
        raise InputError(f"{where}: no oil temperature and no viscosity in this log: map oil_temp_C or a "
                         f"viscosity, or give [oil] temp_C in the motor spec to assume one")
    return np.full(temp.size, float(t_spec)), True


def looks_like_a_unit(cell: str) -> bool:
    """Whether a cell that is not a number reads like a unit ('rpm', '[bar]', '(Nm)'): the first data row
    of a table that holds one is a units row under the header."""
    return re.fullmatch(r"[\[(]?[^\d\s]+[\])]?", str(cell).strip()) is not None


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
    write_bytes_atomic(path, data)
    return path


# --------------------------------------------------------------------------- reading
#
# A header is read as  <quantity>_<unit>  after normalization (strip, lower case,
# brackets / slashes / spaces / hyphens → "_", "·" and "." dropped, "°" → "deg"),
# so "P_A [bar]", "p_a_bar" and " p_A_BAR " are one column.  Lower case cannot
# confuse units here because the quantity fixes the family: "mpa" of a pressure is
# MPa, "mpas" of a viscosity is mPa·s.

_TIME_UNITS = {"s": 1.0, "sec": 1.0, "ms": 1e-3, "us": 1e-6, "min": 60.0, "h": 3600.0}
_ANGLE_UNITS = {"rad": 1.0, "deg": RAD_PER_DEG, "degree": RAD_PER_DEG, "degrees": RAD_PER_DEG,
                "rev": 2.0 * np.pi}
_SPEED_UNITS = {"rad_s": 1.0, "rpm": RAD_S_PER_RPM, "rev_min": RAD_S_PER_RPM,
                "r_min": RAD_S_PER_RPM, "1_min": RAD_S_PER_RPM, "deg_s": RAD_PER_DEG,
                "rps": 2.0 * np.pi, "rev_s": 2.0 * np.pi, "hz": 2.0 * np.pi}
_TORQUE_UNITS = {"nm": 1.0, "n_m": 1.0, "knm": 1e3, "kn_m": 1e3, "lbf_ft": NM_PER_LBF_FT, "ft_lbf": NM_PER_LBF_FT,
                 "lbf_in": NM_PER_LBF_FT / 12.0, "in_lbf": NM_PER_LBF_FT / 12.0}
# "lbf·in", "lbf*ft", "in.lb" normalize without their separator; "lb" for "lbf", as makers write it
_TORQUE_UNITS.update({f"{a}{sep}{b}": _TORQUE_UNITS["lbf_ft" if "ft" in (a, b) else "lbf_in"]
                      for a, b in (("lbf", "ft"), ("ft", "lbf"), ("lbf", "in"), ("in", "lbf"), ("lb", "ft"),
                                   ("ft", "lb"), ("lb", "in"), ("in", "lb")) for sep in ("", "_")})
_PRESSURE_UNITS = {"pa": 1.0, "kpa": 1e3, "mpa": 1e6, "bar": PA_PER_BAR, "barg": PA_PER_BAR, "bar_g": PA_PER_BAR,
                   "mbar": 1e2, "psi": PA_PER_PSI, "psig": PA_PER_PSI}
_FLOW_UNITS = {"m3_s": 1.0, "m3_h": 1.0 / 3600.0, "l_s": 1e-3, "lps": 1e-3, "lpm": M3S_PER_LPM,
               "l_min": M3S_PER_LPM, "ml_s": 1e-6, "ml_min": 1e-6 / 60.0, "cm3_s": 1e-6,
               "cm3_min": 1e-6 / 60.0, "cc_min": 1e-6 / 60.0, "gpm": M3_PER_US_GALLON / 60.0,
               "usgpm": M3_PER_US_GALLON / 60.0, "gal_min": M3_PER_US_GALLON / 60.0, "m3_min": 1.0 / 60.0,
               "l_h": 1e-3 / 3600.0, "lph": 1e-3 / 3600.0, "dm3_min": 1e-3 / 60.0, "dm3_s": 1e-3}
_TEMPERATURE_UNITS = {"c": lambda x: x, "degc": lambda x: x, "celsius": lambda x: x,
                      "k": lambda x: x - 273.15, "kelvin": lambda x: x - 273.15,
                      "f": lambda x: (x - 32.0) * 5.0 / 9.0, "degf": lambda x: (x - 32.0) * 5.0 / 9.0}
_VISCOSITY_UNITS = {"pa_s": 1.0, "pas": 1.0, "mpa_s": 1e-3, "mpas": 1e-3, "cp": 1e-3,
                    # kinematic: converted with the oil density of the motor spec
                    "cst": ("kinematic", 1e-6), "mm2_s": ("kinematic", 1e-6), "m2_s": ("kinematic", 1.0)}


class _Quantity:
    """One logged quantity: its canonical SI column, words, header names and units."""

    def __init__(self, si: str, words: str, example: str, bases: tuple, units: dict):
        self.si, self.words, self.example, self.bases, self.units = si, words, example, bases, units
        suffix = example[len(bases[0]) + 1:]
        self.hint = ", ".join(["_" + suffix] + [f"_{u}" for u in units if u != suffix.lower()][:2])


_QUANTITIES = [
    _Quantity("time_s", "time", "time_s", ("time",), _TIME_UNITS),
    _Quantity("theta_rad", "shaft angle", "shaft_angle_deg", ("shaft_angle", "theta"), _ANGLE_UNITS),
    _Quantity("speed_rad_s", "shaft speed", "speed_rpm", ("speed", "shaft_speed", "omega"), _SPEED_UNITS),
    _Quantity("torque_Nm", "shaft torque", "torque_Nm", ("torque", "shaft_torque"), _TORQUE_UNITS),
    _Quantity("p_a_Pa", "port A pressure", "p_a_bar", ("p_a",), _PRESSURE_UNITS),
    _Quantity("p_b_Pa", "port B pressure", "p_b_bar", ("p_b",), _PRESSURE_UNITS),
    _Quantity("p_case_Pa", "case pressure", "p_case_bar", ("p_case",), _PRESSURE_UNITS),
    _Quantity("q_a_m3_s", "port A flow", "q_a_lpm", ("q_a",), _FLOW_UNITS),
    _Quantity("q_b_m3_s", "port B flow", "q_b_lpm", ("q_b",), _FLOW_UNITS),
    _Quantity("q_case_m3_s", "case drain flow", "q_case_lpm", ("q_case",), _FLOW_UNITS),
    # the names benches give it (T_oil_C, temp_C, Temperature [°C]); the format's own wins where both are
    _Quantity("oil_temp_C", "oil temperature", "oil_temp_C",
              ("oil_temp", "oil_temperature", "t_oil", "oil_t", "temp", "temperature", "fluid_temp",
               "fluid_temperature"), _TEMPERATURE_UNITS),
    _Quantity("viscosity_Pa_s", "oil viscosity", "viscosity_mPas", ("viscosity", "oil_viscosity", "mu"),
              _VISCOSITY_UNITS),
]
_BY_SI = {q.si: q for q in _QUANTITIES}
# normalized header → (quantity, unit)
_HEADERS = {f"{b}_{u}": (q, u) for q in _QUANTITIES for b in q.bases for u in q.units}
_TEXT_HEADERS = {"run_id": "run_id", "runid": "run_id", "run": "run_id", "protocol": "protocol"}
_REQUIRED = [q.si for q in _QUANTITIES if q.si != "viscosity_Pa_s"]
_NA_STRINGS = ["", "nan", "NaN", "NAN", "-nan", "NA", "N/A", "n/a", "#N/A", "null", "NULL", "None",
               "none", "-", "--", "<NA>"]


def normalize_header(name: str) -> str:
    """Header → its normalized form: "P_A [bar]" → "p_a_bar", "Oil Temp (°C)" → "oil_temp_degc"."""
    s = str(name).strip().lower()
    for a, b in (("°", "deg"), ("³", "3"), ("²", "2"), ("·", ""), ("*", ""), ("^", ""), ("µ", "u")):
        s = s.replace(a, b)
    s = re.sub(r"(?<=[a-z0-9])\.(?=[a-z])", "", s)  # "N.m", "mPa.s"
    s = re.sub(r"[\s/\\()\[\]{}\-,;:]+", "_", s)
    return re.sub(r"_+", "_", s).strip("_")


# the column each quantity has in BENCH_LOG_FORMAT.md (normalized)
_FORMAT_HEADER = {q.si: normalize_header(q.example) for q in _QUANTITIES}


#: absolute-pressure units: a channel map converts them (its ``absolute``); the columns are gauge
_ABSOLUTE_SUFFIXES = ("psia", "bara", "bar_a", "kpaa", "kpa_a", "mpaa", "mpa_a", "pa_a")


def absolute_pressure_words(name: str, q) -> str | None:
    """Why column ``name`` (which seems to be quantity ``q``) is not read where it is an absolute
    pressure, in words; None where it is not one."""
    if q.si.startswith("p_") and normalize_header(name).endswith(_ABSOLUTE_SUFFIXES):
        return (f"column '{name}' is an absolute pressure; the columns are gauge: read the file through a "
                f"channel map whose channel says unit = \"psia\" or \"bara\" (docs/formats.md)")
    return None


def _unit_hint(norm: str):
    """The quantity a header seems to name, when its unit suffix is not understood."""
    for q in _QUANTITIES:
        for b in q.bases:
            if len(b) > 1 and (norm == b or norm.startswith(b + "_")):
                return q
    return None


def _read_text(path: Path) -> str:
    """File bytes → text: gunzip (by magic bytes), refuse binary, decode."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read log file ({exc.strerror or exc})") from None
    if not raw:
        raise InputError(f"{path}: empty file")
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, zlib.error) as exc:
            raise InputError(f"{path}: corrupt gzip data ({exc})") from None
        if not raw:
            raise InputError(f"{path}: empty file (empty gzip content)")
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        try:
            return raw.decode("utf-16")
        except UnicodeDecodeError:
            raise InputError(f"{path}: not a text CSV file (undecodable UTF-16)") from None
    head = raw[:65536]
    control = sum(head.count(bytes([c])) for c in range(32) if c not in (9, 10, 13))
    if b"\x00" in head or control > 0.01 * len(head):
        raise InputError(f"{path}: not a text CSV file (binary content)")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _split_header(path: Path, text: str):
    """(header fields, delimiter, body text, 1-based line number of the header)."""
    pos, number = 0, 0
    while True:  # skip blank lines and leading "#" comments
        if pos >= len(text):
            raise InputError(f"{path}: empty file (no header line)")
        end = text.find("\n", pos)
        end = len(text) if end < 0 else end + 1
        header, pos, number = text[pos:end], end, number + 1
        if header.strip() and not header.lstrip().startswith("#"):
            break
    counts = {d: header.count(d) for d in (",", ";", "\t")}
    delim = max(counts, key=counts.get) if max(counts.values()) > 0 else ","
    fields = next(csv.reader([header.rstrip("\r\n")], delimiter=delim, skipinitialspace=True))
    return [f.strip() for f in fields], delim, text[pos:], number


def _map_columns(path: Path, fields: list):
    """Header fields → {SI column or 'run_id'/'protocol': (field index, unit)}; extras."""
    found: dict = {}
    extras: dict = {}
    for j, name in enumerate(fields):
        if name == "":
            continue
        norm = normalize_header(name)
        if norm in _TEXT_HEADERS:
            key, unit, words = _TEXT_HEADERS[norm], None, _TEXT_HEADERS[norm]
        elif norm in _HEADERS:
            q, unit = _HEADERS[norm]
            key, words = q.si, q.words
        else:  # kept, ignored; a repeated name gets its column number
            extras[j] = name if name not in extras.values() else f"{name}.{j + 1}"
            continue
        if key in found:
            other = fields[found[key][0]]
            if normalize_header(other) == norm:
                raise InputError(f"{path}: column '{name}' appears twice (also as '{other}')")
            # the format's own column wins; a copy of its quantity in another unit is an extra
            # column, kept and ignored (BENCH_LOG_FORMAT.md); two copies, neither of them the
            # format's, are ambiguous
            if norm == _FORMAT_HEADER.get(key):
                extras[found[key][0]] = other
            elif normalize_header(other) == _FORMAT_HEADER.get(key):
                extras[j] = name
                continue
            else:
                raise InputError(f"{path}: columns '{other}' and '{name}' both give the {words}; keep one")
        found[key] = (j, unit)
    # a bench without a shaft encoder: the angle column may be left out (its runs become operating
    # points, identify/log_points.py), as an empty column may
    missing = [k for k in ("time_s", "run_id", "protocol", *_REQUIRED[1:]) if k not in found and k != "theta_rad"]
    if missing:
        key = missing[0]
        if key in _BY_SI:
            q = _BY_SI[key]
            what = f"'{q.example}' ({q.words}, any unit suffix such as {q.hint})"
            hints = [fields[j] for j in extras if _unit_hint(normalize_header(fields[j])) is q]
            if hints:
                what += "; " + (absolute_pressure_words(hints[0], q)
                                or f"column '{hints[0]}' has no unit suffix that motorid knows")
        else:
            what = f"'{key}'"
        names = [_BY_SI[k].example if k in _BY_SI else k for k in missing[1:]]
        more = f" (and {len(names)} more: " + ", ".join(names) + ")" if names else ""
        if missing == ["run_id"]:  # runs logged one after another: a channel map splits them by the time track
            more += (" (a log whose runs follow each other in one file: a channel map without run_id splits them "
                     "where the time starts again or pauses, or names the file's one run under [constants]; "
                     "docs/formats.md)")
        raise InputError(f"{path}: missing required column {what}{more}")
    return found, extras


def _parse_body(path: Path, body: str, delim: str, fields: list, found: dict, header_line: int):
    """Body text → DataFrame of the mapped columns (floats, run_id/protocol as text)."""
    numeric = {j for k, (j, _) in found.items() if k not in ("run_id", "protocol")}
    names = list(range(len(fields)))
    opts = dict(sep=delim, header=None, names=names, skip_blank_lines=False, skipinitialspace=True,
                keep_default_na=False, index_col=False, engine="c")
    try:
        # bytes, not a StringIO: pandas' C parser would encode the text back to UTF-8 piece by piece
        return pd.read_csv(io.BytesIO(body.encode("utf-8")), encoding="utf-8",
                           dtype={j: (float if j in numeric else str) for j in names},
                           na_values={j: _NA_STRINGS for j in numeric}, **opts)
    except ValueError as exc:
        if isinstance(exc, pd.errors.ParserError):
            msg = re.sub(r"line (\d+)", lambda m: f"line {int(m.group(1)) + header_line}", str(exc))
            raise InputError(f"{path}: cannot parse as CSV ({msg.split('. ', 1)[-1].strip()})") from None
    # some numeric column holds text: find the first such cell to name it
    table = pd.read_csv(io.StringIO(body), dtype=str, na_filter=False, **opts)
    for j in sorted(numeric):
        cells = table[j].fillna("").astype(str).str.strip()
        values = pd.to_numeric(cells.where(~cells.isin(_NA_STRINGS)), errors="coerce")
        bad = np.flatnonzero(values.isna().to_numpy() & ~cells.isin(_NA_STRINGS).to_numpy())
        if bad.size:
            i = int(bad[0])
            hint = (" (a units row under the header? a channel map with [file] skip_rows = 1 leaves it out: "
                    "docs/formats.md)" if i == 0 and looks_like_a_unit(cells.iloc[i]) else "")
            raise InputError(f"{path}: column '{fields[j]}', line {header_line + 1 + i}: "
                             f"'{cells.iloc[i]}' is not a number{hint}")
    raise InputError(f"{path}: cannot parse as CSV")  # pragma: no cover


def _text_codes(column: pd.Series):
    """Text column → (codes, distinct values stripped): the string work is done once per value."""
    codes, uniques = pd.factorize(column.fillna(""), use_na_sentinel=False)
    return codes, np.array([str(u).strip() for u in uniques], dtype=object)


def _categorical(values: np.ndarray, codes: np.ndarray) -> pd.Categorical:
    """Per-row text ``values[codes]`` as a categorical (distinct values may repeat in ``values``)."""
    value_codes, distinct = pd.factorize(np.asarray(values, dtype=object))
    return pd.Categorical.from_codes(value_codes[codes], categories=pd.Index(distinct, dtype=object))


def _constant_categorical(value: str, n: int) -> pd.Categorical:
    return pd.Categorical.from_codes(np.zeros(n, dtype=np.int8), categories=pd.Index([value], dtype=object))


def _oil_viscosity(spec, temperature_C: np.ndarray) -> np.ndarray:
    """μ [Pa·s] of the spec's oil at ``temperature_C`` [°C], after checking the oil data."""
    o = spec.oil
    where = f"motor spec '{getattr(spec, 'name', '?')}' [oil]"
    if not (np.isfinite(o.nu100_cSt) and 0 < o.nu100_cSt < o.nu40_cSt and np.isfinite(o.nu40_cSt)):
        raise InputError(f"{where}: need 0 < nu100_cSt < nu40_cSt, got {o.nu100_cSt!r} and {o.nu40_cSt!r}")
    if not (np.isfinite(o.density15_kg_m3) and o.density15_kg_m3 > 0):
        raise InputError(f"{where}: density15_kg_m3 must be > 0, got {o.density15_kg_m3!r}")
    return np.asarray(spec.oil.viscosity(np.asarray(temperature_C, dtype=float), xp=np), dtype=float)


def read_log(path, spec=None, channels=None) -> pd.DataFrame:
    """Read and validate one bench log (``.csv`` or ``.csv.gz``) into the canonical SI frame.

    path : the log file (gzip is recognised by its magic bytes too);
    spec : :class:`motorid.model.MotorSpec` whose ``oil`` gives the viscosity
        [Pa·s] from ``oil_temp_C`` [°C] where the log has no viscosity column or
        empty viscosity cells (and converts a kinematic viscosity column).

    Returns a DataFrame with :data:`SI_COLUMNS` (time [s], θ [rad] wrapped to
    [0, 2π), speed [rad/s], torque [N·m], pressures [Pa gauge], flows [m³/s],
    oil temperature [°C], viscosity [Pa·s]), then ``file`` (the path as given),
    ``run`` (= run_id) and the file's extra columns (kept, ignored).  Empty
    sensor cells stay NaN; the row is kept.  Bad input raises
    :class:`~motorid.errors.InputError` with a one-line message naming the file
    and the column, line or run.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not a log file")
    from motorid.io import formats  # DAQ formats and channel maps (docs/formats.md)

    if channels is not None or formats.needs_foreign_reader(path) or formats.find_channel_map(path):
        return formats.read_foreign(path, spec, channels)
    fields, delim, body, header_line = _split_header(path, _read_text(path))
    found, extras = _map_columns(path, fields)
    table = _parse_body(path, body, delim, fields, found, header_line)
    lines = header_line + 1 + np.arange(len(table))
    text = {k: _text_codes(table[found[k][0]]) for k in ("run_id", "protocol")}
    empty = {k: (values == "")[codes] for k, (codes, values) in text.items()}
    keep = ~(empty["run_id"] & empty["protocol"] & table[found["time_s"][0]].isna().to_numpy())  # blank lines
    table, lines = table.loc[keep].reset_index(drop=True), lines[keep]
    if table.empty:
        raise InputError(f"{path}: no data rows after the header")
    for key in ("run_id", "protocol"):
        hole = np.flatnonzero(empty[key][keep])
        if hole.size:
            raise InputError(f"{path}: column '{fields[found[key][0]]}', line {lines[hole[0]]}: empty cell")
    run_codes, run_values = text["run_id"][0][keep], text["run_id"][1]
    proto_codes, proto_values = text["protocol"][0][keep], text["protocol"][1]
    proto_norm = np.array([re.sub(r"[\s\-]+", "_", v.lower()) for v in proto_values], dtype=object)
    unknown = np.flatnonzero(~np.isin(proto_norm, PROTOCOLS)[proto_codes])
    if unknown.size:
        i = unknown[0]
        raise InputError(f"{path}: run '{run_values[run_codes[i]]}', line {lines[i]}: unknown protocol "
                         f"'{proto_values[proto_codes[i]]}' (expected one of {', '.join(PROTOCOLS)})")
    pairs = pd.DataFrame({"run": run_codes, "protocol": pd.factorize(proto_norm[proto_codes])[0]})
    pairs = pairs.drop_duplicates()
    mixed = pairs["run"][pairs["run"].duplicated()]
    if len(mixed):
        # run numbers that start again for each protocol (run 1 of the constant-speed test, run 1 of the
        # startability test): a run is its protocol and its number, '<protocol>:<run>'
        key = proto_codes.astype(np.int64) * len(run_values) + run_codes
        codes, uniq = pd.factorize(key)
        run_values = np.array([f"{proto_norm[k // len(run_values)]}:{run_values[k % len(run_values)]}"
                               for k in uniq], dtype=object)
        run_codes = codes
    # text columns as categoricals: one string per distinct value, not per row
    out = pd.DataFrame({"run_id": _categorical(run_values, run_codes),
                        "protocol": _categorical(proto_norm, proto_codes)})

    kinematic = None
    for si in FORMAT_COLUMNS:
        if si not in found:
            out[si] = np.nan
            continue
        j, unit = found[si]
        x = table[j].to_numpy(dtype=float)
        x = np.where(np.isinf(x), np.nan, x)  # an overflowed sensor reads as missing
        if si == "viscosity_Pa_s" and np.any(x <= 0):
            i = int(np.flatnonzero(x <= 0)[0])
            raise InputError(f"{path}: column '{fields[j]}', line {lines[i]}: viscosity must be > 0")
        conv = _BY_SI[si].units[unit]
        if isinstance(conv, tuple):  # kinematic viscosity, needs the oil density
            kinematic = (fields[j], x * conv[1])
            x = np.full_like(x, np.nan)
        elif callable(conv):
            x = conv(x)
        else:
            x = x * conv
        out[si] = x

    col = lambda si: fields[found[si][0]]  # noqa: E731
    t = out["time_s"].to_numpy()
    if np.isnan(t).any():
        i = int(np.flatnonzero(np.isnan(t))[0])
        raise InputError(f"{path}: column '{col('time_s')}', line {lines[i]}: empty cell (time is required)")
    codes = pd.factorize(out["run_id"])[0]
    order = np.argsort(codes, kind="stable")
    same = codes[order][1:] == codes[order][:-1]
    bad = np.flatnonzero(same & (np.diff(t[order]) <= 0))
    if bad.size:
        rows = order[bad + 1]
        k = int(np.argmin(rows))
        i, prev = int(rows[k]), int(order[bad[k]])
        raise InputError(f"{path}: run '{out['run_id'].iloc[i]}': time not strictly increasing at line "
                         f"{lines[i]} ({col('time_s')} {table[found['time_s'][0]].iloc[i]:g} after "
                         f"{table[found['time_s'][0]].iloc[prev]:g})")
    temp = out["oil_temp_C"].to_numpy()
    if np.any(temp < -273.15):
        i = int(np.flatnonzero(temp < -273.15)[0])
        raise InputError(f"{path}: column '{col('oil_temp_C')}', line {lines[i]}: "
                         f"temperature below absolute zero")
    two_pi = 2.0 * np.pi
    theta = np.mod(out["theta_rad"].to_numpy(), two_pi)
    out["theta_rad"] = np.where(theta >= two_pi, 0.0, theta)

    if np.isnan(temp).any():  # a temperature read slower than the rest: filled between its readings
        from motorid.io.temperature_gaps import fill_temperature_gaps

        temp = fill_temperature_gaps(t, temp, codes)[0]
        out["oil_temp_C"] = temp
    mu = out["viscosity_Pa_s"].to_numpy()
    oil = getattr(spec, "oil", None)
    assumed = False
    if kinematic is None:
        temp, assumed = assumed_temperature(temp, mu, oil, str(path))
        if assumed:
            out["oil_temp_C"] = temp
    else:
        name, nu = kinematic
        if oil is None:
            raise InputError(f"{path}: column '{name}' is a kinematic viscosity; a motor spec with an [oil] "
                             f"table is needed for the density")
        mu = oil.dynamic_from_kinematic(nu, temp)
    gaps = np.isnan(mu)
    if gaps.any() and not assumed:
        refuse_fahrenheit_as_celsius(str(path), col("oil_temp_C"), temp, gaps)
    if gaps.any():
        if oil is None:
            if "viscosity_Pa_s" not in found or gaps.all():
                raise InputError(f"{path}: no viscosity readings (column e.g. 'viscosity_mPas') and no [oil] in "
                                 f"the motor spec to derive them from '{col('oil_temp_C')}'")
        else:
            mu = np.where(gaps, _oil_viscosity(spec, np.where(gaps, temp, 40.0)), mu)
    out["viscosity_Pa_s"] = mu
    out[VISCOSITY_FROM_OIL] = gaps  # rows whose viscosity the oil model gave, not a viscometer
    out[TEMPERATURE_ASSUMED] = np.full(len(out), assumed)

    out["file"] = _constant_categorical(str(path), len(out))
    out["run"] = out["run_id"]
    for j, name in extras.items():
        key = name if name not in out.columns else f"extra:{name}"
        out[key] = table[j].to_numpy()
    return out


def _log_paths(paths) -> list:
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    result = []
    for p in paths:
        p = Path(p)
        if p.is_dir():
            from motorid.io.formats import data_files_in

            found = data_files_in(p)
            if not found:
                raise InputError(f"{p}: directory holds no .csv or .csv.gz log")
            result += found
        else:
            result.append(p)
    if not result:
        raise InputError("no log files given")
    return result


def refuse_repeats(paths, what: str) -> None:
    """One line naming the first file given twice (the same file by any path) among ``paths``."""
    resolved: dict = {}
    for p in map(Path, paths):
        key = p.resolve()
        if key in resolved:
            raise InputError(f"{p}: {what} given twice (also as {resolved[key]})")
        resolved[key] = p


def read_logs(paths, spec=None, channels=None) -> pd.DataFrame:
    """Read a campaign: one or many logs (files, or directories of ``*.csv``/``*.csv.gz``).

    Returns the frames of :func:`read_log` stacked; ``run`` is the run_id, or
    ``"<file>:<run_id>"`` where the same run_id appears in several files
    (``<file>`` is the file name, or the whole path where names repeat).
    """
    files = _log_paths(paths)
    refuse_repeats(files, "log")
    frames = [read_log(p, spec, channels) for p in files]
    names = [p.name for p in files]
    labels = names if len(set(names)) == len(names) else [str(p) for p in files]
    owners: dict = {}
    for k, f in enumerate(frames):
        for rid in f["run_id"].cat.categories:
            owners.setdefault(rid, set()).add(k)
    for k, f in enumerate(frames):
        ids = f["run_id"].cat.categories
        f["run"] = f["run_id"].cat.rename_categories(
            [labels[k] + ":" + r if len(owners[r]) > 1 else r for r in ids])
    text = ("run_id", "protocol", "file", "run")
    frame = pd.concat([f.drop(columns=list(text)) for f in frames], ignore_index=True, sort=False)
    for c in text:  # categoricals of different files joined without a string per row
        frame[c] = union_categoricals([f[c] for f in frames]) if len(frames) > 1 else frames[0][c].array
    return frame[list(frames[0].columns) + [c for c in frame.columns if c not in frames[0].columns]]
