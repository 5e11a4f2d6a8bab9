"""Simulated campaign folders for fleet studies and tests (the bench simulator, nothing else).

:func:`write_simulated_campaign` writes one campaign folder as
BENCH_LOG_FORMAT.md gives it (``campaign.csv.gz``, ``motor.toml``,
``campaign.toml``, and ``truth.toml`` for reference) from true parameters;
:func:`small_protocols` thins the repository's protocols to every n-th run so
that a fleet of campaigns simulates and fits in seconds.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
from pathlib import Path

from motorid._atomic import write_bytes_atomic
from motorid.fleet.campaigns import write_campaign_file

PROCEDURES = ("constant_speed", "constant_pressure", "startability")


def small_protocols(protocol_dir, every: int = 3, procedures=PROCEDURES) -> list:
    """The protocols ``protocol_dir/*_<procedure>.toml`` with every ``every``-th run kept."""
    from motorid.bench.protocols import load_protocol

    files = {p.stem.split("_", 1)[1]: p for p in Path(protocol_dir).glob("*.toml")}
    out = []
    for name in procedures:
        prot = load_protocol(files[name])
        out.append(dataclasses.replace(prot, runs=prot.runs[::every]))
    return out


def write_simulated_campaign(folder, params: dict, protocols, spec, serial: str, date: _dt.date, seed: int,
                             bench: str | None = None, motor_type: str | None = None) -> Path:
    """Simulate ``protocols`` on a motor with the true ``params`` (names as in result.json, SI)
    and write the campaign folder; returns it."""
    from motorid.bench.simulate import simulate_campaign
    from motorid.bench.truth import parse_truth
    from motorid.io.logs import write_log

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    truth = parse_truth({"parameters": dict(params)}, f"{folder} truth")
    camp = simulate_campaign(protocols, spec, truth, seed=seed)
    write_log(camp.frame, folder / "campaign.csv.gz")
    write_bytes_atomic(folder / "motor.toml", spec.to_toml().encode())
    truth_text = "[parameters]\n" + "".join(f"{k} = {float(v)!r}\n" for k, v in params.items())
    write_bytes_atomic(folder / "truth.toml", truth_text.encode())
    write_campaign_file(folder, serial, date, bench=bench, motor_type=motor_type)
    return folder
