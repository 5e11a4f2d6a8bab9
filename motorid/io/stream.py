"""Bench logs read in blocks, handed on run by run: memory set by one block and one run, not the file.

:func:`stream_runs` reads CSV and CSV.gz with pyarrow's streaming CSV reader
(``pyarrow.csv.open_csv``) and Parquet by row groups
(``pyarrow.parquet.ParquetFile.iter_batches``), with the header and unit handling
of :func:`motorid.io.logs.read_log` (the same column names, unit suffixes and
missing-column messages).  Each block is checked and converted to SI as it
arrives; the rows of one run are gathered until the run ends and then handed on
as one :class:`RunColumns`.

Runs are contiguous in a log (BENCH_LOG_FORMAT.md: one set point after the other).
Where a run id comes back in the same file after another run, the stream stops
with :class:`StreamFallback` and the caller reads the campaign whole, as
:func:`~motorid.io.logs.read_logs` always did (its memory then grows with the rows).
The same happens on any cell the block checks refuse (a text in a number column,
a time that does not increase, an unknown protocol, …): the whole-file reader then
names the file, line and column in its usual one-line :class:`~motorid.errors.InputError`,
so a bad file gives exactly the message it gave before, and no partial output.
HDF5, MATLAB v7.3, TDMS and MDF4 files with a channel map are read in blocks of
:data:`FOREIGN_BLOCK_ROWS` samples (h5py slices, npTDMS ``TdmsFile.open``, asammdf record
ranges) through ``ChannelMap.apply(..., rows=…)`` and then go the CSV blocks' way.
Files the streaming readers do not take (xlsx, MATLAB v5, text with a channel map, a
decimal comma, a UTF-16 text, comment lines above the header) are read whole, file by
file, and handed on run by run too.

A run id seen in an earlier file is keyed ``<file name>:<run_id>`` (the earlier
one keeps its bare id; :func:`~motorid.io.logs.read_logs` prefixes both).  Extra
columns are not kept (the fit ignores them).
"""

from __future__ import annotations

import gzip
import re
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np
import pandas as pd

from motorid.errors import InputError
from motorid.units import FORMAT_COLUMNS, SI_COLUMNS

#: bytes of text pyarrow parses at a time (one block in memory, plus the run being gathered);
#: at 4 MiB the reader's peak memory was 150 MB higher and its speed the same
BLOCK_BYTES = 1 << 20
#: rows of a Parquet batch
PARQUET_BATCH_ROWS = 1 << 16
#: samples of a block read from an HDF5, MATLAB v7.3, TDMS or MDF4 file through its channel map
FOREIGN_BLOCK_ROWS = 1 << 16
#: the formats whose libraries read sample ranges (h5py slices, npTDMS TdmsFile.open, asammdf records)
RANGE_FORMATS = ("hdf5", "mat", "tdms", "mdf")


