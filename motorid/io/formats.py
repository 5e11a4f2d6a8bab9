"""The files benches write: one reader per DAQ format, each giving named channels.

Formats (docs/formats.md): MATLAB .mat v5 (scipy.io.loadmat) and v7.3 (h5py),
HDF5 (h5py), Parquet (pyarrow), Excel .xlsx (openpyxl through pandas), NI TDMS
(npTDMS), ASAM MDF4 (asammdf), and delimited text with any delimiter and a
decimal point or comma (sniffed).  A reader is a *source*: ``get(name)`` gives
one channel as an array, ``names()`` what the file holds (for error messages),
and ``table()`` the whole file as columns where the format is tabular.

:func:`read_foreign` turns a file (with a channel map, or tabular with the
format's own column names) into a table in the format's units, writes it as a
full-precision CSV and reads that with :func:`motorid.io.logs.read_log`, so that a
foreign file gives exactly the frame its CSV twin gives, with the same checks.
"""

from __future__ import annotations

import csv
import gzip
import io
import re
import tempfile
import zlib
from pathlib import Path

import numpy as np
import pandas as pd

from motorid.errors import InputError

SUFFIXES = {
    ".mat": "mat", ".h5": "hdf5", ".hdf5": "hdf5", ".hdf": "hdf5", ".parquet": "parquet", ".pq": "parquet",
    ".xlsx": "xlsx", ".xlsm": "xlsx", ".tdms": "tdms", ".mf4": "mdf", ".mdf": "mdf",
    ".txt": "text", ".dat": "text", ".exp": "text", ".tsv": "text", ".csv": "csv",
}
_LIBRARY = {"mat": "scipy.io / h5py", "hdf5": "h5py", "parquet": "pyarrow", "xlsx": "openpyxl",
            "tdms": "npTDMS", "mdf": "asammdf", "text": "pandas", "csv": "pandas"}


def _suffix(path: Path) -> str:
    name = path.name.lower()
    if name.endswith(".gz"):
        name = name[:-3]
    return "." + name.rsplit(".", 1)[-1] if "." in name else ""


def format_of(path, cmap=None) -> str | None:
    """The format of ``path``: the map's [file] format, else by suffix; None if unknown."""
    if cmap is not None and cmap.file.get("format"):
        return cmap.file["format"]
    return SUFFIXES.get(_suffix(Path(path)))


def _not_found(path, name: str, names) -> InputError:
    names = list(names)
    listing = ", ".join(f"'{n}'" for n in names[:12]) + (f", … ({len(names)} in all)" if len(names) > 12 else "")
    return InputError(f"{path}: no channel '{name}' (the file has: {listing or 'none'})")


#: channel names that read a wide sheet (a maker's data-sheet matrix) under a [grid]: its first column,
#: the numbers of its header row after it, and the block of cells under them
WIDE_PARTS = ("@rows", "@columns", "@cells")


class _Columns:
    """A tabular source: a DataFrame whose columns are the channels (or, by :data:`WIDE_PARTS`,
    a wide sheet's axes and cells)."""

    def __init__(self, path, frame: pd.DataFrame, where: str = "", sheets: bool = False):
        self.path, self.frame, self.where = path, frame, where
        self.sheets = sheets  # a workbook's: its frame's "sheet" column names each row's sheet

    def names(self):
        return [str(c) for c in self.frame.columns]

    def _wide(self, sheet: str | None, part: str) -> np.ndarray:
        """``part`` of a wide sheet (``sheet``: one of a workbook's sheets, else the whole table): the
        first column ("@rows"), the numbers of the header row after it ("@columns"), the cells under them
        ("@cells", rows × columns); empty rows and columns left out."""
        frame = self.frame
        if sheet is not None:
            if not self.sheets:
                raise InputError(f"{self.path}: '{sheet}!{part}' names a sheet, and only a workbook has sheets")
            frame = frame[frame["sheet"].astype(str) == sheet]
            if frame.empty:
                raise InputError(f"{self.path}: no sheet '{sheet}' among those read ({self.where}; read several "
                                 "with [file] sheet = \"*\")")
        if self.sheets:
            frame = frame.drop(columns=["sheet"])
        frame = frame.dropna(axis=1, how="all").dropna(axis=0, how="all")
        cols = list(frame.columns)
        if len(cols) < 2 or frame.empty:
            raise InputError(f"{self.path}: a wide sheet ({part}) needs a first column of one axis and at least one "
                             "column headed by a value of the other")
        if part == "@columns":
            values = []
            for c in cols[1:]:
                try:
                    values.append(float(str(c).replace(",", ".")))
                except ValueError:
                    raise InputError(f"{self.path}: header '{c}' of the wide sheet is not a number (@columns: the "
                                     "header row after the first column holds the other axis' values)") from None
            return np.asarray(values)
        block = frame[cols[:1]] if part == "@rows" else frame[cols[1:]]
        numbers = block.apply(pd.to_numeric, errors="coerce")
        text = block.notna().to_numpy() & numbers.isna().to_numpy()
        if text.any():
            i, j = (int(k[0]) for k in np.nonzero(text))
            raise InputError(f"{self.path}: wide sheet, column '{block.columns[j]}', row {i + 1}: "
                             f"'{block.iloc[i, j]}' is not a number")
        out = numbers.to_numpy(dtype=float)
        return out[:, 0] if part == "@rows" else out

    def get(self, name: str):
        head, bang, tail = name.rpartition("!")
        if tail.strip() in WIDE_PARTS:
            return self._wide(head.strip() if bang else None, tail.strip())
        if name not in self.frame.columns:
            matches = [c for c in self.frame.columns if str(c).strip() == name.strip()]
            if len(matches) != 1:
                err = _not_found(self.path, name, self.names())
                raise InputError(f"{err} ({self.where})") if self.where else err
            name = matches[0]
        col = self.frame[name]
        if isinstance(col, pd.DataFrame):
            raise InputError(f"{self.path}: column '{name}' appears twice")
        return col.to_numpy()

    def table(self) -> pd.DataFrame:
        return self.frame


