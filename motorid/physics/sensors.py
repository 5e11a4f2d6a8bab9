"""Sensor errors that look like physics: the torque transducer's zero offset (mechanism).
"""

from __future__ import annotations

from motorid.physics.base import CatalogMechanism, ParameterInfo



class TorqueOffset(CatalogMechanism):
    """Torque transducer zero offset [N·m]: +T0 on every torque reading.

    Added to the running torque and to the held torque read at breakaway; its
    sign does not follow the direction of rotation.
    """

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