class StreamFallback(Exception):
    """The stream cannot go on (an interleaved run, a cell the block checks refuse):
    read the campaign whole instead (``reason`` says why, in words)."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


@dataclass
class RunColumns:
    """One run of a log, SI: ``columns`` maps each numeric column of
    :data:`motorid.units.SI_COLUMNS` (and ``viscosity_from_oil_model``) to an array in file order."""

    key: str
    run_id: str
    protocol: str
    file: str
    columns: dict

    @property
    def n(self) -> int:
        return int(self.columns["time_s"].size)


_NUMERIC = [c for c in SI_COLUMNS if c not in ("run_id", "protocol")]


def _logs():
    from motorid.io import logs

    return logs


# --------------------------------------------------------------------------- sources


def _head(path: Path, size: int = 1 << 16) -> tuple[bytes, bool]:
    """The first ``size`` bytes of the text (gunzipped) and whether the file is gzip."""
    with open(path, "rb") as fh:
        raw = fh.read(size)
    gz = raw[:2] == b"\x1f\x8b"
    if gz:
        try:
            with gzip.open(path, "rb") as fh:
                raw = fh.read(size)
        except (OSError, EOFError, zlib.error):
            return b"", True
    return raw, gz


def _csv_plan(path: Path):
    """(fields, delimiter, found, gzip) where pyarrow can stream ``path``, else None (read it whole)."""
    logs = _logs()
    try:
        head, gz = _head(path)
    except OSError:
        return None
    if not head or head[:2] in (b"\xff\xfe", b"\xfe\xff") or b"\x00" in head:
        return None  # the whole-file reader names what is wrong
    text = head.decode("utf-8-sig", errors="strict") if _is_utf8(head) else None
    if text is None or "\n" not in text:
        return None
    first = text.split("\n", 1)[0]
    if not first.strip() or first.lstrip().startswith("#") or '"' in first:
        return None
    fields, delim, _, header_line = logs._split_header(path, text)
    if header_line != 1:
        return None
    found, _extras = logs._map_columns(path, fields)  # a missing column: the usual message
    return fields, delim, found, gz


def _is_utf8(head: bytes) -> bool:
    try:
        head.decode("utf-8")
        return True
    except UnicodeDecodeError as exc:
        return exc.start > len(head) - 4  # a character cut at the end of the head


def _text(column) -> np.ndarray:
    """A pyarrow text column → numpy object array of stripped strings, one string per distinct value."""
    enc = column.dictionary_encode()
    values = np.array([("" if v is None else str(v).strip()) for v in enc.dictionary.to_pylist()] + [""],
                      dtype=object)
    codes = enc.indices.fill_null(len(values) - 1).to_numpy(zero_copy_only=False)
    return values[codes]


def _csv_blocks(path: Path, plan):
    """Blocks of a CSV as (column index → numpy array, bytes read so far)."""
    import pyarrow as pa
    import pyarrow.csv as pa_csv

    fields, delim, found, gz = plan
    logs = _logs()
    names = [f"c{j}" for j in range(len(fields))]
    text_cols = {found[k][0] for k in ("run_id", "protocol")}
    use = sorted({j for j, _ in found.values()})
    types = {names[j]: (pa.string() if j in text_cols else pa.float64()) for j in use}
    # a Python file, not pa.OSFile: Arrow's own file reads ahead into its pool (100 MB at 4 MiB blocks)
    raw = open(path, "rb")
    source = pa.CompressedInputStream(pa.PythonFile(raw, mode="r"), "gzip") if gz else raw
    try:
        reader = pa_csv.open_csv(
            source,
            read_options=pa_csv.ReadOptions(skip_rows=1, column_names=names, block_size=BLOCK_BYTES,
                                            use_threads=False),
            parse_options=pa_csv.ParseOptions(delimiter=delim),
            convert_options=pa_csv.ConvertOptions(column_types=types, include_columns=[names[j] for j in use],
                                                  null_values=logs._NA_STRINGS, strings_can_be_null=False,
                                                  quoted_strings_can_be_null=False))
        while True:
            try:
                batch = reader.read_next_batch()
            except StopIteration:
                break
            cols = {j: batch.column(names[j]) for j in use}
            yield ({j: (_text(c) if j in text_cols else c.to_numpy(zero_copy_only=False))
                    for j, c in cols.items()}, raw.tell())
    except (pa.ArrowInvalid, pa.ArrowTypeError, OSError) as exc:
        raise StreamFallback(f"{path}: {str(exc).splitlines()[0]}") from None
    finally:
        raw.close()


def _parquet_plan(path: Path):
    import pyarrow.parquet as pq

    logs = _logs()
    try:
        pf = pq.ParquetFile(str(path))
    except Exception:  # noqa: BLE001 — the whole-file reader says what is wrong, in one line
        return None
    fields = [str(n) for n in pf.schema_arrow.names]
    found, _extras = logs._map_columns(path, fields)
    return pf, fields, found


def _parquet_blocks(path: Path, plan):
    import pyarrow as pa

    pf, fields, found = plan
    text_cols = {found[k][0] for k in ("run_id", "protocol")}
    use = sorted({j for j, _ in found.values()})
    done, total = 0, max(pf.metadata.num_rows, 1)
    size = path.stat().st_size
    try:
        for batch in pf.iter_batches(batch_size=PARQUET_BATCH_ROWS, columns=[fields[j] for j in use]):
            out = {}
            for j in use:
                col = batch.column(fields[j])
                if j in text_cols:
                    out[j] = _text(col.cast(pa.string()))
                else:
                    out[j] = col.cast(pa.float64()).to_numpy(zero_copy_only=False)
            done += batch.num_rows
            yield out, int(size * done / total)
    except (pa.ArrowInvalid, pa.ArrowTypeError, pa.ArrowNotImplementedError, OSError) as exc:
        raise StreamFallback(f"{path}: {str(exc).splitlines()[0]}") from None


def _foreign_plan(path: Path, channels):
    """(fields, found, blocks) where ``path`` (HDF5, MATLAB v7.3, TDMS, MDF4) is read through its
    channel map in blocks of samples, else None (read it whole: no map, a table map, a format or a
    file whose channels are not vectors of one length; the whole-file reader then says what is wrong)."""
    from motorid.io import formats
    from motorid.io.channel_map import ChannelMap, load_channel_map

    cmap = channels if channels is not None else formats.find_channel_map(path)
    if cmap is None:
        return None
    cmap = cmap if isinstance(cmap, ChannelMap) else load_channel_map(cmap)
    if not cmap.is_log or cmap.grid_axes or formats.format_of(path, cmap) not in RANGE_FORMATS:
        return None
    try:
        source = formats.open_source(path, cmap, stream=True)
    except InputError:
        return None
    try:
        names = [ch.name for ch in cmap.channels.values() if ch.rate_Hz is None] + list(cmap.extra.values())
        sizes = {source.length(name) for name in names} if hasattr(source, "length") else {None}
    except (InputError, KeyError, ValueError, TypeError):
        sizes = {None}
    if len(sizes) != 1 or None in sizes or not next(iter(sizes)):
        if hasattr(source, "close"):
            source.close()
        return None
    n = next(iter(sizes))
    logs = _logs()
    label = str(path)
    first = cmap.apply(source, label, rows=(0, min(n, FOREIGN_BLOCK_ROWS)))
    fields = [str(c) for c in first.columns]
    found, _extras = logs._map_columns(path, fields)  # a missing column: the usual message
    text_cols = {found[k][0] for k in ("run_id", "protocol")}
    use = sorted({j for j, _ in found.values()})
    size = path.stat().st_size

    def blocks():
        frame, start = first, 0
        try:
            while True:
                out = {}
                for j in use:
                    col = frame[fields[j]]
                    out[j] = (col.astype(str).str.strip().to_numpy(dtype=object) if j in text_cols
                              else col.to_numpy(dtype=float))
                start += len(frame)
                yield out, int(size * start / n)
                if start >= n:
                    return
                frame = cmap.apply(source, label, rows=(start, min(n, start + FOREIGN_BLOCK_ROWS)))
        finally:
            if hasattr(source, "close"):
                source.close()

    # a map that names no run: runs cut by the time track, then by set point (io/set_points.py)
    return fields, found, blocks(), bool(getattr(cmap, "runs_cut_by_time", False))


# --------------------------------------------------------------------------- one block → SI


class _Invalid(Exception):
    pass


class _FileState:
    """What a file's stream carries from block to block."""

    def __init__(self, path: Path, fields, found, spec):
        self.path, self.fields, self.found, self.spec = path, fields, found, spec
        self.oil = getattr(spec, "oil", None)
        self.any_viscosity = False
        self.proto_norm: dict = {}
        self.seen: set = set()
        self.current = None  # (run_id, protocol, [column dicts])
        self.temp_carry = None  # (run, time, value) of the last oil temperature read (io/temperature_gaps.py)
        self.last_time = -np.inf


