"""The breakaway event of a startability run: its onset, the inputs there, the held torque.

The port pressures at the onset come from a line through their last readings
(:func:`value_at_onset`); the held load torque is the median over the late
stuck phase; onsets whose first moving sample met a speed limit are placed with
the acceleration the campaign's other events show (:func:`place_limited_onsets`).
"""

from __future__ import annotations

import math

import numpy as np

from motorid.identify.breakaway import find_breakaway
from motorid.identify.onset_angle import place_limited_onset
from motorid.identify.types import NO_BREAKAWAY, NO_HELD_TORQUE, SHORT_RUN, NoBreakaway
from motorid.robust import nanmedian, robust_polyfit, theil_sen_line


ONSET_WINDOWS = (3, 4, 6, 8, 12, 16, 24, 32, 50)  # readings a line at the onset may go through


def value_at_onset(time, values, onset_time: float, count: int) -> float:
    """A slowly ramped channel at the onset: a line through its last readings before
    the onset, evaluated there [unit of values].

    How many readings (3 … ``count``): those whose line best predicts the reading
    that follows, over the last ten readings before the onset (one step ahead, as
    the onset is at most a step beyond the last reading).  A long line averages the
    sensor's noise; a short one follows a supply ripple that a long one would
    average out (the shaft breaks away where the ripple pushes the pressure up, so
    that averaging reads it low) and stays clear of the hold before the ramp.  The
    line of the chosen length is fitted robustly (readings beyond 3.5 deviations
    left out)."""
    t = np.asarray(time, dtype=float)
    x = np.asarray(values, dtype=float)
    sel = np.flatnonzero((t < onset_time) & np.isfinite(x))[-count:]
    if sel.size == 0:
        return math.nan
    if sel.size < 4:
        return float(x[sel[-1]])
    before = np.flatnonzero((t < onset_time) & np.isfinite(x))
    tests = 40
    keep = before[-(count + tests):]
    c, xx = t[keep] - t[keep[-1]], x[keep]
    # sliding sums for every window at once: a line through readings j−m … j−1, at reading j
    cum = [np.r_[0.0, np.cumsum(v)] for v in (np.ones_like(c), c, c * c, xx, c * xx)]
    best, best_err = min(count, sel.size), math.inf
    for m in [k for k in ONSET_WINDOWS if k < count] + [count]:
        j = np.arange(max(m, keep.size - tests), keep.size)
        if keep.size < m + 3 or j.size == 0:
            break
        n0, s1, s2, sx, scx = (v[j] - v[j - m] for v in cum)
        det = n0 * s2 - s1 * s1
        with np.errstate(invalid="ignore", divide="ignore"):
            slope = np.where(det > 0, (n0 * scx - s1 * sx) / det, 0.0)
        pred = (sx - slope * s1) / n0 + slope * c[j]
        err = float(np.mean((xx[j] - pred) ** 2))
        if err < best_err:
            best, best_err = m, err
    sel = sel[-best:]
    if sel.size < 4:
        u = t[sel] - onset_time
        return float(np.polyval(np.polyfit(u, x[sel], 1), 0.0)) if sel.size >= 2 and np.ptp(u) > 0 else float(x[sel[-1]])
    coef, _ = robust_polyfit(t[sel] - onset_time, x[sel], 1)
    return float(np.polyval(coef, 0.0))


def _circular_mean(theta: np.ndarray) -> float:
    return float(np.mod(np.angle(np.mean(np.exp(1j * theta))), 2.0 * np.pi))


