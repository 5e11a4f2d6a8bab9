"""The motor spec: what is known about the motor and its oil (not fitted).

Read from the TOML of BENCH_LOG_FORMAT.md.  Units are converted to SI here, at
the edge; every bad value raises :class:`motorid.errors.InputError` naming the
file and key.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, asdict
from pathlib import Path

from motorid.errors import InputError


@dataclass(frozen=True)
class OilSpec:
    """The oil: Walther viscosity through two points and density at 15 °C."""

    name: str = "ISO VG 46 mineral oil"
    nu40_cSt: float = 46.0
    nu100_cSt: float = 6.8
    density15_kg_m3: float = 875.0
    expansion_per_K: float = 6.5e-4
    temp_C: float | None = None  # oil temperature where an operating-point table gives none [°C]

    def viscosity(self, temperature_C):
        """Dynamic viscosity μ at ``temperature_C`` [°C] → [Pa·s]."""
        from motorid.physics.oil import dynamic_viscosity

        return dynamic_viscosity(
            temperature_C, self.nu40_cSt, self.nu100_cSt, self.density15_kg_m3, self.expansion_per_K
        )


@dataclass(frozen=True)
class MotorSpec:
    """Known motor data, SI.

    pistons : n [-]; displacement : D [m³/rev]; inertia : J [kg·m²];
    leak_phase : φ of K_LB(θ) = K_LA(θ − φ) [rad], default π/n (MODEL.md);
    leak_harmonics : M, the order of the K_L(θ) Fourier series [-].
    """

    name: str
    pistons: int
    displacement: float
    inertia: float = 0.0
    leak_phase: float | None = None
    leak_harmonics: int = 1
    oil: OilSpec | None = field(default_factory=OilSpec)

    @property
    def phase(self) -> float:
        return math.pi / self.pistons if self.leak_phase is None else self.leak_phase

    @property
    def displacement_cm3(self) -> float:
        return self.displacement * 1e6

    def to_toml(self) -> str:
        lines = [
            "[motor]",
            f'name = "{self.name}"',
            f"pistons = {self.pistons}",
            f"displacement_cm3 = {self.displacement * 1e6!r}",
            f"inertia_kg_m2 = {self.inertia!r}",
        ]
        if self.leak_phase is not None:
            lines.append(f"leak_phase_deg = {math.degrees(self.leak_phase)!r}")
        if self.leak_harmonics != 1:
            lines.append(f"leak_harmonics = {self.leak_harmonics}")
        if self.oil is not None:
            o = self.oil
            lines += [
                "",
                "[oil]",
                f'name = "{o.name}"',
                f"nu40_cSt = {o.nu40_cSt!r}",
                f"nu100_cSt = {o.nu100_cSt!r}",
                f"density15_kg_m3 = {o.density15_kg_m3!r}",
            ]
            if o.expansion_per_K != OilSpec.expansion_per_K:
                lines.append(f"expansion_per_K = {o.expansion_per_K!r}")
            if o.temp_C is not None:
                lines.append(f"temp_C = {o.temp_C!r}")
        return "\n".join(lines) + "\n"

    def as_dict(self) -> dict:
        return asdict(self)


def _number(table: dict, key: str, where: str, *, required=True, default=None, low=None,
            low_open=True, high=None, integer=False):
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


def parse_motor_spec(data: dict, source: str = "motor spec") -> MotorSpec:
    """Build a :class:`MotorSpec` from a parsed TOML mapping, validating every value."""
    if "motor" not in data or not isinstance(data["motor"], dict):
        raise InputError(f"{source}: missing table [motor]")
    m = data["motor"]
    where = f"{source} [motor]"
    pistons = _number(m, "pistons", where, low=2, low_open=False, high=100, integer=True)
    displacement_cm3 = _number(m, "displacement_cm3", where, low=0.0, high=1e6)
    inertia = _number(m, "inertia_kg_m2", where, required=False, default=0.0, low=0.0,
                      low_open=False, high=1e4)
    phase_deg = _number(m, "leak_phase_deg", where, required=False, default=None,
                        low=-360.0, low_open=False, high=360.0)
    harmonics = _number(m, "leak_harmonics", where, required=False, default=1, low=0,
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
        nu40 = _number(o, "nu40_cSt", ow, low=0.0, high=1e5)
        nu100 = _number(o, "nu100_cSt", ow, low=0.0, high=1e5)
        if nu100 >= nu40:
            raise InputError(f"{ow}: key 'nu100_cSt' ({nu100}) must be below 'nu40_cSt' ({nu40})")
        rho = _number(o, "density15_kg_m3", ow, low=100.0, high=5000.0)
        beta = _number(o, "expansion_per_K", ow, required=False, default=6.5e-4, low=0.0,
                       low_open=False, high=0.01)
        oname = o.get("name", "oil")
        temp = _number(o, "temp_C", ow, required=False, default=None, low=-273.15, high=1000.0)
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


def load_motor_spec(path) -> MotorSpec:
    """Read and validate a motor spec TOML file."""
    return parse_motor_spec(read_toml(path, "motor spec"), str(Path(path)))