def _protocol(state: _FileState, value: str) -> str:
    logs = _logs()
    norm = state.proto_norm.get(value)
    if norm is None:
        norm = re.sub(r"[\s\-]+", "_", value.lower())
        if norm not in logs.PROTOCOLS:
            raise _Invalid(f"unknown protocol '{value}'")
        state.proto_norm[value] = norm
    return norm


def _to_si(state: _FileState, block: dict) -> tuple[dict, np.ndarray, np.ndarray]:
    """One block's columns → (SI columns, run ids, protocols), checked as read_log checks them."""
    logs = _logs()
    found = state.found
    run, proto = block[found["run_id"][0]], block[found["protocol"][0]]
    t_raw = np.asarray(block[found["time_s"][0]], dtype=float)
    blank = (run == "") & (proto == "") & np.isnan(t_raw)
    if blank.any():  # a line of delimiters only: skipped, as read_log skips it
        keep = ~blank
        block = {j: v[keep] for j, v in block.items()}
        run, proto = run[keep], proto[keep]
    if np.any(run == "") or np.any(proto == ""):
        raise _Invalid("empty run_id or protocol cell")
    out = {}
    kinematic = None
    for si in FORMAT_COLUMNS:
        if si not in found:
            out[si] = np.full(run.size, np.nan)
            continue
        j, unit = found[si]
        x = np.asarray(block[j], dtype=float)
        x = np.where(np.isinf(x), np.nan, x)
        if si == "viscosity_Pa_s" and np.any(x <= 0):
            raise _Invalid("viscosity must be > 0")
        conv = logs._BY_SI[si].units[unit]
        if isinstance(conv, tuple):
            kinematic = x * conv[1]
            x = np.full_like(x, np.nan)
        elif callable(conv):
            x = conv(x)
        else:
            x = x * conv
        out[si] = x
    if np.isnan(out["time_s"]).any():
        raise _Invalid("empty time cell")
    temp = out["oil_temp_C"]
    if np.any(temp < -273.15):
        raise _Invalid("temperature below absolute zero")
    if np.isnan(temp).any() or state.temp_carry is not None:  # read slower than the rest (io/temperature_gaps.py)
        from motorid.io.temperature_gaps import fill_temperature_gaps

        temp, state.temp_carry = fill_temperature_gaps(out["time_s"], temp, run, state.temp_carry)
        out["oil_temp_C"] = temp
    two_pi = 2.0 * np.pi
    theta = np.mod(out["theta_rad"], two_pi)
    out["theta_rad"] = np.where(theta >= two_pi, 0.0, theta)
    mu = out["viscosity_Pa_s"]
    assumed = False
    if kinematic is None:
        try:
            temp, assumed = logs.assumed_temperature(temp, mu, state.oil, str(state.path))
        except InputError:
            raise _Invalid("no oil temperature, no viscosity and no [oil] temp_C") from None
        if assumed:
            out["oil_temp_C"] = temp
    if kinematic is not None:
        if state.oil is None:
            raise _Invalid("kinematic viscosity without an [oil] density")
        mu = state.oil.dynamic_from_kinematic(kinematic, temp)
    gaps = np.isnan(mu)
    state.any_viscosity |= bool((~gaps).any())
    if gaps.any():
        if state.oil is None:
            if "viscosity_Pa_s" not in found:
                raise _Invalid("no viscosity and no [oil]")
        else:
            mu = np.where(gaps, logs._oil_viscosity(state.spec, np.where(gaps, temp, 40.0)), mu)
    out["viscosity_Pa_s"] = mu
    out[logs.VISCOSITY_FROM_OIL] = gaps
    out[logs.TEMPERATURE_ASSUMED] = np.full(gaps.size, assumed)
    return out, run, proto


