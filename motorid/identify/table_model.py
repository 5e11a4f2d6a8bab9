"""The model of an operating-point table's point: the one model averaged over shaft angle.

:func:`table_samples` gives K angles over a revolution (K = max(64, 2n(M+2)), M the order of
the K_L(θ) series) with S(θ) set to its exact mean n/π, so that the mean over the K angles is
the exact θ-average (identify/tables.py says why).  :func:`angle_samples` gives one angle where
a probe shows nothing in the model varying with θ, so that a table's memory and time go with
its points, not its points × K.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from motorid import _jaxconfig  # noqa: F401
from motorid import model
from motorid.model import Channels

THETA_POINTS = 64  # at least this many shaft angles over a revolution in the θ-average of a table point


def table_samples(spec, table, points: int | None = None):
    """:class:`~motorid.model.Samples` of shape (points of the table, K angles over a revolution),
    S(θ) set to its exact mean n/π (see the module's words)."""
    if points is None:
        points = max(THETA_POINTS, 2 * spec.pistons * (spec.leak_harmonics + 2))
    theta = 2.0 * np.pi * (np.arange(points) + 0.5) / points
    n = len(table)
    col = lambda x: np.asarray(x, dtype=float)[:, None]  # noqa: E731
    s = model.make_samples(spec, np.broadcast_to(theta, (n, points)).copy(), col(table.speed), col(table.p_a),
                           col(table.p_b), col(table.p_case), col(table.viscosity), acceleration=0.0,
                           direction=np.sign(col(table.speed)), temperature=col(table.temperature))
    # S(θ)'s exact mean over a revolution (MODEL.md: mean torque DΔP/2π = (D/2n)·ΔP·S̄)
    return s._replace(port_sum=np.full_like(s.port_sum, spec.pistons / np.pi))


def point_channels(params: dict, spec, samples, displacement=None, mechanisms: Sequence = ()) -> Channels:
    """The model's channels at each table point: :func:`motorid.model.predict` averaged over θ.

    params : parameters (SI); samples : from :func:`table_samples`;
    displacement : per-point D [m³/rev] of a variable unit, or None (the spec's).
    Returns torque [N·m], q_a, q_b, q_case [m³/s], each over the points.
    """
    ch = _angle_channels(params, spec, samples, displacement, mechanisms)
    return Channels(*(jnp.mean(c, axis=-1) for c in ch))


def _angle_channels(params: dict, spec, samples, displacement=None, mechanisms: Sequence = ()) -> Channels:
    """The model's channels at each table point and each of its angles (before the θ-average)."""
    if displacement is not None:
        spec = dataclasses.replace(spec, displacement=jnp.asarray(displacement, dtype=jnp.float64)[:, None])
    for mech in mechanisms:  # conditions the table did not record (bind_mechanisms: to these points)
        samples = mech.table_conditions(params, spec, samples)
    return model.predict(params, spec, samples, mechanisms)


def angle_samples(spec, table, mechanisms: Sequence = (), params: dict | None = None, free: Sequence = ()):
    """:func:`table_samples` with one angle where that is exact, the full K where it is not.

    The θ-average of a model that does not vary with θ is its value at any one angle: the 1992
    model with its K_L(θ) harmonics at 0 (a table cannot identify them) and every mechanism
    without shaft-order terms.  Whether the model varies is probed at a few of the table's points,
    at ``params`` (every parameter's value, SI) and along each parameter in ``free`` (a
    derivative can vary with θ where the value does not: a harmonic at 0).  Memory and time of a
    table fit then go with the points, not the points × K (a map of 50 000 points needed 5 GB)."""
    return table_samples(spec, table, angle_points(spec, table, mechanisms, params, free))


def angle_points(spec, table, mechanisms: Sequence = (), params: dict | None = None, free: Sequence = ()):
    """1 where the probe of :func:`angle_samples` shows the model θ-free at ``table``'s points, else
    None (every angle, :func:`table_samples`' K)."""
    if params is None or not len(table) or _varies_with_angle(spec, table, mechanisms, params, free):
        return None
    return 1


PROBE_POINTS = 12  # table points the θ-probe looks at, spread over the table
_PROBED: dict = {}  # the probe's answers (a diagnosis asks the same question for every fold and candidate)
_PROBED_MAX = 512


def _varies_with_angle(spec, table, mechanisms, params, free, rtol: float = 1e-9) -> bool:
    """Whether the model's channels vary with θ at ``table``'s points (see :func:`angle_samples`).

    The answer depends on the model's structure, not on the values: the spec, the mechanisms, the
    parameters set free, which parameters are nonzero, and whether the table has speed and each
    pressure difference at all.  It is kept under that key (the spec and mechanisms themselves held,
    so that their ids stay theirs), and probed once per key.  Mechanisms declared ``angle_free``
    (physics/base.py: θ only through the 1992 model's S(θ) and K_L(θ)) vary with θ where the base
    model does and only there: they are left out of the probe and of its key, so that a diagnosis
    probes the base model once instead of once for every candidate (tests/test_table_angles.py checks
    each declaration against the probe)."""
    declared = {k for m in mechanisms if getattr(m, "angle_free", False) for k in m.parameters}
    mechanisms = tuple(m for m in mechanisms if not getattr(m, "angle_free", False))
    free = tuple(k for k in free if k not in declared)
    params = {k: v for k, v in params.items() if k not in declared}

    def nonzero(v) -> bool:
        a = np.asarray(v, dtype=float)
        return bool(np.any(a != 0) or np.any(~np.isfinite(a)))

    p_a, p_b, p_c = (np.asarray(x, dtype=float) for x in (table.p_a, table.p_b, table.p_case))
    shape = tuple(bool(np.any(np.abs(x) > 0)) for x in (np.asarray(table.speed, dtype=float), p_a - p_c,
                                                          p_b - p_c, p_a - p_b))
    key = (id(spec), tuple(id(m) for m in mechanisms), tuple(free),
           tuple(sorted(k for k, v in params.items() if v is not None and nonzero(v))), shape,
           bool(table.variable_displacement))
    held = _PROBED.get(key)
    if held is not None and held[1] is spec and all(a is b for a, b in zip(held[2], mechanisms)):
        return held[0]
    answer = _probe_angle(spec, table, mechanisms, params, free, rtol)
    if len(_PROBED) >= _PROBED_MAX:
        _PROBED.pop(next(iter(_PROBED)))
    _PROBED[key] = (answer, spec, tuple(mechanisms))
    return answer


def _probe_angle(spec, table, mechanisms, params, free, rtol: float) -> bool:
    # points spread over the table, and those where a θ-term is largest (it scales with the speed, the
    # port pressures above the case and the pressure difference: zero at rest or at the case's pressure)
    spread = np.linspace(0, len(table) - 1, min(PROBE_POINTS, len(table))).round().astype(int)
    p_a, p_b, p_c = (np.asarray(x, dtype=float) for x in (table.p_a, table.p_b, table.p_case))
    extremes = [int(np.nanargmax(np.abs(np.asarray(x, dtype=float))))
                for x in (table.speed, p_a - p_c, p_b - p_c, p_a - p_b)]
    idx = np.unique(np.concatenate([spread, extremes]))
    sub = table.subset(idx)
    samples = table_samples(spec, sub)
    mechs = bind_mechanisms(mechanisms, sub)
    disp = np.asarray(sub.displacement, dtype=float) if sub.variable_displacement else None
    base = {k: jnp.asarray(v, dtype=jnp.float64) for k, v in params.items() if v is not None}
    free = [k for k in free if k in base]

    def per_angle(z):
        p = dict(base)
        for i, k in enumerate(free):
            p[k] = base[k] + z[i]
        return jnp.stack(_angle_channels(p, spec, samples, disp, mechs))  # (channel, point, angle)

    z0 = jnp.zeros(len(free))
    parts = [np.asarray(per_angle(z0))[..., None]]
    if free:
        parts.append(np.asarray(jax.jacfwd(per_angle)(z0)))  # (channel, point, angle, parameter)
    for a in parts:
        spread = np.ptp(a, axis=2)  # over the angles
        size = np.max(np.abs(a), axis=(1, 2), keepdims=True)[:, :, 0]  # per channel (and parameter)
        if not np.all(spread <= rtol * size):  # NaN counts as varying
            return True
    return False


def bind_mechanisms(mechanisms: Sequence, table) -> tuple:
    """``mechanisms`` with those that belong to a table's points (``bound_to``, e.g. an oil
    temperature per recording) bound to the points of ``table``."""
    return tuple(m.bound_to(table) for m in mechanisms)