def _workbook(path: Path, options: dict) -> _Columns:
    """An Excel workbook's sheet ([file] sheet: a name or index; default the first), or several sheets
    read one after another (a list of names, or "*" for every sheet; a map's ``[extra] recording =
    "sheet"`` then gives each sheet its own recording), as one table with a ``sheet`` column."""
    header = options.get("header_row", 1) - 1
    skip = list(range(header + 1, header + 1 + int(options.get("skip_rows", 0))))  # a units row
    with pd.ExcelFile(path, engine="openpyxl") as book:
        names = [str(n) for n in book.sheet_names]
    want = options.get("sheet", 0)
    chosen = names if want == "*" else (list(want) if isinstance(want, list) else [want])
    for sheet in chosen:
        if isinstance(sheet, str) and sheet not in names:
            raise InputError(f"{path}: no sheet '{sheet}' (the workbook has: {', '.join(names)})")
        if isinstance(sheet, int) and not 0 <= sheet < len(names):
            raise InputError(f"{path}: no sheet {sheet} (the workbook has {len(names)}: {', '.join(names)})")
    frames = [pd.read_excel(path, sheet_name=sheet, header=header, skiprows=skip or None, engine="openpyxl")
              .assign(sheet=sheet if isinstance(sheet, str) else names[sheet]) for sheet in chosen]
    frame = pd.concat(frames, ignore_index=True) if len(frames) > 1 else frames[0]
    if options.get("decimal") == ",":  # numbers a German workbook stores as text: "-2,0", "1.002,5"
        for col in frame.columns:
            if not pd.api.types.is_numeric_dtype(frame[col]):
                frame[col] = _comma_numbers(frame[col])
    label = ", ".join(str(f["sheet"].iloc[0]) if len(f) else "?" for f in frames)
    return _Columns(path, frame, where=f"sheet {label}" + ("" if len(names) == 1 else
                                                           f"; the workbook's sheets: {', '.join(names)}"),
                    sheets=True)


def _comma_numbers(column: pd.Series) -> pd.Series:
    """A column whose text cells are all numbers with a decimal comma (and '.' as thousands), as floats;
    numeric cells kept; any other text: the column unchanged."""
    out = []
    for v in column:
        if isinstance(v, str):
            t = v.strip().replace(".", "").replace(",", ".")
            if not t:
                out.append(np.nan)
                continue
            try:
                out.append(float(t))
            except ValueError:
                return column
        else:
            out.append(v)
    try:
        return pd.Series(out, index=column.index, dtype=float)
    except (TypeError, ValueError):  # a date, a bool: not a column of numbers
        return column


# --------------------------------------------------------------------------- text

_DECIMAL_COMMA = re.compile(r"(?:^|[\s;|\t])[-+]?\d+,\d+(?:[eE][-+]?\d+)?(?=$|[\s;|\t])")


def _read_text(path: Path) -> str:
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except Exception as exc:  # noqa: BLE001 — any corruption is one line
            raise InputError(f"{path}: corrupt gzip data ({exc})") from None
    if b"\x00" in raw[:65536]:
        raise InputError(f"{path}: not a text file (binary content)")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _fields(line: str, delim: str | None) -> list:
    if delim is None:
        return line.split()
    return [f.strip() for f in next(csv.reader([line], delimiter=delim))]


