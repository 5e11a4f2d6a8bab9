"""Efficiency maps and the loss-model comparison for fits with operating-point tables.

Contour plots over (ΔP, speed), all quadrants on one plane (signed ΔP across,
signed speed up; motor mode where ΔP·ω > 0, pump mode where < 0) of the
volumetric, hydromechanical and overall efficiency (:mod:`motorid.physics.efficiency`):
measured, predicted by the fitted model at the same points, and the residual
(measured − predicted).  Triangles that straddle two quadrants are left blank:
the efficiencies are undefined where no power flows.  The comparison table
gives the held-out errors of motorid and of the classical loss models
(:mod:`motorid.comparators.evaluate`).
"""

from __future__ import annotations

import datetime as _dt
import html
from pathlib import Path

import numpy as np

BAR, RPM = 1e5, 2 * np.pi / 60
ROWS = (("volumetric", "η_v"), ("hydromechanical", "η_hm"), ("overall", "η"))
#: the measured points are marked on the maps where there are at most this many
MARKED_POINTS = 600
#: a variable unit's points whose displacements lie within this share of a setting's largest are one setting
SETTING_TOLERANCE = 0.05
#: the efficiency maps of at most this many displacement settings (the largest) are drawn
MAX_SETTINGS = 4


def _esc(x) -> str:
    return html.escape(str(x))


def efficiency_arrays(table, channels: dict) -> dict:
    """name → efficiency at each point, from channels (SI) at the table's operating points."""
    from motorid.physics.efficiency import efficiencies

    ev, ehm, e = efficiencies(np.asarray(channels["torque"], float), np.asarray(channels["q_a"], float),
                              np.asarray(channels["q_b"], float), table.speed, table.p_a, table.p_b,
                              table.displacement)
    return {"volumetric": np.asarray(ev), "hydromechanical": np.asarray(ehm), "overall": np.asarray(e)}


def displacement_settings(table) -> list:
    """The points of each displacement setting of a variable unit (index arrays, largest setting first;
    displacements within :data:`SETTING_TOLERANCE` of the setting's largest are one setting); one array of
    every point where the displacement is fixed.  A map of a variable unit is drawn setting by setting:
    points of several settings at one (ΔP, ω) would be contoured across settings."""
    n = len(table)
    if not getattr(table, "variable_displacement", False) or n == 0:
        return [np.arange(n)]
    d = np.asarray(table.displacement, float)
    order = np.argsort(-d, kind="stable")
    groups, current, top = [], [order[0]], d[order[0]]
    for i in order[1:]:
        if d[i] >= top * (1.0 - SETTING_TOLERANCE):
            current.append(i)
        else:
            groups.append(np.sort(np.array(current)))
            current, top = [i], d[i]
    groups.append(np.sort(np.array(current)))
    return groups


