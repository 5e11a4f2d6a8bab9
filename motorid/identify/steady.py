"""Steady-state samples of the running runs (ISO 4392-1 and -3).

The start-up transient is dropped, isolated input spikes are left out (a Hampel
test per channel), and later samples out of the settled band are unsteady;
every estimate is robust (moving medians, MADs, sustained stretches).
"""

from __future__ import annotations

import numpy as np

from motorid.identify.types import (FEW_STEADY, INPUT_SPIKE, MISSING_INPUT, NO_STEADY_SPEED, SHORT_RUN,
                                    START_TRANSIENT, UNSTEADY, ExtractSettings, INPUT_CHANNELS)
from motorid.robust import MAD_TO_STD, hampel_spikes, moving_median, nanmedian, odd_window


def steady_state_mask(speed, dp, psum, settings: ExtractSettings = ExtractSettings(), smoothed=None):
    """Steady-state samples of one running run → (steady, start_transient) boolean masks.

    speed [rad/s], dp = P_A − P_B [Pa], psum = P_A + P_B [Pa], in time order (NaN
    allowed).  Each channel is smoothed by a short moving median (isolated spikes
    vanish); its settled level is the median of the smoothed second half of the
    run, and the band around it is ``band_sigmas`` robust deviations of that half
    (so shaft-angle ripple at low speed stays inside), at least ``rel_tol`` of the
    level and the floors.  The start transient ends where every channel has
    stayed in its band for a sustained stretch; later samples out of band are
    unsteady.  ``smoothed``: a dict to receive each channel's moving median (the
    caller reuses the speed's).
    """
    speed, dp, psum = (np.asarray(a, dtype=float) for a in (speed, dp, psum))
    n = speed.size
    window = max(1, odd_window(min(int(np.clip(n // 100, 5, 21)), n)))
    in_band = np.ones(n, bool)
    for name, x, floor in (("speed", speed, settings.speed_floor), ("dp", dp, settings.pressure_floor),
                           ("psum", psum, settings.pressure_floor)):
        if not np.isfinite(x).any():
            continue
        smooth = moving_median(x, window)
        if smoothed is not None:
            smoothed[name] = smooth
        tail = smooth[n // 2:]
        if not np.isfinite(tail).any():
            continue
        level = np.nanmedian(tail)
        spread = MAD_TO_STD * np.nanmedian(np.abs(tail - level))
        tol = max(settings.band_sigmas * spread, settings.rel_tol * abs(level), floor)
        in_band &= ~(np.abs(smooth - level) > tol)  # NaN counts as in band
    hold = int(np.clip(n // 20, 3, 50))
    bad = np.concatenate([[0], np.cumsum(~in_band)])
    k = np.arange(n)
    settled = bad[np.minimum(k + hold, n)] - bad[k] == 0
    start = int(np.argmax(settled)) if settled.any() else n
    transient = k < start
    return in_band & ~transient, transient


_INPUT_WORDS = {"theta_rad": "a shaft angle", "speed_rad_s": "a speed", "p_a_Pa": "a port A pressure",
                "p_b_Pa": "a port B pressure", "p_case_Pa": "a case pressure",
                "viscosity_Pa_s": "an oil temperature or viscosity"}


def steady_run(key, cols, settings, excluded, notes, inputs=INPUT_CHANNELS):
    """Steady samples of one running run → (their positions in the run or None, direction, why not).
    inputs : the channels a sample needs (a run reduced to an operating point needs no shaft angle)."""
    n = cols["time_s"].size
    if n < settings.min_samples:
        excluded[SHORT_RUN] = excluded.get(SHORT_RUN, 0) + 1
        notes.append(f"run {key}: only {n} samples (at least {settings.min_samples} needed)")
        return None, 0.0, "too few samples"
    valid = np.all([np.isfinite(cols[c]) for c in inputs], axis=0)
    excluded[MISSING_INPUT] = excluded.get(MISSING_INPUT, 0) + int((~valid).sum())
    speed = cols["speed_rad_s"]
    if not valid.any():
        lacking = [_INPUT_WORDS.get(c, c) for c in inputs if not np.isfinite(cols[c]).any()]
        notes.append(f"run {key}: no sample holds every input the model needs"
                     + (f" (none holds {', '.join(lacking)})" if lacking else ""))
        return None, 0.0, "missing " + (", ".join(lacking) if lacking else "inputs")
    median_speed = nanmedian(speed[valid])
    if not abs(median_speed) >= settings.rest_speed:
        excluded[NO_STEADY_SPEED] = excluded.get(NO_STEADY_SPEED, 0) + int(valid.sum())
        notes.append(f"run {key}: no steady speed (median {median_speed:.3g} rad/s, "
                     f"below {settings.rest_speed:g} rad/s)")
        return None, 0.0, "no steady speed"
    direction = float(np.sign(median_speed))
    # a spike in an input reading: the sample is left out (and bridged in the speed's derivative)
    spikes = np.zeros(n, bool)
    for c in ("speed_rad_s", "p_a_Pa", "p_b_Pa", "p_case_Pa", "viscosity_Pa_s"):
        hit = hampel_spikes(cols[c]) & valid
        if hit.any():
            cols[c] = np.where(hit, np.nan, cols[c])
            spikes |= hit
    if spikes.any():
        excluded[INPUT_SPIKE] = excluded.get(INPUT_SPIKE, 0) + int(spikes.sum())
        valid &= ~spikes
    speed = cols["speed_rad_s"]
    p_a, p_b = cols["p_a_Pa"], cols["p_b_Pa"]
    idx = np.flatnonzero(valid)
    smoothed: dict = {}
    steady, transient = steady_state_mask(speed[idx], (p_a - p_b)[idx], (p_a + p_b)[idx], settings, smoothed)
    smooth = smoothed["speed"]  # the speed's moving median (valid samples have a finite speed)
    stopped = direction * smooth < min(settings.rest_speed, 0.5 * abs(median_speed))
    excluded[START_TRANSIENT] = excluded.get(START_TRANSIENT, 0) + int(transient.sum())
    excluded[NO_STEADY_SPEED] = excluded.get(NO_STEADY_SPEED, 0) + int((stopped & ~transient).sum())
    excluded[UNSTEADY] = excluded.get(UNSTEADY, 0) + int((~steady & ~transient & ~stopped).sum())
    steady &= ~stopped
    if steady.sum() < settings.min_steady:
        excluded[FEW_STEADY] = excluded.get(FEW_STEADY, 0) + 1
        notes.append(f"run {key}: only {int(steady.sum())} steady samples of {n}")
        return None, direction, "too few steady samples"
    return idx[steady], direction, ""