def _runs_of_block(state: _FileState, cols: dict, run: np.ndarray, proto: np.ndarray):
    """Add a block to the run being gathered → the runs it completes, as (run_id, protocol, columns)."""
    starts = np.r_[0, np.flatnonzero(run[1:] != run[:-1]) + 1]
    ends = np.r_[starts[1:], run.size]
    done = []
    for a, b in zip(starts, ends):
        rid = run[a]
        protos = set(proto[a:b])
        norm = {_protocol(state, p) for p in protos}
        if len(norm) > 1:
            raise _Invalid(f"run '{rid}' has several protocols")
        piece = {c: v[a:b] for c, v in cols.items()}
        t = piece["time_s"]
        if state.current is not None and state.current[0] == rid:
            if state.current[1] != next(iter(norm)):
                raise _Invalid(f"run '{rid}' has several protocols")
            if t[0] <= state.last_time:
                raise _Invalid("time not increasing")
            state.current[2].append(piece)
        else:
            if state.current is not None:
                done.append(state.current)
            if rid in state.seen:
                raise StreamFallback(f"{state.path}: run '{rid}' comes back after another run "
                                     f"(runs interleaved): the log is read whole")
            state.seen.add(rid)
            state.current = (rid, next(iter(norm)), [piece])
        if np.any(np.diff(t) <= 0):
            raise _Invalid("time not increasing")
        state.last_time = t[-1]
    return done


