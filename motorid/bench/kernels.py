"""The one model on long sample arrays: compiled once, evaluated in fixed-size chunks.

Eager JAX compiles every primitive again for every new array length, and a
campaign has many lengths; here each evaluation is one ``jax.jit`` program of
a fixed length (:data:`CHUNK`), compiled once per motor spec and mechanism set
(and kept in the persistent compile cache), fed with padded chunks.

Inputs and outputs are dicts of 1-D arrays keyed by canonical SI column names:
``theta_rad``, ``speed_rad_s``, ``acceleration_rad_s2``, ``p_a_Pa``, ``p_b_Pa``,
``p_case_Pa``, ``viscosity_Pa_s``, ``direction``, ``oil_temp_C``, ``time_s``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from motorid import _jaxconfig  # noqa: F401
from motorid.bench.dynamics import load_driven_acceleration
from motorid.model import make_samples, predict, predict_breakaway

#: samples per compiled evaluation
CHUNK = 8192


def _samples(spec, c: dict):
    return make_samples(spec, c["theta_rad"], c["speed_rad_s"], c["p_a_Pa"], c["p_b_Pa"], c["p_case_Pa"],
                        c["viscosity_Pa_s"], c.get("acceleration_rad_s2"), direction=c["direction"],
                        temperature=c["oil_temp_C"], time=c["time_s"])


@functools.lru_cache(maxsize=16)
def _kernels(spec, mechanisms: tuple) -> dict:
    def viscosity(params, c):
        return {"viscosity_Pa_s": spec.oil.viscosity(c["oil_temp_C"])}

    def running(params, c):
        ch = predict(params, spec, _samples(spec, c), mechanisms)
        return {"torque_Nm": ch.torque, "q_a_m3_s": ch.q_a, "q_b_m3_s": ch.q_b, "q_case_m3_s": ch.q_case}

    def held(params, c):
        return {"held_Nm": predict_breakaway(params, spec, _samples(spec, c), mechanisms)}

    def acceleration(params, c):
        s = _samples(spec, {**c, "acceleration_rad_s2": jnp.zeros_like(c["theta_rad"])})
        alpha, _ = load_driven_acceleration(params, spec, mechanisms, s, c["load_torque"], c["load_inertia"])
        return {"acceleration_rad_s2": alpha}

    return {f.__name__: jax.jit(f) for f in (viscosity, running, held, acceleration)}


def evaluate(kind: str, truth, spec, columns: dict) -> dict:
    """Evaluate kernel ``kind`` (viscosity, running, held, acceleration) at every sample.

    truth : :class:`~motorid.bench.truth.Truth`; columns : 1-D arrays (or scalars)
    of one length.  Returns numpy arrays of that length.
    """
    n = max(np.size(v) for v in columns.values())
    fn = _kernels(spec, tuple(truth.mechanisms))[kind]
    params = {k: jnp.asarray(v, dtype=jnp.float64) for k, v in truth.params.items()}
    padded = -(-n // CHUNK) * CHUNK
    cols = {k: np.pad(np.broadcast_to(np.asarray(v, dtype=float), (n,)), (0, padded - n), mode="edge")
            for k, v in columns.items()}
    parts = [fn(params, {k: v[i:i + CHUNK] for k, v in cols.items()}) for i in range(0, padded, CHUNK)]
    return {k: np.concatenate([np.asarray(p[k]) for p in parts])[:n] for k in parts[0]}
