"""Test plans (protocols) as TOML: one file per ISO 4392 procedure.

A protocol names its procedure and the standard it follows, its set points
(swept as a grid), its timing (sample rate, durations, ramp rate), the bench
conditions (back pressure, case pressure, oil temperature drift), the
dynamometer/load, the supply and the sensors.  Every value is validated; a bad
one raises :class:`motorid.errors.InputError` naming the file and the key.
Units are the ones in the key names; inside, SI.

Schema (keys marked * are required; the procedure decides which apply)::

    [protocol]
    procedure* = "constant_speed" | "constant_pressure" | "startability"
                 | "constant_flow" | "constant_torque"
    standard*  = "ISO 4392-1:2002 ..."       # the standard it follows
    title, description = "..."

    [set_points]                             # swept as a grid, one run per point
    oil_temp_C = [40.0]                      # set oil temperatures [°C]
    directions = ["positive", "negative"]    # or [1, -1]
    power_flow = ["motor", "pump"]           # constant_speed, constant_pressure: pump mode turns the
                                             #   shaft against ΔP (dynamometer drives); default ["motor"]
    speed_rpm = [...]                        # constant_speed, constant_pressure (> 0)
    pressure_difference_bar = [...]          # constant_speed, constant_pressure (> 0)
    shaft_angle_deg = [...]                  # startability
    load_torque_Nm = [...]                   # startability, constant_flow, constant_torque (>= 0)
    flow_lpm = [...]                         # constant_flow, constant_torque (> 0)

    [timing]
    sample_rate_Hz* = 100                    # or a list aligned with speed_rpm / flow_lpm
    duration_s = 2.0                         # least logged time of a running set point
    revolutions = 1.0                        # least shaft revolutions of a running set point
                                             #   (default 1 for constant_speed, else 0)
    settle_s = 1.0                           # constant_flow/torque: simulated, not logged
    ramp_rate_bar_s = 2.5                    # startability: inlet pressure ramp
    hold_s = 0.5                             # startability: logged before the ramp
    after_breakaway_s = 1.0                  # startability: logged after breakaway
    max_pressure_bar = 400                   # startability: ramp ends here (no breakaway)
    start_pressure_bar = 20                  # startability: ΔP at the ramp start
                                             #   (default: where pressure torque alone holds the load)
    [conditions]
    back_pressure_bar = 7.0                  # outlet port
    case_pressure_bar = 0.7                  # case, with no drain flow
    case_drain_resistance_bar_per_lpm = 0.05 # case pressure rise per case drain flow
    temp_drift_C_per_min = 0.2               # oil temperature drift within a run
    temp_tolerance_C = 0.5                   # run start temperature within ± this of the set value

    [dynamometer]
    speed_ripple = 0.002                     # speed controller oscillation, relative amplitude
    speed_ripple_Hz = 1.5
    speed_ripple_per_rev = 0.001             # once-per-revolution ripple (coupling), relative
    load_inertia_kg_m2 = 0.5                 # inertia beyond the torque transducer (load-driven runs)
    max_speed_rpm = 10                       # startability: speed limiter after breakaway

    [supply]
    pressure_ripple = 0.0005                 # held pressure fluctuation, relative to ΔP
    pressure_ripple_Hz = 3.0
    flow_ripple = 0.002                      # constant_flow/torque: pump flow ripple, relative
    flow_ripple_Hz = 5.0
    volume_L = 1.0                           # oil volume between pump and inlet port
    bulk_modulus_bar = 14000

    [sensors]                                # see motorid.bench.sensors
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

from motorid.bench.sensors import Sensors, parse_sensors
from motorid.errors import InputError
from motorid.io.logs import PROTOCOLS
from motorid.io.tomlfile import read_toml, toml_number  # noqa: F401  (read_toml is re-exported)
from motorid.units import M3S_PER_LPM, PA_PER_BAR, RAD_S_PER_RPM


#: which [set_points] lists each procedure sweeps, outermost first (after oil_temp_C, directions)
SWEEPS = {
    "constant_speed": ("pressure_difference_bar", "speed_rpm"),
    "constant_pressure": ("pressure_difference_bar", "speed_rpm"),
    "startability": ("load_torque_Nm", "shaft_angle_deg"),
    "constant_flow": ("flow_lpm", "load_torque_Nm"),
    "constant_torque": ("load_torque_Nm", "flow_lpm"),
}
#: the set-point list that a list-valued sample_rate_Hz is aligned with
_RATE_ALIGNED = {"constant_speed": "speed_rpm", "constant_pressure": "speed_rpm",
                 "constant_flow": "flow_lpm", "constant_torque": "flow_lpm"}
_RUNNING_TIMING = ("sample_rate_Hz", "duration_s", "revolutions")
_TIMING = {
    "constant_speed": _RUNNING_TIMING,
    "constant_pressure": _RUNNING_TIMING,
    "constant_flow": (*_RUNNING_TIMING, "settle_s"),
    "constant_torque": (*_RUNNING_TIMING, "settle_s"),
    "startability": ("sample_rate_Hz", "ramp_rate_bar_s", "hold_s", "after_breakaway_s",
                     "max_pressure_bar", "start_pressure_bar"),
}
_SET_POINT_LIMITS = {  # key: (low, low_open, high, SI factor)
    "speed_rpm": (0.0, True, 20000.0, RAD_S_PER_RPM),
    "pressure_difference_bar": (0.0, True, 2000.0, PA_PER_BAR),
    "shaft_angle_deg": (-3600.0, False, 3600.0, math.pi / 180.0),
    "load_torque_Nm": (0.0, False, 1e6, 1.0),
    "flow_lpm": (0.0, True, 1e5, M3S_PER_LPM),
}
#: most samples one protocol may ask for (a typo in a rate or speed should not fill a disk)
MAX_SAMPLES = 5_000_000


@dataclass(frozen=True)
class Conditions:
    """Bench conditions, SI: outlet back pressure [Pa], case pressure with no
    drain flow [Pa], case pressure rise per drain flow [Pa/(m³/s)], oil
    temperature drift [°C/s] and start tolerance [°C]."""

    back_pressure: float = 7.0 * PA_PER_BAR
    case_pressure: float = 0.7 * PA_PER_BAR
    case_drain_resistance: float = 0.05 * PA_PER_BAR / M3S_PER_LPM
    temp_drift: float = 0.2 / 60.0
    temp_tolerance: float = 0.5


@dataclass(frozen=True)
class Dynamometer:
    """Dynamometer and load: speed ripple (relative amplitude [-] at a frequency
    [Hz], and once per revolution [-]), inertia beyond the torque transducer
    [kg·m²], startability speed limiter [rad/s]."""

    speed_ripple: float = 0.002
    speed_ripple_freq: float = 1.5
    speed_ripple_per_rev: float = 0.001
    load_inertia: float = 0.5
    max_speed: float = 10.0 * RAD_S_PER_RPM


@dataclass(frozen=True)
class Supply:
    """Hydraulic supply: held-pressure fluctuation (relative to ΔP [-], at [Hz]),
    pump flow ripple (relative [-], at [Hz]), inlet line volume [m³] and oil
    bulk modulus [Pa]."""

    pressure_ripple: float = 5e-4
    pressure_ripple_freq: float = 3.0
    flow_ripple: float = 0.002
    flow_ripple_freq: float = 5.0
    volume: float = 1e-3
    bulk_modulus: float = 1.4e9


@dataclass(frozen=True)
class Timing:
    """Timing, SI: ramp rate [Pa/s], durations [s], pressures [Pa]; sample rates
    are per run (see :class:`RunPlan`)."""

    duration: float = 2.0
    revolutions: float = 0.0
    settle: float = 1.0
    ramp_rate: float = 2.5 * PA_PER_BAR
    hold: float = 0.5
    after_breakaway: float = 1.0
    max_pressure: float = 400.0 * PA_PER_BAR
    start_pressure: float | None = None


@dataclass(frozen=True)
class RunPlan:
    """One run: one set point, or one startability ramp.  SI; magnitudes are
    positive and ``direction`` (±1) gives the sense of rotation (−1: port B is
    the inlet, speed and ΔP negative).

    oil_temp [°C]; sample_rate [Hz]; speed [rad/s]; pressure_difference [Pa];
    shaft_angle [rad]; load_torque [N·m]; flow [m³/s]; ``None`` where the
    procedure does not set it.
    """

    index: int
    direction: int
    oil_temp: float
    sample_rate: float
    speed: float | None = None
    pressure_difference: float | None = None
    shaft_angle: float | None = None
    load_torque: float | None = None
    flow: float | None = None
    pump: bool = False  # pump mode: the high pressure on the port the shaft's rotation delivers to

    def describe(self) -> dict:
        """The set point in the log's units, for a manifest."""
        d = {"direction": "positive" if self.direction > 0 else "negative",
             "oil_temp_C": self.oil_temp, "sample_rate_Hz": self.sample_rate}
        if self.pump:
            d["power_flow"] = "pump"
        for name, (key, factor) in {"speed": ("speed_rpm", RAD_S_PER_RPM),
                                    "pressure_difference": ("pressure_difference_bar", PA_PER_BAR),
                                    "shaft_angle": ("shaft_angle_deg", math.pi / 180.0),
                                    "load_torque": ("load_torque_Nm", 1.0),
                                    "flow": ("flow_lpm", M3S_PER_LPM)}.items():
            v = getattr(self, name)
            if v is not None:
                d[key] = v / factor
        return d