def _join(parts: list) -> dict:
    return {c: (np.concatenate([p[c] for p in parts]) if len(parts) > 1 else parts[0][c]) for c in parts[0]}


# --------------------------------------------------------------------------- files → runs


def _whole_file_runs(path: Path, spec, channels):
    """A file the streaming readers do not take, read whole → its runs (run_id, protocol, columns)."""
    return _frame_runs(_logs().read_log(path, spec, channels), "run_id")


def runs_of_frame(frame: pd.DataFrame) -> Iterator[RunColumns]:
    """The runs of a frame read whole (:func:`motorid.io.logs.read_logs`), as the stream hands them on."""
    files = frame["file"].astype(str).to_numpy() if "file" in frame.columns else None
    for key, protocol, cols in _frame_runs(frame, "run" if "run" in frame.columns else "run_id", files):
        yield RunColumns(key, key, protocol, cols.pop("_file", ""), cols)


def _frame_runs(frame: pd.DataFrame, by: str, files=None):
    logs = _logs()
    codes, uniques = pd.factorize(frame[by])
    order = np.lexsort((frame["time_s"].to_numpy(dtype=float), codes))
    bounds = np.searchsorted(codes[order], np.arange(len(uniques) + 1))
    numeric = {c: frame[c].to_numpy(dtype=float) for c in _NUMERIC}
    flag = frame[logs.VISCOSITY_FROM_OIL].to_numpy(dtype=bool)
    protos = frame["protocol"].astype(str).to_numpy()
    del frame
    for r, rid in enumerate(uniques):
        pos = order[bounds[r]:bounds[r + 1]]
        cols = {c: v[pos] for c, v in numeric.items()}
        cols[logs.VISCOSITY_FROM_OIL] = flag[pos]
        if files is not None:
            cols["_file"] = str(files[pos[0]])
        yield str(rid), str(protos[pos[0]]), cols


def _file_runs(path: Path, spec, channels, advance) -> Iterator:
    """The runs of one file as (run_id, protocol, columns); ``advance(bytes)`` reports progress."""
    from motorid.io import formats

    size = path.stat().st_size
    fmt = formats.format_of(path)
    streamed = _foreign_plan(path, channels) if fmt in RANGE_FORMATS else None
    if streamed is None and channels is None and formats.find_channel_map(path) is None:
        if fmt == "csv" and not formats.needs_foreign_reader(path):
            plan = _csv_plan(path)
            if plan is not None:
                streamed = (plan[0], plan[2], _csv_blocks(path, plan))
        elif fmt == "parquet":
            plan = _parquet_plan(path)
            if plan is not None:
                streamed = (plan[1], plan[2], _parquet_blocks(path, plan))
    if streamed is None:
        yield from _whole_file_runs(path, spec, channels)
        advance(size)
        return
    fields, found, blocks, *cut = streamed
    if cut and cut[0]:
        from motorid.io.set_points import split_columns as pieces
    else:
        def pieces(rid, protocol, cols):
            yield rid, protocol, cols
    state = _FileState(path, fields, found, spec)
    told = 0
    try:
        for block, pos in blocks:
            cols, run, proto = _to_si(state, block)
            for rid, protocol, parts in _runs_of_block(state, cols, run, proto):
                yield from pieces(rid, protocol, _join(parts))
            advance(pos - told)
            told = pos
        if state.current is None:
            raise _Invalid("no data rows")
        if state.oil is None and not state.any_viscosity:
            raise _Invalid("no viscosity readings")
    except _Invalid as exc:
        raise StreamFallback(f"{path}: {exc}") from None
    rid, protocol, parts = state.current
    yield from pieces(rid, protocol, _join(parts))
    advance(size - told)


