"""The Python API: read bench logs, fit, diagnose, load a result — what the command line does, in a notebook.

    import motorid
    spec = motorid.load_motor_spec("synthetic_data/demo/motor.toml")
    fit = motorid.fit(["synthetic_data/demo/campaign.csv.gz"], spec)
    print(fit)                 # the parameter table, χ²/dof, warnings in words
    fit.params["Kv"]           # fitted values, SI
    fit.plot()                 # data and model (a matplotlib figure)
    fit.to_json("result.json")  # the result.json of `motorid fit`, written atomically

Result objects print a summary (``str``), render as a table in Jupyter
(``_repr_html_``), draw a quick look (``.plot()`` returns the figure) and save
(``.to_json(path)``; ``.save(folder)`` as the command line does), in the manner
of lmfit's results.  Units are SI throughout (parameters as MODEL.md names them:
``Kv`` [-], ``TFc`` [N·m], ``KL0`` [m³], …; a mechanism's ``"<id>.<name>"`` in
the unit its registry entry declares).  Bad input raises
:class:`motorid.errors.InputError` with one line naming the file, column or key.
"""

from __future__ import annotations

import html
import io
from pathlib import Path
from typing import Sequence

from motorid.errors import InputError
from motorid.io.logs import read_logs as _read_logs
from motorid.io.results import DIAGNOSIS_FILE, RESULT_FILE, read_json, write_json
from motorid.io.spec import load_motor_spec
from motorid.model import MotorSpec, OilSpec
from motorid.report.summary import format_diagnosis, format_fit

__all__ = ["read_logs", "fit", "diagnose", "predict", "load_result", "load_motor_spec", "MotorSpec", "OilSpec",
           "FitResult", "DiagnosisResult"]


def predict(result, points, motor=None):
    """Torque, flows and efficiencies at operating points, with 95 % bands (what ``motorid predict`` writes).

    result : a fit folder or its result.json (written by :func:`fit` + ``save`` or ``motorid fit``)
    points : operating-point table file(s) (BENCH_LOG_FORMAT.md, outputs absent or ignored)
    motor : :class:`MotorSpec` or a spec TOML path (default: the spec stored in result.json)
    Returns a ``pandas.DataFrame``, one row per point, SI-free columns as the CSV
    (``torque_Nm``, ``q_a_lpm``, …, each with ``_lo95``/``_hi95`` confidence and
    ``_pi_lo95``/``_pi_hi95`` prediction bands; efficiencies in [-]).
    """
    from motorid.identify.predict import load_result as load_fit, predict_points
    from motorid.io.tables import read_tables

    loaded = load_fit(result, None if motor is None else _spec(motor))
    paths = [points] if isinstance(points, (str, Path)) else list(points)
    return predict_points(loaded, read_tables(paths, loaded[1], require_outputs=False))


def _spec(motor) -> MotorSpec:
    """A :class:`MotorSpec` from itself or from the path of a motor spec TOML."""
    return motor if isinstance(motor, MotorSpec) else load_motor_spec(motor)


def _motor_input(motor, motor_path) -> str | None:
    if motor_path is not None:
        return str(motor_path)
    return None if isinstance(motor, MotorSpec) else str(motor)


def read_logs(paths, motor=None, channels=None):
    """Bench logs (BENCH_LOG_FORMAT.md CSV, or another bench's header dialect) as one SI frame.

    paths : a file or a list of files (``.csv``, ``.csv.gz``)
    motor : :class:`MotorSpec` or a spec TOML path; its [oil] gives the viscosity [Pa·s] of logs that
        carry only the oil temperature [°C]
    Returns a ``pandas.DataFrame``: run_id, protocol, time_s [s], theta_rad [rad], speed_rad_s [rad/s],
    torque_Nm [N·m], p_a_Pa, p_b_Pa, p_case_Pa [Pa gauge], q_a_m3_s, q_b_m3_s, q_case_m3_s [m³/s],
    oil_temp_C [°C], viscosity_Pa_s [Pa·s].
    channels : a channel-map TOML for DAQ files (.mat, HDF5, TDMS, MDF4, Parquet, xlsx, other CSV;
        docs/formats.md)
    """
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    return _read_logs(paths, None if motor is None else _spec(motor), channels)


def _mechanisms(mechanisms) -> tuple:
    from motorid.physics import registry

    return tuple(registry.get(m) if isinstance(m, str) else m for m in mechanisms)


