"""A table checked against the ideal machine of its spec before a fit takes it.

A unit may be valid and still wrong, and a sign convention may be another maker's:
a fit takes either into K_L and K_F and reports them identified.  Four checks,
each a one-line refusal that names the ratio and its likely cause:

- the port flow against the swept flow D·ω/2π (port A; port B's against −D·ω/2π):
  the coefficient k of D·ω/2π in a least-squares fit of the flow on D·ω/2π, P_A
  and P_B (the port's leakage to the case and across the ports, which dominates a
  slow map), within :data:`IDEAL_RATIO`;
- the torque against the pressure torque D·ΔP/2π (a slope through the origin over
  points above a tenth of the largest |ΔP|), within :data:`IDEAL_RATIO`;
- the torque must follow the pressure torque: where the points span pressure, D·ΔP/2π
  (with a constant and a sign-of-speed friction) explains at least
  :data:`MIN_PRESSURE_SHARE` of its variation (a square gridded map read with its two
  axes swapped fits, wrongly, with every ratio in range);
- the power balance: where a point holds the torque and the high-pressure port's
  flow, its overall efficiency (ISO 4409, :mod:`motorid.physics.efficiency`) in the
  median over a mode's points must not exceed :data:`MAX_EFFICIENCY` (a pump map in
  its own signs reads as a motor giving out more than it takes in).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motorid.errors import InputError

#: measured over ideal a table must show; outside, a unit, a sign convention or the spec's displacement
#: is wrong (flow/swept: 0.264 for gpm read as L/min, 9.55 for rad/s read as rpm, 16.4 for a displacement
#: in in³ written as cm³; torque/ideal: 0.069 for psi read as bar; −1 for a pump map's signs)
IDEAL_RATIO = (0.4, 2.5)
#: the median overall efficiency of a mode's points above which power out exceeds power in
MAX_EFFICIENCY = 1.02

_CAUSES = ("a unit (a ratio of 0.264: gpm read as L/min; 9.55: a speed in rad/s read as rpm; 0.069 on the "
           "torque: psi read as bar), or the spec's displacement (16.4: in³ written as cm³)")


def _flow_coefficient(q, swept, p_a, p_b) -> tuple[float, int]:
    """k of q ≈ k·swept + a·P_A + b·P_B over the finite points (NaN where they cannot tell k)."""
    ok = np.isfinite(q) & np.isfinite(swept) & np.isfinite(p_a) & np.isfinite(p_b)
    if ok.sum() < 4 or not np.any(np.abs(swept[ok]) > 0):
        return float("nan"), int(ok.sum())
    # the leakage columns that vary (a one-quadrant map holds its low port at one pressure)
    cols = [swept[ok]] + [p[ok] for p in (p_a, p_b) if np.ptp(p[ok]) > 1e-3 * max(np.abs(p[ok]).max(), 1.0)]
    X = np.column_stack(cols)
    scale = np.where(np.abs(X).max(axis=0) > 0, np.abs(X).max(axis=0), 1.0)
    Xs = X / scale
    coef, _, rank, sv = np.linalg.lstsq(Xs, q[ok], rcond=None)
    if rank < X.shape[1] or X.shape[1] == 1 or sv[-1] < 1e-6 * sv[0]:  # the plain slope of the faster points
        return _slope_of_larger(q, swept, ok, least=1)
    return float(coef[0] / scale[0]), int(ok.sum())


def _slope_of_larger(y, x, ok, least: int) -> tuple[float, int]:
    """The slope through the origin of y on x over the points of ``ok`` above a tenth of the largest |x|
    (NaN where fewer than ``least``), and their count."""
    ok = ok & (np.abs(x) > 0.1 * np.nanmax(np.abs(x[ok])))
    if ok.sum() < least:
        return float("nan"), int(ok.sum())
    return float(np.sum(y[ok] * x[ok]) / np.sum(x[ok] ** 2)), int(ok.sum())


def _torque_slope(t, ideal) -> tuple[float, int]:
    ok = np.isfinite(t) & np.isfinite(ideal)
    if ok.sum() < 3:
        return float("nan"), int(ok.sum())
    return _slope_of_larger(t, ideal, ok, least=3)


#: the share of the torque's variation the pressure torque must explain where the points span
#: pressure (:func:`_torque_follows_pressure`); a working motor's losses are a fraction of D·ΔP/2π
MIN_PRESSURE_SHARE = 0.5


def _torque_follows_pressure(t, ideal, speed) -> tuple[float, int]:
    """R² of the torque on a·D·ΔP/2π + b·sgn ω + c (the pressure torque and a Coulomb-like
    friction) over the finite points, and their count; NaN where the points do not span
    pressure (the pressure torque's range under 0.3 of the largest |torque|) or are too few."""
    ok = np.isfinite(t) & np.isfinite(ideal) & np.isfinite(speed)
    if ok.sum() < 8:
        return float("nan"), int(ok.sum())
    t, ideal, speed = t[ok], ideal[ok], speed[ok]
    if np.ptp(ideal) < 0.3 * np.max(np.abs(t)) or np.ptp(t) == 0:
        return float("nan"), int(ok.sum())
    X = np.column_stack([ideal, np.sign(speed), np.ones_like(t)])
    coef = np.linalg.lstsq(X, t, rcond=None)[0]
    rss = float(np.sum((t - X @ coef) ** 2))
    return 1.0 - rss / float(np.sum((t - t.mean()) ** 2)), int(ok.sum())


def check_against_ideal(table, path, counted: str = "points", whose: str = "") -> None:
    """Refuse (:class:`InputError`, one line) a table whose flows or torque are not near the ideal
    machine's, or whose points give out more power than they take in.  ``counted``, ``whose``: the
    words for the rows (the steady samples of logs: "samples", "the steady samples' ")."""
    from motorid.physics.efficiency import efficiencies

    name = Path(str(path)).name
    d = np.asarray(table.displacement, float) / (2.0 * np.pi)
    swept, ideal = d * table.speed, d * table.dp
    cm3 = float(np.nanmedian(table.displacement)) * 1e6
    nan = np.full(len(table), np.nan)
    m = {c: np.asarray(table.measured.get(c, nan), float) for c in ("torque", "q_a", "q_b")}
    checks = [("port A flow", *_flow_coefficient(m["q_a"], swept, table.p_a, table.p_b), "the swept flow D·ω/2π",
               ""),
              ("port B flow", *_flow_coefficient(-m["q_b"], swept, table.p_a, table.p_b),
               "the swept flow D·ω/2π taken out of port B",
               " (port B's flow is the flow into port B: negative where the oil leaves it)"),
              ("torque", *_torque_slope(m["torque"], ideal), "the ideal torque D·ΔP/2π", "")]
    for words, k, n, base, sign_hint in checks:
        if not np.isfinite(k) or IDEAL_RATIO[0] <= k <= IDEAL_RATIO[1]:
            continue
        if k < 0:
            why = ("its sign runs against the ideal machine's: a sign convention (a pump map's torque and "
                   "flow, the speed's direction: docs/formats.md, channel maps)" + sign_hint)
        else:
            why = _CAUSES + sign_hint
        raise InputError(f"{name}: {whose}{words} is {k:.3g}× {base} of D = {cm3:.4g} cm³/rev over {n} "
                         f"{counted}, outside {IDEAL_RATIO[0]}-{IDEAL_RATIO[1]}: {why}")
    share, n = _torque_follows_pressure(m["torque"], ideal, np.asarray(table.speed, float))
    if np.isfinite(share) and share < MIN_PRESSURE_SHARE:
        raise InputError(f"{name}: {whose}torque does not follow the pressure torque D·ΔP/2π of D = {cm3:.4g} "
                         f"cm³/rev (it explains {max(share, 0.0):.0%} of the torque's variation over {n} {counted}, "
                         f"a working motor's far more): the pressures read are not the motor's ports")
    # the power balance of each mode, at points that hold both the torque and the high-pressure flow
    _, _, eta = efficiencies(m["torque"], m["q_a"], m["q_b"], table.speed, table.p_a, table.p_b,
                             np.asarray(table.displacement, float))
    power = table.dp * table.speed
    big = (np.abs(swept) > 0.1 * np.nanmax(np.abs(swept))) & (np.abs(ideal) > 0.1 * np.nanmax(np.abs(ideal)))
    for mode, where in (("motor", power > 0), ("pump", power < 0)):
        e = np.asarray(eta)[where & big & np.isfinite(eta)]
        if e.size >= 3 and np.median(e) > MAX_EFFICIENCY:
            raise InputError(f"{name}: its {mode}-mode {counted} give out more power than they take in (median "
                             f"overall efficiency {np.median(e):.3g} over {e.size} {counted}): a pump map in its own "
                             f"signs? In the format's sense a pump delivering out of port A turns the way flow "
                             f"into port B drives it: its speed takes sign = -1 (docs/formats.md, sign conventions)")
