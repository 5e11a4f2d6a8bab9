"""Transducer errors: what the bench reads is not what the motor does.

Mechanisms of the physics registry (issue 15) that model the *reading*, as
an extension of the one model (their hooks change the channel a transducer
reports, never the motor's physics):

- ``flow_meter_gain_a``, ``flow_meter_gain_b``, ``flow_meter_gain_case``: one
  flow meter reads (1 + g) times the true flow.  The bench's redundancy names
  the meter: the mass balance Q_AN + Q_BN = Q_CN (Bartos 1992 Eq. 59-61) holds
  for the motor whatever its parameters, so a gain on one meter breaks it by
  g·Q of that meter alone; a port meter's error is ∝ the swept flow D ω/2π
  (∝ speed, one port only), the case meter's ∝ the leakage (∝ ΔP/μ).
- ``torque_meter_gain``: the torque transducer reads (1 + g)·T, in the running
  torque and the held torque at breakaway.  In the torque alone it is the same
  as a displacement error (both scale T_p, friction rescales into K_F, T_Fc…);
  the flows tell them apart: a torque gain leaves every flow alone.
- ``sensor_lag_torque``, ``sensor_lag_q_a``, ``sensor_lag_q_b``,
  ``sensor_lag_q_case``: the transducer is a first-order filter
  τ dy/dt + y = x of time constant τ.  At a steady speed every shaft-locked
  ripple of the channel, a sum of harmonics cos(kθ) of the shaft angle, comes
  through as cos(kθ) → (cos kθ + kωτ sin kθ)/(1 + (kωτ)²): its amplitude falls
  as 1/√(1 + (kωτ)²) and it lags by atan(kωτ) of shaft angle.  The run's mean is
  untouched, so a lag shows only in the ripple's size and phase against the
  shaft order and the speed: nothing at low speed, the ripple flattened and
  shifted at high speed.  The ripple the hook filters is the 1992 model's own:
  the pressure torque D ΔP S(θ)/2n and swept flow D ω S(θ)/2n through the Fourier
  series of S(θ) (:func:`port_sum_harmonics`), and the leakage harmonics K_L(θ).

- ``flow_meter_offset_a``, ``flow_meter_offset_b``, ``flow_meter_offset_case``:
  one flow meter reads a constant c on top of the true flow, the same in
  every run.  The mass balance breaks by ±c (−c for the case meter) at every
  operating point, at rest and in both directions (a gain breaks it in
  proportion to the flow, so not at zero flow, and a port meter's with the
  sign of the swept flow).

Zero offsets: a constant torque offset is :class:`TorqueOffset` (``torque_offset``), a constant
flow-meter offset :class:`MeterOffset`; offsets that differ run to run are told from the motor by
:mod:`motorid.discrepancy.unexplained` (they follow no operating variable).
"""

from __future__ import annotations

import math
import numpy as np

import jax.numpy as jnp

from motorid import _jaxconfig  # noqa: F401
from motorid.physics.base import CatalogMechanism, ParameterInfo
from motorid.physics.flow import leakage_harmonics
from motorid.units import LPM_PER_M3S, RAD_S_PER_RPM
#: shaft orders of S(θ) kept in the lagged ripple (harmonics above fall off as 1/k² and are filtered anyway)
PORT_SUM_HARMONICS = 24

class TorqueOffset(CatalogMechanism):
    """Torque transducer zero offset [N·m]: +T0 on every torque reading.

    Added to the running torque and to the held torque read at breakaway; its
    sign does not follow the direction of rotation.
    """

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    sensor = True  # changes a reading, not the motor: exports leave it out
    id = "torque_offset"
    name = "torque transducer zero offset"
    physics = ("The torque transducer reads a constant offset on top of the true shaft torque, from an "
               "imperfect zero or a drifting strain-gauge bridge. "
               "Unlike friction, which opposes motion, the offset has the same sign in both directions of "
               "rotation, in the held torque at breakaway too.")
    reference = ("ISO 4392-1:2002 and ISO 9110-1 (measurement accuracy of hydraulic test benches); "
                 "E. O. Doebelin, 'Measurement Systems: Application and Design', 5th ed., McGraw-Hill, 2004 "
                 "(zero offset and drift)")
    channels = ("torque", "breakaway")
    parameters = {
        "torque_offset.T0": ParameterInfo("N·m", "torque reading offset, same in both directions", False, 2.0),
    }
    signature = ("running torque in both directions and the breakaway held torque: a constant shift of the same "
                 "sign whatever the speed, pressure and direction (friction would change sign with direction)")

    def running(self, params, spec, samples, ch):
        return ch._replace(torque=ch.torque + self.param(params, "T0"))

    def breakaway_reading(self, params, spec, events, held):
        return held + self.param(params, "T0")

    def describe(self, values, spec=None) -> str:
        t0 = self.value(values, "T0")
        word = "high" if t0 >= 0 else "low"
        return (f"the torque transducer reads {abs(t0):.3g} N·m {word} in both directions of rotation "
                "and at breakaway (zero offset)")


