"""Operating-point tables through the fit: tables alone or with logs (motorid/identify/tables.py does one fit)."""

from __future__ import annotations

import time
from pathlib import Path


def identify_tables(log_paths, table_paths, spec, mechanisms=(), harmonics=None, channels=None):
    """Read the tables (and logs), fit them jointly; returns a :class:`~motorid.identify.tables.TableFit`.
    channels : a channel map (path or ChannelMap): for the tables where it maps no time_s (a foreign
        map, e.g. a gridded .mat; io/tables.py), for the logs where it does."""
    from motorid.identify.tables import fit_table
    from motorid.io.tables import read_tables

    t0 = time.time()
    from motorid.io.tables import split_channel_map

    table_map, log_map = split_channel_map(channels)
    table = read_tables(table_paths, spec, channels=table_map)
    dataset = log_fit = None
    if log_paths:
        from motorid.identify.least_squares import FitOptions, fit_least_squares
        from motorid.identify.pipeline import load_campaign

        _, dataset = load_campaign(log_paths, spec, log_map)
        log_fit = fit_least_squares(dataset, spec, mechanisms=mechanisms, options=FitOptions(harmonics=harmonics))
    tf = fit_table(table, spec, mechanisms, dataset=dataset, log_fit=log_fit, harmonics=harmonics)
    tf.seconds = time.time() - t0
    return tf


def table_inputs(logs, tables, motor, channels=None) -> dict:
    """result.json's ``inputs`` of a table fit: absolute paths (``motorid report`` re-reads the tables
    from any folder), the motor, and the channel map (path or ChannelMap) the files were read through."""
    out = {"logs": [str(Path(p).resolve()) for p in logs], "tables": [str(Path(p).resolve()) for p in tables],
           "motor": motor}
    if channels is not None:
        out["channels"] = str(Path(getattr(channels, "path", channels)).resolve())
    return out


def table_result_document(tf, spec, inputs: dict, comparison: dict | None = None) -> dict:
    """result.json of a fit with tables: the document of a log fit, plus ``table``, ``comparison``
    and ``motor_spec`` (the spec's TOML, so that ``motorid predict`` needs nothing else)."""
    from motorid.identify.results import json_safe as _clean, result_document
    from motorid.identify.tables import table_document

    doc = result_document(tf.ls, spec, tf.dataset, None, inputs, tf.seconds)
    doc["fit"]["method"] = ("scipy.optimize.least_squares (trust region, bounds), JAX Jacobian; table points: the "
                            "model averaged over shaft angle, each output channel weighted by a noise level "
                            "estimated from its residuals" + ("; jointly with the logs, weighted by the logs' own "
                                                             "noise levels" if tf.dataset is not None else ""))
    doc["table"] = _clean(table_document(tf))
    field = model_error_field(tf)
    if field is not None:
        doc["table"]["model_error_field"] = _clean(field)
    if comparison is not None:
        doc["comparison"] = _clean(comparison)
    doc["motor_spec"] = spec.to_toml()
    return doc


def model_error_field(tf) -> dict | None:
    """result.json's ``table.model_error_field``: the fit's residuals kriged over the operating space
    (identify/kriging.py), for channels where neighbouring points share a model error; None where none."""
    from motorid.identify.kriging import field_document, model_error_fields

    if not any(e.get("sigma", 0) > 0 for e in tf.model_error.values()):
        return None
    return field_document(*model_error_fields(tf.table, tf.table_residuals, errors=tf.model_error))