def plot_efficiency_maps(table, predicted: dict):
    """The 3 × 3 grid of contour maps (rows: η_v, η_hm, η; columns: measured, predicted,
    residual) as a :class:`motorid.report.plots.Plot`, or None where no efficiency is defined."""
    import matplotlib.tri as mtri

    from motorid.report.plots import Plot, embed_png, new_figure as _figure

    meas = efficiency_arrays(table, table.measured)
    pred = efficiency_arrays(table, predicted)
    x, y = table.dp / BAR, table.speed / RPM
    rows = [(k, s) for k, s in ROWS if np.isfinite(meas[k]).sum() >= 4]
    if not rows:
        return None
    quadrant = np.sign(x) * 2 + np.sign(y)
    fig, axes = _figure(len(rows), 3, figsize=(11.5, 3.2 * len(rows)), squeeze=False)
    facts = {}
    for r, (k, sym) in enumerate(rows):
        ok = np.isfinite(meas[k]) & np.isfinite(pred[k])
        if ok.sum() < 4:  # measured only: the fit does not predict what it is formed from
            only = np.isfinite(meas[k])
            sc = axes[r, 0].scatter(x[only], y[only], c=meas[k][only], cmap="viridis", s=12)
            fig.colorbar(sc, ax=axes[r, 0], shrink=0.85)
            axes[r, 0].set_title(f"{sym} measured")
            axes[r, 0].set_xlabel("ΔP = P_A − P_B [bar]")
            axes[r, 0].set_ylabel("speed [rpm]")
            for c in (1, 2):
                axes[r, c].text(0.5, 0.5, f"{sym} not predicted", ha="center", va="center",
                                transform=axes[r, c].transAxes)
                axes[r, c].set_axis_off()
            continue
        try:
            tri = mtri.Triangulation(x[ok], y[ok])
            q = quadrant[ok][tri.triangles]
            tri.set_mask(~np.all(q == q[:, :1], axis=1))
        except (RuntimeError, ValueError):  # one speed or one ΔP: the points lie on lines, no triangles
            tri = None
        lo = float(np.nanpercentile(np.r_[meas[k][ok], pred[k][ok]], 2))
        hi = float(np.nanpercentile(np.r_[meas[k][ok], pred[k][ok]], 98))
        levels = np.linspace(lo, hi, 12) if hi > lo else None
        res = meas[k][ok] - pred[k][ok]
        # the residual's colour scale: 98 % of the points inside it (an efficiency near ΔP = 0 or
        # ω = 0 is a ratio of small numbers; its few wild values would wash out every other colour)
        lim = float(np.nanpercentile(np.abs(res), 98)) or float(np.nanmax(np.abs(res))) or 1e-12
        for c, (vals, title, cmap, lev) in enumerate((
                (meas[k][ok], f"{sym} measured", "viridis", levels),
                (pred[k][ok], f"{sym} predicted", "viridis", levels),
                (res, f"{sym} measured − predicted", "RdBu_r", np.linspace(-lim, lim, 13)))):
            ax = axes[r, c]
            try:
                if tri is None:
                    raise ValueError("no triangulation")
                cs = ax.tricontourf(tri, vals, levels=lev, cmap=cmap, extend="both")
                fig.colorbar(cs, ax=ax, shrink=0.85)
            except ValueError:  # all triangles masked, or none (points on a line): the points, coloured
                sc = ax.scatter(x[ok], y[ok], c=vals, cmap=cmap, s=12,
                                vmin=None if lev is None else lev[0], vmax=None if lev is None else lev[-1])
                fig.colorbar(sc, ax=ax, shrink=0.85)
            if ok.sum() <= MARKED_POINTS:  # a dense grid's markers would cover the colours
                ax.plot(x[ok], y[ok], ".", color="k", ms=2)
            ax.axhline(0, color="k", lw=0.6)
            ax.axvline(0, color="k", lw=0.6)
            ax.set_title(title if ok.sum() <= MARKED_POINTS else f"{title} ({ok.sum():,} points)")
            ax.set_xlabel("ΔP = P_A − P_B [bar]")
            ax.set_ylabel("speed [rpm]")
        facts[k] = {"rms_residual": float(np.sqrt(np.mean(res**2))), "points": int(ok.sum())}
    return Plot(embed_png(fig, "efficiency maps: measured, predicted, residual"), facts)


def comparison_section(doc: dict) -> str:
    """The comparison table (held-out errors of motorid and of the classical models) as HTML;
    "" where the document has no ``comparison`` block."""
    comp = doc.get("comparison")
    if not comp:
        return ""
    chans = [c for c in ("torque", "q_a", "q_b", "q_case")
             if any(c in m.get("kfold", {}) for m in comp["models"].values())]
    kinds = (("kfold", "K-fold"), ("extrapolate_pressure", "extrap. ΔP"), ("extrapolate_speed", "extrap. speed"))
    head = "<tr><th rowspan=2>model</th>" + "".join(f"<th colspan=3>{_esc(c)}</th>" for c in chans) + "</tr>"
    head += "<tr>" + "".join(f"<th>{k[1]}</th>" for _ in chans for k in kinds) + "</tr>"
    best = {}
    for c in chans:
        for kind, _ in kinds:
            vals = [m.get(kind, {}).get(c, {}).get("percent_of_span") for m in comp["models"].values()]
            vals = [v for v in vals if v is not None]
            best[(c, kind)] = min(vals) if vals else None
    body = []
    for name, m in comp["models"].items():
        cells = []
        for c in chans:
            for kind, _ in kinds:
                v = m.get(kind, {}).get(c, {}).get("percent_of_span")
                mark = " style=\"font-weight:bold\"" if v is not None and v == best[(c, kind)] else ""
                cells.append(f'<td class="num"{mark}>' + ("—" if v is None else f"{v:.3g}") + "</td>")
        ref = _esc(m.get("equations") or m.get("reference", ""))
        body.append(f'<tr><td title="{ref}">{_esc(name)}</td>' + "".join(cells) + "</tr>")
    method = comp.get("method", {})
    refs = "".join(f"<li><b>{_esc(n)}</b>: {_esc(m.get('equations', ''))} — {_esc(m.get('reference', ''))}</li>"
                   for n, m in comp["models"].items())
    return ("<section id=\"comparison\"><h2>Held-out prediction: motorid and the classical loss models</h2>"
            f"<p>RMS of the held-out residual, in % of each channel's measured span (bold: the best). "
            f"{_esc(method.get('kfold', ''))}; extrapolation: {_esc(method.get('extrapolation', ''))}.</p>"
            f'<div class="wide"><table id="comparison-table">{head}{"".join(body)}</table></div>'
            f"<details><summary>the models</summary><ul>{refs}</ul></details></section>")


