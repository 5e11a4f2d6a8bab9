"""The motor spec TOML (BENCH_LOG_FORMAT.md) → :class:`motorid.model.MotorSpec`.

Units are converted to SI here, at the edge; every bad value raises
:class:`motorid.errors.InputError` naming the file and key.
"""

from __future__ import annotations

import math
from pathlib import Path

from motorid.errors import InputError
from motorid.io.tomlfile import read_toml, toml_number
from motorid.model import MotorSpec, OilSpec


def parse_motor_spec(data: dict, source: str = "motor spec") -> MotorSpec:
    """Build a :class:`MotorSpec` from a parsed TOML mapping, validating every value."""
    if "motor" not in data or not isinstance(data["motor"], dict):
        raise InputError(f"{source}: missing table [motor]")
    m = data["motor"]
    where = f"{source} [motor]"
    pistons = toml_number(m, "pistons", where, low=2, low_open=False, high=100, integer=True)
    displacement_cm3 = toml_number(m, "displacement_cm3", where, low=0.0, high=1e6)
    inertia = toml_number(m, "inertia_kg_m2", where, required=False, default=0.0, low=0.0,
                      low_open=False, high=1e4)
    phase_deg = toml_number(m, "leak_phase_deg", where, required=False, default=None,
                        low=-360.0, low_open=False, high=360.0)
    harmonics = toml_number(m, "leak_harmonics", where, required=False, default=1, low=0,
                        low_open=False, high=10, integer=True)
    name = m.get("name", Path(source).stem)
    if not isinstance(name, str):
        raise InputError(f"{where}: key 'name' must be a string, got {name!r}")
    oil = None
    if "oil" in data:
        o = data["oil"]
        if not isinstance(o, dict):
            raise InputError(f"{source}: [oil] must be a table")
        ow = f"{source} [oil]"
        nu40 = toml_number(o, "nu40_cSt", ow, low=0.0, high=1e5)
        nu100 = toml_number(o, "nu100_cSt", ow, low=0.0, high=1e5)
        if nu100 >= nu40:
            raise InputError(f"{ow}: key 'nu100_cSt' ({nu100}) must be below 'nu40_cSt' ({nu40})")
        rho = toml_number(o, "density15_kg_m3", ow, low=100.0, high=5000.0)
        beta = toml_number(o, "expansion_per_K", ow, required=False, default=6.5e-4, low=0.0,
                       low_open=False, high=0.01)
        oname = o.get("name", "oil")
        temp = toml_number(o, "temp_C", ow, required=False, default=None, low=-273.15, high=1000.0)
        oil = OilSpec(str(oname), float(nu40), float(nu100), float(rho), float(beta),
                      None if temp is None else float(temp))
    return MotorSpec(
        name=name,
        pistons=int(pistons),
        displacement=float(displacement_cm3) * 1e-6,
        inertia=float(inertia),
        leak_phase=None if phase_deg is None else math.radians(phase_deg),
        leak_harmonics=int(harmonics),
        oil=oil,
    )


def load_motor_spec(path) -> MotorSpec:
    """Read and validate a motor spec TOML file."""
    return parse_motor_spec(read_toml(path, "motor spec"), str(Path(path)))


def parse_stored_spec(text: str, where: str) -> MotorSpec:
    """The motor spec a result.json keeps as TOML text (``motor_spec``, written by a table fit);
    ``where`` names it in errors (one line)."""
    import tomllib

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{where}: not valid TOML ({exc})") from None
    return parse_motor_spec(data, where)