_METER_WORDS = {"q_a": "port A flow meter", "q_b": "port B flow meter", "q_case": "case-drain flow meter",
                "torque": "torque transducer"}
_SUFFIX = {"q_a": "a", "q_b": "b", "q_case": "case"}


def port_sum_harmonics(pistons: int, count: int = PORT_SUM_HARMONICS) -> list[tuple[int, float]]:
    """Fourier series of S(θ) = n/π + Σ_k c_k cos(kθ): the first ``count`` pairs (k, c_k) [-].

    One piston contributes max(cos θ, 0) = 1/π + cos θ/2 + Σ_{k even} (2/π) cos(kπ/2)/(1 − k²) cos kθ;
    summed over the n pistons θᵢ = θ + 2π(i−1)/n only the orders k that n divides survive, times n.
    """
    out, k = [], 2
    while len(out) < count:
        if k % pistons == 0 and k % 2 == 0:
            out.append((k, pistons * (2.0 / math.pi) * math.cos(k * math.pi / 2.0) / (1.0 - k * k)))
        k += 1
    return out


def lag_change(k, theta, speed, tau, phase=0.0):
    """First-order lag of cos(kθ + phase) and sin(kθ + phase) at steady speed, minus the unlagged [-].

    With x = kωτ: cos → (cos + x sin)/(1 + x²), sin → (sin − x cos)/(1 + x²).
    returns (Δcos, Δsin).
    """
    x = k * speed * tau
    c, s = jnp.cos(k * theta + phase), jnp.sin(k * theta + phase)
    den = 1.0 + x * x
    return (x * s - x * x * c) / den, (-x * c - x * x * s) / den


def lagged_port_sum_change(theta, speed, tau, pistons: int, port_sum=None):
    """S_lag(θ) − S(θ): what a first-order lag τ takes from the ripple of S at speed ω [-].

    The first :data:`PORT_SUM_HARMONICS` orders exactly; the rest of S (its kinks' 1/k² tail,
    S − n/π − Σ c_k cos kθ) scaled by the lag's cosine factor −x²/(1 + x²) at the first order left
    out (that tail's orders are filtered at least as much).
    """
    from motorid.physics.kinematics import port_a_sum

    harmonics = port_sum_harmonics(pistons)
    total, kept = 0.0, pistons / math.pi
    for k, c in harmonics:
        total = total + c * lag_change(k, theta, speed, tau)[0]
        kept = kept + c * jnp.cos(k * theta)
    s = port_a_sum(theta, pistons) if port_sum is None else port_sum
    k_next = harmonics[-1][0] + (pistons if pistons % 2 == 0 else 2 * pistons)
    x = k_next * speed * tau
    return total - (s - kept) * x * x / (1.0 + x * x)


def lagged_leakage_change(theta, speed, tau, params, pistons: int):
    """K_L(θ)_lag − K_L(θ): the lag's change of the leakage coefficient's harmonics [m³]."""
    m = sum(1 for k in params if k.startswith("KL_a"))
    a, b = leakage_harmonics(params, m)
    total = 0.0
    for order, (am, bm) in enumerate(zip(a, b), start=1):
        dc, ds = lag_change(order * pistons, theta, speed, tau)
        total = total + am * dc + bm * ds
    return params["KL0"] * total


