"""The θ-average of a table point with as few shaft angles as exact (identify/tables.py).

A table point is the model averaged over a revolution.  Where the model does not vary with θ (the
1992 model with its K_L(θ) harmonics at 0, which a table cannot identify, and any mechanism without
shaft-order terms), one angle gives the average exactly; where it varies, in value or in a
derivative along a fitted parameter, the full K angles are kept.  A map of 50 000 points needed
5 GB and a minute with K = 64 angles; with one, a few hundred MB and seconds.
"""

from __future__ import annotations

import numpy as np

from motorid.bench.maps import map_grid, simulate_map
from motorid.identify.tables import angle_samples, bind_mechanisms, fit_table, point_channels, table_samples
from motorid.io.spec import MotorSpec, OilSpec
from motorid.physics import registry

SPEC = MotorSpec("angles-45", 9, 45e-6, 0.003, oil=OilSpec(temp_C=50.0))
TRUTH = {"Kv": 5000.0, "KF": 2e-3, "KFS": 1e-2, "TFc": 1.0, "Ks": 1.0, "KL0": 4e-14, "KL_a1": 0.0,
         "KL_b1": 0.0, "KAB": 2e-14}


def _table(tmp_path, params=TRUTH, mechanisms=()):
    from motorid.io.tables import read_table

    grid = map_grid([100, 600, 1500, 2500], [30, 120, 250], 4)
    df = simulate_map(SPEC, params, grid, mechanisms=mechanisms, noise={
        "torque_Nm": 0.05, "q_a_lpm": 0.02, "q_b_lpm": 0.02, "q_case_lpm": 0.01}, rng=np.random.default_rng(4))
    df.to_csv(tmp_path / "map.csv", index=False)
    return read_table(tmp_path / "map.csv", SPEC)


def test_one_angle_where_the_model_is_angle_free_and_the_mean_is_the_same(tmp_path):
    table = _table(tmp_path)
    one = angle_samples(SPEC, table, (), TRUTH, ("Kv", "KF", "TFc", "KL0", "KAB"))
    full = table_samples(SPEC, table)
    assert one.theta.shape == (len(table), 1) and full.theta.shape[1] >= 64
    a, b = point_channels(TRUTH, SPEC, one), point_channels(TRUTH, SPEC, full)
    for x, y in zip(a, b):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-12, atol=1e-300)


def test_every_angle_where_a_value_or_a_derivative_varies_with_it(tmp_path):
    table = _table(tmp_path)
    ripple = registry.get("misalignment_ripple")  # torque ripple at 1× and 2× shaft order
    zero = {**TRUTH, **{k: 0.0 for k in ripple.parameters}}
    assert angle_samples(SPEC, table, (ripple,), zero, ()).theta.shape[1] == 1  # held at 0: no ripple
    # held at a value: the torque varies over the revolution
    held = {**zero, "misalignment_ripple.A1": 0.5}
    assert angle_samples(SPEC, table, (ripple,), held, ()).theta.shape[1] > 1
    # fitted, from 0: its value does not vary, its derivative does
    assert angle_samples(SPEC, table, (ripple,), zero, tuple(ripple.parameters)).theta.shape[1] > 1
    # a mechanism with no θ in it keeps one angle
    churn = registry.get("hydrodynamic_torque")
    p = {**TRUTH, **{k: info.typical for k, info in churn.parameters.items()}}
    assert angle_samples(SPEC, table, (churn,), p, tuple(churn.parameters)).theta.shape[1] == 1


def test_a_fit_on_one_angle_equals_the_fit_on_every_angle(tmp_path, monkeypatch):
    import motorid.identify.tables as tables

    table = _table(tmp_path)
    fast = fit_table(table, SPEC)
    monkeypatch.setattr(tables, "angle_samples", lambda spec, table, *a, **k: table_samples(spec, table))
    slow = fit_table(table, SPEC)
    for k in ("Kv", "KF", "TFc", "KL0", "KAB"):
        assert abs(fast.ls.params_all[k] - slow.ls.params_all[k]) <= 1e-7 * abs(slow.ls.params_all[k]), k
        assert abs(fast.ls.std[k] - slow.ls.std[k]) <= 1e-6 * slow.ls.std[k], k
    ch = point_channels(fast.ls.params_all, SPEC, table_samples(SPEC, table), None, bind_mechanisms((), table))
    np.testing.assert_allclose(np.asarray(ch.torque), fast.table_prediction["torque"], rtol=1e-10)


