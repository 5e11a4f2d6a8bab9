"""Loss laws that differ between motor and pump mode (the direction of power flow).

A catalog mechanism (registered in :mod:`motorid.physics.registry`) adding
its torque through the ``running`` hook of the one model; pure ``jax.numpy``,
elementwise, finite gradients everywhere (ω = 0 and ΔP = 0 included).

Power flows from the oil to the shaft (motor mode) where ω·ΔP > 0 and from the
shaft to the oil (pump mode) where ω·ΔP < 0, ΔP = P_A − P_B, the sign
convention of the logs (flow into port A turns the shaft positive).

Importing: this module subclasses the catalog's ``CatalogMechanism``; import it
through :mod:`motorid.physics.registry` (``catalog.get("pump_mode_friction")``).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from motorid import _jaxconfig  # noqa: F401
from motorid.physics.base import CatalogMechanism, ParameterInfo
from motorid.units import PA_PER_BAR as BAR

#: pressure over which the mode indicator turns from pump to motor around ΔP = 0 [Pa] (1 bar)
MODE_SMOOTHING = 1e5


def pump_mode_share(direction, dp, scale=MODE_SMOOTHING):
    """1 in pump mode (power from shaft to oil), 0 in motor mode, smooth in ΔP [-].

    s = (1 − sgn ω · tanh(ΔP / ε)) / 2: within 0.1 % of the step for |ΔP| > 4 ε
    (4 bar); ½ where ΔP = 0 or the direction is 0 (a padded sample).  sgn ω is
    the run's direction, so noise at low speed cannot flip the mode.
    """
    return 0.5 * (1.0 - direction * jnp.tanh(dp / scale))


#: points of each mode a table needs before a law differing between the modes is tried on it
MIN_POINTS_PER_MODE = 4


def mode_counts(direction, dp) -> tuple[int, int]:
    """(pump-mode, motor-mode) samples or points: |ΔP| > 4 bar against, or with, the direction of
    rotation (sgn ω)."""
    power = np.asarray(direction, float) * np.asarray(dp, float)
    return int(np.count_nonzero(power < -4.0 * MODE_SMOOTHING)), int(np.count_nonzero(power > 4.0 * MODE_SMOOTHING))


class PumpModeFriction(CatalogMechanism):
    """A pressure-proportional friction that differs in pump mode [N·m].

    T_pm = −sgn ω · ΔK_F · D |ΔP| · s_pump(ω, ΔP)                     (1)

    ΔK_F [-] is the change of the bearing friction coefficient K_F (per unit
    D·ΔP, like K_F) from motor to pump mode, of either sign; s_pump is the
    smooth pump-mode indicator of :func:`pump_mode_share`; D [m³/rev], ΔP [Pa].
    In motor mode the model is unchanged.

    Physics: the friction forces in the piston bores, ball joints and the
    valve-plate/cylinder-block interface depend on how the pressure forces and
    the drive forces meet.  In motor mode the pistons drive the shaft; in pump
    mode the shaft drives the pistons against the pressure, the side forces on
    the pistons and the tilting moments on the block take other values, and the
    friction coefficients measured on the same unit differ between the modes —
    the four-quadrant maps of real units show different torque losses for the
    same |ΔP| and |ω| in pump and in motor mode.

    Signature and what it is confused with: only pump-mode runs (speed against
    the pressure difference) carry it, in proportion to |ΔP| and with the sign
    of friction.  A campaign of motor-mode runs only (the ISO 4392-1 plans)
    cannot see it: the parameter is then not identifiable and the mechanism is
    never named.  With pump-mode runs, the base K_F is fixed by the motor-mode
    runs, so ΔK_F is not confused with K_F; a torque offset (same sign in both
    directions) and the speed-only friction terms (present in both modes) leave
    other patterns.
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "pump_mode_friction"
    name = "pump-mode friction (loss law differing between pump and motor mode)"
    physics = ("In motor mode the pistons drive the shaft; in pump mode the shaft drives the pistons against the "
               "pressure, so the side forces and tilting moments on pistons and cylinder block, and with them the "
               "friction per unit pressure, differ between the two modes. "
               "The torque loss then takes a different coefficient where power flows from the shaft to the oil.")
    reference = ("H. Ivantysyn, M. Ivantysynova, 'Hydrostatic Pumps and Motors', Akademia Books, 2001 (torque "
                 "losses in pump and motor operation); N. D. Manring, 'Fluid Power Pumps and Motors: Analysis, "
                 "Design and Control', McGraw-Hill, 2013 (efficiency of pumps and motors, four quadrants); "
                 "ISO 4409:2019 (steady-state performance of pumps, motors and integral transmissions)")
    channels = ("torque",)
    parameters = {
        "pump_mode_friction.dKF": ParameterInfo(
            "-", "change of the friction coefficient K_F (per unit D|ΔP|) in pump mode", False, 1e-3),
    }
    signature = ("running torque in pump-mode runs only (speed against ΔP): an extra friction ∝ |ΔP|, sign "
                 "following the direction of rotation, absent from every motor-mode run; invisible (never named) "
                 "on a campaign with no pump-mode runs")

    def seen_by(self, dataset) -> bool:
        """Whether the campaign has pump-mode running samples (|ΔP| > 4 bar against the
        direction of rotation) and motor-mode ones (with it); diagnose does not try the mechanism
        where it lacks either: with pump mode alone ΔK_F is K_F in other words."""
        s = dataset.running
        return min(mode_counts(s.direction, np.asarray(s.p_a) - np.asarray(s.p_b))) >= 20

    def unseen_in_table(self, table) -> str | None:
        """A table needs points of both modes (|ΔP| > 4 bar): on points of one mode alone the
        change from one mode to the other is the friction coefficient K_F itself (on a pump's map,
        the pump-mode law is the only law)."""
        pump, motor = mode_counts(np.sign(np.asarray(table.speed, float)), table.dp)
        if min(pump, motor) >= MIN_POINTS_PER_MODE:
            return None
        return (f"the table holds {pump} pump-mode and {motor} motor-mode points: a friction law that differs "
                f"between the modes needs at least {MIN_POINTS_PER_MODE} points of each, and on one mode alone its "
                f"change is the friction coefficient K_F in other words")

    def running(self, params, spec, samples, ch):
        s = samples
        dp = s.p_a - s.p_b
        share = pump_mode_share(s.direction, dp)
        t = -s.direction * self.param(params, "dKF") * spec.displacement * jnp.abs(dp) * share
        return ch._replace(torque=ch.torque + t)

    def describe(self, values, spec=None) -> str:
        dk = self.value(values, "dKF")
        more = "more" if dk >= 0 else "less"
        words = f"in pump mode the friction per unit D|ΔP| is {abs(dk):.3g} {more} than in motor mode (ΔK_F = {dk:.3g})"
        if spec is not None:
            words += f": {abs(dk) * spec.displacement * 250 * BAR:.3g} N·m {more} torque loss at 250 bar"
        return words

