"""Checks of command-line arguments shared by the commands (each a one-line InputError)."""

from __future__ import annotations

from pathlib import Path

from motorid.errors import InputError


def add_campaign_arguments(p, logs_help: str = "bench log CSV or CSV.gz files") -> None:
    """The arguments of a command that reads a campaign: the logs and ``--motor``."""
    p.add_argument("logs", nargs="+", help=logs_help)
    p.add_argument("--motor", required=True, help="motor spec TOML")
    p.add_argument("--channels", default=None, help="channel map TOML for DAQ files (docs/formats.md)")


def check_output(out: Path, force: bool, files=("result.json",)):
    """Refuse to overwrite ``files`` in ``out`` without ``--force``, or an ``--out`` that is not a folder."""
    for name in files:
        if (out / name).exists() and not force:
            raise InputError(f"{out / name} exists; use --force to overwrite it")
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a folder")


def check_logs_exist(logs) -> None:
    """Every bench log named on the command line exists."""
    for log in logs:
        if not Path(log).exists():
            raise InputError(f"{log}: no such file")
