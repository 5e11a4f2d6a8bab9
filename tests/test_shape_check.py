"""A named law must have the shape of what it was named for (issue 15: a wrong name is worse than none).

A churning law ∝ ω|ω| fits a torque loss ∝ ω³ to within a few per cent: the forward selection
names it, and what it leaves is a small spread that reverses with the rotation.  The shape
check (:func:`motorid.discrepancy.empirical.law_shape_check`) asks whether the library's terms,
chosen for what the law leaves, explain what the law was named for without it.  Here on
samples built by hand (no motorid model in the data), the law fitted by least squares as the
selection would: a ∝ ω³ truth makes the law a stand-in; a true churning law with a second
effect beside it (a friction ∝ ΔP²) is kept, and so is a true churning law alone.  The region
split of the where-not-fitted checks holds the running runs only (a startability run's creep
had put the speed split at 0.007 rpm, and its speed half never counted).
"""

import numpy as np
import pytest

from motorid.discrepancy.empirical import law_shape_check, nuisance
from motorid.physics.base import Samples


class _Spec:
    pistons = 9


def _samples(seed=0, per_run=150):
    rng = np.random.default_rng(seed)
    rows = []
    for rpm in (20, 60, 150, 400, 800, 1200, 1600, 2000, 2500):
        for dp in (50e5, 150e5, 250e5):
            for d in (1, -1):
                rows.append((d * rpm * 2 * np.pi / 60, dp))
    n = len(rows) * per_run
    speed = np.repeat([r[0] for r in rows], per_run) * (1 + 1e-3 * rng.standard_normal(n))
    dp = np.repeat([r[1] for r in rows], per_run)
    direction = np.sign(speed)
    p_b = np.full(n, 10e5)
    p_a = p_b + dp
    p_a, p_b = np.where(direction > 0, p_a, p_b), np.where(direction > 0, p_b, p_a)
    x = Samples(theta=rng.uniform(0, 2 * np.pi, n), speed=speed, acceleration=np.zeros(n), p_a=p_a, p_b=p_b,
                p_case=np.full(n, 0.7e5), viscosity=np.full(n, 0.03), direction=direction,
                port_sum=np.ones(n), temperature=np.full(n, 50.0), time=np.zeros(n))
    return x, np.repeat(np.arange(len(rows)), per_run), rng


def _as_named(x, structure, rng, noise=0.08):
    """The churning law fitted (with the 1992 model's torque shapes) as the selection would → residual, change."""
    y = structure + noise * rng.standard_normal(structure.size)
    law = x.speed * np.abs(x.speed)
    A = np.column_stack([nuisance("torque", x, _Spec), law])
    b = np.linalg.lstsq(A, y, rcond=None)[0]
    change = b[-1] * law
    return y - A @ b, change, np.full(y.size, noise)


def test_a_churning_law_fitted_to_a_cubic_loss_is_a_stand_in_by_its_shape():
    x, run_of, rng = _samples()
    residual, change, sigma = _as_named(x, -1e-7 * x.speed ** 3, rng)
    check = law_shape_check("torque", x, residual, change, sigma, run_of, _Spec)
    assert check is not None and check["stand_in"], check
    assert "ω³" in check["terms"]
    gain = check["law_left"] - check["both_left"]
    assert gain > 50 and check["terms_left"] - check["both_left"] < 0.1 * gain


def test_a_true_churning_law_with_a_second_effect_beside_it_is_kept():
    x, run_of, rng = _samples(1)
    dp = x.p_a - x.p_b
    structure = -1.2e-4 * x.speed * np.abs(x.speed) - 0.5 * (dp / 250e5) ** 2 * x.direction
    residual, change, sigma = _as_named(x, structure, rng)
    check = law_shape_check("torque", x, residual, change, sigma, run_of, _Spec)
    assert check is not None and not check["stand_in"], check
    # the terms take the second effect; the law stays needed beside them
    assert check["terms_left"] - check["both_left"] > 10 * (check["law_left"] - check["both_left"]) > 0


@pytest.mark.parametrize("seed", [2, 3])
def test_a_true_churning_law_alone_is_kept(seed):
    x, run_of, rng = _samples(seed)
    residual, change, sigma = _as_named(x, -1.2e-4 * x.speed * np.abs(x.speed), rng)
    check = law_shape_check("torque", x, residual, change, sigma, run_of, _Spec)
    assert check is None or not check["stand_in"], check


def test_a_meter_zero_beside_a_leftover_of_another_cause_is_not_refused_by_its_shape():
    """A flow meter's zero offset is the model's own constant shape: the ω term a second cause leaves
    (a speed gain error: swept flow ∝ ω) must not make it 'add 0' and be refused (the foreign bench's
    n12 campaign, a true 5σ offset on port A)."""
    x, run_of, rng = _samples(4)
    noise = 2e-7
    y = 2.3e-7 + 5e-9 * x.speed + noise * rng.standard_normal(x.speed.size)
    law = np.ones_like(y)
    A = np.column_stack([nuisance("q_a", x, _Spec), law])
    b = np.linalg.lstsq(A, y, rcond=None)[0]
    residual, change = y - A @ b, b[-1] * law
    assert law_shape_check("q_a", x, residual, change, np.full(y.size, noise), run_of, _Spec) is None
    # the same leftover beside a law that is not one of the shapes is still asked (and here kept)
    law = x.speed * np.abs(x.speed)
    A = np.column_stack([nuisance("q_a", x, _Spec), law])
    b = np.linalg.lstsq(A, y, rcond=None)[0]
    check = law_shape_check("q_a", x, y - A @ b, b[-1] * law, np.full(y.size, noise), run_of, _Spec)
    assert check is not None and check["stand_in"] and "ω" in check["terms"], check