class _LinearReading(CatalogMechanism):
    """A transducer error on one channel, linear in its one parameter (a gain, a zero)."""

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    sensor = True  # changes a reading, not the motor: exports leave it out

    single_start = True  # linear in its parameter: one start of the fit is enough

    channel: str  # set by each instance: torque, q_a, q_b or q_case

    def seen_by(self, dataset) -> bool:
        """A flow meter's error is tried only where the meters keep their zeros: where they wander from run
        to run the fit cannot tell a gain or a constant zero from the zeros in the run means, and the mass
        balance's own estimate of the gains (:func:`~motorid.physics.mass_balance.flow_balance`, with
        random-effects weights) goes into the unexplained entry instead.  The torque transducer's is always
        tried."""
        if self.channel == "torque":
            return True
        from motorid.physics.mass_balance import flow_zeros_wander

        return not flow_zeros_wander(dataset)

    def unseen_in_table(self, table) -> str | None:
        """A flow meter's error is named on a table only where the meters' own mass balance shows it:
        without it a zero or a gain of one meter is a leakage law in other words (a constant case
        flow is the low-pressure port's leakage at one boost pressure and temperature)."""
        if self.channel == "torque":
            return self._torque_unseen(table)
        from motorid.physics.mass_balance import table_balance_shows

        return table_balance_shows(table, self.channel, gain=isinstance(self, MeterGain))


    def _torque_unseen(self, table) -> str | None:
        """The torque transducer's error on a table whose running points all have their low-pressure port at
        one pressure: a gain g of the torque is then K_F's shape (K_F·D·(P_A+P_B) = K_F·D·|ΔP| + a
        constant), and in pump mode that of a pump-mode friction, with no ripple to tell them apart."""
        if not isinstance(self, MeterGain):
            return None
        tq = np.isfinite(np.asarray(table.measured["torque"], dtype=float))
        if tq.sum() < 2 or not one_back_pressure(np.minimum(table.p_a, table.p_b)[tq]):
            return None
        return ("every running torque point has its low-pressure port at one pressure: a gain error of the torque "
                "transducer is then a change of K_F (and in pump mode a pump-mode friction) in other words, "
                "which points without the shaft-angle ripple cannot tell apart; a second back pressure does")


#: spread (2-98 %) of the low-pressure port below which the points share one back pressure [Pa]
ONE_BACK_PRESSURE_PA = 1e5


def one_back_pressure(low_port_pressure) -> bool:
    """Whether every running point has its low-pressure port at one pressure (within
    :data:`ONE_BACK_PRESSURE_PA`, 2-98 %): K_F·D·(P_A + P_B) is then K_F·D·|ΔP| plus a constant, the
    shape a gain error of the torque transducer gives the ideal torque."""
    low = np.asarray(low_port_pressure, dtype=float)
    low = low[np.isfinite(low)]
    if low.size < 2:
        return False
    lo, hi = np.percentile(low, [2, 98])
    return bool(hi - lo <= ONE_BACK_PRESSURE_PA)


class MeterGain(_LinearReading):
    """A transducer reading (1 + g) times the true value of one channel [-]."""

    def __init__(self, channel: str):
        self.channel = channel
        word = _METER_WORDS[channel]
        if channel == "torque":
            self.id = "torque_meter_gain"
            self.channels = ("torque", "breakaway")
            self.signature = ("running and held torque in proportion to the torque itself: ∝ ΔP in both "
                              "directions (in the torque alone like a displacement error or a change of K_F), "
                              "while every flow, and the flows' mass balance, agrees with the model")
            self.reference = ("ISO 4392-1:2002 and ISO 9110-1:1990 (measurement accuracy classes of hydraulic "
                              "test benches); E. O. Doebelin, 'Measurement Systems: Application and Design', "
                              "5th ed., McGraw-Hill, 2004 (calibration, sensitivity error)")
            self.physics = ("The torque transducer's sensitivity differs from its calibration certificate, from a "
                            "bridge supply, an amplifier gain or a calibration lever that is off. "
                            "Every torque reading, running or held at breakaway, is then off by the same fraction "
                            "of itself, while the flows and the motor are as the model says.")
            unit_words = "torque"
        else:
            self.id = f"flow_meter_gain_{_SUFFIX[channel]}"
            self.channels = (channel,)
            # the mass balance ties the three meters: the base fit spreads one meter's error over all flows
            self.shows_in = ("q_a", "q_b", "q_case")
            if channel == "q_case":
                self.signature = ("case-drain flow in proportion to itself (∝ the leakage, ΔP/μ), while the port "
                                  "flows agree: the mass balance Q_A + Q_B = Q_case breaks by g·Q_case, seen at low "
                                  "speed where the port flows carry the leakage")
            else:
                other = "B" if channel == "q_a" else "A"
                self.signature = (f"{word[:6]} flow in proportion to itself, mostly ∝ the swept flow Dω/2π (∝ speed), "
                                  f"with no matching change in port {other} or the case drain: the mass balance "
                                  "breaks by g·Q of this meter (a displacement error would move both ports, "
                                  "opposite in sign)")
            self.reference = ("ISO 4392-1:2002 and ISO 9110-1:1990 (measurement accuracy of hydraulic test "
                              "benches); ISO 4185:1980 (measurement of liquid flow, weighing method: meter "
                              "calibration)")
            self.physics = (f"The {word}'s calibration factor (its K-factor, volume per pulse) differs from the "
                            "one the DAQ applies, from wear, another oil's viscosity or a wrong data sheet. "
                            "Its reading is then off by the same fraction of the flow it meters, and no other "
                            "meter shares the error, so the flows no longer add up.")
            unit_words = "flow"
        self.name = f"{word} gain error"
        self.parameters = {f"{self.id}.g": ParameterInfo(
            "-", f"relative gain error of the {word}: reading = (1 + g)·true {unit_words}", False, 0.01)}

    def running(self, params, spec, samples, ch):
        g = self.param(params, "g")
        return ch._replace(**{self.channel: getattr(ch, self.channel) * (1.0 + g)})

    def breakaway_reading(self, params, spec, events, held):
        if self.channel != "torque":
            return held
        return held * (1.0 + self.param(params, "g"))

    def describe(self, values, spec=None) -> str:
        g = self.value(values, "g")
        word = _METER_WORDS[self.channel]
        return f"the {word} reads {100 * abs(g):.3g} % {'high' if g >= 0 else 'low'} (gain {1 + g:.5g})"


