"""A size cap on motorid's compile cache (``$MOTORID_CACHE_DIR``, default ``~/.cache/motorid/jax``).

Both caches there grow with every new shape of data: JAX's persistent compile cache keeps one
file per program and argument shape (eager operations on a campaign's own row counts included),
and :mod:`motorid._aot` one serialized executable per program, static arguments and padded
shape.  A fleet of campaigns of many sizes, re-tested over years, would fill a disk.  Once a day
(a marker file's age says when it last looked) the folder is measured, and where it holds more
than ``MOTORID_CACHE_MAX_MB`` (default :data:`DEFAULT_MAX_MB`) the files used longest ago are
deleted until it holds 80 % of that.  "Used" is a file's modification time: JAX's files carry
the time they were written, motorid's executables the time they were last loaded (:mod:`motorid._aot`
touches a file it loads).  A deleted program is compiled again when next needed, nothing else.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

#: the cap where ``MOTORID_CACHE_MAX_MB`` is not set [MiB]
DEFAULT_MAX_MB = 2048
#: after pruning, the folder holds this share of the cap
PRUNE_TO = 0.8
#: the folder is measured at most this often [s]
CHECK_EVERY_S = 86400.0
MARKER = ".motorid-size-checked"


def max_bytes() -> int | None:
    """The cap in bytes from ``MOTORID_CACHE_MAX_MB`` (0 or below: no cap → None); the default
    where it is unset or not a number (a cache setting never stops a run)."""
    value = os.environ.get("MOTORID_CACHE_MAX_MB", "").strip()
    try:
        mb = float(value) if value else DEFAULT_MAX_MB
    except ValueError:
        mb = DEFAULT_MAX_MB
    return int(mb * 2**20) if mb > 0 else None


def _files(root: Path) -> list:
    """(mtime, size, path) of every file under ``root`` but the marker."""
    out = []
    for folder, _, names in os.walk(root):
        for name in names:
            if name == MARKER:
                continue
            path = os.path.join(folder, name)
            try:
                st = os.stat(path)
            except OSError:
                continue
            out.append((st.st_mtime, st.st_size, path))
    return out


def prune(root, cap: int, keep: float = PRUNE_TO) -> int:
    """Delete the files under ``root`` used longest ago (oldest modification time first) while it
    holds more than ``cap`` bytes, down to ``keep`` × ``cap`` → bytes deleted.  Folders emptied
    on the way are removed; a file that cannot be deleted is passed over."""
    root = Path(root)
    files = _files(root)
    total = sum(size for _, size, _ in files)
    if total <= cap:
        return 0
    target, freed = keep * cap, 0
    for _, size, path in sorted(files):
        if total - freed <= target:
            break
        try:
            os.unlink(path)
        except OSError:
            continue
        freed += size
    for folder, dirs, names in os.walk(root, topdown=False):
        if Path(folder) != root and not dirs and not names:
            try:
                os.rmdir(folder)
            except OSError:
                pass
    return freed


def prune_now_and_then(root, now: float | None = None) -> int:
    """:func:`prune` ``root`` to :func:`max_bytes`, at most once per :data:`CHECK_EVERY_S` (the
    marker file's age) → bytes deleted.  Any error of the file system: nothing done."""
    cap = max_bytes()
    if cap is None:
        return 0
    marker = Path(root) / MARKER
    now = time.time() if now is None else now
    try:
        if marker.exists() and now - marker.stat().st_mtime < CHECK_EVERY_S:
            return 0
        marker.touch()
        os.utime(marker, (now, now))
        return prune(root, cap)
    except OSError:
        return 0