def sniff_text(text: str, delimiter=None, decimal=None, header_row=None):
    """(header fields, data delimiter or None for whitespace, decimal mark, index of the first data line).

    The header is the first line that is not blank and not a '#' comment; a
    '#' line right before the first data line is the header where no other is
    (as in ``#time(s),Pos(in),…`` files).  The header and the data may use
    different delimiters.  A decimal comma is assumed where the data delimiter
    is not a comma and a cell reads like ``1,5``.
    """
    lines = text.splitlines()
    if header_row is not None:
        h = header_row - 1
        if h >= len(lines):
            raise InputError(f"header_row {header_row} is past the end of the file ({len(lines)} lines)")
    else:
        h = None
        for i, line in enumerate(lines):
            s = line.strip()
            if not s:
                continue
            if s.startswith("#"):
                nxt = next((lines[k] for k in range(i + 1, len(lines)) if lines[k].strip()), "")
                if nxt and not nxt.lstrip().startswith("#") and re.match(r"\s*[-+.\d]", nxt):
                    h = i
                    break
                continue
            h = i
            break
        if h is None:
            raise InputError("no header line")
    header = lines[h].strip().lstrip("#").strip()
    first = next((k for k in range(h + 1, len(lines)) if lines[k].strip()), None)
    data = lines[first] if first is not None else ""

    def pick(line: str):
        counts = {d: line.count(d) for d in (";", "\t", "|", ",")}
        best = max(counts, key=counts.get)
        return best if counts[best] > 0 else None

    hdelim = pick(header)
    ddelim = delimiter if delimiter is not None else pick(data) if data else hdelim
    if delimiter is None and hdelim in (";", "\t", "|") and data.count(hdelim) == header.count(hdelim):
        ddelim = hdelim  # "100,0;20,0" under "speed_rpm;p_a_bar": decimal commas, not comma-separated
    if ddelim == " ":
        ddelim = None
    if ddelim == "," and hdelim == "," and data and data.count(",") > header.count(","):
        ddelim = "," if data.count(";") == 0 else ";"  # "1,5,2,0" under a 2-field header: not sniffable
    header_fields = _fields(header, hdelim)
    if decimal is None:
        decimal = "," if ddelim != "," and _DECIMAL_COMMA.search(data) else "."
    return header_fields, ddelim, decimal, (first if first is not None else len(lines))


def read_text_table(path, options: dict | None = None) -> pd.DataFrame:
    """A delimited text file (any delimiter, decimal point or comma) → DataFrame of its columns."""
    options = options or {}
    path = Path(path)
    text = _read_text(path)
    try:
        fields, delim, decimal, start = sniff_text(text, options.get("delimiter"), options.get("decimal"),
                                                   options.get("header_row"))
        skip = int(options.get("skip_rows", 0))  # rows under the header that are no data (a units row)
        if skip:  # dropped, and the data's delimiter and decimal mark sniffed again without them
            lines = text.splitlines()
            drop = set([k for k in range(start, len(lines)) if lines[k].strip()][:skip])
            text = "\n".join(line for k, line in enumerate(lines) if k not in drop)
            fields, delim, decimal, start = sniff_text(text, options.get("delimiter"), options.get("decimal"),
                                                       options.get("header_row"))
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None
    body = "\n".join(text.splitlines()[start:])
    names = [f if f else f"column {j + 1}" for j, f in enumerate(fields)]
    try:
        frame = pd.read_csv(io.StringIO(body), sep=delim if delim is not None else r"\s+", header=None,
                            names=names, decimal=decimal, engine="c",
                            thousands="." if decimal == "," else None,  # 1.002,5: a decimal comma's thousands
                            skipinitialspace=True, comment=None, skip_blank_lines=True, index_col=False)
    except (ValueError, pd.errors.ParserError) as exc:
        raise InputError(f"{path}: cannot parse as delimited text ({str(exc).splitlines()[0]})") from None
    return frame


# --------------------------------------------------------------------------- binary formats

def _mat_v5(path: Path):
    from scipy.io import loadmat

    data = loadmat(str(path), squeeze_me=True, struct_as_record=False, chars_as_strings=True)
    top = {k: v for k, v in data.items() if not k.startswith("__")}

    class _Mat:
        def names(self):
            out = []
            for k, v in top.items():
                fields = getattr(v, "_fieldnames", None)
                out += [f"{k}.{f}" for f in fields] if fields else [k]
            return out

        def get(self, name: str):
            parts = re.split(r"[./]", name.strip("/"))
            value = top.get(parts[0])
            for p in parts[1:]:
                value = getattr(value, p, None) if value is not None else None
            if value is None or parts[0] not in top:
                raise _not_found(path, name, self.names())
            return np.asarray(value)

        def table(self):
            return _columns_of(path, {n: self.get(n) for n in self.names()})

    return _Mat()