@dataclass(frozen=True)
class Protocol:
    """A validated test plan: procedure, standard, the runs and the bench set-up."""

    name: str
    procedure: str
    standard: str
    runs: tuple
    timing: Timing = field(default_factory=Timing)
    conditions: Conditions = field(default_factory=Conditions)
    dynamometer: Dynamometer = field(default_factory=Dynamometer)
    supply: Supply = field(default_factory=Supply)
    sensors: Sensors = field(default_factory=Sensors)
    title: str = ""
    description: str = ""
    source: str = ""


def _check_keys(table: dict, allowed, where: str, why: str = ""):
    for key in table:
        if key not in allowed:
            raise InputError(f"{where}: unknown key '{key}'{why} (expected one of: {', '.join(allowed)})")


def _table(data: dict, name: str, source: str) -> dict:
    t = data.get(name, {})
    if not isinstance(t, dict):
        raise InputError(f"{source}: [{name}] must be a table")
    return t


def _number_list(table: dict, key: str, where: str, *, required=True, default=None, **limits) -> list:
    """A number or a non-empty list of numbers under ``key``, each validated."""
    if key not in table:
        if required:
            raise InputError(f"{where}: missing key '{key}'")
        return list(default)
    value = table[key]
    values = value if isinstance(value, list) else [value]
    if not values:
        raise InputError(f"{where}: key '{key}' must not be an empty list")
    return [toml_number({key: v}, key, where, **limits) for v in values]


