"""The interface of an extra-physics mechanism: an extension of the one model.

A mechanism never copies the model; :func:`motorid.model.predict` calls its
``running`` hook after the 1992 terms, and :func:`motorid.model.predict_breakaway`
calls ``static_limit`` and ``breakaway_reading``.  Its parameters live in the
same parameter dict as the base ones, named ``"<id>.<name>"``.
"""

from __future__ import annotations

from motorid.model import Channels, ParameterInfo, Samples


class Mechanism:
    """Base class: every hook returns its input unchanged."""

    id: str = ""
    name: str = ""
    physics: str = ""  # two sentences, in words an engineer accepts
    reference: str = ""  # literature reference
    channels: tuple[str, ...] = ()  # of: torque, q_a, q_b, q_case, breakaway
    parameters: dict[str, ParameterInfo] = {}

    def running(self, params: dict, spec, samples: Samples, ch: Channels) -> Channels:
        """Add this mechanism's terms to the running channels."""
        return ch

    def static_limit(self, params: dict, spec, events: Samples, limit):
        """Change the static friction limit T_break at breakaway events [N·m]."""
        return limit

    def breakaway_reading(self, params: dict, spec, events: Samples, held):
        """Change the held-torque reading at breakaway (e.g. a transducer offset) [N·m]."""
        return held

    def initial(self) -> dict:
        """Starting values of this mechanism's parameters for a fit."""
        return {k: (v.typical if v.positive else 0.0) for k, v in self.parameters.items()}

    def __repr__(self) -> str:
        return f"<mechanism {self.id}>"
