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