def _directions(table: dict, where: str) -> list[int]:
    value = table.get("directions", ["positive", "negative"])
    values = value if isinstance(value, list) else [value]
    words = {"positive": 1, "negative": -1, "+": 1, "-": -1}
    out = []
    for v in values:
        if isinstance(v, str) and v.lower() in words:
            out.append(words[v.lower()])
        elif isinstance(v, int) and not isinstance(v, bool) and v in (1, -1):
            out.append(v)
        else:
            raise InputError(f"{where}: key 'directions' takes \"positive\", \"negative\", 1 or -1, got {v!r}")
    if not out:
        raise InputError(f"{where}: key 'directions' must not be an empty list")
    return out


def _power_flow(table: dict, where: str) -> list[bool]:
    """[set_points] power_flow: "motor" and/or "pump" → [is pump mode] (default motor only)."""
    value = table.get("power_flow", ["motor"])
    values = value if isinstance(value, list) else [value]
    out = []
    for v in values:
        if not isinstance(v, str) or v.lower() not in ("motor", "pump"):
            raise InputError(f"{where}: key 'power_flow' takes \"motor\" or \"pump\", got {v!r}")
        out.append(v.lower() == "pump")
    if not out:
        raise InputError(f"{where}: key 'power_flow' must not be an empty list")
    return out


def _sample_rates(timing: dict, where: str, procedure: str, set_points: dict) -> list[float]:
    rates = _number_list(timing, "sample_rate_Hz", where, low=0.0, high=1e6)
    aligned = _RATE_ALIGNED.get(procedure)
    if isinstance(timing["sample_rate_Hz"], list):
        if aligned is None:
            raise InputError(f"{where}: key 'sample_rate_Hz' must be one number for {procedure}")
        if len(rates) != len(set_points[aligned]):
            raise InputError(f"{where}: key 'sample_rate_Hz' has {len(rates)} values but "
                             f"[set_points] '{aligned}' has {len(set_points[aligned])}")
        return rates
    return rates * (len(set_points[aligned]) if aligned else 1)


