"""Held-out errors of loss models on a table: K-fold and extrapolation, the same splits for all.

A *model* here is anything with ``fit(table) -> fitted`` and ``fitted.predict(table) -> {channel: array}``
(a :class:`~motorid.comparators.base.LossModel`, or :class:`MotoridModel`, motorid's own fit).

- K-fold: the points are split at random (seed 0) into K folds; each fold is predicted from a
  fit on the others; RMS over all points of the held-out residual, per channel.
- Extrapolation in pressure: fit on the points with |ΔP| up to the 60th percentile of |ΔP|,
  predict the rest; in speed: the same with |ω|.

Each RMS is given in SI and as a percentage of the channel's span (max − min of the
measured values over the whole table).
"""

from __future__ import annotations

import time

import numpy as np

CHANNELS = ("torque", "q_a", "q_b", "q_case")
EXTRAPOLATION_QUANTILE = 0.6


def kfold_indices(n: int, k: int = 5, seed: int = 0) -> list:
    """K disjoint folds covering 0..n−1 (a seeded permutation cut in K near-equal parts)."""
    k = max(2, min(k, n))
    return [np.sort(f) for f in np.array_split(np.random.default_rng(seed).permutation(n), k)]


def extrapolation_split(values: np.ndarray, quantile: float = EXTRAPOLATION_QUANTILE):
    """(train, test) masks: train where |values| ≤ their ``quantile``, test above."""
    a = np.abs(np.asarray(values, dtype=float))
    cut = np.quantile(a, quantile)
    train = a <= cut
    if train.all():  # ties at the cut: keep at least the largest level out
        train = a < a.max()
    return train, ~train


def rms_errors(measured: dict, predicted: dict, span_from: dict) -> dict:
    """channel → {"rms": RMS of measured − predicted [SI], "percent_of_span": …, "points": n}."""
    out = {}
    for c in CHANNELS:
        y = np.asarray(measured[c], float)
        p = np.asarray(predicted.get(c, np.full(y.shape, np.nan)), float)
        ok = np.isfinite(y)
        if not ok.any():
            continue
        span_y = np.asarray(span_from[c], float)
        span = float(np.nanmax(span_y) - np.nanmin(span_y)) if np.isfinite(span_y).any() else np.nan
        good = ok & np.isfinite(p)
        if good.sum() < ok.sum():
            out[c] = {"rms": None, "percent_of_span": None, "points": int(ok.sum()),
                      "note": "the model gives no prediction of this channel"}
            continue
        rms = float(np.sqrt(np.mean((y[ok] - p[ok]) ** 2)))
        out[c] = {"rms": rms, "percent_of_span": 100.0 * rms / span if span > 0 else None, "points": int(ok.sum())}
    return out


def _predict_split(model, table, train, test) -> dict:
    if hasattr(model, "fit_split"):  # one compiled problem for every fold
        fitted = model.fit_split(table, train)
        if isinstance(fitted, _FittedMotorid):  # its fit holds the model at every point of the table
            return {c: v[test] for c, v in fitted.predict(table).items()}
    else:
        fitted = model.fit(table.subset(train))
    return fitted.predict(table.subset(test))


def held_out(model, table, k: int = 5, seed: int = 0, groups=None, extrapolate: bool = True) -> dict:
    """The K-fold and extrapolation errors of ``model`` on ``table`` (see the module's words);
    with ``groups`` (a label per point, e.g. the recording it came from) also the error of
    predicting each group from a fit on the others ("leave_one_group_out"); ``extrapolate``
    False: the K-fold error alone."""
    n = len(table)
    span = table.measured
    t0 = time.time()
    pred = {c: np.full(n, np.nan) for c in CHANNELS}
    for fold in kfold_indices(n, k, seed):
        train = np.ones(n, bool)
        train[fold] = False
        p = _predict_split(model, table, train, ~train)
        for c in CHANNELS:
            pred[c][fold] = p[c]
    out = {"kfold": rms_errors(table.measured, pred, span), "k": max(2, min(k, n))}
    splits = (("extrapolate_pressure", table.p_a - table.p_b), ("extrapolate_speed", table.speed))
    for name, values in splits if extrapolate else ():
        train, test = extrapolation_split(values)
        if train.sum() < 4 or test.sum() < 1:
            out[name] = {}
            continue
        p = _predict_split(model, table, train, test)
        out[name] = rms_errors({c: table.measured[c][test] for c in CHANNELS}, p, span)
    if groups is not None:
        groups = np.asarray(groups)
        labels = np.unique(groups)
        if labels.size >= 2:
            pred = {c: np.full(n, np.nan) for c in CHANNELS}
            for g in labels:
                test = groups == g
                p = _predict_split(model, table, ~test, test)
                for c in CHANNELS:
                    pred[c][test] = p[c]
            out["leave_one_group_out"] = rms_errors(table.measured, pred, span)
    out["seconds"] = time.time() - t0
    return out


class MotoridModel:
    """motorid's own model (the one model, θ-averaged, plus ``mechanisms``) as a comparator:
    ``fit`` refits the table on the training points (weights 0 elsewhere, one compiled residual)."""

    name = "motorid"
    reference = "Bartos (1992), MODEL.md; the one model averaged over shaft angle"

    def __init__(self, spec, mechanisms=(), label: str | None = None):
        self.spec, self.mechanisms = spec, tuple(mechanisms)
        if label:
            self.name = label
        self._cache: dict = {}
        self._fits: dict = {}
        self._full = None

    def fit(self, table):
        return self.fit_split(table, np.ones(len(table), bool))

    def fit_split(self, table, train):
        """Fit on the points where ``train`` holds (the others weigh nothing); a split fitted before on
        the same table is given back (the row with the kriged model error reuses the row's fits)."""
        key = (id(table), np.asarray(train, bool).tobytes())
        if key not in self._fits:
            self._fits[key] = self._fit_split(table, train)
        return self._fits[key]

    def _fit_split(self, table, train):
        from motorid.identify.tables import fit_table

        fitted = _FittedMotorid(self)
        fitted.fit = fit_table(table, self.spec, self.mechanisms, train=train, _cache=self._cache, rounds=1)
        return fitted