def _event_at(t, cols, onset: float, direction: float) -> dict:
    """A breakaway event of a startability run with its onset placed at ``onset`` [s]:
    the port and case pressures there (a line through the readings before it), the
    shaft angle, viscosity and temperature of the late stuck phase, and the held
    load torque (median over the last half of the stuck phase)."""
    stuck = np.flatnonzero(t < onset)
    count = int(np.clip(stuck.size // 4, 8, 50))
    window = stuck[-count:]
    event = {"onset": onset, "direction": direction}
    for c in ("p_a_Pa", "p_b_Pa", "p_case_Pa"):
        event[c] = value_at_onset(t, cols[c], onset, count)
    theta = cols["theta_rad"][window]
    theta = theta[np.isfinite(theta)]
    event["theta_rad"] = _circular_mean(theta) if theta.size else math.nan
    event["viscosity_Pa_s"] = nanmedian(cols["viscosity_Pa_s"][window])
    event["oil_temp_C"] = nanmedian(cols["oil_temp_C"][window])
    torque = cols["torque_Nm"]
    late = stuck[t[stuck] >= t[0] + 0.5 * (onset - t[0])]
    if np.isfinite(torque[late]).sum() < 3:
        late = stuck
    event["held"] = nanmedian(torque[late])
    return event


def place_limited_onsets(events: list, pending: list) -> int:
    """Onsets of the breakaways whose first moving sample had already met a speed limit → how many were placed.

    Such an onset depends on the time u_s the shaft took to reach the limit, which
    no sample saw (:func:`place_limited_onset`); the middle of what the angle allows
    is late by up to a quarter sample where u_s is short.  Just after breakaway the
    shaft accelerates at (static − kinetic friction)/(J_motor + J_load) =
    (D (P_A + P_B) K_FS + T_Fc K_s)/J: a line in P_A + P_B (MODEL.md).  The events
    whose growth the samples did show give |a| (:attr:`Breakaway.acceleration`);
    a robust line of |a| against P_A + P_B over them (a constant where they are
    fewer than five or at one pressure) gives each limited event its a, hence its
    u_s = W/a and onset.  Fewer than three such events: the middles are kept.
    ``pending``: (event, columns of its run) of the limited events, updated in place.
    """
    if not pending:
        return 0
    psum = np.array([e["p_a_Pa"] + e["p_b_Pa"] for e in events], dtype=float)
    accel = np.abs(np.array([e["acceleration"] for e in events], dtype=float))
    have = np.isfinite(psum) & np.isfinite(accel) & (accel > 0)
    if have.sum() < 3:
        return 0
    x, y = psum[have], accel[have]
    centre = float(np.median(x))
    x = x - centre
    if have.sum() >= 5 and np.ptp(x) > 0.1 * max(abs(centre), 1.0):
        coef = theil_sen_line(x, y)  # the events sit at a few loads: Theil-Sen, then least squares
    else:
        coef, _ = robust_polyfit(x, y, 0)
    placed = 0
    for event, cols in pending:
        b = event["breakaway"]
        a = float(np.polyval(coef, event["p_a_Pa"] + event["p_b_Pa"] - centre))
        if not (math.isfinite(a) and a > 0):
            continue
        onset = place_limited_onset(b.limited, a)
        event.update(_event_at(cols["time_s"], cols, onset, b.direction))
        placed += 1
    return placed


def startability_event(key, cols, settings, excluded, notes, theta=None):
    """Breakaway event of one startability run → (dict of the event or None, why not).
    theta : the shaft angle to take where the run logged none [rad] (None: such a run has no event)."""
    t = cols["time_s"]
    if t.size < settings.min_samples:
        excluded[SHORT_RUN] = excluded.get(SHORT_RUN, 0) + 1
        notes.append(f"run {key}: only {t.size} samples (at least {settings.min_samples} needed)")
        return None, "too few samples"

    def turned(before: float) -> float:  # how far the shaft angle moved before a time [rad]
        theta = cols["theta_rad"][t < before]
        theta = np.unwrap(theta[np.isfinite(theta)])
        return float(np.ptp(theta)) if theta.size else 0.0

    try:
        try:
            b = find_breakaway(t, cols["speed_rad_s"], settings.rest_speed, cols["theta_rad"])
        except NoBreakaway:
            if turned(t[-1] + 1.0) <= settings.stuck_turn:
                raise
            b = None
        if b is None or turned(b.onset_time) > settings.stuck_turn:
            end = t[-1] + 1.0 if b is None else b.onset_time
            raise NoBreakaway(f"the shaft is already turning at the start of the run (the shaft angle moved "
                              f"{turned(end):.3g} rad while the speed seemed at rest)")
    except NoBreakaway as exc:
        excluded[NO_BREAKAWAY] = excluded.get(NO_BREAKAWAY, 0) + 1
        notes.append(f"run {key}: no breakaway found, {exc}")
        return None, "no breakaway found"
    event = _event_at(t, cols, b.onset_time, b.direction)
    if theta is not None and not math.isfinite(event["theta_rad"]):
        event["theta_rad"] = float(theta)
    event["acceleration"], event["breakaway"] = b.acceleration, b
    if not math.isfinite(event["held"]):
        excluded[NO_HELD_TORQUE] = excluded.get(NO_HELD_TORQUE, 0) + 1
        notes.append(f"run {key}: breakaway at t = {b.onset_time:.4g} s but no torque reading while stuck")
    dp = event["p_a_Pa"] - event["p_b_Pa"]
    if math.isfinite(dp) and dp * b.direction < 0:
        notes.append(f"run {key}: the shaft broke away against P_A − P_B ({dp:.4g} Pa)")
    missing = [c for c in ("theta_rad", "p_a_Pa", "p_b_Pa", "p_case_Pa", "viscosity_Pa_s")
               if not math.isfinite(event[c])]
    if missing:
        excluded[NO_BREAKAWAY] = excluded.get(NO_BREAKAWAY, 0) + 1
        notes.append(f"run {key}: breakaway at t = {b.onset_time:.4g} s but no reading of "
                     f"{', '.join(missing)} before it")
        return None, "no input readings at the breakaway"
    return event, ""
