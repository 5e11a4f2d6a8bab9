"""Campaign folders (BENCH_LOG_FORMAT.md, "Campaign folders and fleets") and their input hashes.

A campaign is one folder: its logs (every ``*.csv`` / ``*.csv.gz`` at its top
level), its ``motor.toml`` and a ``campaign.toml``::

    [campaign]
    serial = "SN-1042"          # the motor's serial number
    date = 2026-03-14           # the test date (TOML date)
    bench = "bench-2"           # optional
    motor_type = "A2FM-80"      # optional; default: [motor] name of motor.toml

The campaign's *key* is a SHA-256 over the hashes of every input file, the
motorid version and the fit options: a fleet re-run skips a campaign whose
stored result carries the same key.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

from motorid.errors import InputError

CAMPAIGN_FILE = "campaign.toml"
MOTOR_FILE = "motor.toml"
#: file names the log reader takes (motorid.io.logs reads a folder's *.csv and *.csv.gz)
LOG_SUFFIXES = (".csv", ".csv.gz")
_KEYS = ("serial", "date", "bench", "motor_type")


@dataclass(frozen=True)
class Campaign:
    """One campaign folder, read and checked (no log is parsed here)."""

    folder: str  # absolute path of the folder
    name: str  # the folder's name: the campaign's name in the fleet
    serial: str
    date: _dt.date
    bench: str | None
    motor_type: str
    logs: tuple  # absolute paths of the log files, sorted
    motor: str  # absolute path of motor.toml
    hashes: dict = field(default_factory=dict)  # file name relative to the folder -> sha256


def file_sha256(path) -> str:
    """SHA-256 of a file's bytes (hex), read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def log_files(folder: Path) -> list[Path]:
    """The campaign's logs: every top-level file whose name ends in one of LOG_SUFFIXES."""
    return sorted(p for p in folder.iterdir() if p.is_file() and p.name.endswith(LOG_SUFFIXES))


def _text(table: dict, key: str, where: str, required: bool) -> str | None:
    v = table.get(key)
    if v is None:
        if required:
            raise InputError(f"{where}: [campaign] needs '{key}'")
        return None
    if not isinstance(v, str) or not v.strip():
        raise InputError(f"{where}: [campaign] {key} must be a non-empty string, got {v!r}")
    return v.strip()


def read_campaign(folder) -> Campaign:
    """Read and check one campaign folder; :class:`InputError` names what is wrong."""
    from motorid.io.spec import load_motor_spec
    from motorid.io.tomlfile import read_toml

    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a campaign folder (no such folder)")
    folder = folder.resolve()
    ct, mt = folder / CAMPAIGN_FILE, folder / MOTOR_FILE
    for p in (ct, mt):
        if not p.is_file():
            raise InputError(f"{folder}: campaign folder has no {p.name}")
    data = read_toml(ct, "campaign file")
    table = data.get("campaign")
    if not isinstance(table, dict):
        raise InputError(f"{ct}: needs a [campaign] table")
    unknown = [k for k in table if k not in _KEYS]
    if unknown:
        raise InputError(f"{ct}: [campaign] unknown key '{unknown[0]}' (expected one of: {', '.join(_KEYS)})")
    date = table.get("date")
    if isinstance(date, _dt.datetime):
        date = date.date()
    if not isinstance(date, _dt.date):
        raise InputError(f"{ct}: [campaign] date must be a TOML date such as 2026-03-14, got {date!r}")
    serial = _text(table, "serial", str(ct), True)
    bench = _text(table, "bench", str(ct), False)
    motor_type = _text(table, "motor_type", str(ct), False) or load_motor_spec(mt).name
    logs = log_files(folder)
    if not logs:
        raise InputError(f"{folder}: campaign folder holds no log ({' or '.join('*' + s for s in LOG_SUFFIXES)})")
    hashes = {p.name: file_sha256(p) for p in [ct, mt, *logs]}
    return Campaign(str(folder), folder.name, serial, date, bench, motor_type,
                    tuple(str(p) for p in logs), str(mt), hashes)


def campaign_key(campaign: Campaign, options: dict, version: str) -> str:
    """SHA-256 of (input file hashes, motorid version, fit options): equal keys, equal results."""
    blob = json.dumps({"inputs": campaign.hashes, "motorid": version, "options": options},
                      sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()


def write_campaign_file(folder, serial: str, date: _dt.date, bench: str | None = None,
                        motor_type: str | None = None) -> Path:
    """Write ``folder/campaign.toml`` (whole or not at all)."""
    from motorid._atomic import write_bytes_atomic

    lines = ["[campaign]", f"serial = {json.dumps(serial)}", f"date = {date.isoformat()}"]
    if bench:
        lines.append(f"bench = {json.dumps(bench)}")
    if motor_type:
        lines.append(f"motor_type = {json.dumps(motor_type)}")
    return write_bytes_atomic(Path(folder) / CAMPAIGN_FILE, ("\n".join(lines) + "\n").encode())
