"""Operating-point tables: reading, the θ-averaged fit, joint fits with logs, predict, comparators."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pandas as pd
import pytest

from motorid.bench.maps import map_grid, simulate_map
from motorid.model import MotorSpec, OilSpec

TRUTH = {"Kv": 5000.0, "KF": 3e-3, "KFS": 1.5e-2, "TFc": 3.0, "Ks": 1.0, "KL0": 5e-14, "KL_a1": 0.15,
         "KL_b1": 0.08, "KAB": 2e-14}
NOISE = {"torque_Nm": 0.3, "q_a_lpm": 0.05, "q_b_lpm": 0.05, "q_case_lpm": 0.02}
SPEC = MotorSpec("map-9", 9, 80e-6, 0.005, oil=OilSpec(temp_C=50.0))
RECOVERED = ("Kv", "KF", "TFc", "KL0", "KAB")


def _write(df: pd.DataFrame, path):
    df.to_csv(path, index=False)
    return path


@lru_cache(maxsize=4)
def _map(quadrants=4, seed=1, variable=False):
    g = map_grid([100, 400, 1000, 2000], [20, 100, 200, 300], quadrants)
    disp = None
    if variable:
        disp = np.tile([40.0, 60.0, 80.0], len(g) // 3 + 1)[: len(g)]
    return simulate_map(SPEC, TRUTH, g, noise=NOISE, rng=np.random.default_rng(seed), displacement_cm3=disp)


@pytest.fixture(scope="module")
def table_fit(tmp_path_factory):
    from motorid.identify.tables import fit_table
    from motorid.io.tables import read_table

    path = _write(_map(), tmp_path_factory.mktemp("map") / "map.csv")
    table = read_table(path, SPEC)
    return table, fit_table(table, SPEC)


def test_table_fit_recovers_parameters_and_says_what_it_cannot(table_fit):
    _, tf = table_fit
    ls = tf.ls
    for k in RECOVERED:
        assert ls.identifiable[k], k
        assert abs(ls.values[k] - TRUTH[k]) < 3 * ls.std[k], (k, ls.values[k], ls.std[k])
        assert ls.std[k] < 0.1 * TRUTH[k]  # and the table does pin it down
    for k in ("KFS", "Ks"):
        assert not ls.identifiable[k] and ls.values[k] is None and "breakaway" in ls.reasons[k]
    for k in ("KL_a1", "KL_b1"):
        assert not ls.identifiable[k] and ls.values[k] is None and "shaft angle" in ls.reasons[k]
    # noise levels from the residuals: within 30 % of what was added
    assert tf.table_noise["torque"] == pytest.approx(NOISE["torque_Nm"], rel=0.3)
    assert tf.table_noise["q_case"] == pytest.approx(NOISE["q_case_lpm"] * 1e-3 / 60, rel=0.3)


def test_a_positive_parameter_the_data_do_not_tell_from_zero_gets_an_interval_cut_at_zero():
    """K_v at a thousandth of its usual size is lost in the torque noise: its std exceeds its value.
    Its 95 % interval stops at 0 (a positive parameter ends there) and says so, in result.json, the
    text summary and the report, while a parameter the data pin down keeps its symmetric interval."""
    from motorid.identify.results import result_document
    from motorid.identify.tables import fit_table
    from motorid.report.summary import format_fit

    truth = {**TRUTH, "Kv": 5.0}
    g = map_grid([100, 400, 1000, 2000], [20, 100, 200, 300], 4)
    df = simulate_map(SPEC, truth, g, noise=NOISE, rng=np.random.default_rng(3))
    tf = fit_table(read_table_frame(df), SPEC)
    doc = result_document(tf.ls, SPEC)
    kv, kf = doc["parameters"]["Kv"], doc["parameters"]["KF"]
    assert kv["identifiable"] and kv["std"] > kv["value"] > 0, kv
    assert kv["ci95"][0] == 0.0 and kv["ci95"][1] == pytest.approx(kv["value"] + 1.959964 * kv["std"], rel=1e-5)
    assert kv["indistinct_from_zero"] and "zero" in kv["note"]
    assert "indistinct_from_zero" not in kf and kf["ci95"][0] == pytest.approx(kf["value"] - 1.959964 * kf["std"],
                                                                               rel=1e-5)
    line = next(l for l in format_fit(doc).splitlines() if l.startswith("Kv "))
    assert "not told from 0" in line


def read_table_frame(df):
    """A table from a data frame, through the reader (a temporary CSV)."""
    import tempfile
    from pathlib import Path

    from motorid.io.tables import read_table

    with tempfile.TemporaryDirectory() as d:
        return read_table(_write(df, Path(d) / "map.csv"), SPEC)


def test_theta_average_matches_the_mean_pressure_torque():
    """The θ-average of the one model's pressure torque and swept flow is DΔP/2π and Dω/2π (Eq. 16, 43)."""
    from motorid.identify.tables import point_channels, table_samples
    from motorid.io.tables import PointTable

    n = 3
    z = {c: np.full(n, np.nan) for c in ("torque", "q_a", "q_b", "q_case")}
    t = PointTable(np.array(["a", "b", "c"], dtype=object), np.array([10.0, -50.0, 100.0]),
                   np.array([2e7, 1e6, 0.0]), np.array([0.0, 5e6, 1e7]), np.zeros(n), np.full(n, 50.0),
                   np.full(n, 0.03), np.full(n, SPEC.displacement), z, {c: np.ones(n) for c in z},
                   np.array(["x"] * n, dtype=object), np.arange(n))
    zero = {k: 0.0 for k in TRUTH}
    ch = point_channels(zero, SPEC, table_samples(SPEC, t))
    D = SPEC.displacement
    np.testing.assert_allclose(np.asarray(ch.torque), D * (t.p_a - t.p_b) / (2 * np.pi), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(ch.q_a), D * t.speed / (2 * np.pi), rtol=1e-12)


