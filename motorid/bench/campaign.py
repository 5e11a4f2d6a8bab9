"""Write a simulated campaign to a folder: the log, its truth, spec, protocols, a manifest.

    DIR/campaign.csv.gz    the bench log (BENCH_LOG_FORMAT.md), all runs
    DIR/truth.toml         copy of the truth file
    DIR/motor.toml         copy of the motor spec
    DIR/protocols/*.toml   copies of the protocols
    DIR/manifest.json      seed, versions, files, and each run's set point

Every file is written whole or not at all (temporary file, then rename); an
existing log is replaced only when asked (``force``).
"""

from __future__ import annotations

import json
from pathlib import Path

from motorid._version import __version__
from motorid._atomic import write_bytes_atomic
from motorid.bench.simulate import Campaign, protocol_names
from motorid.errors import InputError
from motorid.io.logs import write_log

LOG_NAME = "campaign.csv.gz"


def _write_bytes(path: Path, data: bytes) -> None:
    write_bytes_atomic(path, data)


def _copy(src, dst: Path) -> Path:
    src = Path(src)
    if dst.exists() and src.resolve() == dst.resolve():
        return dst
    try:
        data = src.read_bytes()
    except OSError as exc:
        raise InputError(f"{src}: cannot read ({exc.strerror or exc})") from None
    _write_bytes(dst, data)
    return dst


def write_campaign(campaign: Campaign, out_dir, protocols, motor_path, truth_path, *,
                   full_precision: bool = False, force: bool = False, command: str = "") -> dict:
    """Write ``campaign`` into ``out_dir`` (see the module docstring).

    protocols : the :class:`~motorid.bench.protocols.Protocol` objects simulated
    (their ``source`` files are copied); motor_path, truth_path : the input files.
    full_precision : write 17 significant digits (exact round trip) instead of
    the format's usual digits.  Returns the written paths by role.
    """
    out = Path(out_dir)
    log = out / LOG_NAME
    if log.exists() and not force:
        raise InputError(f"{log} exists; pass --force to replace it")
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: not a folder")
    paths = {"log": write_log(campaign.frame, log, full_precision=full_precision),
             "truth": _copy(truth_path, out / "truth.toml"),
             "motor": _copy(motor_path, out / "motor.toml")}
    names = protocol_names(protocols)
    paths["protocols"] = [_copy(p.source, out / "protocols" / f"{name}.toml") for p, name in zip(protocols, names)]
    manifest = {
        "generator": "motorid simulate",
        "motorid_version": __version__,
        "command": command,
        "seed": campaign.seed,
        "rows": int(len(campaign.frame)),
        "files": {"log": LOG_NAME, "truth": "truth.toml", "motor": "motor.toml",
                  "protocols": [f"protocols/{n}.toml" for n in names]},
        "protocols": [{"name": n, "procedure": p.procedure, "standard": p.standard, "runs": len(p.runs)}
                      for p, n in zip(protocols, names)],
        "runs": [{"run_id": r.run_id, "procedure": r.procedure, "rows": r.rows, **r.plan.describe()}
                 for r in campaign.runs],
        "warnings": list(campaign.warnings),
    }
    paths["manifest"] = out / "manifest.json"
    _write_bytes(paths["manifest"], (json.dumps(manifest, indent=1, ensure_ascii=False) + "\n").encode())
    return paths