class _H5:
    """HDF5 datasets by path; ``matlab``: a MATLAB v7.3 file (column-major: axes reversed)."""

    def __init__(self, path: Path, group: str | None, matlab: bool):
        import h5py

        self.path, self.matlab, self.group = path, matlab, (group or "").strip("/")
        self.file = h5py.File(path, "r")
        self._h5py = h5py

    def names(self):
        out = []

        def visit(name, obj):
            if isinstance(obj, self._h5py.Dataset) and not name.startswith("#"):
                if obj.dtype.names:
                    out.extend(f"{name}/{f}" for f in obj.dtype.names)
                else:
                    out.append(name)

        self.file.visititems(visit)
        return out

    def _full(self, name: str) -> str:
        name = name.strip().replace(".", "/") if self.matlab else name.strip()
        return f"{self.group}/{name.lstrip('/')}" if self.group and not name.startswith("/") else name.lstrip("/")

    def _dataset(self, name: str):
        """(dataset, compound field or None) of channel ``name``."""
        full = self._full(name)
        obj = self.file.get(full)
        if obj is None and "/" in full:  # a field of a compound (table) dataset
            parent, fld = full.rsplit("/", 1)
            ds = self.file.get(parent)
            if isinstance(ds, self._h5py.Dataset) and ds.dtype.names and fld in ds.dtype.names:
                return ds, fld
        if not isinstance(obj, self._h5py.Dataset):
            raise _not_found(self.path, name, self.names())
        return obj, None

    def length(self, name: str):
        """Samples of channel ``name`` where it is one vector (1-D, or 2-D with one axis of 1), else None."""
        ds, _ = self._dataset(name)
        shape = tuple(ds.shape)
        if len(shape) == 1:
            return shape[0]
        if len(shape) == 2 and 1 in shape:
            return max(shape)
        return None

    def get(self, name: str, start: int | None = None, stop: int | None = None):
        ds, fld = self._dataset(name)
        if start is not None:  # samples start … stop − 1 of a vector (length() is not None)
            if fld is not None:
                return np.asarray(ds[start:stop][fld])
            if ds.ndim == 1:
                value = ds[start:stop]
            else:
                value = ds[0, start:stop] if ds.shape[0] == 1 else ds[start:stop, 0]
            value = np.asarray(value)
            return value.astype(str) if value.dtype.kind == "S" else value
        if fld is not None:
            return np.asarray(ds[fld])
        obj = ds
        value = obj[()]
        if self.matlab:
            value = np.asarray(value).T
            if obj.attrs.get("MATLAB_class", b"") in (b"char", "char"):
                if value.ndim == 2 and value.shape[0] > 1:  # a char matrix: one text per row (run names)
                    return np.array(["".join(map(chr, row)).rstrip("\x00 ") for row in value], dtype=object)
                return np.array("".join(map(chr, np.ravel(value))))
        value = np.asarray(value)
        if value.dtype.kind == "S":
            value = value.astype(str)
        return value

    def table(self):
        return _columns_of(self.path, {n: self.get(n) for n in self.names()})

    def attribute(self, name: str):
        """An attribute of the group read (``[file] group``), else of the file's root."""
        for where in ([self.file[self.group]] if self.group and self.group in self.file else []) + [self.file]:
            if name in where.attrs:
                return _attribute_value(where.attrs[name])
        raise InputError(f"{self.path}: no attribute '{name}' on "
                         + (f"group '{self.group}' or " if self.group else "") + "the file's root (it has "
                         + (", ".join(sorted(self.file.attrs)) or "none") + ")")

    def close(self):
        self.file.close()


def _attribute_value(value):
    """An HDF5 attribute or TDMS property → a plain number or text."""
    value = np.asarray(value)
    if value.size == 1:
        value = value.reshape(()).item()
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    return value