# TOML key → (field, factor to SI, low, low open, high) of each settings table
_TIMING_KEYS = {
    "duration_s": ("duration", 1.0, 0.0, True, 1e5),
    "revolutions": ("revolutions", 1.0, 0.0, False, 1e4),
    "settle_s": ("settle", 1.0, 0.0, False, 100.0),
    "ramp_rate_bar_s": ("ramp_rate", PA_PER_BAR, 0.0, True, 1e4),
    "hold_s": ("hold", 1.0, 0.0, False, 1e4),
    "after_breakaway_s": ("after_breakaway", 1.0, 0.0, True, 1e3),
    "max_pressure_bar": ("max_pressure", PA_PER_BAR, 0.0, True, 2000.0),
    "start_pressure_bar": ("start_pressure", PA_PER_BAR, 0.0, False, 2000.0),
}
_CONDITIONS_KEYS = {
    "back_pressure_bar": ("back_pressure", PA_PER_BAR, 0.0, False, 100.0),
    "case_pressure_bar": ("case_pressure", PA_PER_BAR, 0.0, False, 20.0),
    "case_drain_resistance_bar_per_lpm": ("case_drain_resistance", PA_PER_BAR / M3S_PER_LPM, 0.0, False, 10.0),
    "temp_drift_C_per_min": ("temp_drift", 1.0 / 60.0, -10.0, False, 10.0),
    "temp_tolerance_C": ("temp_tolerance", 1.0, 0.0, False, 10.0),
}
_DYNAMOMETER_KEYS = {
    "speed_ripple": ("speed_ripple", 1.0, 0.0, False, 0.2),
    "speed_ripple_Hz": ("speed_ripple_freq", 1.0, 0.0, False, 1e4),
    "speed_ripple_per_rev": ("speed_ripple_per_rev", 1.0, 0.0, False, 0.2),
    "load_inertia_kg_m2": ("load_inertia", 1.0, 0.0, False, 1e4),
    "max_speed_rpm": ("max_speed", RAD_S_PER_RPM, 0.0, True, 20000.0),
}
_SUPPLY_KEYS = {
    "pressure_ripple": ("pressure_ripple", 1.0, 0.0, False, 0.2),
    "pressure_ripple_Hz": ("pressure_ripple_freq", 1.0, 0.0, False, 1e4),
    "flow_ripple": ("flow_ripple", 1.0, 0.0, False, 0.2),
    "flow_ripple_Hz": ("flow_ripple_freq", 1.0, 0.0, False, 1e4),
    "volume_L": ("volume", 1e-3, 0.0, True, 1e4),
    "bulk_modulus_bar": ("bulk_modulus", PA_PER_BAR, 0.0, True, 1e6),
}


def _parse_settings(table: dict, where: str, cls, keys: dict, allowed=None, why: str = ""):
    """A settings dataclass from a TOML table: each key converted to SI, absent keys
    keep the dataclass default."""
    _check_keys(table, list(keys) if allowed is None else allowed, where, why)
    values = {}
    for key, (attr, factor, low, low_open, high) in keys.items():
        value = toml_number(table, key, where, required=False, low=low, low_open=low_open, high=high)
        if value is not None:
            values[attr] = value * factor
    return cls(**values)


def _parse_timing(t: dict, where: str, procedure: str) -> Timing:
    allowed = _TIMING[procedure]
    timing = _parse_settings({k: v for k, v in t.items() if k != "sample_rate_Hz"}, where, Timing,
                             {k: v for k, v in _TIMING_KEYS.items() if k in allowed}, allowed,
                             f" for procedure {procedure}")
    if procedure == "constant_speed" and "revolutions" not in t:
        timing = replace(timing, revolutions=1.0)  # a full revolution unless told otherwise
    if timing.start_pressure is not None and timing.start_pressure >= timing.max_pressure:
        raise InputError(f"{where}: key 'start_pressure_bar' must be below 'max_pressure_bar'")
    return timing


def _expected_samples(procedure: str, plan: RunPlan, timing: Timing) -> float:
    if procedure == "startability":
        span = timing.max_pressure if timing.start_pressure is None else timing.max_pressure - timing.start_pressure
        return plan.sample_rate * (timing.hold + span / timing.ramp_rate + timing.after_breakaway)
    return plan.sample_rate * running_duration(plan, timing)


