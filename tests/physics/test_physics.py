"""Physics identities of the 1992 model (MODEL.md)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from motorid import model
from motorid.physics import flow, kinematics, oil, torque
from motorid.model import MotorSpec

PISTONS = [3, 4, 6, 7, 9, 12]


def revolution(points=20000):
    return jnp.linspace(0.0, 2 * np.pi, points, endpoint=False)


@pytest.mark.parametrize("n", PISTONS)
def test_mean_pressure_torque_is_D_dP_over_2pi(n):
    D, pa, pb = 80e-6, 2.1e7, 1.0e6
    tp = torque.pressure_torque(revolution(), pa, pb, D, n)
    assert float(jnp.mean(tp)) == pytest.approx(D * (pa - pb) / (2 * np.pi), rel=1e-7)


@pytest.mark.parametrize("n", PISTONS)
def test_mean_swept_flow_is_D_omega_over_2pi(n):
    D, w = 80e-6, 12.3
    q = flow.swept_flow_a(revolution(), w, D, n)
    assert float(jnp.mean(q)) == pytest.approx(D * w / (2 * np.pi), rel=1e-7)


@pytest.mark.parametrize("n", PISTONS)
def test_per_piston_sum_matches_eq7_and_depends_on_dp_only(n):
    th = revolution(997)
    D = 50e-6
    angles = np.asarray(kinematics.piston_angles(th, n))
    c = np.cos(angles)
    for pa, pb in [(2e7, 0.0), (2.5e7, 5e6), (1e6, 2e7)]:
        per_piston = D / (2 * n) * np.sum(np.where(c > 0, pa, pb) * c, axis=-1)
        tp = np.asarray(torque.pressure_torque(th, pa, pb, D, n))
        np.testing.assert_allclose(tp, per_piston, rtol=1e-12, atol=1e-9)
    # same ΔP, different level: same torque
    t1 = torque.pressure_torque(th, 2e7, 1e7, D, n)
    t2 = torque.pressure_torque(th, 1.2e7, 2e6, D, n)
    np.testing.assert_allclose(np.asarray(t1), np.asarray(t2), rtol=1e-12)


@pytest.mark.parametrize("n", range(2, 21))
def test_ripple_approximation_within_its_sigma(n):
    c1, c2, sigma = kinematics.ripple_coefficients(n)
    th = revolution(50000)
    exact = np.pi / n * np.asarray(kinematics.port_a_sum(th, n))
    approx = np.pi / n * np.asarray(kinematics.port_a_sum_approx(th, n, c1, c2))
    err = exact - approx
    assert abs(np.mean(err)) < 1e-2 * max(sigma, 1e-12) + 1e-12
    assert np.std(err) == pytest.approx(sigma, rel=2e-2, abs=1e-14)
    assert np.max(np.abs(err)) < 4 * sigma + 1e-12


def _spec(n=9):
    return MotorSpec(name="t", pistons=n, displacement=80e-6, inertia=0.004)


def _params():
    return model.as_jax({"Kv": 4000.0, "KF": 2e-3, "KFS": 1.2e-2, "TFc": 2.0, "Ks": 1.5,
                         "KL0": 6e-14, "KL_a1": 0.2, "KL_b1": -0.1, "KAB": 3e-14})


def _samples(spec, speed, direction=None, n=500, seed=0):
    rng = np.random.default_rng(seed)
    return model.make_samples(
        spec, theta=rng.uniform(0, 2 * np.pi, n), speed=speed,
        p_a=rng.uniform(5e5, 2.5e7, n), p_b=rng.uniform(5e5, 2.5e7, n),
        p_case=rng.uniform(0, 3e5, n), viscosity=rng.uniform(0.01, 0.08, n),
        acceleration=rng.normal(0, 5, n), direction=direction)


@pytest.mark.parametrize("n", [8, 9])
def test_mass_balance(n):
    spec = _spec(n)
    ch = model.predict(_params(), spec, _samples(spec, speed=np.linspace(-30, 30, 500)))
    np.testing.assert_allclose(np.asarray(ch.q_a + ch.q_b), np.asarray(ch.q_case), rtol=1e-12, atol=1e-18)


def test_every_loss_opposes_motion():
    spec, p = _spec(), _params()
    for w in (-20.0, -0.01, 0.01, 20.0):
        s = _samples(spec, speed=w)
        sg = np.sign(w)
        assert np.all(sg * np.asarray(torque.viscous_torque(p["Kv"], spec.displacement, s.viscosity, s.speed)) < 0)
        assert np.all(sg * np.asarray(torque.bearing_friction_torque(p["KF"], spec.displacement, s.p_a, s.p_b, s.direction)) < 0)
        assert np.all(sg * np.asarray(torque.seal_friction_torque(p["TFc"], s.direction)) < 0)
        # the delivered torque falls short of the pressure torque in the direction of motion
        no_inertia = s._replace(acceleration=jnp.zeros_like(s.speed))
        ch = model.predict(p, spec, no_inertia)
        tp = torque.pressure_torque(s.theta, s.p_a, s.p_b, spec.displacement, spec.pistons)
        assert np.all(sg * np.asarray(ch.torque - tp) < 0)
    # inertia opposes acceleration
    assert float(torque.inertia_torque(0.01, 3.0)) < 0 < float(torque.inertia_torque(0.01, -3.0))


def test_breakaway_exceeds_running_friction():
    spec, p = _spec(), _params()
    pa, pb = jnp.linspace(0, 3e7, 50), jnp.linspace(1e6, 0, 50)
    brk = model.static_friction_limit(p, spec, pa, pb)
    run = torque.running_friction(p["KF"], p["TFc"], spec.displacement, pa, pb)
    assert np.all(np.asarray(brk) > np.asarray(run))


def test_leakage_coefficient_repeats_every_piston_pitch_and_phase():
    spec, p = _spec(9), _params()
    th = revolution(1000)
    k = flow.leakage_coefficient(th, p["KL0"], [p["KL_a1"]], [p["KL_b1"]], 9)
    k2 = flow.leakage_coefficient(th + 2 * np.pi / 9, p["KL0"], [p["KL_a1"]], [p["KL_b1"]], 9)
    np.testing.assert_allclose(np.asarray(k), np.asarray(k2), rtol=1e-10)
    assert float(jnp.mean(k)) == pytest.approx(float(p["KL0"]), rel=1e-7)
    # K_LB(θ) = K_LA(θ − φ): equal port pressures → case flow of port B is port A's shifted by φ
    s = model.make_samples(spec, th, 0.0, 1e7, 1e7, 0.0, 0.04)
    ch = model.predict(p, spec, s)
    qa_leak = np.asarray(ch.q_a) - float(p["KAB"]) * 0  # Δp = 0: no cross-port flow, no swept flow
    shifted = model.predict(p, spec, model.make_samples(spec, th - spec.phase, 0.0, 1e7, 1e7, 0.0, 0.04))
    np.testing.assert_allclose(np.asarray(ch.q_b), np.asarray(shifted.q_a), rtol=1e-10)
    assert qa_leak.mean() == pytest.approx(float(p["KL0"]) * 1e7 / 0.04, rel=1e-7)


def test_oil_viscosity_walther_through_its_two_points():
    nu40, nu100, rho15 = 46.0, 6.8, 875.0
    assert float(oil.kinematic_viscosity(40.0, nu40, nu100)) == pytest.approx(46e-6, rel=1e-10)
    assert float(oil.kinematic_viscosity(100.0, nu40, nu100)) == pytest.approx(6.8e-6, rel=1e-10)
    assert float(oil.density(15.0, rho15)) == pytest.approx(rho15)
    t = jnp.linspace(0, 120, 50)
    mu = np.asarray(oil.dynamic_viscosity(t, nu40, nu100, rho15))
    assert np.all(np.diff(mu) < 0)  # thinner when hotter
    # ISO VG 46 at 20 °C is of order 120-160 cSt
    assert 100e-6 < float(oil.kinematic_viscosity(20.0, nu40, nu100)) < 180e-6


def test_ripple_approx_option_matches_mean():
    spec = _spec(7)
    th = revolution(7000)
    exact = model.predict(_params(), spec, model.make_samples(spec, th, 5.0, 2e7, 1e6, 1e5, 0.04))
    approx = model.predict(_params(), spec, model.make_samples(spec, th, 5.0, 2e7, 1e6, 1e5, 0.04, ripple="approx"))
    assert float(jnp.mean(exact.torque)) == pytest.approx(float(jnp.mean(approx.torque)), rel=1e-4)


def test_jit_and_vmap():
    spec = _spec()
    s = _samples(spec, 3.0)
    f = jax.jit(lambda p: model.predict(p, spec, s).torque)
    np.testing.assert_allclose(np.asarray(f(_params())), np.asarray(model.predict(_params(), spec, s).torque))
    batch = {k: jnp.stack([v, 1.1 * v]) for k, v in _params().items()}
    out = jax.vmap(lambda p: model.predict(p, spec, s).q_case)(batch)
    assert out.shape == (2, 500)


def test_parameter_transform_round_trip_and_positivity():
    names = model.parameter_names(2)
    p = {k: v for k, v in _params().items()}
    p.update({"KL_a2": 0.05, "KL_b2": -0.02})
    t = model.ParameterTransform(names)
    y = t.to_unconstrained(p)
    back = t.from_unconstrained(y)
    for k in names:
        assert float(back[k]) == pytest.approx(float(p[k]), rel=1e-12), k
    # any unconstrained vector maps to positive values where physics demands it
    wild = t.from_unconstrained(jnp.linspace(-50, 50, len(names)))
    for k in names:
        if model.parameter_info(k).positive:
            assert float(wild[k]) > 0, k
    # and the map is differentiable
    g = jax.grad(lambda v: t.from_unconstrained(v)["KL0"])(y)
    assert np.all(np.isfinite(np.asarray(g)))
