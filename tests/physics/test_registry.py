"""The registry of extra mechanisms (motorid.physics): every mechanism's gradients, neutrality and physics claims."""

import math
import pickle

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from motorid import model
from motorid.physics import registry
from motorid.physics.base import Mechanism
from motorid.errors import InputError
from motorid.model import MotorSpec

SPEC = MotorSpec(name="t", pistons=9, displacement=80e-6, inertia=0.004)
BASE = {"Kv": 4000.0, "KF": 2e-3, "KFS": 1.2e-2, "TFc": 2.0, "Ks": 1.5,
        "KL0": 6e-14, "KL_a1": 0.2, "KL_b1": -0.1, "KAB": 3e-14}
RPM = 2 * math.pi / 60
BAR = 1e5

#: a non-trivial value of every mechanism parameter (gradients are taken here)
VALUES = {
    "stribeck_friction.T_s": 1.3, "stribeck_friction.K_p": 4e-3, "stribeck_friction.w_s": 0.25,
    "hydrodynamic_torque.C_h": 3e-5,
    "turbulent_leakage.C_t": 6e-10,
    "compressibility_flow.C_c": 5e-15,
    "misalignment_ripple.A1": 1.2, "misalignment_ripple.B1": -0.7,
    "misalignment_ripple.A2": 0.4, "misalignment_ripple.B2": 0.9,
    "torque_offset.T0": 1.7,
    "case_pressure_friction.K_c": 0.05,
    "pressure_viscosity.alpha": 1.5e-8,
    # spec errors and transducers (issue 15)
    "displacement_error.eps": 0.02, "leak_phase.dphi": 0.15, "inertia_error.dJ": 0.003,
    "flow_meter_gain_a.g": 0.01, "flow_meter_gain_b.g": -0.012, "flow_meter_gain_case.g": 0.03,
    "torque_meter_gain.g": -0.008,
    "flow_meter_offset_a.c": 5e-7, "flow_meter_offset_b.c": -4e-7, "flow_meter_offset_case.c": 1.5e-7,
    "sensor_lag_torque.tau": 2e-3, "sensor_lag_q_a.tau": 5e-3, "sensor_lag_q_b.tau": 4e-3,
    "sensor_lag_q_case.tau": 3e-3,
    "mixed_lubrication.C_m": 0.015, "mixed_lubrication.S_m": 2e-9,  # motorid/physics (issue 20)
    "pressure_speed_loss.C_x": 4e-10, "filling_loss.C_f": 3e-10, "pump_mode_friction.dKF": -1.2e-3,
    "film_heating.c_N": 3e-5,
    "relief_valve.P_r": 1.5e7, "relief_valve.C_r": 2e-10,  # opens inside the samples' |ΔP| range
    "gap_deformation.c": 2e-9,
}
REQUIRED = ["stribeck_friction", "hydrodynamic_torque", "turbulent_leakage", "compressibility_flow",
            "misalignment_ripple", "torque_offset"]
ALL = list(registry.CATALOG)
CHANNELS = ("torque", "q_a", "q_b", "q_case", "breakaway")


def _samples(n=48, seed=3, **over):
    """Random operating points: speeds from 0.03 to 300 rad/s in both directions, zero included."""
    rng = np.random.default_rng(seed)
    speed = rng.choice([-1.0, 1.0], n) * 10.0 ** rng.uniform(-1.5, 2.5, n)
    speed[0] = 0.0
    p_a, p_b = rng.uniform(5e5, 2.5e7, n), rng.uniform(5e5, 2.5e7, n)
    p_c = rng.uniform(0, 3e5, n)
    p_a[1] = p_c[1]  # a port exactly at case pressure (padded samples look like this)
    kw = dict(theta=rng.uniform(0, 2 * np.pi, n), speed=speed, p_a=p_a, p_b=p_b, p_case=p_c,
              viscosity=rng.uniform(0.01, 0.08, n), acceleration=rng.normal(0, 5, n))
    kw.update(over)
    return model.make_samples(SPEC, **kw)


