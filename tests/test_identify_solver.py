"""motorid.identify.solver: the small dense Cholesky of the Levenberg-Marquardt step, and the solve."""

import numpy as np

from motorid.identify.solver import cholesky, cholesky_solve


def test_small_cholesky_solve_against_numpy():
    import jax.numpy as jnp

    rng = np.random.default_rng(6)
    a = rng.standard_normal((11, 11))
    A = a @ a.T + 1e-3 * np.eye(11)
    b = rng.standard_normal(11)
    L = np.asarray(cholesky(jnp.asarray(A)))
    np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.asarray(cholesky_solve(jnp.asarray(L), jnp.asarray(b))),
                               np.linalg.solve(A, b), rtol=1e-8)
