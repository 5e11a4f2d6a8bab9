"""Sensor models of the bench DAQ: offset, noise, quantization.

A protocol's ``[sensors]`` table sets them per log column, in the column's own
unit (BENCH_LOG_FORMAT.md)::

    [sensors]
    viscosity = true              # write viscosity_mPas (false: readers derive it)
    [sensors.torque_Nm]
    noise = 0.05                  # standard deviation of additive white noise [column unit]
    relative_noise = 0.0005       # standard deviation as a fraction of the reading [-]
    resolution = 0.01             # quantization step [column unit]; 0 = none
    offset = 0.0                  # constant offset [column unit]

The reading is ``quantize(x + offset + σ(x)·N(0,1))`` with
σ(x)² = noise² + (relative_noise·x)².  Inside, every value is SI.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from motorid.errors import InputError
from motorid.units import FORMAT_COLUMNS
from motorid.io.tomlfile import toml_number

#: log column → canonical SI column, for the channels a sensor reads
SENSOR_COLUMNS = {col: si for si, (col, _) in FORMAT_COLUMNS.items() if si != "time_s"}
_SI_FACTOR = {si: factor for si, (_, factor) in FORMAT_COLUMNS.items()}


@dataclass(frozen=True)
class ChannelSensor:
    """One channel's sensor, SI: noise σ₀ [SI unit], relative noise [-],
    resolution (quantization step) [SI unit], offset [SI unit]."""

    noise: float = 0.0
    relative_noise: float = 0.0
    resolution: float = 0.0
    offset: float = 0.0

    def std(self, x):
        """Noise standard deviation at the true reading ``x`` [SI unit]."""
        return np.sqrt(self.noise**2 + (self.relative_noise * np.asarray(x, dtype=float)) ** 2)

    def read(self, x, rng: np.random.Generator):
        """The reading of true values ``x`` [SI unit] (offset, noise, then quantization)."""
        x = np.asarray(x, dtype=float)
        y = x + self.offset
        if self.noise > 0.0 or self.relative_noise > 0.0:
            y = y + self.std(x) * rng.standard_normal(x.shape)
        if self.resolution > 0.0:
            y = np.round(y / self.resolution) * self.resolution
        return y


def _in_log_units(si: str, noise, rel, res, off) -> ChannelSensor:
    f = _SI_FACTOR[si]
    return ChannelSensor(noise * f, rel, res * f, off * f)


# sensible bench defaults, in the log's units: (noise, relative noise, resolution, offset)
_DEFAULTS_LOG_UNITS = {
    "shaft_angle_deg": (0.0, 0.0, 0.01, 0.0),       # incremental encoder, 36 000 counts/rev
    "speed_rpm": (0.002, 5e-4, 0.001, 0.0),         # encoder-derived speed
    "torque_Nm": (0.05, 5e-4, 0.01, 0.0),           # 500 N·m shaft transducer, 0.01 % FS noise
    "p_a_bar": (0.03, 0.0, 0.01, 0.0),              # 0-600 bar transmitters
    "p_b_bar": (0.03, 0.0, 0.01, 0.0),
    "p_case_bar": (0.003, 0.0, 0.001, 0.0),         # 0-10 bar transmitter
    "q_a_lpm": (0.01, 0.002, 0.001, 0.0),           # gear flow meters, 0.2 % of reading
    "q_b_lpm": (0.01, 0.002, 0.001, 0.0),
    "q_case_lpm": (0.002, 0.003, 0.001, 0.0),       # small gear meter on the case drain
    "oil_temp_C": (0.05, 0.0, 0.01, 0.0),           # Pt100 at the motor inlet
    "viscosity_mPas": (0.0, 0.003, 0.01, 0.0),      # in-line viscometer
}


def default_channels() -> dict[str, ChannelSensor]:
    """The default sensor of every logged channel, keyed by canonical SI column."""
    return {SENSOR_COLUMNS[col]: _in_log_units(SENSOR_COLUMNS[col], *v)
            for col, v in _DEFAULTS_LOG_UNITS.items()}


@dataclass(frozen=True)
class Sensors:
    """The DAQ: one :class:`ChannelSensor` per canonical SI column, and whether
    the viscosity column is written at all."""

    channels: dict = field(default_factory=default_channels)
    viscosity: bool = True

    def ideal(self) -> "Sensors":
        """The same DAQ without noise, quantization or offsets (true values)."""
        return replace(self, channels={k: ChannelSensor() for k in self.channels})

    def read(self, true: dict, rng: np.random.Generator) -> dict:
        """Readings of the true SI channels in ``true`` (column → array).

        Channels are read in the fixed order of :data:`SENSOR_COLUMNS`, so the
        same generator state gives the same readings.
        """
        out = {}
        for si in SENSOR_COLUMNS.values():
            if si not in true or (si == "viscosity_Pa_s" and not self.viscosity):
                continue
            out[si] = self.channels.get(si, ChannelSensor()).read(true[si], rng)
        return out


_SENSOR_KEYS = ("noise", "relative_noise", "resolution", "offset")


def parse_sensors(table, where: str, base: Sensors | None = None) -> Sensors:
    """Build :class:`Sensors` from a ``[sensors]`` TOML table (log units), starting
    from ``base`` (default: :func:`default_channels`); ``where`` names the file."""
    base = Sensors() if base is None else base
    if table is None:
        return base
    if not isinstance(table, dict):
        raise InputError(f"{where}: [sensors] must be a table")
    channels = dict(base.channels)
    viscosity = base.viscosity
    for key, value in table.items():
        if key == "viscosity":
            if not isinstance(value, bool):
                raise InputError(f"{where} [sensors]: key 'viscosity' must be true or false, got {value!r}")
            viscosity = value
            continue
        if key not in SENSOR_COLUMNS:
            raise InputError(f"{where} [sensors]: unknown key '{key}' (expected 'viscosity' or a "
                             f"log column: {', '.join(SENSOR_COLUMNS)})")
        if not isinstance(value, dict):
            raise InputError(f"{where} [sensors]: '{key}' must be a table of {', '.join(_SENSOR_KEYS)}")
        tw = f"{where} [sensors.{key}]"
        for k in value:
            if k not in _SENSOR_KEYS:
                raise InputError(f"{tw}: unknown key '{k}' (expected {', '.join(_SENSOR_KEYS)})")
        si = SENSOR_COLUMNS[key]
        old = channels[si]
        f = _SI_FACTOR[si]
        num = lambda k, d: toml_number(value, k, tw, required=False, default=d, low=0.0, low_open=False)  # noqa: E731
        offset = toml_number(value, "offset", tw, required=False, default=old.offset / f)
        channels[si] = ChannelSensor(noise=num("noise", old.noise / f) * f,
                                     relative_noise=num("relative_noise", old.relative_noise),
                                     resolution=num("resolution", old.resolution / f) * f,
                                     offset=offset * f)
    return Sensors(channels, viscosity)
