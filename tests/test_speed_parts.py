"""The pieces that make the fit fast must give the same numbers as the slow way."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from motorid.identify import extract as ex
from motorid.identify import least_squares as ls

SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    from motorid._aot import cached_jit

    TRACES = []

    def f(x, scale, names):
        TRACES.append(1)  # runs only while JAX traces
        return {n: x * scale * (i + 1) for i, n in enumerate(names)}

    g = cached_jit(f)
    out = g(np.arange(4.0), 2.0, ("a", "b"))
    print(len(TRACES), float(out["b"][3]))
""")


def _run(script, cache):
    env = {**os.environ, "MOTORID_CACHE_DIR": str(cache)}
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout.split()


def test_compiled_program_is_kept_on_disk_and_reloaded(tmp_path):
    script = tmp_path / "prog.py"
    script.write_text(SCRIPT)
    cache = tmp_path / "cache"
    assert _run(script, cache) == ["1", "12.0"]  # traced and compiled
    files = list((cache / "aot").rglob("f-*.bin"))
    assert len(files) == 1
    assert _run(script, cache) == ["0", "12.0"]  # loaded: no trace at all
    files[0].write_bytes(b"not an executable")  # a broken file is replaced, the answer is right
    assert _run(script, cache) == ["1", "12.0"]
    assert _run(script, cache) == ["0", "12.0"]


def test_cached_jit_matches_plain_jax_and_keys_on_static_values(tmp_path):
    import jax

    from motorid._aot import cached_jit

    def f(x, k, names):
        return {n: jax.numpy.sin(x) * k for n in names}

    g = cached_jit(f)
    x = np.linspace(0, 1, 5)
    for k in (1.0, 3.0):  # a static float is part of the key: a new value, a new program
        got = g(x, k, ("a",))
        np.testing.assert_allclose(np.asarray(got["a"]), np.sin(x) * k, rtol=1e-15)
    assert len(g._memory) == 2
    g(np.linspace(0, 1, 7), 1.0, ("a",))  # a new shape, a new program
    assert len(g._memory) == 3


def test_median_of_five_network():
    rng = np.random.default_rng(3)
    x = rng.standard_normal((5, 10000))
    x[:, :3000] = np.round(x[:, :3000])  # ties
    np.testing.assert_array_equal(ls._median_of_five(*x), np.median(x, axis=0))


def test_spikiness_matches_running_median_within_runs():
    rng = np.random.default_rng(4)
    run_of = np.repeat([0, 1, 2], [7, 50, 3])
    res = rng.standard_normal(run_of.size)
    got = ls._spikiness(res, run_of, "torque")
    want = np.empty_like(res)
    for r in np.unique(run_of):
        idx = np.flatnonzero(run_of == r)
        for k, i in enumerate(idx):
            window = idx[np.clip(np.arange(k - 2, k + 3), 0, idx.size - 1)]
            want[i] = res[i] - np.median(res[window])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)


def test_per_run_noise_vectorized_equals_loop():
    rng = np.random.default_rng(5)
    run_of = np.repeat(np.arange(6), [10, 3, 40, 5, 8, 20])
    res = rng.standard_normal(run_of.size) * (1 + run_of)
    res[7] = np.nan
    got = ls._residual_noise(res, run_of, 6, robust=False)
    for r in range(6):
        v = res[run_of == r]
        v = v[np.isfinite(v)]
        want = np.std(v, ddof=1) if v.size >= 5 else np.nan
        np.testing.assert_allclose(got[r], want, rtol=1e-12)


def test_small_cholesky_solve_against_numpy():
    import jax.numpy as jnp

    rng = np.random.default_rng(6)
    a = rng.standard_normal((11, 11))
    A = a @ a.T + 1e-3 * np.eye(11)
    b = rng.standard_normal(11)
    L = np.asarray(ls._cholesky(jnp.asarray(A)))
    np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.asarray(ls._cholesky_solve(jnp.asarray(L), jnp.asarray(b))),
                               np.linalg.solve(A, b), rtol=1e-8)


def test_hinge_costs_equal_nonnegative_least_squares():
    from scipy.optimize import nnls

    rng = np.random.default_rng(7)
    t = np.linspace(0, 1, 40)
    y = np.clip(t - 0.4, 0, None) * 3 + np.clip(t - 0.4, 0, None) ** 2 + 0.01 * rng.standard_normal(t.size)
    y[5] = -0.5  # forces a bound to be active at some t0
    grid = np.linspace(-0.1, 1.05, 60)
    want = [nnls(np.column_stack([np.clip(t - g, 0, None), np.clip(t - g, 0, None) ** 2]), y)[1] ** 2
            for g in grid]
    np.testing.assert_allclose(ex._hinge_costs(t, y, grid), want, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("jitter", [0.0, 2e-4])
def test_even_sampling_derivative_equals_the_local_fit(jitter):
    rng = np.random.default_rng(8)
    t = np.arange(300) * 0.01 + 5.0
    t = t + jitter * 0.01 * rng.uniform(-1, 1, t.size)  # time stamps rounded to a few digits
    w = np.sin(3 * t) + 0.01 * rng.standard_normal(t.size)
    fast = ex.smoothed_acceleration(t, w)
    # the general path: every window's own quadratic (what uneven sampling gets)
    k, n = 9, t.size
    first = np.clip(np.arange(n) - k // 2, 0, n - k)
    slow = np.empty(n)
    for i in range(n):
        sl = slice(first[i], first[i] + k)
        slow[i] = np.polyfit(t[sl] - t[i], w[sl], 2)[1]
    tol = 1e-9 if jitter == 0 else 0.02
    np.testing.assert_allclose(fast, slow, rtol=0, atol=tol * np.max(np.abs(slow)))


@pytest.mark.parametrize("dof", [5.0, 7.5, 12.0, 28.0, 300.0])
@pytest.mark.parametrize("level", [0.6827, 0.95])
def test_t_quantile_without_scipy_stats_matches_scipy(dof, level):
    from scipy import stats

    from motorid.identify.results import interval_factor

    assert interval_factor(dof, level) == pytest.approx(stats.t.ppf(0.5 + level / 2, dof), rel=1.2e-4)


def test_static_object_of_a_foreign_class_is_not_kept_on_disk(tmp_path, monkeypatch):
    from motorid import _aot

    class Setting:  # a user's class: its code is not in motorid's fingerprint
        def __repr__(self):
            return "<setting>"

    monkeypatch.setattr(_aot._jaxconfig, "CACHE_DIR", str(tmp_path))

    def f(x, setting):
        return x * 2.0

    g = _aot.cached_jit(f)
    np.testing.assert_allclose(np.asarray(g(np.ones(3), Setting())), 2.0)
    assert not list(tmp_path.rglob("*.bin"))
    g(np.ones(3), "plain text")  # a plain static value: kept
    assert len(list(tmp_path.rglob("f-*.bin"))) == 1


@pytest.mark.parametrize("n", [1, 2, 5, 20, 21, 22, 300])
@pytest.mark.parametrize("window", [1, 3, 5, 21])
def test_moving_median_matches_pandas_rolling_median(n, window):
    import pandas as pd

    rng = np.random.default_rng(n * 100 + window)
    x = rng.standard_normal(n)
    k = min(window, n) if min(window, n) % 2 else min(window, n) - 1
    for xx in (x, np.where(rng.random(n) < 0.2, np.nan, x)):
        want = pd.Series(xx).rolling(k, center=True, min_periods=1).median().to_numpy()
        np.testing.assert_allclose(ex.moving_median(xx, k), want, equal_nan=True, rtol=0, atol=1e-15)