class SensorLag(CatalogMechanism):
    """A transducer that is a first-order filter of time constant τ [s] on one channel."""

    sensor = True  # changes a reading, not the motor: exports leave it out

    def __init__(self, channel: str):
        self.channel = channel
        word = _METER_WORDS[channel]
        self.id = f"sensor_lag_{channel}"
        self.name = f"{word} lag (first-order filter)"
        self.channels = (channel,)
        self.parameters = {f"{self.id}.tau": ParameterInfo(
            "s", f"time constant τ of the {word}'s first-order response", True,
            2e-3 if channel == "torque" else 5e-4)}
        ripple = {"torque": "the pressure-torque ripple at the piston order",
                  "q_a": "the swept-flow and leakage ripple at the piston order",
                  "q_b": "the swept-flow and leakage ripple at the piston order",
                  "q_case": "the leakage ripple K_L(θ) at the piston order"}[channel]
        self.signature = (f"{_channel_words(channel)} vs shaft angle: {ripple} is smaller and later than the "
                          "model's in proportion to the shaft order times speed (amplitude 1/√(1+(kωτ)²), lag "
                          "atan(kωτ)): exact at low speed, flattened and shifted at high speed; run means untouched")
        self.reference = ("E. O. Doebelin, 'Measurement Systems: Application and Design', 5th ed., McGraw-Hill, "
                          "2004 (first-order instruments: time constant, amplitude ratio and phase); ISO 4392-1:2002 "
                          "(instrument response in motor tests)")
        self.physics = (f"The {word} does not follow fast changes: its reading relaxes toward the true value with a "
                        "time constant τ, from its mechanics, its electronics or the DAQ's anti-alias filter. "
                        "The shaft-locked ripple, whose frequency is the shaft order times the speed, is then "
                        "flattened and delayed more the faster the shaft turns, while slow runs and run means read "
                        "true.")

    def _change(self, params, spec, s, tau):
        n, D = spec.pistons, spec.displacement
        if self.channel == "torque":
            return D * (s.p_a - s.p_b) / (2.0 * n) * lagged_port_sum_change(s.theta, s.speed, tau, n, s.port_sum)
        swept = D * s.speed / (2.0 * n) * lagged_port_sum_change(s.theta, s.speed, tau, n, s.port_sum)
        leak_a = lagged_leakage_change(s.theta, s.speed, tau, params, n) * (s.p_a - s.p_case) / s.viscosity
        leak_b = lagged_leakage_change(s.theta - spec.phase, s.speed, tau, params, n) * (s.p_b - s.p_case) / s.viscosity
        if self.channel == "q_a":
            return swept + leak_a
        if self.channel == "q_b":
            return -swept + leak_b
        return leak_a + leak_b

    def running(self, params, spec, samples, ch):
        tau = self.param(params, "tau")
        return ch._replace(**{self.channel: getattr(ch, self.channel) + self._change(params, spec, samples, tau)})

    def neutral(self) -> dict:
        return {f"{self.id}.tau": 0.0}

    def unseen_in_table(self, table) -> str | None:
        """A lag changes the ripple over shaft angle, not a reading's mean over a revolution, which is
        all a steady table's point holds: diagnose does not try it there."""
        return (f"a table's points are means over shaft angle, and a first-order lag of the "
                f"{_METER_WORDS[self.channel]} leaves a reading's mean untouched: it shows in the ripple over "
                "shaft angle only")

    def describe(self, values, spec=None) -> str:
        tau = self.value(values, "tau")
        word = _METER_WORDS[self.channel]
        text = f"the {word} lags with a time constant of {tau * 1e3:.3g} ms"
        if spec is not None:
            # the case drain ripples with K_L(θ), at the piston order; torque and port flows with S(θ), whose
            # first harmonic is at 2n for odd n
            k = spec.pistons if self.channel == "q_case" or spec.pistons % 2 == 0 else 2 * spec.pistons
            w = 1000 * RAD_S_PER_RPM
            x = k * w * tau
            text += (f": at 1000 rpm its {k}× shaft-order ripple reads {100 / math.sqrt(1 + x * x):.3g} % of its "
                     f"size, {math.degrees(math.atan(x)) / k:.3g}° of shaft angle late")
        return text