def test_tables_of_one_size_class_run_one_compiled_residual(tmp_path):
    """The table's points, the held values and the spec's numbers are inputs of the compiled
    residual, not constants in it: two tables of other sizes (36 and 48 points, both padded to 64),
    another motor's numbers, lower to the same program, and each fit gets its own answer."""
    import dataclasses

    from motorid.identify.table_residual import TableResidual

    from motorid.io.tables import read_table

    def problem(spec, grid, truth, name):
        df = simulate_map(spec, truth, grid, noise={"torque_Nm": 0.05, "q_a_lpm": 0.02},
                          rng=np.random.default_rng(len(grid)))
        df.to_csv(tmp_path / name, index=False)
        table = read_table(tmp_path / name, spec)
        names = ["Kv", "KF", "TFc", "KL0", "KAB", "KFS", "Ks", "KL_a1", "KL_b1"]
        free = ["Kv", "KF", "TFc", "KL0", "KAB"]
        held = {"KFS": 1e-2, "Ks": 1.0 + len(grid), "KL_a1": 0.0, "KL_b1": 0.0}
        prob = TableResidual(spec, table, names, free, held, [5e3, 2e-3, 1.0, 4e-14, 2e-14], ())
        w = {c: np.ones(len(table)) for c in ("torque", "q_a", "q_b", "q_case")}
        return prob, w

    a, wa = problem(SPEC, map_grid([100, 600, 1500], [30, 120, 250], 4), TRUTH, "a.csv")
    other = dataclasses.replace(SPEC, name="other", displacement=63e-6, inertia=0.01)
    b, wb = problem(other, map_grid([100, 600, 1500, 2500], [30, 120, 250], 4), {**TRUTH, "Kv": 7000.0}, "b.csv")
    assert a.n == 36 and b.n == 48 and len(a._pad(wa)["torque"]) == len(b._pad(wb)["torque"]) == 64
    x = np.ones(5)
    text = [p._evaluate.lower(x, p._pad(w), {}, p._data, p._held, p.spec).as_text() for p, w in ((a, wa), (b, wb))]
    assert text[0] == text[1]
    ra, rb = np.asarray(a.residual(x, wa, {})), np.asarray(b.residual(x, wb, {}))
    assert ra.shape == rb.shape and not np.allclose(ra, rb)
    assert len(a.table_pred(x)["torque"]) == 36  # the padding cut off


def test_a_sensor_lag_leaves_every_table_point_as_it_was_and_is_not_tried_there(tmp_path):
    """A first-order lag flattens and delays the ripple over shaft angle; its mean over a revolution,
    all a steady point holds, is the unlagged one. Diagnose says so instead of fitting it (every angle,
    a τ that no table point can show)."""
    table = _table(tmp_path)
    full = table_samples(SPEC, table)
    without = point_channels(TRUTH, SPEC, full)
    for ch in ("torque", "q_a", "q_b", "q_case"):
        lag = registry.get(f"sensor_lag_{ch}")
        assert "mean untouched" in lag.unseen_in_table(table)
        lagged = point_channels({**TRUTH, f"sensor_lag_{ch}.tau": 5e-3}, SPEC, full, None, (lag,))
        for a, b in zip(lagged, without):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=1e-9 * np.max(np.abs(b)))


def test_the_probe_looks_where_a_theta_term_is_largest(tmp_path):
    """A θ-term can be zero at most points (a lag's change scales with the speed and the pressures):
    a table of 40 points at rest and one running point between the evenly spread probe points still
    gets every angle where a held lag varies there."""
    from motorid.io.tables import read_table

    grid = np.zeros((41, 3))
    grid[20] = (1500.0, 200.0, 0.0)  # rpm, bar, bar: not one of the 12 evenly spread points of 41
    simulate_map(SPEC, TRUTH, grid).to_csv(tmp_path / "rest.csv", index=False)
    table = read_table(tmp_path / "rest.csv", SPEC)
    lag = registry.get("sensor_lag_q_a")
    assert angle_samples(SPEC, table, (lag,), {**TRUTH, "sensor_lag_q_a.tau": 5e-3}, ()).theta.shape[1] > 1
    assert angle_samples(SPEC, table, (lag,), {**TRUTH, "sensor_lag_q_a.tau": 0.0}, ()).theta.shape[1] == 1


def test_each_mechanism_declared_angle_free_is_so_by_the_probe(tmp_path):
    """A mechanism declared ``angle_free`` is left out of the θ-probe (its θ only through the 1992
    model's S(θ) and K_L(θ)): the probe itself, with the mechanism in the model, its parameters
    nonzero and free, must find the model θ-free where the base model is; and with the base's
    K_L(θ) harmonics nonzero the declared mechanism does not hide them."""
    from motorid.identify import table_model

    table = _table(tmp_path)
    base_free = ("Kv", "KF", "TFc", "KL0", "KAB")
    declared, probed = [], []
    for mech in registry.all_mechanisms():
        values = {k: (info.typical or 0.1) for k, info in mech.parameters.items()}
        p = {**TRUTH, **values}
        varies = table_model._probe_angle(SPEC, table, bind_mechanisms((mech,), table), p,
                                          base_free + tuple(values), 1e-9)
        (declared if mech.angle_free else probed).append(mech.id)
        assert not (mech.angle_free and varies), mech.id
        if mech.angle_free:
            # the base's harmonics still make the table's points vary, the mechanism declared or not
            assert angle_samples(SPEC, table, (mech,), {**p, "KL_a1": 0.2}, base_free).theta.shape[1] > 1, mech.id
    # the shaft-order terms are probed: the ripple and a lagged transducer's ripple
    assert {"misalignment_ripple", "sensor_lag_torque", "sensor_lag_q_a"} <= set(probed)
    assert len(declared) >= 20
