"""Wear trends: a parameter's change per year for a motor tested on several dates.

For the estimates x_j ± σ_j of one motor's parameter at test dates t_j [years],
the trend is the weighted least-squares line [Eq. T1]::

    x_j = a + b (t_j − t̄),   weights w_j = 1/σ_j²,
    b̂ = Σ w_j (t_j − t̄_w) x_j / Σ w_j (t_j − t̄_w)²,   SE(b̂) = 1 / √(Σ w_j (t_j − t̄_w)²)

in SI per year (``per_year``).  With two dates it is the difference over the
time between them, SE = √(σ₁² + σ₂²)/Δt, and the 95 % interval is b̂ ± 1.96 SE.
With three or more dates, where the dates scatter about the line more than
their standard errors allow (χ²/(n−2) > 1: bench-to-bench differences the
per-date errors do not hold), SE is multiplied by √(χ²/(n−2)) (Birge ratio)
and the interval uses Student's t with n − 2 degrees of freedom.

Verdict [Eq. T2]: ``rising`` where b̂ / SE exceeds the two-sided critical value
at α = 0.05 / P (P: the parameters trended for this motor; Bonferroni, so a
motor that does not change shows any verdict other than ``stable`` in at most
5 % of re-tests), ``falling`` where it is below minus that value, else
``stable``.
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

DAYS_PER_YEAR = 365.25
TREND_ALPHA = 0.05


@dataclass
class Trend:
    serial: str
    parameter: str
    dates: list  # datetime.date, sorted
    values: list  # SI
    stds: list  # SI
    per_year: float  # SI per year
    se: float
    ci95: tuple
    z: float  # per_year / se
    critical: float  # |z| beyond which the verdict is not "stable"
    verdict: str  # rising | falling | stable


def years(dates) -> np.ndarray:
    """Dates as years since the first one [a]."""
    d0 = min(dates)
    return np.array([(d - d0).days / DAYS_PER_YEAR for d in dates], float)


def wls_slope(t, x, s) -> tuple[float, float, float]:
    """Eq. T1: (slope, its SE with the Birge inflation where n > 2, Student dof or inf)."""
    t, x, s = (np.asarray(v, float) for v in (t, x, s))
    w = 1.0 / (s * s)
    tb = np.sum(w * t) / np.sum(w)
    sxx = float(np.sum(w * (t - tb) ** 2))
    b = float(np.sum(w * (t - tb) * x) / sxx)
    se = 1.0 / math.sqrt(sxx)
    n = t.size
    if n <= 2:
        return b, se, math.inf
    a = float(np.sum(w * x) / np.sum(w))
    chi2 = float(np.sum(w * (x - a - b * (t - tb)) ** 2))
    return b, se * math.sqrt(max(1.0, chi2 / (n - 2))), float(n - 2)


def motor_trends(serial: str, series: dict, alpha: float = TREND_ALPHA) -> list[Trend]:
    """Trends of one motor: ``series`` = {parameter: [(date, value, std), ...]} (identifiable
    estimates only). Parameters seen on fewer than two distinct dates get none."""
    usable = {}
    for parameter, rows in series.items():
        rows = sorted(rows, key=lambda r: r[0])
        if len({r[0] for r in rows}) >= 2 and all(r[2] is not None and r[2] > 0 for r in rows):
            usable[parameter] = rows
    if not usable:
        return []
    crit_z = float(stats.norm.isf(alpha / len(usable) / 2))
    out = []
    for parameter, rows in sorted(usable.items()):
        dates = [r[0] for r in rows]
        x = [float(r[1]) for r in rows]
        s = [float(r[2]) for r in rows]
        b, se, dof = wls_slope(years(dates), x, s)
        q95 = float(stats.norm.isf(0.025) if math.isinf(dof) else stats.t.isf(0.025, dof))
        crit = crit_z if math.isinf(dof) else float(stats.t.isf(alpha / len(usable) / 2, dof))
        z = b / se
        verdict = "rising" if z > crit else "falling" if z < -crit else "stable"
        out.append(Trend(serial, parameter, dates, x, s, b, se, (b - q95 * se, b + q95 * se), z, crit, verdict))
    return out


def as_date(x) -> _dt.date:
    if isinstance(x, _dt.datetime):
        return x.date()
    if isinstance(x, _dt.date):
        return x
    return _dt.date.fromisoformat(str(x)[:10])