def _params(mech, values=None):
    p = dict(BASE)
    p.update({k: VALUES[k] for k in mech.parameters} if values is None else values)
    return model.as_jax(p)


def _outputs(p, s, mechs):
    ch = model.predict(p, SPEC, s, mechs)
    events = s._replace(direction=jnp.where(s.p_a >= s.p_b, 1.0, -1.0), speed=jnp.zeros_like(s.speed))
    held = model.predict_breakaway(p, SPEC, events, mechs)
    return {"torque": ch.torque, "q_a": ch.q_a, "q_b": ch.q_b, "q_case": ch.q_case, "breakaway": held}


def _delta(mech, s, values=None):
    """What the mechanism adds to every channel [SI]."""
    p = _params(mech, values)
    with_, without = _outputs(p, s, (mech,)), _outputs(p, s, ())
    return {c: np.asarray(with_[c]) - np.asarray(without[c]) for c in CHANNELS}


def test_values_cover_every_parameter():
    names = {k for m in registry.all_mechanisms() for k in m.parameters}
    assert names == set(VALUES)


# --------------------------------------------------------------------------- interface


@pytest.mark.parametrize("mid", ALL)
def test_mechanism_describes_itself(mid):
    mech = registry.CATALOG[mid]
    assert isinstance(mech, Mechanism) and mech.id == mid
    assert mech.name and mech.reference and mech.signature
    assert mech.physics.count(". ") == 1 and mech.physics.endswith(".")  # two sentences
    assert mech.channels and set(mech.channels) <= set(CHANNELS)
    for name, info in mech.parameters.items():
        assert name.startswith(mid + ".") and info.unit and info.meaning and info.typical > 0
        assert model.parameter_info(name, [mech]) is info
    assert set(mech.neutral()) == set(mech.parameters) == set(mech.initial())
    text = mech.describe(VALUES)
    assert isinstance(text, str) and "\n" not in text and any(ch.isdigit() for ch in text)
    short = {k.split(".", 1)[1]: v for k, v in VALUES.items() if k in mech.parameters}
    assert mech.describe(short) == text
    assert isinstance(mech.describe(VALUES, spec=SPEC), str)


def test_required_mechanisms_present_and_singletons():
    assert set(REQUIRED) <= set(registry.CATALOG)
    assert len(registry.CATALOG) > len(REQUIRED)
    assert registry.all_mechanisms() == list(registry.CATALOG.values())
    for mid in ALL:
        mech = registry.get(mid)
        assert mech is registry.CATALOG[mid] and hash(mech) == hash(registry.get(mid))
        assert pickle.loads(pickle.dumps(mech)) is mech


def test_get_unknown_names_the_known_ones():
    with pytest.raises(InputError) as err:
        registry.get("coulomb_magic")
    msg = str(err.value)
    assert msg.startswith("unknown mechanism 'coulomb_magic'; known: ")
    for mid in ALL:
        assert mid in msg
    assert isinstance(err.value, ValueError)


# --------------------------------------------------------------------------- numerics


@pytest.mark.parametrize("mid", ALL)
def test_gradients_match_central_differences(mid):
    mech = registry.CATALOG[mid]
    s = _samples()
    p = _params(mech)
    names = list(mech.parameters)
    jac = jax.jacfwd(lambda q: _outputs({**p, **q}, s, (mech,)))({k: p[k] for k in names})
    for name in names:
        h = 1e-5 * abs(VALUES[name])
        plus = _outputs({**p, name: p[name] + h}, s, (mech,))
        minus = _outputs({**p, name: p[name] - h}, s, (mech,))
        for ch in CHANNELS:
            ad = np.asarray(jac[ch][name])
            fd = (np.asarray(plus[ch]) - np.asarray(minus[ch])) / (2 * h)
            assert np.all(np.isfinite(ad)), (name, ch)
            scale = np.max(np.abs(fd)) + np.max(np.abs(ad))
            if ch in mech.channels:
                assert scale > 0, f"{name} does not move {ch}"
            else:
                assert scale == 0, f"{name} moves {ch}, not among its channels"
                continue
            np.testing.assert_allclose(ad, fd, rtol=1e-5, atol=1e-6 * scale, err_msg=f"{name} → {ch}")


