"""Oil temperature logged slower than the other channels: the empty cells between its readings filled in time.

A DAQ that writes every channel into one table at the fastest rate leaves the slow ones empty between
their readings: an oil temperature read once a second sits on one row in a thousand at 1 kHz.  Taken
as it is, every other row has no viscosity and is left out of the fit.  The oil's temperature changes
over seconds to minutes (the thermal mass of the motor and its lines), so within a run the empty
cells are filled by linear interpolation in time between the readings around them, and held at the
run's ends, wherever the readings around are less than :data:`TEMPERATURE_GAP_S` apart (a longer gap
stays empty: nothing is invented over it).  Used by :func:`motorid.io.logs.read_log` and the
streamed reader (:mod:`motorid.io.stream`, which carries the last reading from block to block).
"""

from __future__ import annotations

import numpy as np

#: readings further apart than this [s] (or further from a run's end) leave the cells between them empty
TEMPERATURE_GAP_S = 60.0


def fill_temperature_gaps(t, temp, runs, carry=None):
    """(temperatures with the gaps between readings filled [°C], carry) for rows in time order within each
    run: ``t`` [s], ``temp`` [°C] (NaN: no reading), ``runs`` a label or code per row (rows of one run
    contiguous); ``carry`` (run, time, value) of the last reading of the block before, or None; the
    returned carry is this block's."""
    temp = np.array(temp, dtype=float)
    t = np.asarray(t, dtype=float)
    runs = np.asarray(runs)
    if temp.size == 0:
        return temp, carry
    starts = np.flatnonzero(np.r_[True, runs[1:] != runs[:-1]])
    ends = np.r_[starts[1:], temp.size]
    missing = np.isnan(temp)
    for a, b in zip(starts, ends):
        y = temp[a:b]
        have = ~missing[a:b]
        xs, ys = t[a:b][have], y[have]
        if carry is not None and carry[0] == runs[a]:
            xs, ys = np.r_[carry[1], xs], np.r_[carry[2], ys]
        if have.any():
            carry = (runs[a], float(xs[-1]), float(ys[-1]))
        if xs.size == 0 or have.all():
            continue
        q = t[a:b][~have]
        right = np.searchsorted(xs, q)
        before = np.where(right > 0, q - xs[np.maximum(right - 1, 0)], np.inf)
        after = np.where(right < xs.size, xs[np.minimum(right, xs.size - 1)] - q, np.inf)
        span = np.where(np.isfinite(before) & np.isfinite(after), before + after, np.minimum(before, after))
        y[~have] = np.where(span <= TEMPERATURE_GAP_S, np.interp(q, xs, ys), np.nan)
    return temp, carry