def _parameter_rows(doc: dict) -> str:
    rows = []
    for k, e in doc["parameters"].items():
        if e.get("identifiable"):
            rows.append(f"<tr><td>{_esc(k)}</td><td class=\"num\">{e['value']:.5g}</td>"
                        f"<td class=\"num\">{e['std']:.3g}</td><td>{_esc(e['unit'])}</td><td class=\"yes\">yes</td></tr>")
        else:
            rows.append(f"<tr class=\"no\"><td>{_esc(k)}</td><td>—</td><td>—</td><td>{_esc(e['unit'])}</td>"
                        f"<td class=\"no\">no: {_esc(e.get('reason', ''))}</td></tr>")
    return ("<table id=\"parameter-table\"><tr><th>parameter</th><th>value</th><th>std</th><th>unit</th>"
            "<th>identifiable</th></tr>" + "".join(rows) + "</table>")


def diagnosis_section(diagnosis: dict | None) -> str:
    """What ``motorid diagnose`` found on the tables (its diagnosis.json beside result.json): each
    named mechanism in words with its parameters, what is left unexplained, and the candidates
    left out and why; empty where diagnose was not run."""
    if not isinstance(diagnosis, dict):
        return ""
    from motorid.report.causes import unexplained_words
    from motorid.report.html import _mechanism

    if "unreadable" in diagnosis:
        return (f"<section id=\"diagnosis\"><h2>What diagnose found</h2><p class=\"missing\">"
                f"{_esc(diagnosis['unreadable'])}</p></section>")
    mechs = diagnosis.get("mechanisms") or []
    body = ["<section id=\"diagnosis\"><h2>What diagnose found</h2>",
            "<p>From diagnosis.json (<code>motorid diagnose</code>): physics and causes beyond the 1992 model, "
            "each kept only where it lowers the BIC by 10 or more (docs/maps.md).</p>"]
    if mechs:
        for m in mechs:
            words = m.get("description") if isinstance(m, dict) else None
            body.append(_mechanism({k: v for k, v in m.items() if k not in ("description", "reference", "signature")})
                        if isinstance(m, dict) else _mechanism(m))
            if words:
                body.append(f"<p>{_esc(words)}</p>")
    else:
        body.append("<p>None: no candidate mechanism earned its place.</p>")
    body.append("<h3>Unexplained</h3>" + (unexplained_words(diagnosis.get("unexplained"))
                                           or "<p>Nothing: the residuals left are consistent with the noise.</p>"))
    left = [s for s in (diagnosis.get("selection") or {}).get("steps", [])
            if isinstance(s, dict) and ("skipped" in s or "refused" in s)]
    if left:  # skipped before a fit, or refused as a stand-in after one
        body.append("<h3>Left out</h3><ul>" + "".join(
            f"<li><code>{_esc(s['id'])}</code>: {_esc(s.get('skipped') or 'refused: ' + s['refused'])}</li>"
            for s in left) + "</ul>")
    body.append("</section>")
    return "\n".join(body)


def _diagnosis_beside(out_dir) -> dict | None:
    """diagnosis.json of ``out_dir`` where there is one (:func:`~motorid.io.results.read_diagnosis_beside`,
    as the report of a log fit reads it); one that does not read → ``{"unreadable": why}``."""
    from motorid.io.results import read_diagnosis_beside

    doc, unreadable = read_diagnosis_beside(out_dir)
    return {"unreadable": unreadable} if unreadable else doc