class FitResult:
    """A fit: ``document`` is its result.json (a dict, SI), ``params`` the fitted values, ``std`` their
    standard errors.  ``identification`` holds the fit in memory (``None`` for :func:`load_result`)."""

    def __init__(self, document: dict, spec: MotorSpec | None = None, identification=None):
        self.document = document
        self.spec = spec
        self.identification = identification
        self.log_points = None  # LogPoints where the logs held no shaft angle (identify/log_points.py)

    @property
    def params(self) -> dict:
        """Fitted value of every parameter the logs identify, SI (unit in ``document["parameters"]``)."""
        return {k: e["value"] for k, e in self.document["parameters"].items() if e.get("identifiable", True)}

    @property
    def std(self) -> dict:
        """Standard error of every identified parameter, SI."""
        return {k: e["std"] for k, e in self.document["parameters"].items() if e.get("identifiable", True)}

    @property
    def warnings(self) -> list:
        """What the fit warns about, in words."""
        return list(self.document["fit"]["warnings"])

    def __str__(self) -> str:
        return format_fit(self.document)

    def __repr__(self) -> str:
        fit = self.document["fit"]
        return (f"<motorid.FitResult of {self.document['motor'].get('name', '?')}: {len(self.params)} parameters, "
                f"χ²/dof = {fit['reduced_chi2']:.3g}>")

    def _repr_html_(self) -> str:
        rows = "".join(
            f"<tr><td>{html.escape(k)}</td><td>{e['value']:.5g}</td><td>{e['std']:.3g}</td>"
            f"<td>{html.escape(e['unit'])}</td><td>yes</td></tr>" if e["identifiable"] else
            f"<tr><td>{html.escape(k)}</td><td>—</td><td>—</td><td>{html.escape(e['unit'])}</td>"
            f"<td>no: {html.escape(e.get('reason', ''))}</td></tr>"
            for k, e in self.document["parameters"].items())
        fit = self.document["fit"]
        notes = "".join(f"<li>{html.escape(w)}</li>" for w in fit["warnings"])
        return ("<table><thead><tr><th>parameter</th><th>value</th><th>std</th><th>unit</th>"
                f"<th>identifiable</th></tr></thead><tbody>{rows}</tbody></table>"
                f"<p>χ²/dof = {fit['reduced_chi2']:.3f}</p>" + (f"<ul>{notes}</ul>" if notes else ""))

    def _model_inputs(self):
        """(dataset, spec, params, mechanisms) of the fit; re-read from the logs of a loaded result."""
        from motorid.identify.pipeline import load_campaign

        if self.identification is not None:
            ls = self.identification.ls
            return self.identification.dataset, self.spec, dict(ls.params_all), tuple(ls.mechanisms)
        inputs = self.document.get("inputs", {})
        if not inputs.get("logs") or (self.spec is None and not inputs.get("motor")):
            raise InputError("this result names no logs or motor spec (inputs) to draw the data from")
        spec = self.spec or load_motor_spec(inputs["motor"])
        _, dataset = load_campaign(inputs["logs"], spec, inputs.get("channels"))
        params = {k: e["value"] for k, e in self.document["parameters"].items() if e.get("value") is not None}
        return dataset, spec, params, _mechanisms(self.document["fit"].get("mechanisms", []))

    def plot(self):
        """Data and model: running torque and flows against speed, held breakaway torque against the
        model's.  Returns the ``matplotlib.figure.Figure``."""
        from motorid.report.quicklook import fit_figure

        dataset, spec, params, mechanisms = self._model_inputs()
        return fit_figure(dataset, spec, params, mechanisms, title=f"motorid fit: {spec.name}")

    def to_json(self, path) -> Path:
        """Write the result.json document to ``path``, whole or not at all (temporary file, then rename)."""
        return write_json(self.document, path)

    def save(self, folder) -> Path:
        """Write ``folder``/result.json (and chain.npz after a Bayesian fit), as ``motorid fit --out``."""
        from motorid.identify.results import CHAIN_FILE, write_chain

        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        if self.log_points is not None:  # logs without a shaft angle: their points go with the result
            self.log_points.move_into(self.document, out)
        if getattr(self.identification, "bayes", None) is not None:  # a table fit has none
            write_chain(self.identification.bayes, out / CHAIN_FILE)
        return self.to_json(out / RESULT_FILE)

    def write_report(self, folder) -> Path:
        """Write ``folder``/report.html (after :meth:`save` into the same folder); returns its path."""
        from motorid.report.html import write_report

        return write_report(Path(folder), identification=self.identification, spec=self.spec)


