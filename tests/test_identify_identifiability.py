"""motorid.identify.identifiability: parameters the weighted Jacobian cannot see are named, with why."""

import numpy as np

from motorid.identify.identifiability import null_space_reasons


def test_two_parameters_that_move_the_data_alike_cannot_be_told_apart():
    J = np.array([[1.0, 2.0, 0.0], [2.0, 4.0, 1.0], [3.0, 6.0, 0.0], [1.0, 2.0, 5.0]])  # column b = 2 a
    got = null_space_reasons(J.T @ J, ["a", "b", "c"], 1e-7)
    assert got == {"a": "cannot be told apart from b with these logs", "b": "cannot be told apart from a with these logs"}
    # a small but real difference between them is seen
    J[0, 1] += 1e-3
    assert null_space_reasons(J.T @ J, ["a", "b", "c"], 1e-7) == {}


def test_a_parameter_the_data_do_not_depend_on():
    J = np.array([[1.0, 0.0], [0.0, 0.0], [2.0, 0.0]])
    assert null_space_reasons(J.T @ J, ["a", "b"], 1e-7) == {"b": "the fitted channels do not depend on it in these logs"}


def test_one_back_pressure_says_k_f_carries_a_torque_gain():
    """At one back pressure K_F·D·(P_A + P_B) has the shape a torque-transducer gain g gives the ideal
    torque: K_F takes g/2π, 0.0016 per 1 % (a probe's 1.5 % gain gave K_F 0.00066 for 0.003, no word)."""
    from motorid.identify.identifiability import one_back_pressure_warning

    rng = np.random.default_rng(0)
    one = 7e5 + rng.normal(0, 0.1e5, 200)
    words = one_back_pressure_warning(one, 0.003)
    assert "(7 bar)" in words and "0.0016, 53 % of this fit's K_F" in words
    assert one_back_pressure_warning(np.r_[one, one + 20e5], 0.003) == ""
    assert one_back_pressure_warning(one[:1], 0.003) == ""