class MeterOffset(_LinearReading):
    """A flow meter reading a constant c [m³/s] on top of the true flow of one channel, in every run."""

    def __init__(self, channel: str):
        self.channel = channel
        word = _METER_WORDS[channel]
        self.id = f"flow_meter_offset_{_SUFFIX[channel]}"
        self.name = f"{word} zero offset"
        self.channels = (channel,)
        self.shows_in = ("q_a", "q_b", "q_case")  # the base fit spreads one meter's zero over all flows
        where = ("the case-drain flow" if channel == "q_case" else f"port {_SUFFIX[channel].upper()} flow")
        self.signature = (f"{where} shifted by one constant at every speed, pressure and temperature, with the "
                          "same sign in both directions of rotation (a gain error follows the flow, the swept flow "
                          "changes sign with the direction, a leakage follows (P − P_c)/μ): the mass balance "
                          "Q_A + Q_B = Q_case breaks by the same amount in every run")
        self.reference = ("ISO 4392-1:2002 and ISO 9110-1:1990 (measurement accuracy of hydraulic test benches); "
                          "E. O. Doebelin, 'Measurement Systems: Application and Design', 5th ed., McGraw-Hill, 2004 "
                          "(zero offset and drift)")
        self.physics = (f"The {word} reads a flow where none passes, from a zero that was not set, an amplifier "
                        "drift or a frequency-to-analogue converter's offset. "
                        "The same amount is added to every reading, so the meters' flows no longer add up and the "
                        "error is largest, relative to the flow, at low speed and low leakage.")
        typical = 2e-7 if channel == "q_case" else 3e-6  # 0.012 and 0.18 L/min: a fraction of a meter's class
        self.parameters = {f"{self.id}.c": ParameterInfo(
            "m³/s", f"zero offset of the {word}: reading = true flow + c", False, typical)}

    def running(self, params, spec, samples, ch):
        c = self.param(params, "c")
        return ch._replace(**{self.channel: getattr(ch, self.channel) + c})

    def describe(self, values, spec=None) -> str:
        c = self.value(values, "c")
        word = _METER_WORDS[self.channel]
        return (f"the {word} reads {abs(c) * LPM_PER_M3S:.3g} L/min {'high' if c >= 0 else 'low'} at every operating "
                "point and in both directions (zero offset)")


def _channel_words(channel: str) -> str:
    return {"torque": "running torque", "q_a": "port A flow", "q_b": "port B flow",
            "q_case": "case-drain flow"}[channel]


MECHANISMS = (
    MeterGain("q_a"), MeterGain("q_b"), MeterGain("q_case"), MeterGain("torque"),
    MeterOffset("q_a"), MeterOffset("q_b"), MeterOffset("q_case"),
    SensorLag("torque"), SensorLag("q_a"), SensorLag("q_b"), SensorLag("q_case"),
)