class _H5Groups:
    """Every group under one parent of an HDF5 file, one after another ([file] group = "*" for the root's
    groups, "runs/*" for those under /runs): a channel is its dataset in each group, :meth:`sample_groups`
    the group of each sample (the run of a map that maps no run column), :meth:`sample_attribute` an
    attribute of each sample's group.  Read whole (no blocks)."""

    def __init__(self, path: Path, parent: str):
        import h5py

        self.path, self.file = path, h5py.File(path, "r")
        top = self.file[parent] if parent else self.file
        if parent and not isinstance(top, h5py.Group):
            self.file.close()
            raise InputError(f"{path}: no group '{parent}' ([file] group = \"{parent}/*\")")
        self.groups = [(k, top[k]) for k in top if isinstance(top[k], h5py.Group)]
        if not self.groups:
            self.file.close()
            raise InputError(f"{path}: no group under '/{parent}' to read as runs ([file] group)")
        self._h5py = h5py

    def close(self):
        self.file.close()

    def names(self):
        return [k for k in self.groups[0][1] if isinstance(self.groups[0][1][k], self._h5py.Dataset)]

    def _datasets(self, name: str):
        out = []
        for g, grp in self.groups:
            ds = grp.get(name.strip().lstrip("/"))
            if not isinstance(ds, self._h5py.Dataset):
                raise InputError(f"{self.path}: group '{g}' has no dataset '{name}' (group = \"*\" reads every "
                                 f"group as a run; each must hold the mapped channels)")
            out.append(ds)
        return out

    def get(self, name: str):
        parts = []
        for ds in self._datasets(name):
            v = np.ravel(np.asarray(ds[()]))
            parts.append(v.astype(str) if v.dtype.kind == "S" else v)
        return np.concatenate(parts) if parts else np.zeros(0)

    def sample_groups(self, name: str) -> np.ndarray:
        """The group name of every sample of channel ``name`` (from the datasets' sizes)."""
        return np.concatenate([np.full(ds.size, g, dtype=object)
                               for (g, _), ds in zip(self.groups, self._datasets(name))])

    def sample_attribute(self, attr: str, name: str) -> np.ndarray:
        """The attribute ``attr`` of each sample's group (of the file's root where a group has none)."""
        out = []
        for (g, grp), ds in zip(self.groups, self._datasets(name)):
            where = grp if attr in grp.attrs else self.file if attr in self.file.attrs else None
            if where is None:
                raise InputError(f"{self.path}: group '{g}' has no attribute '{attr}' (it has "
                                 f"{', '.join(sorted(grp.attrs)) or 'none'})")
            value = _attribute_value(where.attrs[attr])
            out.append(np.full(ds.size, value, dtype=object))
        return np.concatenate(out)

    def table(self):
        return _columns_of(self.path, {n: self.get(n) for n in self.names()})


def _columns_of(path, arrays: dict) -> pd.DataFrame:
    """Same-length 1-D arrays → DataFrame (a file read without a channel map)."""
    cols = {k: np.ravel(v) for k, v in arrays.items() if np.ndim(np.squeeze(v)) == 1}
    sizes = {v.size for v in cols.values()}
    if len(sizes) != 1:
        raise InputError(f"{path}: its channels are not one table of equal-length columns; "
                         f"read it with a channel map (--channels, docs/formats.md)")
    return pd.DataFrame(cols)


class _QuietTruncation:
    """npTDMS's two warning lines on a last segment shorter than announced, held back from the console
    while a file opens (only those: every other record passes; the filter comes off when the block
    ends): :func:`_check_tdms_complete` then says it in one line, or nothing where no data is missing."""

    MESSAGES = ("less data than expected", "not a multiple of the chunk size")

    def __enter__(self):
        import logging

        from nptdms.log import log_manager

        self.handler, self.filter = log_manager.console_handler, logging.Filter()
        self.filter.filter = lambda record: not any(m in record.getMessage() for m in self.MESSAGES)
        self.handler.addFilter(self.filter)
        return self

    def __exit__(self, *exc):
        self.handler.removeFilter(self.filter)
        return False


def _check_tdms_complete(path: Path, tdms) -> None:
    """Refuse a TDMS file whose last segment holds fewer samples of a channel than its header
    announces (a DAQ stopped mid-write, a copy interrupted): npTDMS reads what is there, and the fit
    would take part of the data.  A last segment left open by its writer with its data whole (a state
    the format allows) passes (npTDMS ``TdmsFile.file_status``)."""
    statuses = getattr(tdms.file_status, "channel_statuses", None) or {}
    for name, st in statuses.items():
        if st.read_length < st.expected_length:
            raise InputError(f"{path}: cut short: its last segment holds {st.read_length} of the "
                             f"{st.expected_length} samples its header announces for {name}")