def fit(logs: Sequence, motor, *, bayes: bool = False, harmonics: int | None = None, seed: int = 0,
        mechanisms: Sequence = (), motor_path=None, channels=None) -> FitResult:
    """Identify the motor's parameters from bench logs and/or operating-point tables (what
    ``motorid fit`` does).

    logs : bench log and table paths (a table: no time column, or a foreign map read through a
        ``channels`` map without time_s, e.g. a gridded .mat loss map); motor : :class:`MotorSpec` or a spec TOML path
    bayes : also sample the posterior with emcee (``seed`` seeds it)
    harmonics : order M of the K_L(θ) Fourier series [-] (default: the spec's)
    mechanisms : extra physics fitted too (ids of :mod:`motorid.physics.registry` or mechanisms)
    motor_path : the spec's file, recorded in result.json's inputs when ``motor`` is a MotorSpec
    channels : a channel-map TOML for DAQ files (docs/formats.md)
    """
    from motorid.identify.least_squares import FitOptions
    from motorid.identify.pipeline import identify

    spec = _spec(motor)
    logs = [logs] if isinstance(logs, (str, Path)) else list(logs)
    from motorid.io.tables import split_logs_and_tables

    from motorid.identify.log_points import (angle_missing_everywhere, points_from_logs,
                                             reduce_logs_without_angle)
    from motorid.io.tables import split_channel_map

    log_paths, tables = split_logs_and_tables(logs, channels)

    def with_points(log_paths, tables, reduced) -> FitResult:  # the table fit, with the logs' points if any
        result = _fit_tables(log_paths, tables, spec, harmonics, _mechanisms(mechanisms), channels,
                             _motor_input(motor, motor_path), bayes)
        if reduced is not None:
            reduced.annotate(result.document, reduced.sources)
            result.log_points = reduced
        return result

    # logs without a shaft angle: their operating points, with the rest (identify/log_points.py)
    log_paths, reduced = reduce_logs_without_angle(log_paths, spec, split_channel_map(channels)[1])
    if tables or reduced is not None:  # operating-point tables, alone or with logs (identify/table_pipeline.py)
        return with_points(log_paths, list(tables) + ([reduced.path] if reduced is not None else []), reduced)
    res = identify(logs, spec, bayes=bayes, options=FitOptions(harmonics=harmonics), seed=seed,
                   mechanisms=_mechanisms(mechanisms), channels=channels)
    if angle_missing_everywhere(res.dataset):  # an empty angle channel the header did not tell
        reduced = points_from_logs(log_paths, spec, channels, known=True)
        return with_points(reduced.logs_for_breakaways(log_paths), [reduced.path], reduced)
    return _log_fit_result(res, spec, logs, _motor_input(motor, motor_path), channels)


def _log_fit_result(res, spec, logs, motor_input, channels) -> FitResult:
    """result.json of a fit of bench logs (an :class:`~motorid.identify.pipeline.Identification`), as
    ``motorid fit`` writes it."""
    from motorid.identify.log_points import mixed_angle_warning
    from motorid.identify.results import result_document

    note = mixed_angle_warning(res.dataset)
    if note and note not in res.ls.warnings:
        res.ls.warnings.append(note)
    inputs = {"logs": [str(p) for p in logs], "motor": motor_input}
    if channels is not None:
        inputs["channels"] = str(channels)
    doc = result_document(res.ls, spec, res.dataset, res.bayes, inputs, res.seconds, res.priors)
    doc["motor_spec"] = spec.to_toml()  # motorid predict and export need nothing else
    return FitResult(doc, spec, res)


def _fit_tables(log_paths, tables, spec, harmonics, mechanisms, channels, motor_input, bayes) -> FitResult:
    """The table branch of :func:`fit`: the joint fit, the held-out comparison with the classical
    loss models (10 points or more), result.json as ``motorid fit`` writes it."""
    from motorid.comparators.evaluate import compare
    from motorid.identify.table_pipeline import identify_tables, table_inputs, table_result_document

    if bayes:
        raise InputError("bayes is not available with operating-point tables (the least-squares covariance is "
                         "reported)")
    tf = identify_tables(log_paths, tables, spec, mechanisms=mechanisms, harmonics=harmonics, channels=channels)
    comparison = compare(tf.table, spec, mechanisms=mechanisms) if len(tf.table) >= 10 else None
    inputs = table_inputs(log_paths, tables, motor_input, channels)
    return FitResult(table_result_document(tf, spec, inputs, comparison), spec, tf)


def load_result(path) -> FitResult:
    """A saved fit: ``path`` is a result folder or its result.json.  ``.plot()`` re-reads the logs it names."""
    path = Path(path)
    return FitResult(read_json(path / RESULT_FILE if path.is_dir() else path, "result.json"))


