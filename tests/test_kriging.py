"""The kriged model error of a table fit (motorid.identify.kriging, comparators.evaluate.WithModelError)."""

import json

import numpy as np

from motorid.identify.kriging import fit_residual_kriging


def _grid(n=30):
    x, y = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    return np.column_stack([x.ravel(), y.ravel()])


def test_a_smooth_model_error_is_interpolated_and_left_alone_outside():
    """Residuals = a smooth field + noise: kriged from every other point, the field at the points left out
    is recovered to well under the noise; far outside the training points nothing is added; where the
    residuals are noise alone no field is fitted."""
    rng = np.random.default_rng(0)
    X = _grid()
    field = 0.5 * np.sin(2 * X[:, 0]) * np.cos(1.5 * X[:, 1])
    noise = 0.05
    r = field + noise * rng.normal(size=len(X))
    train = np.arange(len(X)) % 2 == 0
    krig = fit_residual_kriging(X[train], r[train], sigma_m=float(np.sqrt(np.mean(field**2))))
    assert krig is not None
    mean, var = krig.predict(X[~train])
    err = mean - field[~train]
    assert np.sqrt(np.mean(err**2)) < 0.5 * noise
    assert np.all(var >= 0) and np.all(var <= krig.sigma_m**2 + 1e-15)
    far, far_var = krig.predict(np.array([[30.0, 30.0]]))
    assert abs(far[0]) < 1e-6 and np.isclose(far_var[0], krig.sigma_m**2)
    assert fit_residual_kriging(X, noise * rng.normal(size=len(X)), sigma_m=0.0) is None


def test_noise_alone_is_not_kriged_even_if_a_model_error_is_claimed():
    """A claimed model error on residuals that are noise: no length predicts left-out points better than
    zero, so nothing is fitted (the physics alone predicts)."""
    rng = np.random.default_rng(1)
    X = _grid(20)
    assert fit_residual_kriging(X, rng.normal(size=len(X)), sigma_m=0.3) is None


def test_scaling_drops_constant_axes_and_fills_gaps():
    """The axes' scaling kriging uses: a constant axis left out, a missing value at the median, each axis
    to unit spread, and the direction of rotation (sign of axis 0) a coordinate of its own, far apart;
    the scaling of the training points applies unchanged to other points, also read back from JSON."""
    from motorid.identify.lack_of_fit import DIRECTION_SEPARATION, AxisScaling

    raw = np.column_stack([np.linspace(-3, 10, 50), np.full(50, 3.0), np.r_[np.linspace(-1, 1, 49), np.nan]])
    s = AxisScaling(raw)
    X = s(raw)
    assert X.shape == (50, 3) and np.all(np.isfinite(X))
    assert np.allclose(X[:, :2].std(axis=0), 1.0) and np.allclose(X[:, :2].mean(axis=0), 0.0)
    assert np.array_equal(X[:, 2], DIRECTION_SEPARATION * np.sign(raw[:, 0]))
    assert np.allclose(s(raw[:5]), X[:5])
    back = AxisScaling.from_document(json.loads(json.dumps(s.document())))
    assert np.allclose(back(raw), X)


def test_the_kriged_model_error_lowers_the_held_out_error_of_a_map_the_model_misses(tmp_path):
    """A map with a loss the model lacks (a smooth torque bump over speed and pressure): the 5-fold
    held-out torque error of motorid + kriged model error is well below motorid's alone, and it
    predicts the ΔP extrapolation no worse (the field adds nothing far from the training points)."""
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.comparators.evaluate import MotoridModel, WithModelError, held_out
    from motorid.io.spec import load_motor_spec
    from motorid.io.tables import read_table

    import tomllib

    spec = load_motor_spec("synthetic_data/demo/motor.toml")
    truth = tomllib.loads(open("synthetic_data/demo/truth.toml").read())["parameters"]
    grid = map_grid(np.linspace(100, 2500, 9), np.linspace(20, 300, 9), quadrants=1)
    frame = simulate_map(spec, truth, grid, noise={"torque_Nm": 0.05, "q_a_lpm": 0.02, "q_b_lpm": 0.02,
                                                   "q_case_lpm": 0.01}, rng=np.random.default_rng(2))
    w = frame["speed_rpm"].to_numpy() / 2500.0
    dp = (frame["p_a_bar"] - frame["p_b_bar"]).to_numpy() / 300.0
    frame["torque_Nm"] = frame["torque_Nm"] + 3.0 * np.exp(-((w - 0.5) ** 2 + (dp - 0.5) ** 2) / 0.08)
    path = tmp_path / "map.csv"
    frame.to_csv(path, index=False)
    table = read_table(path, spec)
    plain = held_out(MotoridModel(spec), table)
    kriged = held_out(WithModelError(MotoridModel(spec)), table)
    assert kriged["kfold"]["torque"]["rms"] < 0.6 * plain["kfold"]["torque"]["rms"]
    assert kriged["extrapolate_pressure"]["torque"]["rms"] <= 1.05 * plain["extrapolate_pressure"]["torque"]["rms"]