def _tdms(path: Path, group: str | None, stream: bool = False):
    from nptdms import TdmsFile

    # stream: the file's index only; each read takes the samples it asks for (TdmsFile.open)
    with _QuietTruncation():
        tdms = TdmsFile.open(str(path)) if stream else TdmsFile.read(str(path))
    try:
        _check_tdms_complete(path, tdms)
    except InputError:
        if stream:
            tdms.close()
        raise

    if group == "*":  # a group per run (as many NI loggers write a test): the groups one after another
        return _TdmsGroups(path, tdms)

    class _Tdms:
        def names(self):
            return [f"{g.name}/{c.name}" for g in tdms.groups() for c in g.channels()]

        def _channel(self, name: str):
            base = name
            if "/" in base:
                g, c = base.split("/", 1)
                try:
                    return tdms[g][c]
                except KeyError:
                    pass
            groups = [tdms[group]] if group and group in [g.name for g in tdms.groups()] else tdms.groups()
            found = [g[base] for g in groups if base in [c.name for c in g.channels()]]
            if len(found) == 1:
                return found[0]
            if len(found) > 1:
                raise InputError(f"{path}: channel '{name}' is in several groups; write it as 'group/{name}'")
            raise _not_found(path, name, self.names())

        def length(self, name: str):
            return len(self._channel(name[:-5] if name.endswith("@time") else name))

        def get(self, name: str, start: int | None = None, stop: int | None = None):
            if name.endswith("@time"):
                ch = self._channel(name[:-5])
                if start is not None and "wf_increment" in ch.properties:
                    # the waveform's time track (nptdms time_track()), for these samples alone
                    step = float(ch.properties["wf_increment"])
                    offset = float(ch.properties.get("wf_start_offset", 0.0))
                    return offset + step * np.arange(start, min(stop, len(ch)), dtype=float)
                try:
                    t = ch.time_track()
                except (KeyError, ValueError) as exc:
                    raise InputError(f"{path}: channel '{name[:-5]}' has no waveform timing ({exc})") from None
                return t if start is None else t[start:stop]
            ch = self._channel(name)
            with _QuietTruncation():
                return np.asarray(ch[:] if start is None else ch[start:stop])

        def close(self):
            if stream:
                tdms.close()

        def attribute(self, name: str):
            """A property of the group read ([file] group), else of the file."""
            chosen = [g for g in tdms.groups() if g.name == group] if group else []
            for props in [g.properties for g in chosen] + [tdms.properties]:
                if name in props:
                    return _attribute_value(props[name])
            raise InputError(f"{path}: no property '{name}' on " + (f"group '{group}' or " if group else "")
                             + "the file (it has " + (", ".join(sorted(tdms.properties)) or "none") + ")")

        def table(self):
            groups = [tdms[group]] if group else tdms.groups()
            if len(groups) != 1:
                raise InputError(f"{path}: {len(groups)} groups; name one ([file] group) or use a channel map")
            return _columns_of(path, {c.name: c[:] for c in groups[0].channels()})

    return _Tdms()


class _TdmsGroups:
    """Every group of a TDMS file, one after another ([file] group = "*"): a channel is its values in
    each group (``name@time`` each group's waveform time track), and :meth:`sample_groups` the group
    of each sample, the run of a map that maps no run column.  Read whole (no blocks)."""

    def __init__(self, path: Path, tdms):
        self.path, self.tdms, self.groups = path, tdms, list(tdms.groups())
        if not self.groups:
            raise InputError(f"{path}: no group in the file")

    def close(self):
        close = getattr(self.tdms, "close", None)
        if close is not None:
            close()

    def names(self):
        return [c.name for c in self.groups[0].channels()]

    def _channels(self, base: str):
        """The channel ``base`` of every group."""
        out = []
        for g in self.groups:
            if base not in [c.name for c in g.channels()]:
                raise InputError(f"{self.path}: group '{g.name}' has no channel '{base}' (group = \"*\" reads "
                                 f"every group as a run; each must hold the mapped channels)")
            out.append(g[base])
        return out

    def _each(self, name: str):
        base = name[:-5] if name.endswith("@time") else name
        out = []
        for g, ch in zip(self.groups, self._channels(base)):
            if name.endswith("@time"):
                try:
                    out.append(np.asarray(ch.time_track(), dtype=float))
                except (KeyError, ValueError) as exc:
                    raise InputError(f"{self.path}: channel '{g.name}/{base}' has no waveform timing ({exc})") \
                        from None
            else:
                with _QuietTruncation():
                    out.append(np.asarray(ch[:]))
        return out

    def get(self, name: str):
        parts = self._each(name)
        return np.concatenate(parts) if parts else np.zeros(0)

    def sample_groups(self, name: str) -> np.ndarray:
        """The group name of every sample of channel ``name`` (from the channels' lengths, nothing read)."""
        base = name[:-5] if name.endswith("@time") else name
        return np.concatenate([np.full(len(ch), g.name, dtype=object)
                               for g, ch in zip(self.groups, self._channels(base))])

    def sample_attribute(self, attr: str, name: str) -> np.ndarray:
        """The property ``attr`` of each sample's group (of the file where a group has none)."""
        base = name[:-5] if name.endswith("@time") else name
        out = []
        for g, ch in zip(self.groups, self._channels(base)):
            props = g.properties if attr in g.properties else self.tdms.properties
            if attr not in props:
                raise InputError(f"{self.path}: group '{g.name}' has no property '{attr}' (it has "
                                 f"{', '.join(sorted(g.properties)) or 'none'})")
            out.append(np.full(len(ch), _attribute_value(props[attr]), dtype=object))
        return np.concatenate(out)

    def table(self):
        return _columns_of(self.path, {n: self.get(n) for n in self.names()})