def test_torque_only_table_leaves_flow_parameters_unidentified(tmp_path):
    from motorid.identify.tables import fit_table
    from motorid.io.tables import read_table

    df = _map().drop(columns=["q_a_lpm", "q_b_lpm", "q_case_lpm"])
    tf = fit_table(read_table(_write(df, tmp_path / "t.csv"), SPEC), SPEC)
    for k in ("KL0", "KAB"):
        assert not tf.ls.identifiable[k] and "flow" in tf.ls.reasons[k]
    for k in ("Kv", "KF", "TFc"):
        assert abs(tf.ls.values[k] - TRUTH[k]) < 3 * tf.ls.std[k]


def test_case_flow_only_cannot_give_cross_port_leakage(tmp_path):
    from motorid.identify.tables import fit_table
    from motorid.io.tables import read_table

    df = _map().drop(columns=["q_a_lpm", "q_b_lpm"])
    tf = fit_table(read_table(_write(df, tmp_path / "t.csv"), SPEC), SPEC)
    assert tf.ls.identifiable["KL0"] and not tf.ls.identifiable["KAB"]


def test_dp_form_gives_the_same_fit_as_port_pressures(tmp_path):
    from motorid.identify.tables import fit_table
    from motorid.io.tables import read_table

    g = map_grid([200, 1000, 2000], [50, 150, 300], 2)  # the low-pressure port at 0 at every point
    df = simulate_map(SPEC, TRUTH, g, noise=NOISE, rng=np.random.default_rng(3))
    ports = read_table(_write(df, tmp_path / "ports.csv"), SPEC)
    dp = df.assign(dp_bar=df.p_a_bar - df.p_b_bar).drop(columns=["p_a_bar", "p_b_bar"])
    dp_t = read_table(_write(dp, tmp_path / "dp.csv"), SPEC)
    neg = dp_t.p_b > 0  # ΔP < 0 is read as P_A = 0, P_B = −ΔP: port B high, never below vacuum
    np.testing.assert_allclose(dp_t.p_a - dp_t.p_b, ports.p_a - ports.p_b)
    np.testing.assert_allclose(dp_t.p_a, ports.p_a)
    assert neg.any() and np.all(dp_t.p_a[neg] == 0) and np.all(dp_t.p_b[~neg] == 0)
    a = fit_table(ports, SPEC).ls
    b = fit_table(dp_t, SPEC).ls
    for k in RECOVERED:
        assert b.values[k] == pytest.approx(a.values[k], rel=1e-6)


