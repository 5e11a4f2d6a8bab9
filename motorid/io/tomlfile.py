"""TOML files at the edge: read one, and validate the numbers in its tables.

Every failure is an :class:`motorid.errors.InputError` naming the file (and the
table and key), for the motor spec, the bench protocols, truths and sensors.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

from motorid.errors import InputError


def read_toml(path, what: str) -> dict:
    """Parse a TOML file; unreadable or invalid files raise :class:`InputError` naming it."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise InputError(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML ({exc})") from None


def toml_number(table: dict, key: str, where: str, *, required=True, default=None, low=None,
                low_open=True, high=None, integer=False):
    """``table[key]`` checked: a finite number (an integer if ``integer``), within (low, high];
    ``low_open=False`` makes the lower bound inclusive.  Missing and ``required``, or wrong:
    :class:`InputError` naming ``where`` and the key."""
    if key not in table:
        if required:
            raise InputError(f"{where}: missing key '{key}'")
        return default
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{where}: key '{key}' must be a number, got {value!r}")
    if integer and (not isinstance(value, int)):
        raise InputError(f"{where}: key '{key}' must be an integer, got {value!r}")
    if not math.isfinite(value):
        raise InputError(f"{where}: key '{key}' must be finite, got {value!r}")
    if low is not None and (value <= low if low_open else value < low):
        op = ">" if low_open else ">="
        raise InputError(f"{where}: key '{key}' must be {op} {low}, got {value!r}")
    if high is not None and value > high:
        raise InputError(f"{where}: key '{key}' must be <= {high}, got {value!r}")
    return value