def render_map_report(doc: dict, tf, diagnosis: dict | None = None) -> str:
    """The report page of a fit with operating-point tables (``diagnosis``: diagnose's document,
    where it was run)."""
    from motorid.comparators.evaluate import not_predicted
    from motorid.report.html import CSS

    motor = doc.get("motor", {})
    t = doc.get("table", {})
    settings = displacement_settings(tf.table)
    unpredicted = not_predicted({k: bool(v.get("identifiable", True)) for k, v in (doc.get("parameters") or {}).items()
                                 if isinstance(v, dict)})
    figures = []
    for idx in settings[:MAX_SETTINGS]:
        sub = tf.table if len(settings) == 1 else tf.table.subset(idx)
        pred = tf.table_prediction if len(settings) == 1 else {
            c: np.asarray(v)[idx] for c, v in tf.table_prediction.items()}
        # a channel the fit cannot predict (a parameter it needs not identified) is not drawn as predicted
        pred = {c: (np.full(len(sub), np.nan) if c in unpredicted else np.asarray(v)) for c, v in pred.items()}
        plot = plot_efficiency_maps(sub, pred)
        if plot is None:
            continue
        facts = "; ".join(f"{k}: RMS residual {v['rms_residual']:.4f} over {v['points']} points"
                          for k, v in plot.facts.items())
        setting = "" if len(settings) == 1 else (
            f"At the displacement setting D ≈ {np.median(sub.displacement) * 1e6:.4g} cm³/rev "
            f"({len(sub)} points). ")
        figures.append(f"<figure>{plot.img}<figcaption>{_esc(setting)}Efficiencies over (ΔP, speed), all quadrants "
                       f"(motor mode where ΔP·ω &gt; 0, pump mode where &lt; 0; definitions in docs/maps.md): "
                       f"measured, predicted by the fitted model at the same points, and measured − predicted. "
                       f"{_esc(facts)}.</figcaption></figure>")
    if len(settings) > MAX_SETTINGS and figures:
        figures.append(f"<p>{len(settings)} displacement settings in the table: maps of {len(figures)} of the "
                       f"{MAX_SETTINGS} largest are drawn.</p>")
    maps = "\n".join(figures) or ('<p class="missing">No efficiency can be formed: the table lacks torque or the '
                                   'port flows.</p>')
    if unpredicted:
        maps = ("<p>Not predicted: " + "; ".join(f"{c} (it needs {k}, which the fit did not identify)"
                                                  for c, k in unpredicted.items())
                + ". The efficiencies formed from it are drawn as measured only.</p>\n" + maps)
    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
             f"<title>motorid map report: {_esc(motor.get('name', 'motor'))}</title>", f"<style>{CSS}</style>",
             "</head><body>", f"<h1>motorid map report: {_esc(motor.get('name', 'motor'))}</h1>",
             f'<p class="meta">{t.get("points", "?")} operating points from {_esc(", ".join(t.get("files", [])))}; '
             f'written {_dt.datetime.now().strftime("%Y-%m-%d %H:%M")}.</p>',
             "<section id=\"parameters\"><h2>Parameters</h2>", _parameter_rows(doc), "</section>",
             "<section id=\"efficiency-maps\"><h2>Efficiency maps</h2>", maps, "</section>",
             diagnosis_section(diagnosis), comparison_section(doc), "</body></html>"]
    return "\n".join(parts) + "\n"


def write_map_report(out_dir, doc: dict, tf, spec=None) -> Path:
    """Write ``out_dir/report.html`` for a fit with tables (whole or not at all)."""
    from motorid._atomic import write_bytes_atomic

    path = Path(out_dir) / "report.html"
    write_bytes_atomic(path, render_map_report(doc, tf, _diagnosis_beside(out_dir)).encode("utf-8"))
    return path


def is_table_result(out_dir) -> bool:
    """True when ``out_dir/result.json`` is a fit with operating-point tables."""
    import json

    f = Path(out_dir) / "result.json"
    try:
        return "table" in json.loads(f.read_text())
    except (OSError, ValueError):
        return False


def rerender_map_report(out_dir, motor=None) -> Path:
    """report.html of a table fit from its result.json: the tables it names are re-read and
    the model evaluated at the fitted parameters (nothing refitted)."""
    from types import SimpleNamespace

    from motorid.errors import InputError
    from motorid.identify.predict import fitted_parameters, load_result
    from motorid.identify.tables import angle_samples, bind_mechanisms, point_channels
    from motorid.io.spec import load_motor_spec
    from motorid.io.tables import read_tables, split_channel_map

    doc, spec, mechanisms = load_result(out_dir, load_motor_spec(motor) if motor else None)
    paths = doc.get("inputs", {}).get("tables") or []
    missing = [p for p in paths if not Path(p).exists()]
    if not paths or missing:
        raise InputError(f"{Path(out_dir) / 'result.json'}: the table {missing[0] if missing else '(none named)'} "
                         f"it was fitted on is not found")
    channels = doc.get("inputs", {}).get("channels")
    if channels and not Path(channels).exists():
        raise InputError(f"{Path(out_dir) / 'result.json'}: the channel map {channels} the tables were read "
                         "through is not found")
    table = read_tables(paths, spec, channels=split_channel_map(channels)[0] if channels else None)
    params = fitted_parameters(doc, spec, mechanisms)[0]
    mechanisms = bind_mechanisms(mechanisms, table)
    ch = point_channels(params, spec, angle_samples(spec, table, mechanisms, params),
                        table.displacement if table.variable_displacement else None, mechanisms)
    tf = SimpleNamespace(table=table, table_prediction=dict(zip(("torque", "q_a", "q_b", "q_case"),
                                                                (np.asarray(c) for c in ch))))
    return write_map_report(out_dir, doc, tf, spec)
