"""Predictions at steady operating points from a fit, with 95 % bands (`motorid predict`).

For each point (the columns of an operating-point table, outputs absent) the one
model averaged over shaft angle (:func:`motorid.identify.tables.point_channels`)
gives torque, the three flows and the efficiencies (:mod:`motorid.physics.efficiency`).

Bands, both 95 %, normal quantile 1.96:

- ``*_lo95`` / ``*_hi95``: a **confidence band** of the model's value, from the fit's
  covariance by the delta method: var f = J C Jᵀ with J the JAX Jacobian of the
  output with respect to the fitted parameters (C rebuilt from result.json's
  ``std`` and ``correlation``), plus, for a table fit, the model's own error σ_m²:
  what neighbouring points of the table share of their residuals (a model that misses
  a real map by structure, :mod:`motorid.identify.lack_of_fit`; 0 where it does not),
  carried into the efficiencies.  It says where the true mean of the motor lies.
- ``*_pi_lo95`` / ``*_pi_hi95`` (torque and flows): a **prediction band** of a new
  measurement, var f + σ²(1 − s_m), σ the fit's noise of that channel (a table fit:
  the scatter of table points about the model, at the predicted value where it grows with
  the reading, s_m the model error's share of that scatter, already in the confidence band;
  a log fit: the noise of one reading).

A channel that depends on a parameter the fit could not identify is left empty,
with the reason in ``note``; one that does not (K_FS, K_s and the K_L(θ)
harmonics never enter a θ-averaged running point) is predicted.
"""

from __future__ import annotations

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from motorid import _jaxconfig  # noqa: F401
from motorid import model
from motorid.errors import InputError
from motorid.io.tables import STALL_SPEED  # |ω| [rad/s] below which a point is at rest
from motorid.physics.efficiency import efficiencies, operating_mode

Z95 = 1.959963984540054
LPM = 1e-3 / 60.0
_OUT = (("torque", "torque_Nm", 1.0), ("q_a", "q_a_lpm", LPM), ("q_b", "q_b_lpm", LPM), ("q_case", "q_case_lpm", LPM),
        ("eta_v", "volumetric_efficiency", 1.0), ("eta_hm", "hydromechanical_efficiency", 1.0),
        ("eta", "overall_efficiency", 1.0))


