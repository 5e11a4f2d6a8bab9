"""What every mechanism works on, and the interface of a mechanism.

- :class:`ParameterInfo`  what a parameter means: unit, words, sign, typical size
- :class:`Samples`        the operating point of each sample (SI)
- :class:`Channels`       the predicted bench channels (SI)
- :class:`Mechanism`      an extension of the one model: hooks that add terms to
  the channels :func:`motorid.model.predict` computes, never a second copy of it
- :class:`CatalogMechanism` a mechanism the discrepancy search can name: with a
  residual signature, ``neutral()`` values and ``describe()`` words

A mechanism's parameters live in the model's parameter dict as ``"<id>.<name>"``
(SI).  Its hooks are pure ``jax.numpy``, elementwise over the samples (jit- and
vmap-safe), differentiable in every parameter with finite gradients at every
operating point, padded samples (zero speed and pressure) included.  Mechanisms
are singletons (:mod:`motorid.physics.registry`): compiled kernels are cached by
mechanism, and unpickling one gives back the same object.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401


@dataclass(frozen=True)
class ParameterInfo:
    """What a parameter means: unit, words, sign constraint and a typical size."""

    unit: str
    meaning: str
    positive: bool
    typical: float


class Samples(NamedTuple):
    """Operating point of each sample, SI, all arrays of one shape.

    theta [rad], speed ω [rad/s], acceleration α [rad/s²], p_a, p_b, p_case
    [Pa gauge], viscosity μ [Pa·s], direction sgn ω [-] (±1; the run's direction
    in a fit, so sensor noise at very low speed cannot flip friction), port_sum
    S(θ) [-] (depends on no parameter, so it is computed once), temperature [°C]
    and time [s] (for mechanisms that need them).
    """

    theta: jax.Array
    speed: jax.Array
    acceleration: jax.Array
    p_a: jax.Array
    p_b: jax.Array
    p_case: jax.Array
    viscosity: jax.Array
    direction: jax.Array
    port_sum: jax.Array
    temperature: jax.Array
    time: jax.Array


class Channels(NamedTuple):
    """Predicted bench channels, SI: shaft torque to the load [N·m], flow into
    port A, into port B and out of the case drain [m³/s]."""

    torque: jax.Array
    q_a: jax.Array
    q_b: jax.Array
    q_case: jax.Array


#: pressure over which the orifice law √ΔP is smoothed near ΔP = 0 [Pa] (0.1 bar)
ORIFICE_SMOOTHING = 1e4
#: speed over which |ω| is smoothed near ω = 0 [rad/s] (0.01 rpm, far below any test speed)
SPEED_SMOOTHING = 1e-3


def smooth_sqrt(x, scale=ORIFICE_SMOOTHING):
    """Signed square root sgn(x)·√|x| made smooth at 0: x / (x² + ε²)^¼ [√(unit of x)].

    Equal to sgn(x)√|x| within 0.01 % for |x| > 100 ε; slope 1/√ε at x = 0.
    """
    return x / (x * x + scale * scale) ** 0.25


def smooth_abs(x, scale=SPEED_SMOOTHING):
    """|x| made smooth at 0: x² / √(x² + ε²) [unit of x].

    Exactly 0 at x = 0, slope 0 there; within (ε/x)²/2 of |x| relative.
    """
    return x * x / jnp.sqrt(x * x + scale * scale)


class Mechanism:
    """Base class: every hook returns its input unchanged."""

    id: str = ""
    name: str = ""
    physics: str = ""  # two sentences, in words an engineer accepts
    reference: str = ""  # literature reference
    channels: tuple[str, ...] = ()  # of: torque, q_a, q_b, q_case, breakaway
    parameters: dict[str, ParameterInfo] = {}
    #: True where the mechanism's terms depend on the shaft angle θ only through the 1992 model's
    #: S(θ) and K_L(θ) harmonics (in value and in every derivative): a table's θ-average then needs
    #: one angle whenever the base model does (identify/table_model.py), without probing it.  False
    #: (the default, for a mechanism not declared so): its θ-dependence is probed numerically.
    angle_free: bool = False

    def running(self, params: dict, spec, samples: Samples, ch: Channels) -> Channels:
        """Add this mechanism's terms to the running channels."""
        return ch

    def table_conditions(self, params: dict, spec, samples: Samples) -> Samples:
        """Change the operating conditions of an operating-point table's points before the model
        sees them (e.g. an oil temperature the table did not record); samples are points × angles."""
        return samples

    def bound_to(self, table) -> "Mechanism":
        """This mechanism for the points of ``table`` (a mechanism of a table's own points, such as
        an oil temperature per recording, looks its recordings up there)."""
        return self

    def for_training(self, table, train) -> "Mechanism":
        """This mechanism for a fit on ``table``'s points where ``train`` holds."""
        return self

    def table_reasons(self, table, train) -> dict:
        """parameter → why a fit on ``table``'s points where ``train`` holds cannot give it."""
        return {}

    def unseen_in_table(self, table) -> str | None:
        """Why ``table``'s points cannot tell this mechanism from the physics it mimics (words), or
        None where they can: diagnose does not try it on such a table (a flow meter's error needs the
        meters' mass balance, which only a table of all three flows holds)."""
        return None

    def data_starts(self, abs_dp) -> list:
        """Extra starting values from the data's pressure differences ``abs_dp`` (|ΔP| [Pa] of the
        points or runs), for a parameter a start far from the data cannot find (a threshold, a
        knee) → [{parameter: value}]; none by default."""
        return []

    def outside_data(self, values: dict, abs_dp) -> str | None:
        """Why fitted ``values`` describe no effect inside the data, whose pressure differences
        are ``abs_dp`` (|ΔP| [Pa] of the points or runs): a threshold fitted beyond every point,
        whose tail then stands in for some other smooth law (words), or None.  Diagnose does not
        name a mechanism so fitted."""
        return None

    def fold_into_spec(self, params: dict, spec):
        """The spec with a value this mechanism measured folded in, for an export that writes the spec
        instead of the mechanism's term (a rotor inertia: the exported torque leaves J·α to the load);
        None where the mechanism is a term of the exported model, as most are."""
        return None

    def static_limit(self, params: dict, spec, events: Samples, limit):
        """Change the static friction limit T_break at breakaway events [N·m]."""
        return limit

    def breakaway_reading(self, params: dict, spec, events: Samples, held):
        """Change the held-torque reading at breakaway (e.g. a transducer offset) [N·m]."""
        return held

    def initial(self) -> dict:
        """Starting values of this mechanism's parameters for a fit."""
        return {k: (v.typical if v.positive else 0.0) for k, v in self.parameters.items()}

    def __repr__(self) -> str:
        return f"<mechanism {self.id}>"


class CatalogMechanism(Mechanism):
    """A catalog entry: a :class:`Mechanism` with a residual signature and words for its fit."""

    signature: str = ""  # where its residual shows in the bench data
    sensor: bool = False  # True: it changes a transducer's reading, not the motor (exports leave it out)

    def neutral(self) -> dict:
        """Parameter values at which this mechanism adds exactly nothing."""
        return {k: 0.0 for k in self.parameters}

    def value(self, values: dict, name: str) -> float:
        """Parameter ``name`` from ``values`` keyed ``"<id>.<name>"`` or ``"<name>"``."""
        full = f"{self.id}.{name}"
        return float(values[full] if full in values else values[name])

    def describe(self, values: dict, spec=None) -> str:
        """One sentence on the fitted mechanism, numbers in engineering units."""
        raise NotImplementedError

    def param(self, params: dict, name: str):
        """This mechanism's parameter ``name`` from a model parameter dict."""
        return params[f"{self.id}.{name}"]

    def __reduce__(self):  # unpickle to the catalog's singleton
        from motorid.physics.registry import get

        return (get, (self.id,))
