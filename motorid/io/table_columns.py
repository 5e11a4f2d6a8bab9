"""Which file is an operating-point table, and which of its columns is what (BENCH_LOG_FORMAT.md,
"Operating-point tables"): the header read, each column named to the quantity and unit it holds.
The values are read and converted in :mod:`motorid.io.tables`."""

from __future__ import annotations

from pathlib import Path

from motorid.errors import InputError
from motorid.io.efficiency_columns import HEADERS as EFFICIENCY_HEADERS
from motorid.io.efficiency_columns import loss_headers
from motorid.io.logs import (_FLOW_UNITS, _FORMAT_HEADER, _HEADERS, _PRESSURE_UNITS, _TORQUE_UNITS, _read_text,
                          _split_header, _unit_hint, absolute_pressure_words, normalize_header)

#: the outputs a table may give, SI column of the logs → channel name of the fit
OUTPUTS = {"torque_Nm": "torque", "q_a_m3_s": "q_a", "q_b_m3_s": "q_b", "q_case_m3_s": "q_case"}
_INPUT_SI = ("speed_rad_s", "p_a_Pa", "p_b_Pa", "p_case_Pa", "oil_temp_C", "viscosity_Pa_s")
_DISPLACEMENT_UNITS = {"cm3": 1e-6, "cc": 1e-6, "ml": 1e-6, "cm3_rev": 1e-6, "cc_rev": 1e-6, "ml_rev": 1e-6,
                       "m3": 1.0, "m3_rev": 1.0, "l": 1e-3, "l_rev": 1e-3, "in3": 1.6387064e-5,
                       "in3_rev": 1.6387064e-5}
_DP_HEADERS = {f"{b}_{u}": u for b in ("dp", "delta_p", "deltap", "p_ab") for u in _PRESSURE_UNITS}
_LOSS_HEADERS = loss_headers(_TORQUE_UNITS, _FLOW_UNITS)
_ID_HEADERS = ("point_id", "pointid", "point", "id")
_COUNT_HEADERS = ("n_samples", "samples", "n", "count")
#: a text column naming the recording (test session) each point was averaged from
_RECORDING_HEADERS = ("recording", "session")


def _header_fields(path: Path):
    fields, delim, body, header_line = _split_header(path, _read_text(path))
    return fields, delim, body, header_line


def _head_text(path: Path, size: int = 65536) -> str:
    """The first ``size`` bytes of a (possibly gzipped) text file, decoded: enough for the header,
    without reading a multi-gigabyte log twice."""
    import gzip
    import zlib

    with open(path, "rb") as fh:
        raw = fh.read(size)
    if raw[:2] == b"\x1f\x8b":
        try:
            with gzip.open(path, "rb") as fh:
                raw = fh.read(size)
        except (OSError, EOFError, zlib.error):
            return ""
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return raw.decode("utf-16", errors="ignore")
    return raw.decode("utf-8-sig", errors="ignore")


def is_table(path) -> bool:
    """True when ``path`` is an operating-point table: its header has no time column.

    Only the file's head is read (of a Parquet file its schema, of a workbook its first row:
    :func:`~motorid.io.formats.column_names`); a file whose head is not text, and which is not one of
    those, is not a table (the log reader then says what is wrong with it)."""
    from motorid.io.formats import column_names

    path = Path(path)
    fields = column_names(path)
    if fields is None:
        try:
            text = _head_text(path)
        except OSError:
            return False
        if not text or "\x00" in text:
            return False
        try:
            fields = _split_header(path, text)[0]
        except InputError:
            return False
    if not fields:
        return False
    for name in fields:
        norm = normalize_header(name)
        if norm in _HEADERS and _HEADERS[norm][0].si == "time_s":
            return False
        if norm in ("run_id", "runid", "protocol"):  # a bench log that lost its time column: the log
            return False                             # reader names what is missing
    return True


def _is_number(text) -> bool:
    try:
        float(str(text).strip().replace(",", "."))
    except ValueError:
        return False
    return True