@pytest.mark.parametrize("mid", ALL)
def test_neutral_values_give_exactly_the_base_model(mid):
    mech = registry.CATALOG[mid]
    d = _delta(mech, _samples(), mech.neutral())
    for ch in CHANNELS:
        assert np.all(d[ch] == 0.0), ch


@pytest.mark.parametrize("mid", ALL)
def test_jit_and_vmap_agree_with_eager(mid):
    mech = registry.CATALOG[mid]
    p = _params(mech)
    batch = [_samples(n=16, seed=k) for k in range(3)]
    def combined(s):  # one array that depends on every channel
        c = model.predict(p, SPEC, s, (mech,))
        return jnp.stack([c.torque, c.q_a * 1e4, c.q_b * 1e4, c.q_case * 1e4])

    eager = np.stack([np.asarray(combined(s)) for s in batch])
    stacked = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *batch)
    np.testing.assert_allclose(np.asarray(jax.jit(jax.vmap(combined))(stacked)), eager, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("mid", ALL)
def test_typical_sizes_are_noticeable_but_modest(mid):
    """At typical values each mechanism moves its channels by 0.05-15 % over an 80 cm³/rev duty."""
    mech = registry.CATALOG[mid]
    w = np.array([0.3, 3, 30, 300, 1000, 3000]) * RPM
    dp = np.array([50.0, 150.0, 250.0]) * BAR
    ww, pp = np.meshgrid(np.r_[w, -w], dp)
    n = ww.size
    # the acceleration of a dynamometer's 0.2 % once-per-revolution speed ripple, 0.002·ω²
    s = model.make_samples(SPEC, np.linspace(0, 2 * np.pi, n), ww.ravel(), 7 * BAR + pp.ravel(),
                           np.full(n, 7 * BAR), np.full(n, 0.7 * BAR), np.full(n, 0.04),
                           acceleration=0.002 * ww.ravel() ** 2 * np.cos(np.linspace(0, 2 * np.pi, n)))
    typical = {k: v.typical for k, v in mech.parameters.items()}
    d = _delta(mech, s, typical)
    base = _outputs(_params(mech, typical), s, ())
    rel = max(np.max(np.abs(d[c])) / np.max(np.abs(np.asarray(base[c]))) for c in mech.channels)
    assert 5e-4 < rel < 0.15, rel


# --------------------------------------------------------------------------- physics claims


def _fixed(speed, *, theta=None, p_a=20e6, p_b=1e6, p_c=0.1e6, mu=0.04):
    speed = np.asarray(speed, dtype=float)
    theta = np.linspace(0, 1, speed.size) if theta is None else theta
    return model.make_samples(SPEC, theta, speed, p_a + 0 * speed, p_b + 0 * speed, p_c + 0 * speed,
                              mu + 0 * speed)


def test_stribeck_grows_as_speed_falls_opposes_motion_and_vanishes_fast():
    mech = registry.get("stribeck_friction")
    w = np.geomspace(1e-3, 300.0, 40)
    up, down = _delta(mech, _fixed(w))["torque"], _delta(mech, _fixed(-w))["torque"]
    assert np.all(up <= 0) and np.all(up[w < 3.0] < 0) and np.all(np.diff(up) >= 0)  # opposes motion, shrinks
    np.testing.assert_allclose(down, -up, rtol=1e-12)  # the same size both ways, opposing
    amp = VALUES["stribeck_friction.T_s"] + VALUES["stribeck_friction.K_p"] * SPEC.displacement * 21e6
    np.testing.assert_allclose(-up[0], amp, rtol=1e-2)  # the full excess at standstill
    assert abs(up[-1]) < 1e-12 * amp  # gone at high speed
    w_s = VALUES["stribeck_friction.w_s"]
    np.testing.assert_allclose(_delta(mech, _fixed([w_s]))["torque"], -amp / math.e, rtol=1e-12)
    lo, hi = (_delta(mech, _fixed([0.01], p_a=p, p_b=p))["torque"][0] for p in (1e6, 2e7))
    assert hi < lo < 0  # grows with P_A + P_B
    assert np.all(_delta(mech, _fixed(w))["breakaway"] == 0)


def test_hydrodynamic_torque_goes_as_speed_squared_without_viscosity():
    mech = registry.get("hydrodynamic_torque")
    w = np.array([10.0, 20.0, 100.0, 200.0, -100.0, -200.0])
    d = _delta(mech, _fixed(w))["torque"]
    np.testing.assert_allclose(d, -VALUES["hydrodynamic_torque.C_h"] * w * np.abs(w), rtol=1e-9)
    np.testing.assert_allclose(d[1] / d[0], 4.0, rtol=1e-9)
    np.testing.assert_allclose(_delta(mech, _fixed(w, mu=0.01))["torque"], d, rtol=1e-9)


def test_turbulent_leakage_goes_as_root_pressure_without_viscosity_and_balances_mass():
    mech = registry.get("turbulent_leakage")
    c = VALUES["turbulent_leakage.C_t"]
    dps = np.array([1e6, 4e6, 16e6])
    d = [_delta(mech, _fixed([5.0], p_a=0.1e6 + dp, p_b=0.1e6))["q_a"][0] for dp in dps]
    np.testing.assert_allclose(d, c * np.sqrt(dps), rtol=5e-5)  # smoothed within 0.1 bar of zero
    np.testing.assert_allclose(d[2] / d[1], 2.0, rtol=1e-5)
    s = _samples()
    d1, d2 = _delta(mech, s), _delta(mech, s._replace(viscosity=s.viscosity * 3))
    for ch in ("q_a", "q_b", "q_case"):
        np.testing.assert_allclose(d1[ch], d2[ch], rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(d1["q_a"] + d1["q_b"], d1["q_case"], rtol=1e-12)
    out = _outputs(_params(mech), s, (mech,))
    np.testing.assert_allclose(out["q_a"] + out["q_b"], out["q_case"], rtol=1e-9, atol=1e-15)
    assert np.all(d1["q_case"] > 0)  # ports above case pressure leak into the case


def test_compressibility_flow_is_absent_from_case_drain_and_goes_as_pressure_times_speed():
    mech = registry.get("compressibility_flow")
    c = VALUES["compressibility_flow.C_c"]
    w = np.array([10.0, 20.0, -10.0, -20.0])
    d = _delta(mech, _fixed(w, p_a=20e6, p_b=1e6))
    assert np.all(d["q_case"] == 0)
    np.testing.assert_allclose(d["q_b"], -d["q_a"], rtol=1e-12)
    np.testing.assert_allclose(d["q_a"], c * 19e6 * np.abs(w), rtol=1e-6)
    assert d["q_a"][0] > 0  # drawn from the high-pressure port
    d2 = _delta(mech, _fixed(w, p_a=39e6, p_b=1e6))
    np.testing.assert_allclose(d2["q_a"] / d["q_a"], 2.0, rtol=1e-9)
    np.testing.assert_allclose(d["q_a"][2:], d["q_a"][:2], rtol=1e-12)  # both directions alike
    np.testing.assert_allclose(d["q_a"][1] / d["q_a"][0], 2.0, rtol=1e-6)
    swap = _delta(mech, _fixed(w, p_a=1e6, p_b=20e6))
    np.testing.assert_allclose(swap["q_a"], -d["q_a"], rtol=1e-12)  # follows the high port


def test_misalignment_ripple_has_shaft_period_and_zero_mean():
    mech = registry.get("misalignment_ripple")
    theta = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    d = _delta(mech, _fixed(np.full(256, 1.0), theta=theta))["torque"]
    shifted = _delta(mech, _fixed(np.full(256, 1.0), theta=theta + 2 * np.pi))["torque"]
    np.testing.assert_allclose(shifted, d, atol=1e-12)
    assert abs(d.mean()) < 1e-12
    spectrum = np.abs(np.fft.rfft(d)) / 128
    v = VALUES
    np.testing.assert_allclose(spectrum[1], math.hypot(v["misalignment_ripple.A1"], v["misalignment_ripple.B1"]))
    np.testing.assert_allclose(spectrum[2], math.hypot(v["misalignment_ripple.A2"], v["misalignment_ripple.B2"]))
    assert np.all(spectrum[3:] < 1e-12)
    back = _delta(mech, _fixed(np.full(256, -1.0), theta=theta))["torque"]
    np.testing.assert_allclose(back, d, atol=1e-12)  # a function of θ, not of direction


def test_torque_offset_is_equal_in_both_directions_and_at_breakaway():
    mech = registry.get("torque_offset")
    t0 = VALUES["torque_offset.T0"]
    s = _samples()
    d = _delta(mech, s)
    np.testing.assert_allclose(d["torque"], t0, rtol=1e-12)
    np.testing.assert_allclose(d["breakaway"], t0, rtol=1e-12)
    assert np.any(np.asarray(s.direction) > 0) and np.any(np.asarray(s.direction) < 0)
    assert np.any(np.asarray(s.p_a) > np.asarray(s.p_b)) and np.any(np.asarray(s.p_a) < np.asarray(s.p_b))


def test_case_pressure_friction_follows_case_pressure_and_direction():
    mech = registry.get("case_pressure_friction")
    k = VALUES["case_pressure_friction.K_c"]
    w = np.array([5.0, -5.0])
    for p_c in (0.5e6, 1e6):
        d = _delta(mech, _fixed(w, p_c=p_c))
        np.testing.assert_allclose(d["torque"], -np.sign(w) * k * SPEC.displacement * p_c, rtol=1e-9)
    s = _samples()
    d = _delta(mech, s)
    direction = np.where(np.asarray(s.p_a) >= np.asarray(s.p_b), 1.0, -1.0)
    np.testing.assert_allclose(d["breakaway"], -direction * k * SPEC.displacement * np.asarray(s.p_case),
                               rtol=1e-9, atol=1e-12)


def test_pressure_viscosity_matches_the_barus_gap_integral():
    mech = registry.get("pressure_viscosity")
    a = VALUES["pressure_viscosity.alpha"]
    s = _samples()
    d = _delta(mech, s)
    base = _outputs(_params(mech), s, ())
    pa, pb, pc, mu = (np.asarray(x) for x in (s.p_a, s.p_b, s.p_case, s.viscosity))
    th = np.asarray(s.theta)
    kl = lambda t: BASE["KL0"] * (1 + BASE["KL_a1"] * np.cos(9 * t) + BASE["KL_b1"] * np.sin(9 * t))  # noqa: E731
    barus = lambda k, up, down: k * (np.exp(-a * down) - np.exp(-a * up)) / (a * mu)  # noqa: E731
    lin = lambda k, up, down: k * (up - down) / mu  # noqa: E731
    q_la, q_lb = barus(kl(th), pa, pc), barus(kl(th - np.pi / 9), pb, pc)
    np.testing.assert_allclose(np.asarray(base["q_case"]) + d["q_case"], q_la + q_lb, rtol=1e-9)
    d_la = q_la - lin(kl(th), pa, pc)
    d_ab = barus(BASE["KAB"], pa, pb) - lin(BASE["KAB"], pa, pb)
    np.testing.assert_allclose(d["q_a"], d_la + d_ab, rtol=1e-7, atol=1e-9 * np.max(np.abs(d_la)))
    np.testing.assert_allclose(d["q_a"] + d["q_b"], d["q_case"], rtol=1e-9, atol=1e-18)
    assert np.all(d["q_case"] <= 0)  # thicker oil leaks less
    d3 = _delta(mech, s._replace(viscosity=s.viscosity * 2))
    np.testing.assert_allclose(d3["q_case"], d["q_case"] / 2, rtol=1e-9)  # still ∝ 1/μ
    tiny = _delta(mech, s, {"pressure_viscosity.alpha": 1e-14})  # series branch: first order in α
    first = -1e-14 * (kl(th) * (pa - pc) * (pa + pc) + kl(th - np.pi / 9) * (pb - pc) * (pb + pc)) / (2 * mu)
    np.testing.assert_allclose(tiny["q_case"], first, rtol=1e-4)
