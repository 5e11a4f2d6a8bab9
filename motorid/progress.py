"""Progress bars on stderr (tqdm) for the steps that can take more than a few seconds.

One rule for every step (reading, extraction, candidates, emcee, fleet): a bar is shown
only where stderr is a terminal, never under ``--quiet`` (:func:`set_quiet`) or with the
environment variable ``MOTORID_QUIET`` set to anything but "" or "0".  A caller's explicit
``progress=True/False`` wins over both.
"""

from __future__ import annotations

import os
import sys

_quiet = False


def set_quiet(quiet: bool) -> None:
    """Silence (or allow) every progress bar of this process (the CLI's ``--quiet``)."""
    global _quiet
    _quiet = bool(quiet)


def enabled(progress: bool | None = None) -> bool:
    """Whether a bar is shown: ``progress`` if given, else a terminal and not quiet."""
    if progress is not None:
        return bool(progress)
    if _quiet or os.environ.get("MOTORID_QUIET", "") not in ("", "0"):
        return False
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # a closed or replaced stderr
        return False


def bar(iterable=None, *, total=None, desc: str = "", unit: str = "it", progress: bool | None = None):
    """A tqdm bar on stderr over ``iterable`` (or updated by hand up to ``total``); a silent
    pass-through where :func:`enabled` says no."""
    from tqdm import tqdm

    return tqdm(iterable, total=total, desc=desc, unit=unit, disable=not enabled(progress), file=sys.stderr,
                leave=False, dynamic_ncols=True)