def load_result(result_dir, spec=None):
    """(result.json document, motor spec, mechanisms) of a fit folder.

    The spec comes from ``spec`` where given, else from the document's ``motor_spec``
    (the spec's TOML, written by ``motorid fit``), else from the ``inputs.motor`` path."""
    from motorid.io.spec import load_motor_spec, parse_stored_spec

    path = Path(result_dir)
    f = path / "result.json" if path.is_dir() else path
    if not f.exists():
        raise InputError(f"{f}: no such file (a folder written by motorid fit is expected)")
    try:
        doc = json.loads(f.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{f}: not a readable result.json ({exc})") from None
    if "parameters" not in doc:
        raise InputError(f"{f}: not a motorid result (no 'parameters')")
    if spec is None:
        if doc.get("motor_spec"):
            spec = parse_stored_spec(doc["motor_spec"], f"{f} motor_spec")
        elif doc.get("inputs", {}).get("motor") and Path(doc["inputs"]["motor"]).exists():
            spec = load_motor_spec(doc["inputs"]["motor"])
        else:
            raise InputError(f"{f}: the motor spec is neither stored in it nor found at its inputs.motor; "
                             f"give --motor")
    from motorid.physics.registry import get

    # a transducer's error (a zero, a gain, a lag) is the bench's, not the motor's: predict gives the motor,
    # as the exports do (its parameters were fitted with it, so the motor's are unbiased)
    mechanisms = tuple(m for m in (get(i) for i in doc.get("fit", {}).get("mechanisms", []))
                       if not getattr(m, "sensor", False))
    return doc, spec, mechanisms


def fitted_parameters(doc: dict, spec, mechanisms):
    """(values of every parameter, fitted names, their covariance, unidentified names)."""
    params = model.default_parameters(spec)
    for mech in mechanisms:
        params.update(mech.initial())
    unidentified = []
    for k, e in doc["parameters"].items():
        if e.get("identifiable") and e.get("value") is not None:
            params[k] = float(e["value"])
        else:
            unidentified.append(k)
    names = [k for k in doc.get("correlation", {}).get("names", []) if k in params and k not in unidentified]
    corr = np.asarray(doc.get("correlation", {}).get("matrix") or np.zeros((0, 0)), dtype=float)
    all_names = doc.get("correlation", {}).get("names", [])
    idx = [all_names.index(k) for k in names]
    corr = corr[np.ix_(idx, idx)] if len(idx) else np.zeros((0, 0))
    std = np.array([float(doc["parameters"][k]["std"] or 0.0) for k in names])
    cov = np.nan_to_num(corr) * np.outer(std, std)
    return params, names, cov, unidentified


def refuse_repeated_ids(table) -> None:
    """Predictions are keyed by ``point_id``: one that names two points is refused (one line,
    naming the file, the id and its lines)."""
    if not table.has_point_id:
        return
    ids = np.asarray(table.point_id, dtype=object)
    _, first, counts = np.unique(ids, return_index=True, return_counts=True)
    if np.any(counts > 1):
        k = int(first[np.flatnonzero(counts > 1)].min())
        twins = np.flatnonzero(ids == ids[k])
        where = ", ".join(f"{Path(str(table.file[i])).name} line {table.line[i]}" for i in twins[:3])
        raise InputError(f"{Path(str(table.file[k])).name}: column 'point_id': '{ids[k]}' names {twins.size} points "
                         f"({where}); predictions are keyed by point_id: give each point its own")


def predict_points(result, table, spec=None, physics_only: bool = False) -> pd.DataFrame:
    """Predictions at every point of ``table`` (:class:`motorid.io.tables.PointTable`) from a fit.

    result : a fit folder, a result.json path, or a (doc, spec, mechanisms) tuple from
    :func:`load_result`.  Returns one row per point: ``point_id`` where the table has
    it, the inputs, each output with its confidence band (``_lo95``, ``_hi95``) and,
    for torque and flows, its prediction band (``_pi_lo95``, ``_pi_hi95``), the
    operating ``mode`` (motor / pump / none) and a ``note``.  Where the fit kriged its model error
    (result.json ``table.model_error_field``, identify/kriging.py) it is added to the channels it
    holds (``<channel>_model_error`` columns say by how much) and its kriging variance replaces σ_m²
    in their bands, unless ``physics_only``.
    """
    from motorid.identify.tables import angle_samples, bind_mechanisms, point_channels

    refuse_repeated_ids(table)
    doc, spec, mechanisms = result if isinstance(result, tuple) else load_result(result, spec)
    params, names, cov, unidentified = fitted_parameters(doc, spec, mechanisms)
    for k in _carried(doc):  # held at 0 by the fit, another carrying it: not the spec's default
        params[k] = 0.0
    mechanisms = bind_mechanisms(mechanisms, table)
    samples = angle_samples(spec, table, mechanisms, params, names)
    disp = np.asarray(table.displacement, float)
    disp_arg = disp if table.variable_displacement else None

    def outputs_at(p, at):
        ch = point_channels(p, spec, at, disp_arg, mechanisms)
        ev, ehm, e = efficiencies(ch.torque, ch.q_a, ch.q_b, jnp.asarray(table.speed), jnp.asarray(table.p_a),
                                  jnp.asarray(table.p_b), jnp.asarray(disp))
        return jnp.stack([ch.torque, ch.q_a, ch.q_b, ch.q_case, ev, ehm, e])

    outputs_at = jax.jit(outputs_at)
    outputs = lambda p: outputs_at(p, samples)  # noqa: E731
    base = {k: jnp.asarray(v, dtype=jnp.float64) for k, v in params.items()}
    value = np.array(outputs(base))  # a copy: the kriged model error is added to it
    var = np.zeros_like(value)
    if names:
        std = np.sqrt(np.clip(np.diag(cov), 0, None))
        std = np.where(std > 0, std, 1.0)

        def of_z(z):
            p = dict(base)
            for i, k in enumerate(names):
                p[k] = base[k] + z[i] * std[i]
            return outputs(p)

        J = np.asarray(jax.jit(jax.jacfwd(of_z))(jnp.zeros(len(names))))  # (7, N, k)
        C = cov / np.outer(std, std)
        var = np.einsum("onk,kl,onl->on", J, C, J)
    # channels that lean on a parameter the fit did not identify: left empty
    blank = np.zeros(value.shape, bool)
    why = {}
    carried = _carried(doc)
    for k in unidentified:
        if k not in params:
            continue
        p2 = dict(base)
        if k in carried:  # held for another that carries it (K_AB by K_L0): only their split is unknown
            other = carried[k]
            step = 0.5 * abs(float(params[other])) or 1e-13
            p2[k], p2[other] = base[k] + step, base[other] - step
        else:
            p2[k] = base[k] * 2.0 + (0.1 if float(params[k]) == 0.0 else 0.0)
        # where the model at p2 varies with θ (a K_L(θ) harmonic), its θ-average needs every angle
        at = angle_samples(spec, table, mechanisms, p2)
        ref = value if at.theta.shape == samples.theta.shape else np.asarray(outputs_at(base, at))
        moved = np.abs(np.asarray(outputs_at(p2, at)) - ref) > 1e-9 * (np.abs(ref) + 1e-300)
        if k not in carried:  # the whole output, wherever it moves
            moved = np.repeat(np.any(moved, axis=1, keepdims=True), moved.shape[1], axis=1)
        finite = np.isfinite(value)
        moved &= finite
        blank |= moved
        for i in np.flatnonzero(moved.any(axis=1)):
            # a whole output (the column's note) unless the split of a carried pair moves it at some points only
            whole = k not in carried or bool(moved[i][finite[i]].all())
            why.setdefault(_OUT[i][1], (k, whole))
    noise = (doc.get("table", {}).get("noise") or doc.get("noise") or {})
    kriged = {} if physics_only else _kriged_model_error(doc, table)
    for i, (c, _, _) in enumerate(_OUT[:4]):
        if c in kriged:
            value[i] = value[i] + kriged[c][0]
    if kriged:  # the efficiencies of the corrected channels
        value[4:] = np.asarray(efficiencies(*value[:3], np.asarray(table.speed, float), np.asarray(table.p_a, float),
                                            np.asarray(table.p_b, float), disp))
    var = var + _model_error_variance(noise, value, table, disp, {c: v for c, (_, v) in kriged.items()})
    out = pd.DataFrame()
    if table.has_point_id:
        out["point_id"] = table.point_id
    out["speed_rpm"] = table.speed * 60 / (2 * np.pi)
    out["p_a_bar"], out["p_b_bar"] = table.p_a / 1e5, table.p_b / 1e5
    out["p_case_bar"] = table.p_case / 1e5
    out["viscosity_mPas"] = table.viscosity * 1e3
    if table.variable_displacement:
        out["displacement_cm3"] = disp * 1e6
    out["mode"] = operating_mode(table.speed, table.p_a, table.p_b)
    for i, (c, col, unit) in enumerate(_OUT):
        v = np.where(blank[i], np.nan, value[i]) / unit
        half = Z95 * np.sqrt(var[i]) / unit
        out[col], out[col + "_lo95"], out[col + "_hi95"] = v, v - half, v + half
        if c in kriged:
            out[col + "_model_error"] = np.where(blank[i], np.nan, kriged[c][0]) / unit
        if i < 4:
            sigma = _noise_at((noise.get(c) or {}), value[i])
            if sigma is not None:  # the noise about the model, less the model error the band holds already
                # (its share of the scatter, point by point where the noise grows with the reading)
                share = min(max(float((noise.get(c) or {}).get("model_error_share") or 0.0), 0.0), 1.0)
                half_p = Z95 * np.sqrt(var[i] + sigma ** 2 * (1.0 - share)) / unit
                out[col + "_pi_lo95"], out[col + "_pi_hi95"] = v - half_p, v + half_p
    note = "; ".join(f"{col} empty: it depends on {k}, not identified by the fit" for col, (k, whole) in why.items()
                     if whole)
    where = {col: k for col, (k, whole) in why.items() if not whole}  # empty at some points only: said there
    notes = [[note] if note else [] for _ in range(len(out))]
    for i, (c, col, _) in enumerate(_OUT):
        if col in where:
            for j in np.flatnonzero(blank[i]):
                notes[j].append(f"{col} empty: it depends on how {where[col]} and {carried[where[col]]} "
                                "share their sum here, which the fit did not determine")

    # at rest the torque lies anywhere within static friction, which a running fit does not give
    rest = np.abs(np.asarray(table.speed, float)) < STALL_SPEED
    for col in ("torque_Nm", "volumetric_efficiency", "hydromechanical_efficiency", "overall_efficiency"):
        for suffix in ("", "_lo95", "_hi95", "_pi_lo95", "_pi_hi95"):
            if col + suffix in out:
                out.loc[rest, col + suffix] = np.nan
    for i in np.flatnonzero(rest):
        notes[i].append("at rest: the torque lies anywhere within static friction (not predicted), and no "
                        "power flows (no efficiency)")
    # an efficiency outside [0, 1]: power in at both the shaft and the ports (friction above the ideal
    # torque, leakage above the swept flow), neither a motor nor a pump: no ratio of output to input
    eff = out[["volumetric_efficiency", "hydromechanical_efficiency", "overall_efficiency"]].to_numpy(float)
    dissipating = ~rest & np.any((eff < 0) | (eff > 1), axis=1)
    for col in ("volumetric_efficiency", "hydromechanical_efficiency", "overall_efficiency"):
        for suffix in ("", "_lo95", "_hi95"):
            out.loc[dissipating, col + suffix] = np.nan
    for i in np.flatnonzero(dissipating):
        notes[i].append("no efficiency: the model's power balance here is not that of a motor or a pump "
                        "(power in at both the shaft and the ports)")
    for i, words in _outside(doc, table).items():
        notes[i].append(words)
    out["note"] = ["; ".join(n) for n in notes]
    return out


def _carried(doc: dict) -> dict:
    """parameter held for another that carries it → that one (K_AB held at 0, K_L0 its sum with it)."""
    from motorid.identify.identifiability import KAB_HELD_FOR_KL0

    reason = str((doc.get("parameters", {}).get("KAB") or {}).get("reason") or "")
    return {"KAB": "KL0"} if KAB_HELD_FOR_KL0 in reason else {}


def _noise_at(noise: dict, value: np.ndarray) -> np.ndarray | None:
    """The noise σ [SI] of one reading of a channel at the model's ``value`` (result.json
    ``noise.<c>``): its ``sigma``, or where the fit found it growing with the reading
    (identify/table_noise.py) √(floor² + (reading_share · value)²); None where the fit has none."""
    if noise.get("sigma") is None:
        return None
    share = noise.get("reading_share")
    if share:
        return np.sqrt(float(noise.get("floor") or 0.0) ** 2 + (float(share) * np.nan_to_num(value)) ** 2)
    return np.full(np.shape(value), float(noise["sigma"]))


def _kriged_model_error(doc: dict, table) -> dict:
    """channel → (kriged model error, its variance) at each point [SI, its square], from result.json's
    ``table.model_error_field``; empty where the fit has none."""
    from motorid.identify.kriging import fields_from_document
    from motorid.identify.lack_of_fit import operating_axes

    scaling, fields = fields_from_document((doc.get("table") or {}).get("model_error_field"))
    if not fields:
        return {}
    X = scaling(operating_axes(table))
    return {c: krig.predict(X) for c, krig in fields.items()}


def _model_error_variance(noise: dict, value: np.ndarray, table, disp, kriged_var: dict) -> np.ndarray:
    """The variance the model's own error adds to each output (result.json ``table.noise.<c>.model_error``:
    what neighbouring points of the fitted table share of their residuals, identify/lack_of_fit.py; its
    kriging variance where it was kriged, ``kriged_var``): to the channels itself, to the efficiencies what
    it moves them by (central differences)."""
    out = np.zeros_like(value)
    errors = [np.sqrt(kriged_var[c]) if c in kriged_var else
              np.full(value.shape[1], float((noise.get(c) or {}).get("model_error") or 0.0)) for c, _, _ in _OUT[:4]]
    if not any(np.any(e > 0) for e in errors):
        return out
    args = (np.asarray(table.speed, float), np.asarray(table.p_a, float), np.asarray(table.p_b, float), disp)
    for i, e in enumerate(errors):
        if not np.any(e > 0):
            continue
        out[i] = e**2
        if i == 3:  # the case drain enters no efficiency (the inlet flow does)
            continue
        up, down = value[:3].copy(), value[:3].copy()
        up[i] += e
        down[i] -= e
        eta_up = np.asarray(efficiencies(*up, *args))
        eta_down = np.asarray(efficiencies(*down, *args))
        out[4:] += np.nan_to_num((0.5 * (eta_up - eta_down)) ** 2)
    return out


def _outside(doc: dict, table) -> dict:
    """point index → words on where it lies outside the region the fit saw (result.json's
    ``table.ranges``, or ``data.ranges`` of a fit of logs: its steady running samples)."""
    ranges = (doc.get("table") or {}).get("ranges") or (doc.get("data") or {}).get("ranges") or {}
    values = {"speed_rad_s": (np.abs(np.asarray(table.speed, float)), "speed", 60 / (2 * np.pi), "rpm"),
              "dp_Pa": (np.abs(np.asarray(table.dp, float)), "|ΔP|", 1e-5, "bar"),
              "viscosity_Pa_s": (np.asarray(table.viscosity, float), "viscosity", 1e3, "mPa·s")}
    out: dict = {}
    for key, bounds in ranges.items():
        if key not in values:
            continue
        lo, hi = bounds
        v, words, f, unit = values[key]
        # above: 2 % of the range (of the level, where one speed or one viscosity was fitted); below: 5 % of
        # the lowest fitted value (losses change fastest near rest and near zero ΔP: 20 rpm is far below 50
        # rpm, though near it on the scale of a 3 500 rpm range)
        slack_hi, slack_lo = 0.02 * max(hi - lo, abs(hi)), 0.05 * abs(lo)
        for i in np.flatnonzero((v < lo - slack_lo) | (v > hi + slack_hi)):
            part = f"{words} {v[i] * f:.4g} {unit} outside the fitted {lo * f:.4g}-{hi * f:.4g} {unit}"
            out[int(i)] = (out[int(i)] + ", " if int(i) in out else "extrapolated: ") + part
    seen = ranges.get("quadrants")
    if seen:  # a quadrant no fitted point was in: pump-mode or reverse-rotation losses were never seen
        from motorid.identify.results import quadrants

        where = quadrants(table.speed, table.dp)
        for i in np.flatnonzero((where != "") & ~np.isin(where, seen)):
            part = f"{where[i]}, a quadrant the fit never saw (it saw {'; '.join(seen)})"
            out[int(i)] = (out[int(i)] + ", " if int(i) in out else "extrapolated: ") + part
    # a model error measured inside the fitted range may grow outside it (a leak steeper than the model's)
    return {i: w + "; its bands take the model error at its size inside the fitted range" for i, w in out.items()}


def write_predictions(frame: pd.DataFrame, path) -> Path:
    """The predictions as CSV, written whole or not at all."""
    from motorid._atomic import write_bytes_atomic

    return write_bytes_atomic(path, frame.to_csv(index=False, float_format="%.8g", lineterminator="\n").encode())