def test_per_point_displacement_of_a_variable_unit(tmp_path):
    from motorid.identify.tables import fit_table
    from motorid.io.tables import read_table

    df = _map(variable=True)
    t = read_table(_write(df, tmp_path / "v.csv"), SPEC)
    assert t.variable_displacement and set(np.round(t.displacement * 1e6)) == {40.0, 60.0, 80.0}
    tf = fit_table(t, SPEC)
    for k in RECOVERED:
        assert abs(tf.ls.values[k] - TRUTH[k]) < 3 * tf.ls.std[k], k
    # the same numbers read as a fixed 80 cm³/rev unit miss the torque by far more than the noise
    fixed = fit_table(read_table(_write(df.drop(columns=["displacement_cm3"]), tmp_path / "f.csv"), SPEC), SPEC)
    assert fixed.table_noise["torque"] > 20 * tf.table_noise["torque"]


def test_std_and_count_columns_weight_the_points(tmp_path):
    from motorid.io.tables import read_table

    df = _map().copy()
    df["n_samples"] = 100
    df.loc[:5, "n_samples"] = 400
    df["torque_std_Nm"] = 2.0
    t = read_table(_write(df, tmp_path / "w.csv"), SPEC)
    s = t.relative_sigma["torque"]
    assert s[0] == pytest.approx(0.5 * s[10]) and t.weights_from["torque"] == "std columns and n_samples"


def test_joint_fit_of_table_and_logs(tmp_path):
    """Logs give what a table cannot (K_FS, K_s, the harmonics); both give the rest, more precisely together."""
    from conftest import simulated

    from motorid.identify.least_squares import fit_least_squares
    from motorid.identify.extract import extract
    from motorid.identify.tables import fit_table
    from motorid.io.tables import read_table

    frame, spec, truth = simulated(protocols=("constant_speed", "startability"))
    spec = MotorSpec(spec.name, spec.pistons, spec.displacement, spec.inertia, oil=OilSpec(temp_C=50.0))
    ds = extract(frame, spec)
    logs = fit_least_squares(ds, spec)
    table = read_table(_write(_map(2, seed=5), tmp_path / "m.csv"), spec)
    joint = fit_table(table, spec, dataset=ds, log_fit=logs).ls
    alone = fit_table(table, spec).ls
    for k in ("KFS", "Ks", "KL_a1", "KL_b1"):
        assert joint.identifiable[k] and abs(joint.values[k] - truth[k]) < 3 * joint.std[k], k
    for k in RECOVERED:
        assert abs(joint.values[k] - truth[k]) < 3 * joint.std[k], k
        assert joint.std[k] <= 1.01 * min(alone.std[k], logs.std[k] or np.inf), k


def test_predict_columns_and_band_coverage(table_fit, tmp_path):
    from motorid.identify.predict import predict_points
    from motorid.identify.results import result_document
    from motorid.identify.tables import point_channels, table_samples, table_document
    from motorid.io.tables import read_table

    table, tf = table_fit
    doc = result_document(tf.ls, SPEC)
    doc["table"] = table_document(tf)
    g = map_grid([150, 700, 1500], [40, 150, 250], 4)
    truth_df = simulate_map(SPEC, TRUTH, g)  # noise-free: the model's true mean
    pts = truth_df[["point_id", "speed_rpm", "p_a_bar", "p_b_bar"]]
    pts_t = read_table(_write(pts, tmp_path / "pts.csv"), SPEC, require_outputs=False)
    out = predict_points((doc, SPEC, ()), pts_t)
    for col in ("torque_Nm", "q_a_lpm", "q_b_lpm", "q_case_lpm", "volumetric_efficiency",
                "hydromechanical_efficiency", "overall_efficiency"):
        assert {col, col + "_lo95", col + "_hi95"} <= set(out.columns)
        assert np.all(out[col + "_lo95"] <= out[col]) and np.all(out[col] <= out[col + "_hi95"])
    assert list(out["point_id"]) == list(pts["point_id"])
    for col in ("torque_Nm", "q_a_lpm", "q_case_lpm"):
        inside = (truth_df[col] >= out[col + "_lo95"]) & (truth_df[col] <= out[col + "_hi95"])
        assert inside.mean() >= 0.75, (col, inside.mean())
        assert np.all(out[col + "_pi_hi95"] - out[col + "_pi_lo95"] > out[col + "_hi95"] - out[col + "_lo95"])
    # efficiencies from the truth agree with the predicted ones within their bands for most points
    from motorid.physics.efficiency import efficiencies

    ch = point_channels(TRUTH, SPEC, table_samples(SPEC, pts_t))
    ev = np.asarray(efficiencies(ch.torque, ch.q_a, ch.q_b, pts_t.speed, pts_t.p_a, pts_t.p_b, pts_t.displacement)[0])
    inside = (ev >= out["volumetric_efficiency_lo95"]) & (ev <= out["volumetric_efficiency_hi95"])
    assert inside.mean() >= 0.75