def _mdf(path: Path):
    from asammdf import MDF

    mdf = MDF(str(path))

    class _Mdf:
        def names(self):
            return sorted(n for n in mdf.channels_db if not n.startswith("$"))

        def _signal(self, name: str):
            self._signal_check(name)
            return mdf.get(name)

        def length(self, name: str):
            base = name[:-5] if name.endswith("@time") else name
            self._signal_check(base)
            group = mdf.channels_db[base][0][0]
            return int(mdf.groups[group].channel_group.cycles_nr)

        def _signal_check(self, name: str):
            if name not in mdf.channels_db:
                raise _not_found(path, name, self.names())
            if len(mdf.channels_db[name]) > 1:
                raise InputError(f"{path}: channel '{name}' is in several groups; rename it in the "
                                 f"recorder or export one group")

        def get(self, name: str, start: int | None = None, stop: int | None = None):
            base = name[:-5] if name.endswith("@time") else name
            if start is None:
                sig = self._signal(base)
            else:  # those records alone (asammdf reads them from the file)
                self._signal_check(base)
                sig = mdf.get(base, record_offset=start, record_count=stop - start)
            if name.endswith("@time"):
                return np.asarray(sig.timestamps, dtype=float)
            return np.asarray(sig.samples)

        def table(self):
            frame = mdf.to_dataframe(time_from_zero=False)
            frame.insert(0, "time_s", frame.index.to_numpy(dtype=float))
            return frame.reset_index(drop=True)

        def close(self):
            mdf.close()

    return _Mdf()


def open_source(path, cmap=None, stream: bool = False):
    """Open ``path`` as a source of named channels (see the module doc); ``stream``: a TDMS file
    is opened for reads of sample ranges (its index only is read now)."""
    path = Path(path)
    fmt = format_of(path, cmap)
    if fmt is None:
        raise InputError(f"{path}: unknown file type '{_suffix(path) or path.name}' (motorid reads "
                         f"{', '.join(sorted(set(SUFFIXES)))}; name the format in a channel map's [file] format)")
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not a data file")
    options = dict(cmap.file) if cmap is not None else {}
    try:
        if fmt in ("text", "csv"):
            return _Columns(path, read_text_table(path, options))
        if fmt == "parquet":
            import pyarrow.parquet as pq

            return _Columns(path, pq.read_table(str(path)).to_pandas())
        if fmt == "xlsx":
            return _workbook(path, options)
        if fmt == "tdms":
            return _tdms(path, options.get("group"), stream)
        if fmt == "mdf":
            return _mdf(path)
        if fmt == "hdf5":
            group = str(options.get("group") or "")
            if group == "*" or group.endswith("/*"):  # a group per run
                return _H5Groups(path, group[:-1].strip("/"))
            return _H5(path, options.get("group"), matlab=False)
        if fmt == "mat":
            import h5py

            if h5py.is_hdf5(str(path)):  # MATLAB v7.3
                return _H5(path, options.get("group"), matlab=True)
            return _mat_v5(path)
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 — a library's complaint about a bad file, as one line
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{path}: cannot read as {fmt} with {_LIBRARY[fmt]} ({msg})") from None
    raise InputError(f"{path}: format '{fmt}' has no reader")  # pragma: no cover


def column_names(path) -> list | None:
    """The column names of a tabular binary file (Parquet: its schema; Excel: the first row of its
    first sheet), read without its data; None for any other format, or where the file cannot be read
    (its reader then says why)."""
    path = Path(path)
    fmt = SUFFIXES.get(_suffix(path))
    try:
        if fmt == "parquet":
            import pyarrow.parquet as pq

            return [str(n) for n in pq.read_schema(str(path)).names]
        if fmt == "xlsx":
            import openpyxl

            book = openpyxl.load_workbook(path, read_only=True, data_only=True)
            try:
                first = next(book.worksheets[0].iter_rows(max_row=1, values_only=True), ())
            finally:
                book.close()
            return [str(v) for v in first if v is not None]
    except Exception:  # noqa: BLE001 — not readable here: the reader of the file says what is wrong
        return None
    return None


# --------------------------------------------------------------------------- to the log reader

def needs_foreign_reader(path) -> bool:
    """True where read_log's own CSV parser cannot take ``path``: a foreign suffix, or
    a delimited text with a decimal comma, whitespace or '|' delimiter, or a '#' header."""
    path = Path(path)
    fmt = SUFFIXES.get(_suffix(path))
    if fmt is None:
        return False
    if fmt != "csv":
        return True
    try:
        with open(path, "rb") as fh:
            head = fh.read(8192)
        if head[:2] == b"\x1f\x8b":
            with gzip.open(path, "rb") as gz:
                head = gz.read(8192)
    except (OSError, EOFError, zlib.error):
        return False  # read_log reports it
    text = head.decode("utf-8", "replace")
    try:
        fields, delim, decimal, _ = sniff_text(text)
    except InputError:
        return False
    lines = [ln for ln in text.splitlines() if ln.strip()]
    first = next((ln for ln in lines if not ln.lstrip().startswith("#")), "")
    header_in_comment = bool(re.match(r"\s*[-+.\d]", first))  # '#time,…' right above the data
    return decimal == "," or delim not in (",", ";", "\t") or header_in_comment


