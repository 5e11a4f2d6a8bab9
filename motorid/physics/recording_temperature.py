"""An oil temperature that was not recorded and differs between recordings (operating-point tables).

A loss map is often put together from several recordings (test sessions, days,
seasons), and many benches log no oil temperature: the table then takes every
point at the spec's assumed ``[oil] temp_C``.  The oil was not at one temperature
in all of them.  The viscosity μ enters the 1992 model in two places, the viscous
torque T_v = −K_v D μ ω (Eq. 24) and the laminar leakage K_L (P − P_c)/μ (Eq. 46-61),
so a recording run hotter than assumed shows *less* viscous torque, growing with
speed, and *more* leakage, in proportion to (P − P_c), both by the same factor.

The model: each recording r has its own viscosity

    μ_r = μ(T_assumed) · exp(s_r),   Σ_r s_r = 0                             (1)

s_r [-] the log of the ratio of the recording's viscosity to the assumed one.  The
assumed temperature is taken as the recordings' mean (in log viscosity): a common
change of μ in every recording is one of K_v and K_L0 (the 1992 model's viscous
terms are products K_v μ and K_L/μ) and the table cannot tell it from them.  The
parameters are s_r of every recording but one (the one with the most points,
called the *reference* below), whose s is minus their sum.  ``describe`` turns s_r
into a temperature difference through the spec oil's Walther (ASTM D341) law: for
ISO VG 32 near 25 °C, s = −0.2 is about +4 K.  A point of a recording the fit never
saw (or of no recording) is taken at the assumed temperature, the recordings' mean:
the best guess for a new recording, not that of any one of them.

Signature: the run-to-run part of the torque residual that grows with ω (and the
part of the leakage that follows (P − P_c)), one level per recording, the same at
every pressure.  A per-recording torque *offset* is the same at every speed, a
per-recording torque *gain* follows the torque itself (∝ ΔP at low speed): on the
MBARI F11-5 table (real_data/) the recordings' torque residuals shrink by 62 % with
a viscosity per recording, by 46 % with a gain per recording, by 4 % with an
offset per recording.  Anything else that scales the viscous torque by recording
(a different oil, a bearing run in between recordings) takes the same shape; the
words say so.

This is not a catalog mechanism: it belongs to a table (its parameters are its
recordings), is offered by ``diagnose`` on a table alone only where no point holds a
temperature and at least two recordings have three points or more, and is bound to
the points of a table (:meth:`RecordingTemperature.bound_to`) before the model sees
them.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from motorid import _jaxconfig  # noqa: F401
from motorid.physics.base import Mechanism, ParameterInfo

#: a recording needs this many points to be given its own viscosity
MIN_POINTS = 3


class RecordingTemperature(Mechanism):
    """Viscosity per recording, μ_r = μ(T_assumed)·exp(s_r), Σ s_r = 0, Eq. (1); s_r [-] a
    parameter of every recording but the reference (most points), whose s is −Σ of the others."""

    angle_free = True  # θ only through the 1992 model's S(θ) and K_L(θ) (physics/base.py)

    id = "recording_temperature"
    name = "oil temperature not recorded, different from recording to recording"
    physics = ("The table takes every point at the spec's assumed oil temperature, but its recordings were made "
               "with the oil at different temperatures: a hotter recording shows less viscous torque (growing "
               "with speed) and more leakage, by the same viscosity factor. "
               "One viscosity per recording, relative to the recording with the most points, takes it.")
    reference = ("Bartos 1992, Eq. 24 (viscous torque K_v D μ ω) and Eq. 52-58 (laminar leakage to the case and across the ports ∝ 1/μ); "
                 "ASTM D341 (viscosity-temperature charts, the Walther equation); ISO 4409:2019 §6 "
                 "(the oil temperature to be held and recorded for each test point)")
    signature = ("running torque residual that grows with speed, one level per recording, the same at every "
                 "pressure (and the leakage share of the flows, opposite in sign); gone within a recording")
    sensor = False

    def __init__(self, labels, reference_recording, index=None, fitted=None, implied=None):
        self.labels = tuple(str(v) for v in labels)  # the recordings with a parameter, in order
        self.reference_recording = str(reference_recording)
        self.index = None if index is None else np.asarray(index, dtype=np.int64)
        # the recordings a fit saw (None: all) and the one whose s is −Σ of theirs (the reference where seen)
        self.fitted = None if fitted is None else frozenset(map(str, fitted))
        self.implied = self.reference_recording if implied is None else str(implied)
        self.parameters = {self.key(v): ParameterInfo(
            "-", f"ln(μ/μ_assumed) of recording '{v}' (the recordings' mean at the assumed temperature)",
            False, 0.1)
            for v in self.labels}
        self.channels = ("torque", "q_a", "q_b", "q_case")

    @staticmethod
    def key(label: str) -> str:
        return f"recording_temperature.{label}"

    def _copy(self, **changes):
        state = dict(labels=self.labels, reference_recording=self.reference_recording, index=self.index,
                     fitted=self.fitted, implied=self.implied)
        state.update(changes)
        return type(self)(**state)

    @classmethod
    def for_table(cls, table):
        """The mechanism for ``table``, or None where it has fewer than two recordings of at least
        :data:`MIN_POINTS` points, or where any point's temperature was recorded (a measured
        temperature pins K_v and K_L0, and the recordings' mean is then not free to stand for
        the assumed temperature)."""
        rec = table.recordings()
        assumed = table.assumed_temperature()
        if not assumed.all():
            return None
        labels, counts = np.unique(rec[assumed & (rec != "")], return_counts=True)  # "": no recording named
        labels, counts = labels[counts >= MIN_POINTS], counts[counts >= MIN_POINTS]
        if labels.size < 2:
            return None
        order = np.lexsort((labels.astype(str), -counts))  # most points first, then by name
        reference = str(labels[order[0]])
        return cls(sorted(str(v) for v in labels if str(v) != reference), reference).bound_to(table)

    @staticmethod
    def too_small(table) -> list:
        """The named recordings of ``table`` with fewer than :data:`MIN_POINTS` points: given no
        viscosity of their own (taken at the assumed temperature)."""
        rec = table.recordings()
        labels, counts = np.unique(rec[rec != ""], return_counts=True)
        return [str(v) for v, c in zip(labels, counts) if c < MIN_POINTS]

    def bound_to(self, table):
        """The same mechanism (what a fit saw included), its recordings looked up at the points of
        ``table``."""
        rec = table.recordings()
        pos = {self.reference_recording: 0, **{v: i + 1 for i, v in enumerate(self.labels)}}
        unknown = len(self.labels) + 1
        assumed = table.assumed_temperature()
        index = np.array([pos.get(str(v), unknown) if a else unknown for v, a in zip(rec, assumed)], dtype=np.int64)
        return self._copy(index=index)

    def for_training(self, table, train):
        """The mechanism for a fit on ``table``'s points where ``train`` holds: a recording without
        such a point is taken at the assumed temperature (the mean of those seen), and where the
        reference is not seen, the seen recording with the most points carries −Σ of the others."""
        rec = table.recordings()[np.asarray(train, bool) & table.assumed_temperature()]
        seen = {v: int(np.sum(rec == v)) for v in (self.reference_recording,) + self.labels if np.any(rec == v)}
        implied = self.reference_recording if self.reference_recording in seen or not seen else max(sorted(seen), key=seen.get)
        return self._copy(fitted=frozenset(seen), implied=implied).bound_to(table)

    def _seen(self, label: str) -> bool:
        return self.fitted is None or label in self.fitted

    def _free(self) -> list:
        """The recordings whose s is a fitted parameter: seen, and not the one carrying −Σ."""
        return [v for v in self.labels if self._seen(v) and v != self.implied]

    def table_reasons(self, table, train) -> dict:
        """parameter → why a fit on ``table``'s points where ``train`` holds does not fit it (call on
        :meth:`for_training`'s mechanism)."""
        out = {self.key(v): f"recording '{v}' has no point in the fitted set (its points are taken at the "
                            f"assumed oil temperature, the mean of the others)" for v in self.labels if not self._seen(v)}
        if self.implied != self.reference_recording:
            out[self.key(self.implied)] = (f"minus the sum of the other recordings' (the reference "
                                           f"'{self.reference_recording}' has no point in the fitted set)")
        return out

    def table_conditions(self, params, spec, samples):
        """Table samples (points × shaft angles) with each point's viscosity of its recording."""
        if self.index is None or not self.labels:
            return samples
        if np.shape(samples.viscosity)[0] != self.index.size:
            raise ValueError(f"{self.id}: bound to {self.index.size} points, given {np.shape(samples.viscosity)[0]}")
        zero = jnp.zeros((), dtype=jnp.float64)
        free = {v: jnp.asarray(params[self.key(v)], dtype=jnp.float64) for v in self._free()}
        implied = -sum(free.values(), zero)
        names = (self.reference_recording,) + self.labels
        shift = jnp.stack([implied if v == self.implied and self._seen(v) else free.get(v, zero) for v in names]
                          + [zero])  # the reference, the labels, an unknown recording
        factor = jnp.exp(shift[self.index])
        factor = factor.reshape(factor.shape + (1,) * (np.ndim(samples.viscosity) - 1))
        return samples._replace(viscosity=samples.viscosity * factor)

    def neutral(self) -> dict:
        return self.initial()  # every s_r at 0: the assumed temperature in every recording

    def shifts(self, values: dict, covariance=None, names=None) -> dict:
        """recording → (s_r, its std or None) [-] as the fit used them (:meth:`for_training`): the
        implied recording's s = −Σ of the other seen ones, an unseen one 0; std from ``covariance``
        over ``names`` (the fit's free parameters) where given."""
        free = self._free()
        out = {v: (0.0, None) for v in (self.reference_recording,) + self.labels}
        for v in free:
            out[v] = (float(values[self.key(v)]), None)
        cov = None if covariance is None or names is None else np.asarray(covariance, float)
        idx = {}
        if cov is not None:
            names = list(names)
            idx = {v: names.index(self.key(v)) for v in free if self.key(v) in names}
            for v, i in idx.items():
                out[v] = (out[v][0], float(np.sqrt(max(cov[i, i], 0.0))))
        if self._seen(self.implied):
            ii = list(idx.values())
            sd = float(np.sqrt(max(cov[np.ix_(ii, ii)].sum(), 0.0))) if ii else None
            out[self.implied] = (-sum(out[v][0] for v in free), sd)
        return out

    def temperature_differences(self, values: dict, spec, covariance=None, names=None) -> dict:
        """recording → (ΔT [K] against the assumed temperature, its std [K] or None) through the
        spec oil's viscosity law (None where the spec has no oil or the law cannot reach it)."""
        oil = getattr(spec, "oil", None)
        t0 = getattr(oil, "temp_C", None) if oil is not None else None
        out = {}
        for v, (s, sd) in self.shifts(values, covariance, names).items():
            if t0 is None:
                out[v] = (None, None)
                continue
            dt = _delta_t(oil, float(t0), s)
            if dt is None or sd is None:
                out[v] = (dt, None)
                continue
            hi, lo = _delta_t(oil, float(t0), s + sd), _delta_t(oil, float(t0), s - sd)
            out[v] = (dt, None if hi is None or lo is None else abs(lo - hi) / 2.0)
        return out

    def describe(self, values, spec=None) -> str:
        dts = self.temperature_differences(values, spec) if spec is not None else {}
        parts = []
        for v, (s, _) in self.shifts(values).items():
            dt = dts.get(v, (None, None))[0]
            words = f"'{v}' μ {100 * (math.exp(s) - 1):+.3g} %"
            if dt is not None:
                words += f" ({dt:+.2g} K)"
            parts.append(words)
        t0 = getattr(getattr(spec, "oil", None), "temp_C", None)
        at = f" {t0:g} °C" if t0 is not None else " temperature"
        return (f"the oil viscosity differs from recording to recording, around the assumed{at} taken as "
                f"their mean: " + ", ".join(parts) + " — an oil temperature the table does not hold (or "
                "anything else that scales the viscous torque and the leakage by recording)")


def _delta_t(oil, t0: float, s: float):
    """T − t0 [K] where the oil's μ(T) = μ(t0)·e^s, or None outside −40 … 200 °C."""
    from scipy.optimize import brentq

    target = math.log(float(oil.viscosity(t0))) + s
    f = lambda t: math.log(float(oil.viscosity(t))) - target  # noqa: E731
    lo, hi = -40.0, 200.0
    if f(lo) * f(hi) > 0:
        return None
    return brentq(f, lo, hi, xtol=1e-6) - t0
