"""A recording that holds many set points in one run: cut into one run per set point.

BENCH_LOG_FORMAT.md has a run hold one set point (or one startability ramp).  A bench script that
logs a whole test into one file, stepping from set point to set point without a pause and with no
run column, breaks that: read as one run, its ramps pass for steady samples, its reverse half is
dropped (a run has one direction), and a startability file of eighteen breakaways gives none (the
shaft is turning at the start of the "run").  A file whose channel map names no run column is
therefore cut by its time track (pauses, a restarting clock: :mod:`motorid.io.channel_map`) and
then, here, by its set points:

- running protocols (constant speed, pressure, flow or torque): a *plateau* is a stretch of at least
  :data:`MIN_PLATEAU_S` where neither the speed nor ΔP (moving medians over :data:`SMOOTH_S`) changes
  across ±:data:`SMOOTH_S` by more than :data:`SPEED_REL` (:data:`DP_REL`) of its level or the
  absolute floors :data:`SPEED_FLOOR` (:data:`DP_FLOOR`); neighbouring plateaus at one level (within
  twice those) are one set point.  With two set points or more, each becomes a run
  ``<run>~1``, ``<run>~2``, … from its first plateau's start to its last one's end; the ramps
  between them are left out.
- startability: the shaft *moves* where its smoothed |speed| exceeds :data:`MOVE_SHARE` of the run's
  largest (and 10 rest speeds); two breakaways or more, each after at least :data:`MIN_REST_S` at
  rest, become one run each, from where the motion before has come to rest (its smoothed |speed|
  below :data:`REST_SPEED`, then ±:data:`SMOOTH_S` more; else the middle of the rest: the hold and the
  pressure ramp) to the end of its own motion.

A run with one set point (or one breakaway) is left whole, as are runs a run column, a constant
run_id or a file's groups name (the writer said what a run is), and running runs with no shaft angle
(the no-angle route makes its points from quasi-steady cells of the motion: identify/log_points.py).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

#: moving medians over this time [s] (at least 5 samples), and changes taken across ± this time
SMOOTH_S = 0.1
#: shortest plateau [s] (and at least MIN_PLATEAU_SAMPLES samples)
MIN_PLATEAU_S = 0.5
MIN_PLATEAU_SAMPLES = 20
#: a change of speed or ΔP across ±SMOOTH_S beyond this share of its level is motion
SPEED_REL, DP_REL = 0.03, 0.03
#: ... or beyond these floors [rad/s], [Pa]
SPEED_FLOOR, DP_FLOOR = 0.01, 2e5
#: startability: moving above this share of the run's largest smoothed |speed| (and 10 rest speeds)
MOVE_SHARE = 0.05
REST_SPEED = 2e-3
#: startability: at least this long at rest between two breakaways [s]
MIN_REST_S = 1.0

RUNNING = ("constant_speed", "constant_pressure", "constant_flow", "constant_torque")


def _smooth(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, int]:
    """(moving median of x over SMOOTH_S, the half-window in samples); gaps filled in time first."""
    step = np.median(np.diff(t)) if t.size > 1 else 1.0
    half = max(2, int(round(SMOOTH_S / step))) if step > 0 else 2
    filled = pd.Series(x).interpolate(limit_direction="both").to_numpy()
    return pd.Series(filled).rolling(2 * half + 1, center=True, min_periods=1).median().to_numpy(), half


def _change(x: np.ndarray, half: int) -> np.ndarray:
    """|x(i + half) − x(i − half)| (ends clipped)."""
    i = np.arange(x.size)
    return np.abs(x[np.minimum(i + half, x.size - 1)] - x[np.maximum(i - half, 0)])


def _stretches(mask: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of each stretch where ``mask`` holds."""
    edges = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1))


def _running_pieces(t, speed, dp) -> list[np.ndarray] | None:
    ws, half = _smooth(t, speed)
    ds, _ = _smooth(t, dp)
    if not (np.isfinite(ws).any() and np.isfinite(ds).any()):
        return None
    still = ((_change(ws, half) <= np.maximum(SPEED_REL * np.abs(ws), SPEED_FLOOR))
             & (_change(ds, half) <= np.maximum(DP_REL * np.abs(ds), DP_FLOOR)))
    plateaus = [(a, b) for a, b in _stretches(still)
                if b - a + 1 >= MIN_PLATEAU_SAMPLES and t[b] - t[a] >= MIN_PLATEAU_S]
    groups: list[list] = []
    for a, b in plateaus:
        level = (np.median(ws[a:b + 1]), np.median(ds[a:b + 1]))
        if groups:
            w0, d0 = groups[-1][2]
            if (abs(level[0] - w0) <= 2 * max(SPEED_REL * abs(w0), SPEED_FLOOR)
                    and abs(level[1] - d0) <= 2 * max(DP_REL * abs(d0), DP_FLOOR)):
                groups[-1][1] = b  # the same set point, interrupted
                continue
        groups.append([a, b, level])
    if len(groups) < 2:
        return None
    return [np.arange(a, b + 1) for a, b, _ in groups]


