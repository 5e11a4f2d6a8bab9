"""``motorid simulate``: run ISO 4392 protocols on the model and write a campaign."""

from __future__ import annotations

import dataclasses
import shlex
import sys
import time
from pathlib import Path

from motorid.errors import InputError


def protocol_paths(args: list) -> list[Path]:
    """Protocol files from the command line; a folder stands for its ``*.toml``, sorted."""
    out = []
    for item in args:
        path = Path(item)
        if path.is_dir():
            found = sorted(path.glob("*.toml"))
            if not found:
                raise InputError(f"{path}: no protocol .toml files in this folder")
            out += found
        else:
            out.append(path)
    return out


def _command_line(args) -> str:
    """The command, rebuilt from the parsed arguments, for the manifest."""
    words = ["motorid", "simulate"]
    for group in args.protocol:
        words += ["--protocol", *group]
    words += ["--motor", args.motor, "--truth", args.truth, "--out", args.out, "--seed", str(args.seed)]
    if args.sensors:
        words += ["--sensors", args.sensors]
    words += [f"--{flag.replace('_', '-')}" for flag in ("ideal_sensors", "omit_viscosity", "full_precision")
              if getattr(args, flag)]
    return " ".join(shlex.quote(w) for w in words)


def run(args) -> int:
    from motorid.bench.campaign import write_campaign
    from motorid.bench.protocols import load_protocol, read_toml
    from motorid.bench.sensors import parse_sensors
    from motorid.bench.simulate import simulate_campaign
    from motorid.bench.truth import load_truth
    from motorid.io.spec import load_motor_spec

    if args.seed < 0:
        raise InputError(f"--seed must be a non-negative integer, got {args.seed}")
    spec = load_motor_spec(args.motor)
    truth = load_truth(args.truth)
    protocols = [load_protocol(p) for p in protocol_paths([p for group in args.protocol for p in group])]
    if args.sensors:
        table = read_toml(args.sensors, "sensors table")
        unknown = [k for k in table if k != "sensors"]
        if unknown or "sensors" not in table:
            raise InputError(f"{args.sensors}: expected one table [sensors] (and its [sensors.<column>] tables)")
        protocols = [dataclasses.replace(p, sensors=parse_sensors(table["sensors"], args.sensors, p.sensors))
                     for p in protocols]
    start = time.perf_counter()
    campaign = simulate_campaign(protocols, spec, truth, args.seed, ideal_sensors=args.ideal_sensors,
                                 omit_viscosity=args.omit_viscosity)
    elapsed = time.perf_counter() - start
    command = _command_line(args)
    paths = write_campaign(campaign, args.out, protocols, args.motor, args.truth,
                           full_precision=args.full_precision, force=args.force, command=command)
    for w in campaign.warnings:
        print(f"motorid simulate: warning: {w}", file=sys.stderr)
    print(f"simulated {len(campaign.runs)} runs from {len(protocols)} protocols, {len(campaign.frame)} rows, "
          f"in {elapsed:.1f} s")
    print(f"wrote {paths['log']}, {paths['truth'].name}, {paths['motor'].name}, "
          f"{len(paths['protocols'])} protocols, {paths['manifest'].name}")
    return 0


def register(sub):
    p = sub.add_parser("simulate", help="run ISO 4392 protocols on the model: a synthetic bench campaign",
                       description="Simulate ISO 4392 bench runs of a motor with known true parameters and "
                                   "write the campaign log (BENCH_LOG_FORMAT.md) with its truth and spec.")
    p.add_argument("--protocol", action="append", nargs="+", required=True, metavar="P.toml",
                   help="protocol file(s); repeat or list several; a folder means all its *.toml")
    p.add_argument("--motor", required=True, metavar="SPEC.toml", help="motor spec (with its [oil])")
    p.add_argument("--truth", required=True, metavar="TRUTH.toml", help="true parameters ([parameters], "
                   "optional [mechanisms.<id>])")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0): same seed, same bytes")
    p.add_argument("--sensors", metavar="SENSORS.toml",
                   help="a [sensors] table applied on top of every protocol's sensors")
    p.add_argument("--ideal-sensors", action="store_true",
                   help="log true values: no sensor noise, quantization or offsets")
    p.add_argument("--omit-viscosity", action="store_true",
                   help="leave the optional viscosity_mPas column out (readers derive it from temperature)")
    p.add_argument("--full-precision", action="store_true", help="write 17 significant digits")
    p.add_argument("--force", action="store_true", help="replace an existing campaign in --out")
    p.set_defaults(func=run)