class DiagnosisResult:
    """A diagnosis: ``document`` is its diagnosis.json (a dict, SI); ``mechanisms`` the ids found."""

    def __init__(self, document: dict, arrays: dict | None = None, diagnosis=None):
        self.document = document
        self.arrays = arrays or {}
        self.diagnosis = diagnosis
        self.log_points = None  # LogPoints where the logs held no shaft angle (identify/log_points.py)
        # the fit of the diagnosed model (a FitResult, bench logs only): the result.json diagnose writes
        self.refit = None

    @property
    def mechanisms(self) -> list:
        """Ids of the mechanisms found (:mod:`motorid.physics.registry`), in the order they were accepted."""
        return [m["id"] for m in self.document["mechanisms"]]

    def __str__(self) -> str:
        return format_diagnosis(self.document)

    def __repr__(self) -> str:
        return f"<motorid.DiagnosisResult: mismatch {self.document['mismatch']}, found {self.mechanisms}>"

    def _repr_html_(self) -> str:
        return "<pre>" + html.escape(str(self)) + "</pre>"

    def plot(self):
        """Residuals over σ before and after the search, per channel.  Returns the figure."""
        from motorid.report.quicklook import diagnosis_figure

        return diagnosis_figure(self.arrays, title="motorid diagnose")

    def to_json(self, path) -> Path:
        """Write the diagnosis.json document to ``path``, atomically."""
        return write_json(self.document, path)

    def save(self, folder) -> Path:
        """Write ``folder``/diagnosis.json and diagnosis_residuals.npz, as ``motorid diagnose --out``."""
        import numpy as np

        from motorid._atomic import write_bytes_atomic

        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        if self.log_points is not None:
            self.log_points.move_into(self.document, out)
        buf = io.BytesIO()
        np.savez_compressed(buf, **self.arrays)
        write_bytes_atomic(out / "diagnosis_residuals.npz", buf.getvalue())
        return self.to_json(out / DIAGNOSIS_FILE)


def diagnose(logs: Sequence, motor, *, alpha: float = 1e-3, min_evidence: float = 10.0, progress=None,
             motor_path=None, channels=None) -> DiagnosisResult:
    """Locate where the base model misses the data, name the missing physics, refit (``motorid diagnose``).

    alpha : family-wise false-alarm rate of the structure tests [-]
    min_evidence : ΔBIC a mechanism must earn [-]; progress : a callable taking one line, or None
    """
    from motorid.discrepancy.select import diagnose as _diagnose, diagnosis_document, residual_arrays
    from motorid.identify.pipeline import load_campaign

    spec = _spec(motor)
    logs = [logs] if isinstance(logs, (str, Path)) else list(logs)
    from motorid.identify.log_points import angle_missing_everywhere, points_from_logs

    reduced = points_from_logs(logs, spec, channels)
    frame = dataset = None
    if reduced is None:
        frame, dataset = load_campaign(logs, spec, channels)
        if angle_missing_everywhere(dataset):  # an empty angle channel the header did not tell
            reduced = points_from_logs(logs, spec, channels, known=True)
    if reduced is not None:  # no shaft angle: the logs' operating points, diagnosed as a table
        from motorid.discrepancy.tables import diagnose_tables, diagnosis_table_document

        dg = diagnose_tables(reduced.logs_for_breakaways(logs), [reduced.path], spec, min_evidence=min_evidence,
                             progress=progress, channels=channels)
        doc = diagnosis_table_document(dg, spec)
        doc["inputs"] = {"tables": [str(reduced.path)], "motor": _motor_input(motor, motor_path)}
        reduced.annotate(doc, logs)
        result = DiagnosisResult(doc, None, dg)
        result.log_points = reduced
        return result
    dg = _diagnose(dataset, spec, alpha=alpha, min_evidence=min_evidence, progress=progress)
    doc = diagnosis_document(dg, spec)
    doc["inputs"] = {"logs": [str(p) for p in logs], "motor": _motor_input(motor, motor_path)}
    result = DiagnosisResult(doc, residual_arrays(dg, dataset), dg)
    # the final model's fit, as `api.fit(..., mechanisms=[...])` gives it: diagnose's own final fit (every
    # sample, noise re-estimated), not a second reading and fit of the same logs
    from motorid.identify.pipeline import Identification, add_fit_warnings

    final = add_fit_warnings(dg.final, dataset, frame)
    left = sorted({u["channel"] for u in dg.unexplained_detail or []})
    if left:  # a probe's friction ∝ ΔP²: K_FS −80σ, K_s +67σ in this result.json, and not a word there
        from motorid.units import CHANNEL_WORDS

        final.warnings.append(f"diagnose left structure unexplained in the {', '.join(CHANNEL_WORDS[c] for c in left)}"
                              " (diagnosis.json → unexplained): these values are those of a model that misses "
                              "it, and the parameters of those channels may be biased beyond their std")
    ident = Identification(final, None, dataset, frame, dg.seconds.get("final fit", 0.0), {})
    result.refit = _log_fit_result(ident, spec, logs, _motor_input(motor, motor_path), channels)
    return result