def test_efficiency_identities_in_motor_and_pump_mode():
    from motorid.physics.efficiency import efficiencies

    D = 80e-6
    w, dp = 100.0, 2e7
    qth, tth = D * w / (2 * np.pi), D * dp / (2 * np.pi)
    # motor: flow in 5 % above swept, torque 10 % below ideal
    ev, ehm, e = efficiencies(0.9 * tth, 1.05 * qth, -qth, w, dp, 0.0, D)
    assert ev == pytest.approx(1 / 1.05) and ehm == pytest.approx(0.9) and e == pytest.approx(0.9 / 1.05)
    # pump (ΔP < 0 at ω > 0: port B high): 4 % less flow out of B than swept, 8 % more torque in
    ev, ehm, e = efficiencies(-1.08 * tth, qth, -0.96 * qth, w, 0.0, dp, D)
    assert ev == pytest.approx(0.96) and ehm == pytest.approx(1 / 1.08) and e == pytest.approx(0.96 / 1.08)
    assert np.isnan(efficiencies(1.0, 1.0, 1.0, 0.0, dp, 0.0, D)[2])


def _law_table(model=None, coef: dict | None = None):
    """A 4-quadrant grid; with ``coef``, noise-free channels generated by ``model``'s own law
    (its basis times the coefficients)."""
    from motorid.comparators.base import Operating, channels_from_losses
    from motorid.io.tables import PointTable

    g = map_grid([50, 300, 800, 1500, 2500], [10, 60, 150, 250, 350], 4)
    df = pd.DataFrame(g, columns=["speed_rpm", "p_a_bar", "p_b_bar"]).assign(point_id=[f"P{i}" for i in range(len(g))])
    n = len(df)
    nan = {c: np.full(n, np.nan) for c in ("torque", "q_a", "q_b", "q_case")}
    t = PointTable(df.point_id.to_numpy(), df.speed_rpm.to_numpy() * np.pi / 30, df.p_a_bar.to_numpy() * 1e5,
                   df.p_b_bar.to_numpy() * 1e5, np.zeros(n), np.full(n, 50.0), np.full(n, 0.026),
                   np.full(n, SPEC.displacement), nan, {c: np.ones(n) for c in nan}, np.array(["x"] * n, dtype=object),
                   np.arange(n))
    if coef:
        op = Operating(t)
        loss = {k: model._terms("torque" if k == "torque" else "flow", op, model.shapes[len(model.shapes) // 2]) @ c
                for k, c in coef.items()}
        t.measured = channels_from_losses(op, loss)
    return t


@pytest.mark.parametrize("name", ["Wilson", "Schloesser", "McCandlishDorey", "Jeong"])
def test_each_comparator_recovers_its_own_law(name):
    import motorid.comparators as comp

    from motorid.comparators.base import Operating

    model = getattr(comp, name)()
    rng = np.random.default_rng(7)
    op = Operating(_law_table())
    h = model.shapes[len(model.shapes) // 2]
    n_t = model._terms("torque", op, h).shape[1]
    n_f = model._terms("flow", op, h).shape[1]
    # coefficients of sizes that make each term a few % of the ideal torque and flow
    A_t, A_f = model._terms("torque", op, h), model._terms("flow", op, h)
    t_ideal = np.max(np.abs(op.d * op.dp))
    q_ideal = np.max(np.abs(op.d * op.omega))
    coef = {"torque": 0.02 * t_ideal * rng.uniform(0.5, 1.5, n_t) / np.max(np.abs(A_t), axis=0)}
    for key in ("hp", "lp", "case"):
        coef[key] = 0.01 * q_ideal * rng.uniform(0.5, 1.5, n_f) / np.max(np.abs(A_f), axis=0)
    t = _law_table(model, coef)
    fitted = getattr(comp, name)().fit(t)
    pred = fitted.predict(t)
    for c in ("torque", "q_a", "q_b", "q_case"):
        span = np.ptp(t.measured[c])
        assert np.max(np.abs(pred[c] - t.measured[c])) < 1e-8 * span, c
    for key in coef:
        np.testing.assert_allclose(fitted.coef[key], coef[key], rtol=1e-12)
    # and Wilson's law cannot follow a richer law: the test could fail
    if name == "McCandlishDorey":
        w = comp.Wilson().fit(t).predict(t)
        assert np.max(np.abs(w["torque"] - t.measured["torque"])) > 1e-3 * np.ptp(t.measured["torque"])


def test_jeong_takes_no_speed_scale_its_fitted_points_cannot_see():
    """Fitted on fast points only, Jeong's e^{−|ω|/ω_s} with a small ω_s is 10⁻⁴⁵ there: such a
    scale is not tried (it got a coefficient of 10⁴⁰ and predicted 10²⁸ % of span at slow points)."""
    from motorid.comparators import Jeong
    from motorid.comparators.base import Operating

    t = _law_table()
    op = Operating(t)
    t.measured = {c: np.asarray(v, float) for c, v in t.measured.items()}
    t.measured["torque"] = op.d * op.dp + 0.3 * np.sign(op.omega) * np.random.default_rng(3).standard_normal(len(t))
    fast = np.abs(op.omega) > np.median(np.abs(op.omega))
    model = Jeong().fit(t.subset(fast))
    w_min = np.min(np.abs(op.omega[fast]))
    assert np.exp(-w_min / model.shape["torque"]) >= 1e-2
    pred = model.predict(t.subset(~fast))["torque"]
    assert np.all(np.abs(pred - t.measured["torque"][~fast]) < 0.05 * np.ptp(t.measured["torque"]))


def test_polynomial_map_recovers_a_polynomial_and_picks_its_degree():
    from motorid.comparators import Polynomial
    from motorid.comparators.base import Operating, channels_from_losses

    t = _law_table()
    op = Operating(t)
    x, y = op.P / op.P.max(), op.W / op.W.max()
    law = lambda a, b, c: a + b * x * y + c * x**2  # noqa: E731  degree 2
    loss = {"torque": law(2.0, 5.0, 3.0), "hp": law(1e-5, 2e-5, 1e-5), "lp": law(-1e-6, -2e-6, 1e-6),
            "case": law(2e-6, 1e-6, 3e-6)}
    t.measured = channels_from_losses(op, loss)
    p = Polynomial().fit(t)
    assert all(h[0] == 2 for h in p.shape.values())
    pred = p.predict(t)
    for c in ("torque", "q_a", "q_case"):
        assert np.max(np.abs(pred[c] - t.measured[c])) < 1e-8 * np.ptp(t.measured[c])


def test_kfold_machinery_on_a_known_answer():
    """A model that predicts its training mean: its K-fold error has a closed form."""
    from motorid.comparators.evaluate import extrapolation_split, held_out, kfold_indices

    folds = kfold_indices(23, 5)
    allidx = np.concatenate(folds)
    assert sorted(allidx) == list(range(23)) and len(folds) == 5
    tr, te = extrapolation_split(np.arange(1.0, 11.0))
    assert list(np.flatnonzero(tr)) == list(range(6)) and te.sum() == 4

    class Mean:
        def fit(self, table):
            self.m = {c: np.nanmean(v) if np.isfinite(v).any() else np.nan for c, v in table.measured.items()}
            return self

        def predict(self, table):
            return {c: np.full(len(table), self.m[c]) for c in self.m}

    t = _law_table()
    y = np.random.default_rng(2).normal(size=len(t))
    t.measured = {"torque": y, "q_a": y * 2, "q_b": np.full(len(t), np.nan), "q_case": y + 1}
    res = held_out(Mean(), t, k=5)
    expect = np.empty(len(t))
    for f in kfold_indices(len(t), 5):
        expect[f] = y[f] - np.delete(y, f).mean()
    rms = np.sqrt(np.mean(expect**2))
    assert res["kfold"]["torque"]["rms"] == pytest.approx(rms, rel=1e-12)
    assert res["kfold"]["q_a"]["rms"] == pytest.approx(2 * rms, rel=1e-12)
    assert res["kfold"]["torque"]["percent_of_span"] == pytest.approx(100 * rms / np.ptp(y))
    assert "q_b" not in res["kfold"]
    groups = np.arange(len(t)) % 3  # leave one group out: each group predicted by the others' mean
    res = held_out(Mean(), t, k=5, groups=groups)
    expect = np.array([y[i] - y[groups != groups[i]].mean() for i in range(len(t))])
    assert res["leave_one_group_out"]["torque"]["rms"] == pytest.approx(np.sqrt(np.mean(expect**2)), rel=1e-12)


@pytest.mark.parametrize("edit,words", [
    (lambda df: df.drop(columns=["speed_rpm"]), "'speed_rpm'"),
    (lambda df: df.assign(torque_Nm=df.torque_Nm.astype(object).where(df.index != 3, "n/a?")), "'torque_Nm', line 5"),
    (lambda df: df.assign(p_a_bar=df.p_a_bar.where(df.index != 2, np.inf)), "'p_a_bar', line 4: 'inf' is no reading"),
    (lambda df: df.iloc[:2], "2 points: too few to identify any parameter"),
])
def test_bad_table_one_line_exit_2(tmp_path, capsys, edit, words):
    from motorid.cli import main

    path = _write(edit(_map()), tmp_path / "bad.csv")
    motor = tmp_path / "m.toml"
    motor.write_text(SPEC.to_toml())
    rc = main(["fit", str(path), "--motor", str(motor), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and str(path) in err and words in err
    assert not (tmp_path / "out").exists()


def test_fit_and_predict_commands(tmp_path, capsys):
    import json

    from motorid.cli import main

    path = _write(_map(), tmp_path / "map.csv")
    motor = tmp_path / "m.toml"
    motor.write_text(SPEC.to_toml())
    assert main(["fit", str(path), "--motor", str(motor), "--out", str(tmp_path / "fit")]) == 0
    doc = json.loads((tmp_path / "fit" / "result.json").read_text())
    models = doc["comparison"]["models"]
    assert {"motorid", "Wilson (1950)", "polynomial map"} <= set(models)
    # on data from its own model motorid predicts held-out torque at least as well as Wilson's law
    assert models["motorid"]["kfold"]["torque"]["rms"] <= models["Wilson (1950)"]["kfold"]["torque"]["rms"]
    assert main(["report", str(tmp_path / "fit")]) == 0  # re-rendered from result.json and the table
    page = (tmp_path / "fit" / "report.html").read_text()
    assert 'id="comparison-table"' in page and 'id="efficiency-maps"' in page and "data:image/png" in page
    pts = _map()[["point_id", "speed_rpm", "p_a_bar", "p_b_bar"]]
    pts_path = _write(pts, tmp_path / "pts.csv")
    assert main(["predict", str(tmp_path / "fit"), str(pts_path), "--out", str(tmp_path / "p.csv")]) == 0
    pred = pd.read_csv(tmp_path / "p.csv")
    assert len(pred) == len(pts) and pred["torque_Nm"].notna().all()
    resid = _map()["torque_Nm"] - pred["torque_Nm"]
    assert np.sqrt(np.mean(resid**2)) < 2 * NOISE["torque_Nm"]
    # points beside a bench's logs and their channels.toml (which maps time_s) are not read through
    # that map: it is the logs' (a probe's points file was refused as 'a time series')
    beside = tmp_path / "bench"
    beside.mkdir()
    (beside / "channels.toml").write_text("""[file]
group = "runs/*"
[constants]
protocol = {attribute = "test"}
[channels]
""" + "".join(f'{k} = {{name = "{k.split("_")[0]}{i}", unit = "{u}"}}\n' for i, (k, u) in enumerate(
        [("time_s", "ms"), ("shaft_angle_deg", "rad"), ("speed_rpm", "rad/s"), ("torque_Nm", "lbf*ft"),
         ("p_a_bar", "psi"), ("p_b_bar", "psi"), ("p_case_bar", "psi"), ("q_a_lpm", "gpm"), ("q_b_lpm", "gpm"),
         ("q_case_lpm", "gpm"), ("oil_temp_C", "F")])))
    assert main(["predict", str(tmp_path / "fit"), str(_write(pts, beside / "pts.csv")), "--out",
                 str(tmp_path / "b.csv")]) == 0
    assert np.allclose(pd.read_csv(tmp_path / "b.csv")["torque_Nm"], pred["torque_Nm"])
    # predictions are keyed by point_id: an id that names two points is refused in one line, nothing written
    twice = pts.copy()
    twice.loc[3, "point_id"] = twice.loc[2, "point_id"]
    twice_path = _write(twice, tmp_path / "twice.csv")
    capsys.readouterr()
    assert main(["predict", str(tmp_path / "fit"), str(twice_path), "--out", str(tmp_path / "q.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert f"twice.csv: column 'point_id': '{twice.loc[2, 'point_id']}' names 2 points" in err
    assert "line 4" in err and "line 5" in err and not (tmp_path / "q.csv").exists()
    # a fit takes the repeats as separate points, and says the id repeats
    full = _map()
    full.loc[3, "point_id"] = full.loc[2, "point_id"]
    assert main(["fit", _write(full, tmp_path / "rep.csv").as_posix(), "--motor", str(motor), "--out",
                 str(tmp_path / "fit2")]) == 0
    assert "names more than one point" in capsys.readouterr().out


def test_diagnose_on_a_table_names_the_missing_physics(tmp_path):
    """A map with churning torque (ω²): the forward selection picks it, not a flow law, and a
    shaft-order ripple (nothing to show in a θ-average) is never a candidate it can fit."""
    from motorid.physics.registry import get
    from motorid.discrepancy.tables import diagnose_table
    from motorid.io.tables import read_table

    hydro = get("hydrodynamic_torque")
    truth = dict(TRUTH, **{"hydrodynamic_torque.C_h": 1e-4})
    g = map_grid([100, 500, 1000, 2000, 3000], [20, 100, 200, 300], 2)
    df = simulate_map(SPEC, truth, g, mechanisms=(hydro,), noise=NOISE, rng=np.random.default_rng(4))
    table = read_table(_write(df, tmp_path / "h.csv"), SPEC)
    cands = [get("turbulent_leakage"), hydro, get("misalignment_ripple")]
    dg = diagnose_table(table, SPEC, candidates=cands, max_mechanisms=2)
    assert [m.id for m in dg["mechanisms"]] == ["hydrodynamic_torque"]
    skipped = {s["id"]: s["skipped"] for s in dg["steps"] if "skipped" in s}
    assert "averages to zero" in skipped["misalignment_ripple"]  # said why, not fitted to find it out
    ls = dg["fit"].ls
    k = "hydrodynamic_torque.C_h"
    assert abs(ls.values[k] - 1e-4) < 3 * ls.std[k]
    assert dg["comparison"]["models"]["motorid + hydrodynamic_torque"]["kfold"]["torque"]["rms"] < \
        dg["comparison"]["models"]["Wilson (1950)"]["kfold"]["torque"]["rms"]


def test_temperature_from_the_spec_where_the_table_has_none(tmp_path):
    from motorid.errors import InputError
    from motorid.io.tables import read_table
    from motorid.io.spec import load_motor_spec

    df = _map().drop(columns=["oil_temp_C"])
    path = _write(df, tmp_path / "t.csv")
    motor = tmp_path / "m.toml"
    motor.write_text(SPEC.to_toml())
    spec = load_motor_spec(motor)
    assert spec.oil.temp_C == 50.0
    t = read_table(path, spec)
    np.testing.assert_allclose(t.viscosity, float(SPEC.oil.viscosity(50.0)), rtol=1e-12)
    no_temp = MotorSpec("x", 9, 80e-6, oil=OilSpec())
    with pytest.raises(InputError, match=r"t\.csv: line 2: no viscosity_mPas nor oil_temp_C.*\[oil\] temp_C"):
        read_table(path, no_temp)
    mu = _map().drop(columns=["oil_temp_C"]).assign(viscosity_mPas=30.0)
    t = read_table(_write(mu, tmp_path / "mu.csv"), no_temp)
    np.testing.assert_allclose(t.viscosity, 0.030)


def test_noise_floor_and_scale_recover_both_parts_of_a_points_sigma():
    """σ_i² = σ_floor² + (s r_i)² (identify/tables.py): from residuals drawn with a known floor and
    scale, maximum likelihood gives both back; with no floor, a floor far below the scale."""
    from motorid.identify.table_noise import noise_floor_and_scale

    rng = np.random.default_rng(4)
    rel = 10 ** rng.uniform(-1.5, 1.0, 4000)  # averaging counts and spreads over two decades
    for floor, scale in ((0.3, 0.07), (0.0, 0.5)):
        r = rng.normal(0, np.sqrt(floor**2 + (scale * rel) ** 2))
        f, s = noise_floor_and_scale(r, rel)
        assert abs(s - scale) < 0.06 * scale, (s, scale)
        if floor:
            assert abs(f - floor) < 0.06 * floor, (f, floor)
        else:
            assert f < 0.02 * scale, f


def test_the_map_report_says_what_diagnose_found(tmp_path):
    """A table fit's report.html shows diagnose's document where it lies beside result.json: each
    name with its words and parameters, what is left unexplained, the candidates left out and why."""
    import json

    from motorid.cli import main
    from motorid.discrepancy.tables import diagnose_table, diagnosis_table_document
    from motorid.io.tables import read_table
    from motorid.physics.registry import get

    hydro = get("hydrodynamic_torque")
    truth = dict(TRUTH, **{"hydrodynamic_torque.C_h": 1e-4})
    df = simulate_map(SPEC, truth, map_grid([100, 500, 1000, 2000, 3000], [20, 100, 200, 300], 2),
                      mechanisms=(hydro,), noise=NOISE, rng=np.random.default_rng(4))
    path = _write(df, tmp_path / "h.csv")
    motor = tmp_path / "m.toml"
    motor.write_text(SPEC.to_toml())
    assert main(["fit", str(path), "--motor", str(motor), "--out", str(tmp_path / "fit")]) == 0
    assert main(["report", str(tmp_path / "fit")]) == 0
    assert 'id="diagnosis"' not in (tmp_path / "fit" / "report.html").read_text()  # diagnose not run
    table = read_table(path, SPEC)
    dg = diagnose_table(table, SPEC, candidates=[get("turbulent_leakage"), hydro, get("flow_meter_gain_a")],
                        max_mechanisms=2)
    doc = diagnosis_table_document(dg, SPEC)
    (tmp_path / "fit" / "diagnosis.json").write_text(json.dumps(doc))
    assert main(["report", str(tmp_path / "fit")]) == 0
    page = (tmp_path / "fit" / "report.html").read_text()
    section = page[page.index('<section id="diagnosis">'):]
    section = section[:section.index("</section>")]
    words = doc["mechanisms"][0]["description"]
    assert [m["id"] for m in doc["mechanisms"]] == ["hydrodynamic_torque"]
    assert "hydrodynamic_torque.C_h" in section and words.split(":")[0].replace("'", "&#x27;") in section
    assert "Nothing: the residuals left are consistent with the noise" in section
    assert "flow_meter_gain_a" in section and "mass balance" in section  # left out, with its reason
    # a diagnosis.json that does not read is said in the section, as the log report says it, and the
    # rest of the report is written
    (tmp_path / "fit" / "diagnosis.json").write_text("{not json")
    assert main(["report", str(tmp_path / "fit")]) == 0
    page = (tmp_path / "fit" / "report.html").read_text()
    assert "not valid JSON" in page and 'id="comparison-table"' in page