def stream_runs(paths, spec=None, channels=None, progress: bool | None = None) -> Iterator[RunColumns]:
    """The runs of a campaign (log files, or folders of them), one at a time, SI.

    paths : as :func:`motorid.io.logs.read_logs`; spec : the motor spec (its [oil]
    gives the viscosity where the log has none); channels : a channel map (its files
    are then read whole).  Raises :class:`StreamFallback` where the campaign must be
    read whole (see the module doc), :class:`~motorid.errors.InputError` for a missing
    column, a missing file or a file given twice.
    """
    from motorid.progress import bar

    logs = _logs()
    files = logs._log_paths(paths)
    resolved: dict = {}
    for p in files:
        key = p.resolve()
        if key in resolved:
            raise InputError(f"{p}: log given twice (also as {resolved[key]})")
        if not p.exists():
            raise InputError(f"{p}: cannot read log file (no such file)")
        if p.is_dir():
            raise InputError(f"{p}: is a directory, not a log file")
        resolved[key] = p
    names = [p.name for p in files]
    labels = names if len(set(names)) == len(names) else [str(p) for p in files]
    total = sum(p.stat().st_size for p in files)
    owners: set = set()
    with bar(total=total, desc="reading", unit="B", progress=progress) as pbar:
        for k, p in enumerate(files):
            seen_here: set = set()
            for rid, protocol, cols in _file_runs(p, spec, channels, pbar.update):
                key = f"{labels[k]}:{rid}" if rid in owners else rid
                seen_here.add(rid)
                yield RunColumns(key, rid, protocol, str(p), cols)
            owners |= seen_here


def read_streamed(paths, spec=None, channels=None) -> pd.DataFrame:
    """The runs of :func:`stream_runs` joined into one SI frame (for checks: the fit never builds it)."""
    logs = _logs()
    runs = list(stream_runs(paths, spec, channels, progress=False))
    parts = []
    for r in runs:
        part = pd.DataFrame(r.columns)
        part["run_id"], part["protocol"], part["file"], part["run"] = r.run_id, r.protocol, r.file, r.key
        parts.append(part)
    frame = pd.concat(parts, ignore_index=True)
    return frame[list(SI_COLUMNS) + [logs.VISCOSITY_FROM_OIL, "file", "run"]]


# --------------------------------------------------------------------------- how big


def estimate_rows(paths) -> int:
    """About how many rows the logs hold, without reading them: Parquet from its metadata,
    text from its size and the bytes per line of its first 64 KiB (gzip: times the
    compression ratio of its first 1 MiB), other formats at 100 bytes a row."""
    logs = _logs()
    total = 0
    for p in logs._log_paths(paths):
        try:
            size = p.stat().st_size
            if p.suffix.lower() in (".parquet", ".pq"):
                import pyarrow.parquet as pq

                total += pq.ParquetFile(str(p)).metadata.num_rows
                continue
            with open(p, "rb") as fh:
                start = fh.read(1 << 20)
            if start[:2] == b"\x1f\x8b":
                d = zlib.decompressobj(16 + zlib.MAX_WBITS)
                text = d.decompress(start, 1 << 24)
                consumed = len(start) - len(d.unconsumed_tail) - len(d.unused_data)
                size = size * len(text) / max(consumed, 1)
                start = text
            head = start[: 1 << 16]
            lines = head.count(b"\n")
            total += int(size / (len(head) / lines)) if lines and b"\x00" not in head else int(size / 100)
        except (OSError, zlib.error, ValueError):
            continue
        except Exception:  # noqa: BLE001 — an unreadable file: the reader says why
            continue
    return total
