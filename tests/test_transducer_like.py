"""A law too small to tell from a transducer's own calibration curve is not named (issue 15).

On a long campaign a flow deficit of a few hundredths of a per cent of the port flow is many noise
levels: diagnose used to name it (a filling loss ∝ ω², a displacement error, two meter gains as
stand-ins).  A flow meter's curvature and slope error (its linearity class, 0.1-0.5 % of reading)
say the same.  motorid.discrepancy.verdicts.transducer_like tells that case from a law a calibration
curve cannot make (a ripple over shaft angle, friction that rises at slow speed) and from one larger
than a transducer's linearity.
"""

from types import SimpleNamespace

import pytest

from conftest import concealed
from motorid.discrepancy.verdicts import LINEARITY_SHARE, transducer_like
from motorid.identify.least_squares import fit_least_squares
from motorid.physics.registry import CATALOG


@pytest.fixture(scope="module")
def filling():
    """The concealed filling-loss campaign fitted with the filling loss, a port-A meter gain, Stribeck
    friction and a torque offset in the model."""
    spec, ds, _, truth = concealed("filling_loss")
    mechs = [CATALOG[m] for m in ("filling_loss", "flow_meter_gain_a", "stribeck_friction", "torque_offset")]
    return fit_least_squares(ds, spec, mechs), truth


def _at(fit, **values):
    """``fit`` with some parameters moved (the problem, its free parameters and inliers unchanged)."""
    return SimpleNamespace(problem=fit.problem, params_all={**fit.params_all, **values}, inliers=fit.inliers)


def test_a_law_as_big_as_the_truth_is_not_transducer_like(filling):
    fit, truth = filling
    c_f = truth["mechanisms"]["filling_loss"]["C_f"]
    assert fit.values["filling_loss.C_f"] == pytest.approx(c_f, rel=0.1)
    assert transducer_like(CATALOG["filling_loss"], fit) is None  # 0.7 % of the port flow at 2500 rpm


def test_the_same_law_thirty_times_smaller_is_a_flow_meter_curve(filling):
    fit, truth = filling
    small = truth["mechanisms"]["filling_loss"]["C_f"] / 30
    like = transducer_like(CATALOG["filling_loss"], _at(fit, **{"filling_loss.C_f": small}))
    assert like is not None and like["channel"] in ("q_a", "q_b")
    assert 1e-4 < like["share"] < LINEARITY_SHARE
    assert like["calibration_share"] > 0.9  # ∝ ω|ω|: a curve of the reading itself
    # and a meter gain that small is one too
    gain = transducer_like(CATALOG["flow_meter_gain_a"], _at(fit, **{"flow_meter_gain_a.g": 2e-4}))
    assert gain is not None and gain["channel"] == "q_a" and gain["calibration_share"] > 0.99
    assert transducer_like(CATALOG["flow_meter_gain_a"], _at(fit, **{"flow_meter_gain_a.g": 5e-3})) is None


def test_shapes_no_calibration_curve_makes_are_named_at_any_size(filling):
    fit, _ = filling
    # friction rising below 0.5 rad/s, 0.05 N·m (0.02 % of the torque scale): not a curve of the torque reading
    tiny = _at(fit, **{"stribeck_friction.T_s": 0.05, "stribeck_friction.K_p": 0.0, "stribeck_friction.w_s": 0.5})
    assert transducer_like(CATALOG["stribeck_friction"], tiny) is None
    # a zero offset is what its name says at any size
    assert transducer_like(CATALOG["torque_offset"], _at(fit, **{"torque_offset.T0": 0.02})) is None