def standard_table(path, cmap=None) -> pd.DataFrame:
    """``path`` as a table with the format's column names and units (a log or an
    operating-point table), through the channel map ``cmap`` where given."""
    source = open_source(path, cmap)
    try:
        if cmap is not None:
            return cmap.apply(source, str(path))
        return source.table()
    except InputError:
        raise
    except (KeyError, ValueError, TypeError) as exc:
        raise InputError(f"{path}: cannot read its channels ({str(exc).splitlines()[0]})") from None
    finally:
        if hasattr(source, "close"):
            source.close()


def data_files_in(folder) -> list:
    """The files of ``folder`` motorid reads: CSV and the binary formats always; other
    text (.txt, .dat, .exp, .tsv) only where a ``channels.toml`` maps them."""
    folder = Path(folder)
    mapped = (folder / "channels.toml").is_file()
    out = []
    for q in sorted(folder.iterdir()):
        fmt = SUFFIXES.get(_suffix(q))
        if q.is_file() and fmt is not None and (fmt != "text" or mapped):
            out.append(q)
    return out


def find_channel_map(path):
    """The channel map beside ``path``: ``<stem>.channels.toml``, else ``channels.toml`` in its folder."""
    path = Path(path)
    stem = path.name[:-3] if path.name.endswith(".gz") else path.name
    stem = stem.rsplit(".", 1)[0]
    for candidate in (path.with_name(f"{stem}.channels.toml"), path.with_name("channels.toml")):
        if candidate.is_file():
            return candidate
    return None


def _write_exact_csv(table: pd.DataFrame, path: Path) -> None:
    """Table → CSV whose floats read back bit for bit (shortest round-trip text; NaN → empty).
    Arrow's C++ writer is about ten times faster than pandas'; pandas where Arrow cannot
    type a column (mixed text and numbers in an extra column)."""
    import pyarrow as pa
    import pyarrow.csv as pa_csv

    try:
        pa_csv.write_csv(pa.Table.from_pandas(table, preserve_index=False), str(path))
    except (pa.ArrowException, TypeError, ValueError):
        table.to_csv(path, index=False, lineterminator="\n")  # repr: shortest round-trip text


def read_foreign(path, spec=None, channels=None) -> pd.DataFrame:
    """Read a foreign file into the canonical SI frame of :func:`motorid.io.logs.read_log`.

    channels : a channel map (path or :class:`~motorid.io.channel_map.ChannelMap`);
        None: the map beside the file (:func:`find_channel_map`), else the file's
        own column names must follow BENCH_LOG_FORMAT.md.
    """
    from motorid.io.channel_map import ChannelMap, load_channel_map
    from motorid.io.logs import read_log

    path = Path(path)
    if channels is None:
        channels = find_channel_map(path)
    cmap = channels if isinstance(channels, ChannelMap) or channels is None else load_channel_map(channels)
    table = standard_table(path, cmap)
    if getattr(cmap, "runs_cut_by_time", False) and {"speed_rpm", "p_a_bar", "p_b_bar"} <= set(table.columns):
        from motorid.io.set_points import split_table  # many set points in one run: one run each
        from motorid.io.temperature_gaps import fill_temperature_gaps
        from motorid.units import PA_PER_BAR, RAD_S_PER_RPM

        if "oil_temp_C" in table.columns and table["oil_temp_C"].isna().any():  # before the ramps go
            table = table.assign(oil_temp_C=fill_temperature_gaps(
                table["time_s"].to_numpy(float), table["oil_temp_C"].to_numpy(float),
                pd.factorize(table["run_id"])[0])[0])
        table = split_table(table, RAD_S_PER_RPM, PA_PER_BAR)
    with tempfile.TemporaryDirectory(prefix="motorid-") as tmp:
        twin = Path(tmp) / (path.name + ".csv")
        _write_exact_csv(table, twin)
        try:
            frame = read_log(twin, spec)
        except InputError as exc:
            msg = str(exc).replace(str(twin), str(path))
            msg = re.sub(r"\bline (\d+)", lambda m: f"row {int(m.group(1)) - 1}", msg)
            if cmap is not None:
                msg += f" (read through {cmap.path})"
            elif "missing required column" in msg:
                msg += ("; its channels were taken by name as the format's columns: map them once in a channel "
                        "map (--channels MAP.toml, or channels.toml beside the file; docs/formats.md)")
            raise InputError(msg) from None
    frame["file"] = pd.Categorical.from_codes(np.zeros(len(frame), dtype=np.int8),
                                              categories=pd.Index([str(path)], dtype=object))
    return frame
