"""motorid.identify.steady: the start transient dropped, spikes that do not end a steady state."""

import numpy as np

from motorid.identify.steady import steady_run, steady_state_mask
from motorid.identify.types import INPUT_SPIKE, SHORT_RUN, START_TRANSIENT, ExtractSettings


def _run(n=400, tau=20.0, spike_at=None):
    k = np.arange(n, dtype=float)
    settle = 1.0 - np.exp(-k / tau)
    speed = 10.0 * settle
    dp = 100e5 * (0.2 + 0.8 * settle)
    psum = dp + 10e5
    if spike_at is not None:
        speed = speed.copy()
        speed[spike_at] += 50.0
    return speed, dp, psum


def test_the_start_transient_ends_when_every_channel_has_settled():
    speed, dp, psum = _run()
    steady, transient = steady_state_mask(speed, dp, psum)
    # within 2 % of the level from k = τ·ln 50 ≈ 78 on: the band's smallest half-width (rel_tol)
    first = int(np.argmax(steady))
    assert 70 <= first <= 100
    assert transient[:first].all() and not transient[first:].any()
    assert steady[first:].all()


def test_an_isolated_spike_neither_ends_the_steady_state_nor_is_steady_itself_in_a_run():
    speed, dp, psum = _run(spike_at=300)
    steady, transient = steady_state_mask(speed, dp, psum)
    assert steady[200:400].all()  # the moving median does not see one sample
    cols = {"time_s": np.arange(400) / 100.0, "theta_rad": np.mod(np.cumsum(speed) / 100.0, 2 * np.pi),
            "speed_rad_s": speed, "p_a_Pa": psum / 2 + dp / 2, "p_b_Pa": psum / 2 - dp / 2,
            "p_case_Pa": np.full(400, 1e5), "viscosity_Pa_s": np.full(400, 0.03)}
    excluded, notes = {}, []
    chosen, direction, why = steady_run("R", cols, ExtractSettings(), excluded, notes)
    assert why == "" and direction == 1.0
    assert 300 not in chosen and excluded[INPUT_SPIKE] == 1  # the Hampel test left it out
    assert excluded[START_TRANSIENT] == int(np.argmax(np.isin(np.arange(400), chosen)))


def test_a_short_run_gives_nothing_and_says_so():
    cols = {c: np.ones(5) for c in ("time_s", "theta_rad", "speed_rad_s", "p_a_Pa", "p_b_Pa", "p_case_Pa",
                                    "viscosity_Pa_s")}
    excluded, notes = {}, []
    chosen, _, why = steady_run("R7", cols, ExtractSettings(), excluded, notes)
    assert chosen is None and why == "too few samples" and excluded[SHORT_RUN] == 1
    assert notes == ["run R7: only 5 samples (at least 10 needed)"]