def running_duration(plan: RunPlan, timing: Timing, speed: float | None = None) -> float:
    """Logged duration of a running set point [s]: at least ``timing.duration`` and
    ``timing.revolutions`` shaft revolutions at ``speed`` [rad/s] (default: the plan's)."""
    speed = plan.speed if speed is None else speed
    if not speed:
        return timing.duration
    return max(timing.duration, timing.revolutions * 2.0 * math.pi / abs(speed))


def parse_protocol(data: dict, source: str = "protocol", name: str | None = None) -> Protocol:
    """Build a :class:`Protocol` from a parsed TOML mapping, validating every value."""
    _check_keys(data, ("protocol", "set_points", "timing", "conditions", "dynamometer", "supply", "sensors"),
                source, " at the top level")
    head = _table(data, "protocol", source)
    if not head:
        raise InputError(f"{source}: missing table [protocol]")
    where = f"{source} [protocol]"
    _check_keys(head, ("procedure", "standard", "title", "description"), where)
    procedure = head.get("procedure")
    if procedure not in PROTOCOLS:
        raise InputError(f"{where}: key 'procedure' must be one of {', '.join(PROTOCOLS)}, got {procedure!r}")
    for key in ("standard", "title", "description"):
        if key in head and not isinstance(head[key], str):
            raise InputError(f"{where}: key '{key}' must be a string")
    standard = head.get("standard", "")
    if not standard.strip():
        raise InputError(f"{where}: missing key 'standard' (cite the standard the procedure follows)")

    sp = _table(data, "set_points", source)
    sw = f"{source} [set_points]"
    swept = SWEEPS[procedure]
    modal = ("power_flow",) if procedure in _RATE_ALIGNED and "speed_rpm" in swept else ()
    _check_keys(sp, ("oil_temp_C", "directions", *modal, *swept), sw, f" for procedure {procedure}")
    modes = _power_flow(sp, sw) if modal else [False]
    set_points = {"oil_temp_C": _number_list(sp, "oil_temp_C", sw, required=False, default=[40.0],
                                             low=-40.0, low_open=False, high=150.0)}
    for key in swept:
        low, low_open, high, _ = _SET_POINT_LIMITS[key]
        set_points[key] = _number_list(sp, key, sw, low=low, low_open=low_open, high=high)
    directions = _directions(sp, sw)

    tt = _table(data, "timing", source)
    tw = f"{source} [timing]"
    timing = _parse_timing(tt, tw, procedure)
    rates = _sample_rates(tt, tw, procedure, set_points)

    runs = []
    aligned = _RATE_ALIGNED.get(procedure)
    for temp, direction, pump, *point in itertools.product(set_points["oil_temp_C"], directions, modes,
                                                           *(range(len(set_points[k])) for k in swept)):
        values = {k: set_points[k][i] * _SET_POINT_LIMITS[k][3] for k, i in zip(swept, point)}
        rate = rates[point[swept.index(aligned)]] if aligned else rates[0]
        runs.append(RunPlan(
            index=len(runs), direction=direction, oil_temp=float(temp), sample_rate=float(rate),
            speed=values.get("speed_rpm"), pressure_difference=values.get("pressure_difference_bar"),
            shaft_angle=values.get("shaft_angle_deg"), load_torque=values.get("load_torque_Nm"),
            flow=values.get("flow_lpm"), pump=pump))
    total = sum(_expected_samples(procedure, r, timing) for r in runs)
    if total > MAX_SAMPLES:
        raise InputError(f"{tw}: the plan asks for about {total:.3g} samples (more than {MAX_SAMPLES:.0e}); "
                         "lower 'sample_rate_Hz' or the durations, or raise the lowest speed or flow")

    return Protocol(
        name=name or Path(source).stem,
        procedure=procedure,
        standard=standard.strip(),
        runs=tuple(runs),
        timing=timing,
        conditions=_parse_settings(_table(data, "conditions", source), f"{source} [conditions]", Conditions,
                                   _CONDITIONS_KEYS),
        dynamometer=_parse_settings(_table(data, "dynamometer", source), f"{source} [dynamometer]",
                                    Dynamometer, _DYNAMOMETER_KEYS),
        supply=_parse_settings(_table(data, "supply", source), f"{source} [supply]", Supply, _SUPPLY_KEYS),
        sensors=parse_sensors(data.get("sensors"), source),
        title=head.get("title", ""),
        description=head.get("description", ""),
        source=source,
    )


def load_protocol(path) -> Protocol:
    """Read and validate a protocol TOML file."""
    return parse_protocol(read_toml(path, "protocol"), str(path), Path(path).stem)