def _startability_pieces(t, speed) -> list[np.ndarray] | None:
    ws, half = _smooth(t, speed)
    if not np.isfinite(ws).any():
        return None
    top = float(np.nanmax(np.abs(ws)))
    moving = np.abs(ws) > max(MOVE_SHARE * top, 10 * REST_SPEED)
    motions = _stretches(moving)
    if len(motions) < 2:
        return None
    # a motion after less than MIN_REST_S at rest goes on the one before (stick-slip, a stop and go)
    joined = [list(motions[0])]
    for a, b in motions[1:]:
        if t[a] - t[joined[-1][1]] < MIN_REST_S:
            joined[-1][1] = b
        else:
            joined.append([a, b])
    if len(joined) < 2:
        return None
    # each from where the motion before has come to rest (its slowing tail is not a shaft held at rest)
    starts = [0]
    for (_, b), (a, _) in zip(joined[:-1], joined[1:]):
        still = np.flatnonzero(np.abs(ws[b:a]) <= REST_SPEED)
        starts.append(min(b + int(still[0]) + 2 * half, (a + b) // 2) if still.size else (a + b) // 2)
    ends = [b for _, b in joined[:-1]] + [t.size - 1]
    return [np.arange(a, b + 1) for a, b in zip(starts, ends)]


def set_point_pieces(protocol: str, t, speed, dp, angle: bool = True) -> list[np.ndarray] | None:
    """Index arrays of the set points of one run (time order; SI: s, rad/s, Pa), or None where it holds
    one (or its protocol is not one this cuts).  ``angle`` False (no shaft angle logged): running runs
    are left whole, the no-angle route makes its points from quasi-steady cells of the motion
    (identify/log_points.py), plateaus and the motion between them alike."""
    t, speed, dp = (np.asarray(v, float) for v in (t, speed, dp))
    if t.size < 2 * MIN_PLATEAU_SAMPLES:
        return None
    if protocol in RUNNING and angle:
        return _running_pieces(t, speed, dp)
    if protocol == "startability":
        return _startability_pieces(t, speed)
    return None


def piece_name(run: str, k: int) -> str:
    """The name of the k-th (1-based) set point of ``run``."""
    return f"{run}~{k}"


def split_table(table: pd.DataFrame, rpm: float, bar: float) -> pd.DataFrame:
    """A log table in the format's columns (``run_id``, ``protocol``, ``time_s``, ``speed_rpm``,
    ``p_a_bar``, ``p_b_bar``) with each run of many set points cut into one run per set point (the ramps
    between them dropped); ``rpm``, ``bar``: SI per unit of its speed and pressure columns."""
    keep = np.ones(len(table), bool)
    names = table["run_id"].astype(object).to_numpy().copy()
    runs = pd.factorize(table["run_id"])[0]
    for r in np.unique(runs):
        rows = np.flatnonzero(runs == r)
        rows = rows[np.argsort(table["time_s"].to_numpy(float)[rows], kind="stable")]
        protocol = str(table["protocol"].iloc[rows[0]]).strip().lower().replace(" ", "_").replace("-", "_")
        angle = "shaft_angle_deg" in table and bool(np.isfinite(table["shaft_angle_deg"].to_numpy(float)[rows]).any())
        pieces = set_point_pieces(protocol, table["time_s"].to_numpy(float)[rows],
                                  table["speed_rpm"].to_numpy(float)[rows] * rpm,
                                  (table["p_a_bar"].to_numpy(float)[rows] - table["p_b_bar"].to_numpy(float)[rows]) * bar,
                                  angle)
        if pieces is None:
            continue
        keep[rows] = False
        run = str(names[rows[0]])
        for k, idx in enumerate(pieces, start=1):
            keep[rows[idx]] = True
            names[rows[idx]] = piece_name(run, k)
    out = table.assign(run_id=names)
    return out if keep.all() else out[keep].reset_index(drop=True)


def split_columns(run: str, protocol: str, cols: dict):
    """(run, protocol, columns) of each set point of one run read as SI columns (``time_s``,
    ``speed_rad_s``, ``p_a_Pa``, ``p_b_Pa``): itself where it holds one."""
    pieces = set_point_pieces(protocol, cols["time_s"], cols["speed_rad_s"], cols["p_a_Pa"] - cols["p_b_Pa"],
                              bool(np.isfinite(cols["theta_rad"]).any()))
    if pieces is None:
        yield run, protocol, cols
        return
    for k, idx in enumerate(pieces, start=1):
        yield piece_name(run, k), protocol, {c: (v[idx] if isinstance(v, np.ndarray) and v.shape[:1] == (len(cols["time_s"]),)
                                                 else v) for c, v in cols.items()}
