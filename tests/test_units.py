"""motorid.units: each factor says what it converts, both directions agree, the channel table is SI."""

import math

import pytest

from motorid import units


@pytest.mark.parametrize("to_si, from_si", [("RAD_S_PER_RPM", "RPM_PER_RAD_S"), ("M3S_PER_LPM", "LPM_PER_M3S")])
def test_the_two_directions_are_reciprocal(to_si, from_si):
    assert getattr(units, to_si) * getattr(units, from_si) == pytest.approx(1.0, rel=1e-15)


def test_factors_against_their_definitions():
    assert 3000 * units.RAD_S_PER_RPM == pytest.approx(3000 * 2 * math.pi / 60)  # one revolution = 2π rad, 60 s
    assert 250 * units.PA_PER_BAR == 25e6
    assert 60 * units.M3S_PER_LPM == pytest.approx(1e-3)  # 60 L/min = 1 L/s
    assert 180 * units.RAD_PER_DEG == pytest.approx(math.pi)
    assert units.PA_PER_PSI == pytest.approx(4.4482216152605 / 0.0254 ** 2)  # lbf / in²
    assert units.NM_PER_LBF_FT == pytest.approx(4.4482216152605 * 0.3048)
    assert units.M3_PER_US_GALLON == pytest.approx(231 * 0.0254 ** 3)  # 231 in³


def test_channel_table_is_the_log_format_in_si():
    si_units = {"time_s": "s", "theta_rad": "rad", "speed_rad_s": "rad_s", "torque_Nm": "Nm", "p_a_Pa": "Pa",
                "q_a_m3_s": "m3_s", "oil_temp_C": "C", "viscosity_Pa_s": "Pa_s"}
    for si, unit in si_units.items():
        assert si.endswith(unit) and si in units.FORMAT_COLUMNS
    assert units.FORMAT_COLUMNS["speed_rad_s"] == ("speed_rpm", units.RAD_S_PER_RPM)
    assert units.FORMAT_COLUMNS["p_case_Pa"] == ("p_case_bar", units.PA_PER_BAR)
    assert units.SI_COLUMNS[:2] == ["run_id", "protocol"] and len(units.SI_COLUMNS) == 2 + len(units.FORMAT_COLUMNS)
    assert set(units.RUNNING_CHANNELS) < set(units.CHANNELS)
