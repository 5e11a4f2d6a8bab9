"""The truth of a simulated motor: its parameters and any extra physics.

Schema (SI, names as in MODEL.md)::

    [parameters]
    Kv = 5000.0        # [-]
    KF = 0.003         # [-]
    KFS = 0.015        # [-]
    TFc = 3.0          # [N·m]
    Ks = 1.0           # [-]
    KL0 = 5e-14        # [m³]
    KL_a1 = 0.15       # [-]  (KL_a2, KL_b2, … for more harmonics; missing ones are 0)
    KL_b1 = 0.08       # [-]
    KAB = 2e-14        # [m³]

    [mechanisms.<id>]  # optional: extra physics from motorid.physics.registry
    <name> = value     # enters the parameter dict as "<id>.<name>"
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from motorid.bench.protocols import read_toml
from motorid.errors import InputError
from motorid.model import BASE_PARAMETERS, parameter_info
from motorid.physics import registry

_HARMONIC_PREFIXES = ("KL_a", "KL_b")


@dataclass(frozen=True)
class Truth:
    """True parameters (dict name → float, SI) and mechanism objects."""

    params: dict
    mechanisms: tuple = field(default_factory=tuple)
    source: str = ""

    @property
    def harmonics(self) -> int:
        """Order M of the K_L(θ) Fourier series the parameters name."""
        orders = [int(k[4:]) for k in self.params if k.startswith(_HARMONIC_PREFIXES)]
        return max(orders, default=0)


def resolve_mechanism(mech_id: str, where: str):
    """The mechanism named ``mech_id`` in :mod:`motorid.physics.registry`; :class:`InputError` otherwise."""
    try:
        return registry.get(mech_id)
    except InputError as exc:  # the registry's own words (it names the known mechanisms)
        raise InputError(f"{where}: {exc}") from None


def _value(table: dict, key: str, where: str) -> float:
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{where}: key '{key}' must be a finite number, got {value!r}")
    return float(value)


def parse_truth(data: dict, source: str = "truth") -> Truth:
    """Build a :class:`Truth` from a parsed TOML mapping, validating every value."""
    for key in data:
        if key not in ("parameters", "mechanisms"):
            raise InputError(f"{source}: unknown table '{key}' (expected [parameters] and [mechanisms.<id>])")
    table = data.get("parameters")
    if not isinstance(table, dict):
        raise InputError(f"{source}: missing table [parameters]")
    where = f"{source} [parameters]"
    params = {}
    for key in table:
        is_harmonic = key.startswith(_HARMONIC_PREFIXES) and key[4:].isdigit() and int(key[4:]) >= 1
        if key not in BASE_PARAMETERS and not is_harmonic:
            raise InputError(f"{where}: unknown parameter '{key}' (expected {', '.join(BASE_PARAMETERS)}, "
                             "KL_a1, KL_b1, …)")
        params[key] = _value(table, key, where)
        if parameter_info(key).positive and params[key] < 0.0:
            raise InputError(f"{where}: key '{key}' must be >= 0, got {params[key]!r}")
    for key in BASE_PARAMETERS:
        if key not in params:
            raise InputError(f"{where}: missing key '{key}'")
    order = max((int(k[4:]) for k in params if k.startswith(_HARMONIC_PREFIXES)), default=0)
    for m in range(1, order + 1):  # a harmonic named on one side only is zero on the other
        params.setdefault(f"KL_a{m}", 0.0)
        params.setdefault(f"KL_b{m}", 0.0)

    mechs = data.get("mechanisms", {})
    if not isinstance(mechs, dict):
        raise InputError(f"{source}: 'mechanisms' must be tables [mechanisms.<id>]")
    resolved = []
    for mech_id, mtable in mechs.items():
        mw = f"{source} [mechanisms.{mech_id}]"
        if not isinstance(mtable, dict):
            raise InputError(f"{mw}: must be a table of the mechanism's parameters")
        mech = resolve_mechanism(mech_id, mw)
        prefix = f"{getattr(mech, 'id', mech_id) or mech_id}."
        names = list(getattr(mech, "parameters", {}))
        for key in mtable:
            if prefix + key not in names:
                accepted = ", ".join(n[len(prefix):] for n in names) or "none"
                raise InputError(f"{mw}: unknown parameter '{key}' (this mechanism takes: {accepted})")
            params[prefix + key] = _value(mtable, key, mw)
        for full in names:
            if full not in params:
                raise InputError(f"{mw}: missing key '{full[len(prefix):]}'")
        resolved.append(mech)
    return Truth(params, tuple(resolved), source)


def load_truth(path) -> Truth:
    """Read and validate a truth TOML file."""
    return parse_truth(read_toml(path, "truth"), str(Path(path)))