def _map_table_columns(path: Path, fields: list):
    """Header → {key: (index, unit)} for the table's columns; keys are log SI columns plus
    "dp_Pa", "displacement_m3", "n_samples", "point_id" and "std:<channel>"."""
    found: dict = {}

    def put(key, j, unit, name):
        if key in found:
            other = fields[found[key][0]]
            own = _FORMAT_HEADER.get(key)  # the format's own column wins over another name of its quantity
            other_own, new_own = (own is not None and normalize_header(f) == own for f in (other, name))
            if other_own == new_own:
                raise InputError(f"{path}: columns '{other}' and '{name}' give the same quantity; keep one")
            if other_own:
                return
        found[key] = (j, unit)

    for j, name in enumerate(fields):
        if name == "":
            continue
        norm = normalize_header(name)
        if norm in _ID_HEADERS:
            put("point_id", j, None, name)
        elif norm in _COUNT_HEADERS:
            put("n_samples", j, None, name)
        elif norm in _RECORDING_HEADERS:
            put("recording", j, None, name)
        elif norm in _DP_HEADERS:
            put("dp_Pa", j, _DP_HEADERS[norm], name)
        elif norm in EFFICIENCY_HEADERS:  # a data sheet's efficiencies: torque and flow derived from them
            key, scale = EFFICIENCY_HEADERS[norm]
            put("eff:" + key, j, scale, name)
        elif norm in _LOSS_HEADERS:  # a loss table's T_loss, Q_loss: torque and the inlet flow derived from them
            key, factor = _LOSS_HEADERS[norm]
            put("loss:" + key, j, factor, name)
        elif norm.startswith("displacement_") and norm[len("displacement_"):] in _DISPLACEMENT_UNITS:
            put("displacement_m3", j, norm[len("displacement_"):], name)
        elif "_std_" in norm and norm.replace("_std_", "_", 1) in _HEADERS:
            q, unit = _HEADERS[norm.replace("_std_", "_", 1)]
            if q.si in OUTPUTS:
                put("std:" + OUTPUTS[q.si], j, unit, name)
        elif norm in _HEADERS:
            q, unit = _HEADERS[norm]
            if q.si in OUTPUTS or q.si in _INPUT_SI:
                put(q.si, j, unit, name)
    used = {j for j, _ in found.values()}
    for j, name in enumerate(fields):  # a channel in a unit motorid does not know: not dropped in silence
        norm = normalize_header(name) if name else ""
        q = _unit_hint(norm) if j not in used and norm and "_std" not in norm else None
        if q is not None and any(norm.endswith("_" + normalize_header(u)) for u in q.units):
            q = None  # 'torque_setpoint_Nm', 'q_b_set_lpm': a known unit, a channel of its own (kept, ignored)
        given = q is not None and (q.si in found or (q.si in ("p_a_Pa", "p_b_Pa") and "dp_Pa" in found))
        if q is not None and (q.si in OUTPUTS or q.si in _INPUT_SI) and not given:
            raise InputError(f"{path}: " + (absolute_pressure_words(name, q) or (
                f"column '{name}' seems to be the {q.words}, but its unit suffix is not one motorid knows (such as "
                f"{q.hint}): rename it, or read the file with a channel map")))
    if "speed_rad_s" not in found:
        wide = ""
        if sum(_is_number(f) for f in fields[1:]) >= 2:  # a header row of speeds: a maker's data-sheet matrix
            wide = ("; its header holds numbers: a wide data sheet (one axis down the first column, the other along "
                    "the header) reads through a channel map's [grid] with names \"@rows\", \"@columns\", "
                    "\"@cells\" (docs/formats.md)")
        raise InputError(f"{path}: missing required column 'speed_rpm' (shaft speed, any unit suffix such as "
                         f"_rpm, _rad_s){wide}")
    has_ports = "p_a_Pa" in found and "p_b_Pa" in found
    if not has_ports and "dp_Pa" not in found:
        missing = "p_b_bar" if "p_a_Pa" in found else "p_a_bar"
        raise InputError(f"{path}: missing required column '{missing}' (port pressures 'p_a_bar' and 'p_b_bar', "
                         f"or 'dp_bar' = P_A − P_B)")
    if has_ports and "dp_Pa" in found:
        raise InputError(f"{path}: both port pressures and '{fields[found['dp_Pa'][0]]}' given; keep one form")
    if "dp_Pa" in found and ("p_a_Pa" in found or "p_b_Pa" in found):
        other = fields[found["p_a_Pa" if "p_a_Pa" in found else "p_b_Pa"][0]]
        raise InputError(f"{path}: '{fields[found['dp_Pa'][0]]}' and '{other}' given; use p_a_bar and p_b_bar, "
                         f"or dp_bar alone")
    return found
