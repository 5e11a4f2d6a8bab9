"""JAX gradients of every channel against central finite differences (float64)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from motorid import model
from motorid.model import MotorSpec

SPEC = MotorSpec(name="t", pistons=9, displacement=80e-6, inertia=0.004)
P0 = {"Kv": 4000.0, "KF": 2e-3, "KFS": 1.2e-2, "TFc": 2.0, "Ks": 1.5,
      "KL0": 6e-14, "KL_a1": 0.2, "KL_b1": -0.1, "KAB": 3e-14}


def _samples(n=64, seed=1):
    rng = np.random.default_rng(seed)
    return model.make_samples(SPEC, rng.uniform(0, 2 * np.pi, n), rng.uniform(-30, 30, n),
                              rng.uniform(5e5, 2.5e7, n), rng.uniform(5e5, 2.5e7, n),
                              rng.uniform(0, 3e5, n), rng.uniform(0.01, 0.08, n),
                              acceleration=rng.normal(0, 5, n))


def _outputs(p, s):
    ch = model.predict(p, SPEC, s)
    held = model.predict_breakaway(p, SPEC, s._replace(direction=jnp.sign(s.p_a - s.p_b)))
    return {"torque": ch.torque, "q_a": ch.q_a, "q_b": ch.q_b, "q_case": ch.q_case, "breakaway": held}


@pytest.mark.parametrize("name", list(P0))
def test_gradient_matches_central_differences(name):
    s = _samples()
    p = model.as_jax(P0)
    jac = jax.jacfwd(lambda v: _outputs({**p, name: v}, s))(p[name])
    h = 1e-5 * max(abs(P0[name]), 1e-3)
    plus, minus = _outputs({**p, name: p[name] + h}, s), _outputs({**p, name: p[name] - h}, s)
    for ch in jac:
        fd = (np.asarray(plus[ch]) - np.asarray(minus[ch])) / (2 * h)
        ad = np.asarray(jac[ch])
        scale = np.max(np.abs(fd)) + np.max(np.abs(ad))
        if scale == 0:
            continue  # the channel does not depend on this parameter: both say so
        np.testing.assert_allclose(ad, fd, rtol=1e-6, atol=1e-7 * scale, err_msg=f"{name} → {ch}")


def test_gradients_are_nonzero_where_physics_says():
    s = _samples()
    p = model.as_jax(P0)
    jac = jax.jacfwd(lambda q: _outputs(q, s))(p)
    depends = {"torque": {"Kv", "KF", "TFc"}, "q_case": {"KL0", "KL_a1", "KL_b1"},
               "q_a": {"KL0", "KL_a1", "KL_b1", "KAB"}, "breakaway": {"KF", "KFS", "TFc", "Ks"}}
    for ch, names in depends.items():
        for name in P0:
            nonzero = bool(np.any(np.asarray(jac[ch][name]) != 0))
            assert nonzero == (name in names), (ch, name)
