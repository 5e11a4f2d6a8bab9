"""A size cap on motorid's compile cache (``$MOTORID_CACHE_DIR``, default ``~/.cache/motorid/jax``).

Both caches there grow with every new shape of data: JAX's persistent compile cache keeps one
file per program and argument shape (eager operations on a campaign's own row counts included),
and :mod:`motorid._aot` one serialized executable per program, static arguments and padded
shape.  A fleet of campaigns of many sizes, re-tested over years, would fill a disk.  Once a day
(a marker file's age says when it last looked) the folder is measured, and where it holds more
than ``MOTORID_CACHE_MAX_MB`` (default :data:`DEFAULT_MAX_MB`) the cache entries used longest
ago are deleted until they hold 80 % of that (JAX's ``*-cache`` and ``*-atime`` files and
motorid's ``aot/<version>/*.bin``; any other file in the folder is left alone).  "Used" is a file's modification time: JAX's files carry
the time they were written (an entry read on every run is not kept longer for that), motorid's
executables the time they were last loaded (:mod:`motorid._aot` touches a file it loads).  A deleted program is compiled again when next needed, nothing else.
"""

from __future__ import annotations

import math
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
    if not math.isfinite(mb):  # "inf": no cap; "nan": the default
        return None if mb > 0 else DEFAULT_MAX_MB * 2**20
    return int(mb * 2**20) if mb > 0 else None


def _ours(root: Path, folder: str, name: str) -> bool:
    """Whether a file is a cache entry: JAX's (``*-cache``, ``*-atime`` in the folder itself) or
    motorid's (``aot/<version>/*.bin``).  Anything else is left alone, should the variable point
    at a folder that holds other files too."""
    where = Path(folder)
    if where == root:
        return name.endswith(("-cache", "-atime"))
    return name.endswith(".bin") and where.parent == root / "aot"


def _entries(root: Path) -> list:
    """(mtime, size, paths) of every cache entry under ``root`` (:func:`_ours`): a JAX entry's
    ``-cache`` and ``-atime`` files are one (deleted together: JAX's own eviction fails on a
    ``-cache`` without its ``-atime``), with the later time and the two sizes."""
    grouped: dict = {}
    for folder, _, names in os.walk(root):
        for name in names:
            if not _ours(root, folder, name):
                continue
            path = os.path.join(folder, name)
            try:
                st = os.stat(path)
            except OSError:
                continue
            key = path.removesuffix("-cache").removesuffix("-atime") if Path(folder) == root else path
            t, size, paths = grouped.get(key, (-math.inf, 0, []))
            grouped[key] = (max(t, st.st_mtime), size + st.st_size, paths + [path])
    return list(grouped.values())


def prune(root, cap: int, keep: float = PRUNE_TO) -> int:
    """Delete the cache entries under ``root`` used longest ago (oldest modification time first)
    while they hold more than ``cap`` bytes, down to ``keep`` × ``cap`` → bytes deleted.  Version
    folders of :mod:`motorid._aot` emptied on the way are removed; a file that cannot be deleted is
    passed over; no other file is touched (:func:`_ours`)."""
    root = Path(root)
    entries = _entries(root)
    total = sum(size for _, size, _ in entries)
    if total <= cap:
        return 0
    target, freed = keep * cap, 0
    for _, size, paths in sorted(entries, key=lambda e: e[0]):
        if total - freed <= target:
            break
        gone = True
        for path in paths:
            try:
                os.unlink(path)
            except FileNotFoundError:  # another process pruning at once took it: freed all the same
                pass
            except OSError:
                gone = False
        if gone:
            freed += size
    aot = root / "aot"
    for folder in (aot.iterdir() if aot.is_dir() else ()):  # a version folder emptied on the way
        try:
            if folder.is_dir() and not any(folder.iterdir()):
                folder.rmdir()
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