class _FittedMotorid:
    def __init__(self, owner):
        self.owner = owner

    def predict(self, table) -> dict:
        from motorid.identify.tables import angle_samples, bind_mechanisms, point_channels

        o = self.owner
        if table is self.fit.table:
            # the table it was fitted on (a fold's other points weigh 0 there): the θ-averaged model at
            # every point, as the fit's own program gave it (the same model, evaluated once)
            return self._identified({c: np.array(self.fit.table_prediction[c], dtype=float) for c in CHANNELS},
                                    len(table))
        p = self.fit.ls.params_all
        disp = table.displacement if table.variable_displacement else None
        # the mechanisms as the fit used them (set for its training points), looked up at these points
        mechanisms = bind_mechanisms(self.fit.ls.mechanisms, table)
        ch = point_channels(p, o.spec, angle_samples(o.spec, table, mechanisms, p), disp, mechanisms)
        return self._identified(dict(zip(CHANNELS, (np.asarray(v) for v in ch))), len(table))

    def _identified(self, out: dict, n: int) -> dict:
        for c in not_predicted(self.fit.ls.identifiable):
            out[c] = np.full(n, np.nan)
        return out


class WithModelError:
    """A model plus its model error kriged between the training points (:mod:`motorid.identify.kriging`):
    the residuals neighbouring points share, interpolated; nothing where the neighbours share none,
    nothing far from every training point (extrapolation is the model's alone)."""

    reference = ("simple kriging of the residuals (Cressie 1993 §3.2), the model plus a discrepancy field "
                 "(Kennedy & O'Hagan 2001)")

    def __init__(self, inner, label: str | None = None):
        self.inner = inner
        self.name = label or f"{inner.name} + kriged model error"

    def fit(self, table):
        return self.fit_split(table, np.ones(len(table), bool))

    def fit_split(self, table, train):
        train = np.asarray(train, bool)
        fitted = self.inner.fit_split(table, train) if hasattr(self.inner, "fit_split") else \
            self.inner.fit(table.subset(train))
        from motorid.identify.kriging import model_error_fields

        sub = table.subset(train)
        pred = fitted.predict(sub)
        residuals = {c: np.asarray(sub.measured[c], float) - np.asarray(pred[c], float) for c in CHANNELS}
        fit = getattr(fitted, "fit", None)  # a table fit's own σ of each point, where it has one
        sigma = {c: np.asarray(s, float)[train] for c, s in fit.table_sigma.items()
                 if c in fit.table_reading_share} if fit is not None and hasattr(fit, "table_sigma") else None
        return _FittedWithModelError(fitted, *model_error_fields(sub, residuals, sigma))


class _FittedWithModelError:
    def __init__(self, fitted, scaling, fields: dict):
        self.fitted, self.scaling, self.fields = fitted, scaling, fields
        self.fit = getattr(fitted, "fit", None)

    def predict(self, table) -> dict:
        from motorid.identify.lack_of_fit import operating_axes

        out = dict(self.fitted.predict(table))
        if self.fields:
            X = self.scaling(operating_axes(table))
            for c, krig in self.fields.items():
                out[c] = np.asarray(out[c], float) + krig.predict(X)[0]
        return out


#: the parameters each channel needs identified before it is predicted
PREDICTION_NEEDS = {"torque": ("Kv", "KF", "TFc"), "q_a": ("KL0",), "q_b": ("KL0",), "q_case": ("KL0",)}


def not_predicted(identifiable: dict) -> dict:
    """channel → the parameter it needs that the fit did not identify (a channel not predicted)."""
    out = {}
    for c, ks in PREDICTION_NEEDS.items():
        missing = [k for k in ks if not identifiable.get(k, True)]
        if missing:
            out[c] = missing[0]
    return out


def compare(table, spec, comparators=None, mechanisms=(), k: int = 5, motorid_model=None,
            model_error_row: bool = True) -> dict:
    """The ``comparison`` block: held-out errors of motorid and of every comparator on ``table``
    (``motorid_model``: motorid's row, where not the one model plus ``mechanisms``); with
    ``model_error_row`` also motorid's model plus its kriged model error (:class:`WithModelError`, what
    ``motorid predict`` gives), on the same fits."""
    from motorid.comparators import all_comparators

    models = [motorid_model or MotoridModel(spec, mechanisms, label="motorid" + (
        " + " + "+".join(m.id for m in mechanisms) if mechanisms else ""))]
    if model_error_row:
        models.append(WithModelError(models[0]))
    models += list(comparators if comparators is not None else all_comparators())
    out = {"method": {"kfold": f"{k}-fold, seeded permutation (seed 0)",
                      "extrapolation": f"fit on |ΔP| (or |ω|) up to its {int(EXTRAPOLATION_QUANTILE * 100)}th "
                                       f"percentile, predict the rest",
                      "units": "rms in SI (N·m, m³/s); percent_of_span: of the channel's measured span"},
           "models": {}}
    for m in models:
        res = held_out(m, table, k)
        res["reference"] = getattr(m, "reference", "")
        if getattr(m, "equations", ""):
            res["equations"] = m.equations
        out["models"][m.name] = res
    return out

