"""``report.html``: one self-contained page of what a fit found and how far to trust it.

Plots are embedded as base64 PNG ``data:`` URIs and the styling sits in one
``<style>`` tag: the page opens offline in any browser, with no script and no
external resource.  The numbers of the parameter table are those of
``result.json`` (each cell also carries the full-precision value in a
``data-value`` attribute).
"""

from __future__ import annotations

import datetime as _dt
import html
import math
import sys
from pathlib import Path

import numpy as np

from motorid._atomic import write_bytes_atomic
from motorid.report import format as fmt
from motorid.report import plots
from motorid.report.evaluate import Ensemble, ReportData, gather, noise_by_run
from motorid.units import PA_PER_BAR, RPM_PER_RAD_S

REPORT_FILE = "report.html"

SECTIONS = [
    ("summary", "Summary"),
    ("parameters", "Parameters"),
    ("data", "Data"),
    ("model-vs-data", "Model against data"),
    ("residuals", "Residuals"),
    ("uncertainty", "Uncertainty: correlation, posterior and chain"),
    ("efficiency", "Derived figures: efficiency"),
    ("discrepancy", "Discrepancy analysis"),
    ("provenance", "Provenance"),
]

STANDARDS = {"constant_speed": "ISO 4392-1", "constant_pressure": "ISO 4392-1", "startability": "ISO 4392-2",
             "constant_flow": "ISO 4392-3", "constant_torque": "ISO 4392-3"}

CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; color: #1d1d1f;
       max-width: 1280px; margin: 0 auto; padding: 0 24px 48px; line-height: 1.45; font-size: 15px; }
h1 { font-size: 1.6em; margin: 24px 0 4px; }
h2 { font-size: 1.3em; border-bottom: 2px solid #d0d7de; padding-bottom: 4px; margin-top: 40px; }
h3 { font-size: 1.08em; margin-top: 26px; }
p.verdict { font-size: 1.12em; background: #f0f6ff; border-left: 5px solid #2f6fdf; padding: 10px 14px; }
p.verdict.warn { background: #fff6e5; border-left-color: #e39b00; }
p.meta, .caption, .small { color: #555; font-size: 0.9em; }
nav ol { columns: 3; font-size: 0.92em; }
table { border-collapse: collapse; margin: 10px 0 16px; font-size: 0.9em; }
th, td { border: 1px solid #d0d7de; padding: 4px 8px; vertical-align: top; }
th { background: #f3f5f7; text-align: left; }
#parameter-table td:nth-child(2) { min-width: 190px; font-size: 0.92em; color: #333; }
#parameter-table td.iv { white-space: normal; min-width: 8em; }
div.wide { overflow-x: auto; }
td.num { text-align: right; white-space: nowrap; font-variant-numeric: tabular-nums; }
tr.no td { background: #fff4f2; }
td.no { color: #b3261e; }
td.yes { color: #1a7f37; }
td.weak { color: #9a6700; }
figure { margin: 16px 0 28px; }
figure img { max-width: 100%; height: auto; border: 1px solid #e4e7eb; }
figcaption { color: #444; font-size: 0.9em; max-width: 1100px; }
code { background: #f3f5f7; padding: 1px 4px; border-radius: 3px; font-size: 0.92em; }
.missing { color: #8a5a00; background: #fff8e6; padding: 8px 12px; border-radius: 4px; }
details { margin: 8px 0; }
summary { cursor: pointer; color: #2f6fdf; }
ul.warnings li { color: #8a5a00; }
dl.kv dt { font-weight: 600; float: left; clear: left; width: 170px; }
dl.kv dd { margin-left: 180px; }
"""


def esc(x) -> str:
    return html.escape(str(x))


# ----------------------------------------------------------------------------- writing


def write_report(out_dir, identification=None, spec=None, logs=None, motor=None) -> Path:
    """Write ``out_dir/report.html`` beside ``result.json`` and return its path.

    identification : the :class:`~motorid.identify.pipeline.Identification` just
        made (with ``spec``), so nothing is re-read; None: read ``result.json``
        (and ``chain.npz``), re-read the campaign it names and evaluate the model
        at its parameters (no refit).
    logs, motor : bench logs and motor spec to use instead of those ``result.json`` names.
    The file is written whole or not at all (temporary file, then rename).
    """
    out = Path(out_dir)
    rd = gather(out, identification=identification, spec=spec, logs=logs, motor=motor)
    page = render(rd)
    path = out / REPORT_FILE
    write_bytes_atomic(path, page.encode("utf-8"))  # temporary file, then rename; readable as the umask allows
    return path


def render(rd: ReportData) -> str:
    """The whole page as a string."""
    doc = rd.doc
    motor = doc.get("motor", {})
    ens = Ensemble(rd) if rd.dataset is not None else None
    figs = _figures(rd, ens)
    title = f"motorid report: {motor.get('name', 'motor')}"
    parts = [
        "<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{esc(title)}</title>", f"<style>{CSS}</style>", "</head>", "<body>",
        f"<h1>{esc(title)}</h1>",
        f'<p class="meta">Bent-axis piston motor, {motor.get("pistons", "?")} pistons, '
        f'D = {fmt.number((motor.get("displacement_m3") or 0) * 1e6)} cm³/rev; model of Bartos (1992); '
        f'written {_dt.datetime.now().strftime("%Y-%m-%d %H:%M")} by motorid '
        f'{esc(doc.get("versions", {}).get("motorid", ""))}.</p>',
        _nav(),
        _summary(rd),
        _parameters(rd),
        _data(rd),
        _model_vs_data(rd, figs),
        _residuals(rd, figs),
        _uncertainty(rd, figs),
        _efficiency(rd, figs),
        _discrepancy(rd),
        _comparison(doc),
        _provenance(rd),
        "</body>", "</html>",
    ]
    return "\n".join(parts) + "\n"


def _comparison(doc: dict) -> str:
    """Held-out errors beside the classical loss models, where the fit had tables (report/maps.py)."""
    from motorid.report.maps import comparison_section

    return comparison_section(doc)


def _figures(rd: ReportData, ens) -> dict:
    """Draw every figure; one that fails leaves a note instead of the whole report failing."""
    jobs = {
        "correlation": lambda: plots.plot_correlation((rd.doc.get("correlation") or {}).get("names") or [],
                                                      (rd.doc.get("correlation") or {}).get("matrix")),
        "corner": lambda: plots.plot_corner(rd),
        "traces": lambda: plots.plot_traces(rd),
    }
    if ens is not None:
        jobs.update({
            "torque_speed": lambda: plots.plot_torque_speed(rd, ens),
            "ripple": lambda: plots.plot_ripple(rd, ens),
            "breakaway": lambda: plots.plot_breakaway(rd, ens),
            "flows": lambda: plots.plot_flows_speed(rd, ens),
            "residuals": lambda: plots.plot_residuals(rd),
        })
        if not _unidentified(rd.doc, EFFICIENCY_NEEDS):
            jobs["efficiency"] = lambda: plots.plot_efficiency_maps(rd, ens)
        if not _unidentified(rd.doc, STARTING_NEEDS):
            jobs["starting"] = lambda: plots.plot_starting_efficiency(rd, ens)
    out = {}
    for key, job in jobs.items():
        try:
            out[key] = job()
        except Exception as exc:  # noqa: BLE001  (a figure must not take the report down)
            out[key] = None
            msg = f"the figure '{key}' could not be drawn: {type(exc).__name__}: {exc}"
            rd.notes.append(msg)
            print(f"motorid report: warning: {msg}", file=sys.stderr)
    return out


def _nav() -> str:
    items = "".join(f'<li><a href="#{sid}">{esc(name)}</a></li>' for sid, name in SECTIONS)
    return f"<nav><ol>{items}</ol></nav>"


def _section(sid: str, body: str) -> str:
    name = dict(SECTIONS)[sid]
    return f'<section id="{sid}">\n<h2>{esc(name)}</h2>\n{body}\n</section>'


def new_figure(plot, caption: str, missing: str) -> str:
    if plot is None:
        return f'<p class="missing">{missing}</p>'
    return f"<figure>{plot.img}<figcaption>{caption}</figcaption></figure>"


# ----------------------------------------------------------------------------- summary


def verdict(doc: dict) -> tuple[str, bool]:
    """The sentence at the top of the report, and whether all is well."""
    params = doc.get("parameters", {})
    ok = True
    bad = [k for k, e in params.items() if not e.get("identifiable")]
    if not bad:
        parts = ["All parameters identified"]
    else:
        ok = False
        parts = [f"{len(params) - len(bad)} of {len(params)} parameters identified "
                 f"({', '.join(bad)} not identifiable from these logs)"]
    fit = doc.get("fit", {})
    rc = fit.get("reduced_chi2")
    if rc is not None:
        parts.append(f"χ²/dof {rc:.2f}" + (" (the model misses structure in the data)" if rc > 1.5 else ""))
        ok = ok and rc <= 1.5
    if fit.get("converged") is False:
        parts.append("least squares stopped before converging")
        ok = False
    m = doc.get("mcmc")
    if m:
        tau = [v for v in (m.get("tau") or {}).values() if v is not None]
        ess = [v for v in (m.get("ess") or {}).values() if v is not None]
        stats = f"τ {max(tau):.0f} steps, {fmt.count(min(ess))} effective samples" if tau and ess else ""
        if m.get("converged"):
            parts.append(f"chain converged ({stats})" if stats else "chain converged")
        else:
            parts.append(f"chain NOT converged ({stats}): treat the Bayesian intervals with care")
            ok = False
    else:
        parts.append("no Bayesian run (add --bayes to sample the posterior)")
    return "; ".join(parts) + ".", ok


def _summary(rd: ReportData) -> str:
    text, ok = verdict(rd.doc)
    body = [f'<p class="verdict{"" if ok else " warn"}" id="verdict">{esc(text)}</p>']
    warnings = list(rd.doc.get("fit", {}).get("warnings") or []) + list((rd.doc.get("mcmc") or {}).get("warnings") or [])
    if warnings:
        body.append("<p>Warnings of the fit:</p><ul class=\"warnings\">"
                    + "".join(f"<li>{esc(w)}</li>" for w in warnings) + "</ul>")
    if rd.notes:
        body.append("<p>Notes on this report:</p><ul class=\"warnings\">"
                    + "".join(f"<li>{esc(n)}</li>" for n in rd.notes) + "</ul>")
    body.append(_agreement(rd))
    dg = rd.diagnosis
    if isinstance(dg, dict) and "mismatch" in dg:
        names = [m.get("name", m.get("id", "?")) for m in dg.get("mechanisms") or [] if isinstance(m, dict)]
        left = dg.get("unexplained") or []
        body.append("<p>Discrepancy analysis: " + (
            "the residuals are consistent with the noise." if not dg["mismatch"] else
            "the residuals show structure the 1992 model lacks; "
            + (f"explained by {esc(', '.join(names))}" if names else "no named mechanism explains it")
            + (f"; {len(left)} structure(s) left unexplained" if left else "") + ".")
            + ' See <a href="#discrepancy">the discrepancy analysis</a>.</p>')
    return _section("summary", "\n".join(body))


def _agreement(rd: ReportData) -> str:
    """Least squares against the posterior (and against the truth of a synthetic campaign)."""
    params = rd.doc.get("parameters", {})
    words = []
    both = [(k, e) for k, e in params.items() if e.get("posterior") and e.get("value") is not None and e.get("std")]
    if both:
        off = [(k, abs(e["posterior"]["median"] - e["value"]) / e["std"]) for k, e in both]
        far = [k for k, z in off if z > 1.0]
        if far:
            words.append(f"The posterior median differs from the least-squares value by more than one standard "
                         f"error for {', '.join(far)}: the likelihood is not Gaussian there; prefer the "
                         f"Bayesian interval.")
        else:
            worst = max(z for _, z in off)
            words.append(f"The posterior agrees with least squares: every median lies within {worst:.2f} "
                         f"standard errors of the least-squares value.")
    if rd.truth:
        inside, outside = [], []
        for k, e in params.items():
            if k in rd.truth and e.get("ci95"):
                lo, hi = e["ci95"]
                (inside if lo <= rd.truth[k] <= hi else outside).append(k)
        if inside or outside:
            words.append(f"Synthetic campaign: the true value lies inside the least-squares 95 % interval for "
                         f"{len(inside)} of {len(inside) + len(outside)} parameters"
                         + (f" (outside: {', '.join(outside)})." if outside else "."))
    return "".join(f"<p>{esc(w)}</p>" for w in words)


# ----------------------------------------------------------------------------- parameters


def _cell(name: str, field: str, value, unit, digits=4) -> str:
    return (f'<td class="num" data-param="{esc(name)}" data-field="{field}" data-value="{fmt.attr(value)}" '
            f'title="{fmt.attr(value)}">{fmt.quantity(value, unit, digits)}</td>')


def _interval_cell(name: str, field: str, pair, unit) -> str:
    lo, hi = (pair or [None, None])[:2] if pair else (None, None)
    return (f'<td class="num iv" data-param="{esc(name)}" data-field="{field}" '
            f'data-low="{fmt.attr(lo)}" data-high="{fmt.attr(hi)}">{fmt.interval(pair, unit)}</td>')


def _parameters(rd: ReportData) -> str:
    params = rd.doc.get("parameters", {})
    bayes = any(e.get("posterior") for e in params.values())
    truth = rd.truth or {}
    head = ["parameter", "physical meaning", "least squares: value", "standard error", "95 % interval"]
    if bayes:
        head += ["posterior: median", "standard deviation", "95 % credible interval"]
    if truth:
        head += ["true value (synthetic)"]
    head += ["identifiable"]
    rows = []
    for k, e in params.items():
        unit = e.get("unit")
        ident = bool(e.get("identifiable"))
        cells = [f'<td><code>{esc(k)}</code> {fmt.symbol(k)}</td>', f"<td>{esc(e.get('meaning', ''))}</td>"]
        if ident:
            cells += [_cell(k, "value", e.get("value"), unit), _cell(k, "std", e.get("std"), unit, 2),
                      _interval_cell(k, "ci95", e.get("ci95"), unit)]
        else:
            cells += [f'<td colspan="3" data-param="{esc(k)}" data-field="value">not identifiable from these '
                      f'logs</td>']
        if bayes:
            p = e.get("posterior")
            if p:
                cells += [_cell(k, "posterior.median", p.get("median"), unit),
                          _cell(k, "posterior.std", p.get("std"), unit, 2),
                          _interval_cell(k, "posterior.ci95", p.get("ci95"), unit)]
            else:
                cells += ['<td colspan="3">—</td>']
        if truth:
            cells.append(_cell(k, "truth", truth.get(k), unit) if k in truth else "<td>—</td>")
        if ident and e.get("indistinct_from_zero"):
            cells.append(f'<td class="weak">yes, but not told from 0: {esc(e.get("note", ""))}</td>')
        elif ident:
            cells.append('<td class="yes">yes</td>')
        else:
            cells.append(f'<td class="no">no: {esc(e.get("reason", "not determined by these logs"))}</td>')
        rows.append(f'<tr class="{"yes" if ident else "no"}">' + "".join(cells) + "</tr>")
    table = ("<div class=\"wide\"><table id=\"parameter-table\"><thead><tr>"
             + "".join(f"<th>{esc(h)}</th>" for h in head)
             + "</tr></thead><tbody>" + "\n".join(rows) + "</tbody></table></div>")
    note = ('<p class="caption">Values in SI units with 4 significant digits (hover a value for all its '
            "digits); standard errors with 2. The least-squares 95 % interval is value ± 1.96 standard "
            "errors; the credible interval holds the central 95 % of the posterior draws. A parameter the "
            "logs cannot determine is held fixed and given no number.</p>")
    return _section("parameters", table + note)


# ----------------------------------------------------------------------------- data


def _data(rd: ReportData) -> str:
    d = rd.doc.get("data")
    body = []
    if not d:
        body.append('<p class="missing">result.json holds no summary of the data.</p>')
        return _section("data", "\n".join(body))
    protos = d.get("protocols", {})
    runs = d.get("runs", [])
    events_by = {}
    for r in runs:
        if r.get("protocol") == "startability" and not r.get("excluded") and r.get("onset_time_s") is not None:
            events_by["startability"] = events_by.get("startability", 0) + 1
    rows = []
    for p, s in protos.items():
        ev = events_by.get(p, 0) if p == "startability" else None
        rows.append(f"<tr><td>{esc(p)}</td><td>{esc(STANDARDS.get(p, ''))}</td><td class=\"num\">{s['runs']}</td>"
                    f"<td class=\"num\">{fmt.count(s['samples'])}</td><td class=\"num\">{fmt.count(s['steady'])}</td>"
                    f"<td class=\"num\">{'—' if ev is None else ev}</td></tr>")
    body.append("<h3>Runs found, by protocol</h3><table id=\"protocol-table\"><tr><th>protocol</th><th>standard</th>"
                "<th>runs</th><th>samples</th><th>steady samples used</th><th>breakaway events</th></tr>"
                + "".join(rows) + "</table>")
    body.append(f"<p>{fmt.count(d.get('events', 0))} breakaway events in all; "
                f"{fmt.count(sum(s['steady'] for s in protos.values()))} steady running samples.</p>")
    excluded = {k: v for k, v in (d.get("excluded") or {}).items()}
    outliers = rd.doc.get("fit", {}).get("outliers") or {}
    ex_rows = [f"<tr><td>{esc(k)}</td><td class=\"num\">{fmt.count(v)}</td></tr>" for k, v in excluded.items()]
    ex_rows += [f"<tr><td>{esc(fmt.CHANNELS.get(c, (c,))[0])}: rejected as outliers by the fit (beyond 5 σ)</td>"
                f"<td class=\"num\">{fmt.count(v)}</td></tr>" for c, v in outliers.items()]
    bad_runs = [r for r in runs if r.get("excluded")]
    body.append("<h3>Excluded samples and why</h3>" + (
        "<table id=\"excluded-table\"><tr><th>reason</th><th>count</th></tr>" + "".join(ex_rows) + "</table>"
        if ex_rows else "<p>Nothing was excluded.</p>"))
    if bad_runs:
        body.append("<p>Runs that gave nothing:</p><ul>" + "".join(
            f"<li>{esc(r['run'])} ({esc(r.get('protocol'))}): {esc(r['excluded'])}</li>" for r in bad_runs) + "</ul>")
    if d.get("notes"):
        body.append("<p>Notes from the extraction:</p><ul>" + "".join(f"<li>{esc(n)}</li>" for n in d["notes"])
                    + "</ul>")
    body.append(_noise_table(rd))
    body.append(_run_table(runs))
    return _section("data", "\n".join(body))


def _noise_table(rd: ReportData) -> str:
    noise = rd.doc.get("noise", {})
    fit = rd.doc.get("fit", {})
    spread = noise_by_run(rd)
    rows = []
    for c, e in noise.items():
        sig = e.get("sigma")
        name, unit, factor = fmt.CHANNELS.get(c, (c, e.get("unit", ""), 1.0))
        rng = spread.get(c)
        rng_txt = "—" if rng is None else f"{fmt.number(rng[0] * factor, 3)} – {fmt.number(rng[1] * factor, 3)} {esc(unit)}"
        rows.append(f'<tr><td>{esc(name)} (<code>{esc(c)}</code>)</td>'
                    f'<td class="num" data-channel="{esc(c)}" data-value="{fmt.attr(sig)}">{fmt.channel_noise(c, sig)}</td>'
                    f'<td class="num">{fmt.quantity(sig, e.get("unit"), 3)}</td><td class="num">{rng_txt}</td>'
                    f'<td class="num">{fmt.count((fit.get("used") or {}).get(c, 0))}</td>'
                    f'<td class="num">{fmt.count((fit.get("outliers") or {}).get(c, 0))}</td></tr>')
    return ("<h3>Noise level per channel</h3><table id=\"noise-table\"><tr><th>channel</th><th>σ (pooled)</th>"
            "<th>σ, SI</th><th>σ range across runs</th><th>readings used</th><th>outliers</th></tr>"
            + "".join(rows) + "</table><p class=\"caption\">Estimated from the data by the fit: the robust "
            "standard deviation of the residuals within each run (the pooled value is their median). The fit "
            "weights each reading by its run's σ.</p>")


def _run_table(runs: list) -> str:
    if not runs:
        return ""
    rows = []
    for r in runs:
        f = lambda k, s=1.0, d=4: fmt.number(None if r.get(k) is None else r[k] * s, d)  # noqa: E731
        rows.append(f"<tr><td>{esc(r.get('run'))}</td><td>{esc(r.get('protocol'))}</td>"
                    f"<td class=\"num\">{r.get('n_samples', '')}</td><td class=\"num\">{r.get('n_steady', '')}</td>"
                    f"<td class=\"num\">{f('speed_median_rad_s', RPM_PER_RAD_S)}</td><td class=\"num\">{f('dp_median_Pa', 1 / PA_PER_BAR)}</td>"
                    f"<td class=\"num\">{f('psum_median_Pa', 1 / PA_PER_BAR)}</td><td class=\"num\">{f('temp_median_C', 1, 3)}</td>"
                    f"<td>{esc(r.get('excluded') or '')}</td></tr>")
    return ("<details><summary>Every run (" + str(len(runs)) + ")</summary><table id=\"run-table\"><tr><th>run</th>"
            "<th>protocol</th><th>samples</th><th>steady</th><th>speed [rpm]</th><th>ΔP [bar]</th>"
            "<th>P_A+P_B [bar]</th><th>oil [°C]</th><th>excluded</th></tr>" + "".join(rows) + "</table></details>")


# ----------------------------------------------------------------------------- figures


def _band_words(rd: ReportData) -> str:
    return (f"Bands: 95 % of the model over {len(rd.draws)} parameter draws from the {rd.draw_source}"
            if rd.draws is not None else "No parameter draws: the model is drawn without a band")


def _model_vs_data(rd: ReportData, figs: dict) -> str:
    if rd.dataset is None:
        return _section("model-vs-data", '<p class="missing">The bench logs could not be read, so the data are '
                                         "not plotted (see the notes in the summary).</p>")
    body = []
    f = figs.get("torque_speed")
    body.append("<h3>Running torque against speed</h3>" + new_figure(
        f, (f"One colour per pressure level ({f.facts['levels']} levels: ΔP and oil temperature); circles: "
            "positive direction, squares: negative; lines: the model averaged over a shaft revolution. Each point "
            "is a run's mean, corrected by the model to the level's nominal conditions (the curve plus the run's "
            "mean residual; the largest correction is "
            f"{fmt.number(f.facts['correction'], 2)} N·m). {_band_words(rd)}; its half-width is at most "
            f"{fmt.number(f.facts['band'], 2)} N·m, so it is thin at this scale. Right: the torque lost to "
            "friction and viscous drag.") if f else "", "No running-torque data."))
    f = figs.get("ripple")
    body.append("<h3>Torque ripple and case-drain flow against shaft angle</h3>" + new_figure(
        f, ("The slowest run at each pressure level that covers a whole piston pitch (runs "
            f"{esc(', '.join(f.facts['runs']))}): the model at the run's median pressures, speed and oil "
            "temperature, and every reading corrected by the model to those conditions (the curve plus the "
            "reading's residual; the oil warms a little during a slow run). Bands: the model's 95 % band (dark) "
            "and the 95 % band of a single reading, which adds the channel's noise (light).") if f else "", "No slow run covers a whole piston pitch of shaft angle."))
    f = figs.get("breakaway")
    body.append("<h3>Breakaway torque against pressure and shaft angle</h3>" + new_figure(
        f, (f"Left: the load torque held at the instant of breakaway in {f.facts['events']} startability runs "
            "(circles: positive direction, squares: negative); grey: the model over all shaft angles; crosses: "
            "the model at each event. Middle: the static friction the shaft overcame, the pressure torque "
            "T_p(θ, ΔP) of the exact piston sum (no parameter in it) less the held torque, against the port "
            "pressure sum; the model is the line T_break = D(P_A+P_B)(K_F+K_FS) + T_Fc(1+K_s). Right: the held "
            "torque over the ideal torque D|ΔP|/2π against the shaft angle within a piston pitch. Bands: the "
            "model's 95 % band (dark) and the 95 % band of a single reading (light).") if f else "",
        "No breakaway events in these logs (ISO 4392-2 runs needed)."))
    f = figs.get("flows")
    body.append("<h3>Port and case-drain flows against speed</h3>" + new_figure(
        f, ("Run means corrected by the model to each level's nominal conditions, as above. The inlet flow is "
            "port A's in the positive direction and port B's in the negative one. The flow beyond (and short "
            "of) the swept flow D|ω|/2π is the leakage that the laminar coefficients K_L0 and K_AB describe. "
            f"{_band_words(rd)}; its half-width is at most {fmt.number(f.facts['band'], 2)} L/min.")
        if f else "", "No running flow data."))
    return _section("model-vs-data", "\n".join(body))


def _residuals(rd: ReportData, figs: dict) -> str:
    f = figs.get("residuals")
    if rd.dataset is None:
        return _section("residuals", '<p class="missing">The bench logs could not be read.</p>')
    shown = ""
    if f:
        shown = "; ".join(f"{c}: {fmt.count(a)} of {fmt.count(b)}" for c, (a, b) in f.facts["shown"].items())
    beyond = ""
    if f:
        beyond = "; ".join(f"{c} {100 * v:.1f} %" for c, v in f.facts["beyond2"].items() if np.isfinite(v))
    cap = ("Measured minus model for every channel, divided by the noise σ of the reading's run (the noise table "
           "gives the σ), against signed speed (symmetric log scale), pressure difference, shaft angle and the "
           "time since the run started. Dashed: ± 2 σ, which should hold about 95 % of the points; red crosses: "
           "readings the fit rejected as outliers (beyond 5 σ; drawn at the edge when off the scale). Structure "
           "here (a trend, a step, a ripple) is physics the model lacks. Readings beyond ± 2 σ: "
           f"{beyond}. Readings drawn per channel: {shown}.")
    return _section("residuals", new_figure(f, cap, "No residuals to show."))


def _uncertainty(rd: ReportData, figs: dict) -> str:
    body = ["<h3>Correlation matrix</h3>" + new_figure(
        figs.get("correlation"), "Correlation of the least-squares estimates (from the covariance of the weighted "
                                 "Jacobian). Near ±1: the data hardly tell the two apart.",
        "No correlation matrix (no parameter was fitted).")]
    f = figs.get("corner")
    body.append("<h3>Posterior (corner plot)</h3>" + new_figure(
        f, (f"{fmt.count(f.facts['draws'])} posterior draws after burn-in and thinning; each axis in posterior "
            "standard deviations from the median (the numbers are in the parameter table). Orange: the "
            "least-squares Gaussian. " + (f"First {f.facts['shown']} of {f.facts['total']} parameters."
                                          if f.facts["shown"] < f.facts["total"] else ""))
        if f else "", "No posterior: the fit ran without --bayes (or its chain.npz is missing)."))
    body.append("<h3>Chain diagnostics</h3>" + _chain_diagnostics(rd))
    f = figs.get("traces")
    if f:
        body.append(new_figure(f, f"Traces of {f.facts['walkers']} walkers, in posterior standard deviations from the "
                               "median; grey: burn-in, discarded. A good chain looks like stationary noise.", ""))
    return _section("uncertainty", "\n".join(body))


def chain_verdict(m: dict) -> str:
    """Plain words on whether the emcee chain can be trusted."""
    tau = [v for v in (m.get("tau") or {}).values() if v is not None]
    ess = [v for v in (m.get("ess") or {}).values() if v is not None]
    steps, acc = m.get("steps") or 0, m.get("acceptance")
    if not tau or not ess:
        return "The autocorrelation time could not be estimated: the chain is too short to judge."
    t, e = max(tau), min(ess)
    words = [f"The chain ran {fmt.count(steps)} steps with {m.get('walkers')} walkers: "
             f"{steps / t:.0f} times the longest autocorrelation time τ = {t:.0f} steps (50 are asked for)."]
    problems = []
    if not m.get("converged") or steps < 50 * t:
        problems.append("it is too short for τ to be trusted; run it longer")
    if e < 1000:
        problems.append(f"the fewest effective samples of a parameter is {e:.0f}, below 1,000, so the tails of "
                        "the 95 % intervals are rough")
    if acc is not None and not 0.15 <= acc <= 0.7:
        problems.append(f"the acceptance fraction {acc:.2f} is outside 0.15–0.7, a sign of a poorly scaled "
                        "or multi-modal posterior")
    if problems:
        words.append("But " + "; ".join(problems) + ".")
    else:
        words.append(f"Every parameter has at least {fmt.count(e)} effective samples and the acceptance fraction "
                     f"{acc:.2f} is in the healthy range: the medians and 95 % intervals are reliable.")
    return " ".join(words)


def _chain_diagnostics(rd: ReportData) -> str:
    m = rd.doc.get("mcmc")
    if not m:
        return ('<p class="missing">Not run: the fit had no Bayesian step. Run <code>motorid fit … --bayes</code> '
                "for the posterior, its corner plot and these diagnostics.</p>")
    rows = "".join(
        f'<tr><td><code>{esc(k)}</code></td><td class="num" data-param="{esc(k)}" data-field="tau">'
        f'{fmt.number(v, 3)}</td><td class="num" data-param="{esc(k)}" data-field="ess">'
        f'{fmt.count(m["ess"][k]) if m.get("ess", {}).get(k) is not None else "—"}</td></tr>'
        for k, v in (m.get("tau") or {}).items())
    table = ("<table id=\"chain-table\"><tr><th>parameter</th><th>τ [steps]</th><th>effective samples</th></tr>"
             + rows + "</table>")
    facts = (f"<p>Sampler: {esc(m.get('sampler', 'emcee'))}; {fmt.count(m.get('steps', 0))} steps × "
             f"{m.get('walkers')} walkers; burn-in {m.get('burn')} steps, thinned by {m.get('thin')}; "
             f"acceptance fraction <b>{fmt.number(m.get('acceptance'), 2)}</b>; converged: "
             f"<b>{'yes' if m.get('converged') else 'no'}</b>; {fmt.number(m.get('seconds'), 3)} s.</p>")
    return f'<p class="verdict" id="chain-verdict">{esc(chain_verdict(m))}</p>' + facts + table


EFFICIENCY_NEEDS = ("Kv", "KF", "TFc", "KL0", "KAB")
STARTING_NEEDS = ("KF", "KFS", "TFc", "Ks")


def _unidentified(doc: dict, names) -> list:
    params = doc.get("parameters", {})
    return [k for k in names if k in params and not params[k].get("identifiable")]


def _not_identified(doc: dict, names, what: str) -> str:
    return (f"No {what}: {', '.join(_unidentified(doc, names))} cannot be identified from these logs, and a "
            "figure built on default values would say nothing about this motor.")


def _efficiency(rd: ReportData, figs: dict) -> str:
    body = []
    f = figs.get("efficiency")
    if f:
        ref = f.facts["ref"]
        x, y, hm, v, t = f.facts["point"]
        cap = ("The fitted model over speed and pressure difference, averaged over a shaft revolution, with oil at "
               f"{ref['temperature']:.1f} °C (μ = {fmt.number(ref['viscosity'] * 1e3, 3)} mPa·s, the median of the "
               f"data), back pressure {ref['p_low'] / PA_PER_BAR:.1f} bar and case pressure {ref['p_case'] / PA_PER_BAR:.2f} bar. "
               "η_hm = T/(DΔP/2π); η_v = (Dω/2π)/Q_A; η_t = η_hm·η_v. Dots: the operating points tested; outside "
               f"them the maps extrapolate the model. At {x:.3g} rpm and {y:.0f} bar: η_hm {hm:.4f}, η_v {v:.4f}, "
               f"η_t {t:.4f}.")
    else:
        cap = ""
    missing = (_not_identified(rd.doc, EFFICIENCY_NEEDS, "efficiency maps")
               if _unidentified(rd.doc, EFFICIENCY_NEEDS) else "No running data to anchor the maps.")
    body.append("<h3>Efficiency maps</h3>" + new_figure(f, cap, missing))
    f = figs.get("starting")
    cap = ""
    if f:
        x, mean, worst = f.facts["point"]
        cap = ("Starting torque efficiency (ISO 4392-2): the torque the motor can hold against a load at the "
               "instant it breaks away, over the ideal torque D|ΔP|/2π; the mean over the shaft angle and the "
               f"worst angle, with their 95 % bands; points: the breakaway events. At {x:.0f} bar: mean "
               f"{mean:.4f}, worst {worst:.4f}.")
    missing = (_not_identified(rd.doc, STARTING_NEEDS, "starting torque efficiency")
               if _unidentified(rd.doc, STARTING_NEEDS) else "No data to compute it from.")
    body.append("<h3>Starting torque efficiency</h3>" + new_figure(f, cap, missing))
    return _section("efficiency", "\n".join(body))


# ----------------------------------------------------------------------------- discrepancy


def _any(x) -> str:
    """Render a JSON value readably (the diagnosis document's fields are free-form)."""
    if x is None:
        return "—"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, (int, float)):
        return fmt.number(x)
    if isinstance(x, str):
        return esc(x)
    if isinstance(x, list):
        if not x:
            return "none"
        return "<ul>" + "".join(f"<li>{_any(v)}</li>" for v in x) + "</ul>"
    if isinstance(x, dict):
        return '<dl class="kv">' + "".join(f"<dt>{esc(k)}</dt><dd>{_any(v)}</dd>" for k, v in x.items()) + "</dl>"
    return esc(x)


def _mechanism(m: dict) -> str:
    if not isinstance(m, dict):
        return f"<div>{_any(m)}</div>"
    title = f"{esc(m.get('name', m.get('id', 'mechanism')))}" + (f" (<code>{esc(m['id'])}</code>)" if m.get("id") else "")
    out = [f"<h4>{title}</h4>", "<dl class=\"kv\">"]
    for key, label in (("channels", "channels"), ("where", "where"), ("explanation", "explanation")):
        if key in m:
            out.append(f"<dt>{label}</dt><dd>{_any(m[key])}</dd>")
    out.append("</dl>")
    ps = m.get("parameters")
    if isinstance(ps, dict) and ps:
        rows = []
        for name, p in ps.items():
            p = p if isinstance(p, dict) else {"value": p}
            rows.append(f"<tr><td><code>{esc(name)}</code></td>{_cell(name, 'value', p.get('value'), p.get('unit'))}"
                        f"{_cell(name, 'std', p.get('std'), p.get('unit'), 2)}</tr>")
        out.append("<table><tr><th>parameter</th><th>value</th><th>standard error</th></tr>" + "".join(rows)
                   + "</table>")
    if "evidence" in m:
        out.append(f"<p><b>Evidence:</b></p>{_any(m['evidence'])}")
    rest = {k: v for k, v in m.items() if k not in ("id", "name", "channels", "where", "explanation",
                                                   "parameters", "evidence")}
    if rest:
        out.append(_any(rest))
    return "\n".join(out)


def _diagnose_command(rd: ReportData) -> str:
    inputs = rd.doc.get("inputs") or {}
    logs = " ".join(inputs.get("logs") or []) or "LOG..."
    return f"motorid diagnose {logs} --motor {inputs.get('motor') or 'SPEC.toml'} --out {rd.out_dir}"


def _rms_table(dg: dict) -> str:
    """Residual RMS per channel before and after the mechanisms, against the noise."""
    rows = []
    chans = dg.get("channels")
    if isinstance(chans, dict) and chans:
        items = [(c, v.get("residual_rms_before"), v.get("residual_rms_after"), v.get("noise"), v.get("words"))
                 for c, v in chans.items() if isinstance(v, dict)]
    elif isinstance(dg.get("residual_rms"), dict):
        items = [(c, v.get("before"), v.get("after"), v.get("noise"), None) if isinstance(v, dict)
                 else (c, None, v, None, None) for c, v in dg["residual_rms"].items()]
    else:
        return ""
    for c, before, after, noise, words in items:
        name, unit, factor = fmt.CHANNELS.get(c, (words or c, "", 1.0))
        cells = "".join(f'<td class="num">{fmt.quantity(None if v is None else v * factor, unit, 3)}</td>'
                        for v in (before, after, noise))
        ratio = "—" if after is None or not noise else f"{after / noise:.2f}"
        rows.append(f"<tr><td>{esc(name)} (<code>{esc(c)}</code>)</td>{cells}<td class=\"num\">{ratio}</td></tr>")
    return ("<h3>Residual RMS per channel</h3><table id=\"rms-table\"><tr><th>channel</th><th>before</th>"
            "<th>after</th><th>noise σ</th><th>after / noise</th></tr>" + "".join(rows) + "</table>"
            "<p class=\"caption\">Before: the 1992 model; after: with the mechanisms found. An RMS near the "
            "noise σ (ratio ≈ 1) leaves nothing to explain.</p>")


def _unexplained(x) -> str:
    if isinstance(x, list) and x and all(isinstance(u, dict) for u in x):
        keys = [k for k in ("channel", "where", "p_value", "effect", "effect_sigma") if any(k in u for u in x)]
        keys += [k for k in x[0] if k not in keys]
        return ("<table id=\"unexplained-table\"><tr>" + "".join(f"<th>{esc(k)}</th>" for k in keys) + "</tr>"
                + "".join("<tr>" + "".join(f"<td>{_any(u.get(k))}</td>" for k in keys) + "</tr>" for u in x)
                + "</table>")
    if isinstance(x, list) and not x:
        return "<p>Nothing: every structure found in the residuals is explained.</p>"
    return _any(x)


def _discrepancy(rd: ReportData) -> str:
    dg = rd.diagnosis
    if dg is None:
        return _section("discrepancy", (
            f'<p class="missing" id="discrepancy-status">Not run: there is no diagnosis.json in this folder. '
            f"To look for physics the 1992 model lacks (where the residuals show structure, which named "
            f"mechanism explains it, and what is left unexplained), run <code>{esc(_diagnose_command(rd))}</code>, "
            f"then <code>motorid report {esc(rd.out_dir)}</code>.</p>"))
    body = ['<p id="discrepancy-status">From diagnosis.json (<code>motorid diagnose</code>).</p>']
    mismatch = dg.get("mismatch")
    if isinstance(mismatch, bool):
        body.append("<h3>Mismatch</h3><p>" + (
            "<b>Yes</b>: the residuals show structure beyond the noise that the 1992 model does not explain."
            if mismatch else "<b>No</b>: the residuals of every channel are consistent with the noise.") + "</p>")
    elif mismatch is not None:
        body.append(f"<h3>Mismatch</h3>{_any(mismatch)}")
    mechs = dg.get("mechanisms")
    body.append("<h3>Mechanisms</h3>")
    if mechs:
        body += [_mechanism(m) for m in mechs]
    else:
        body.append("<p>None: no candidate mechanism earned its place.</p>")
    body.append(_rms_table(dg))
    fig = plots.plot_discrepancy_residuals(Path(rd.out_dir) / "diagnosis_residuals.npz")
    if fig is not None:
        body.append('<h3>Residuals before and after</h3><p>Residual over the noise level of each sample, '
                    'grey with the 1992 model alone, blue with the mechanisms found added.</p>' + fig.img)
    from motorid.report.causes import refused_words, unexplained_words  # issue 15

    body.append(f"<h3>Unexplained</h3>{unexplained_words(dg.get('unexplained'))}"
                f"{refused_words(dg.get('refused_stand_ins'))}{_unexplained(dg.get('unexplained'))}")
    rest = {k: v for k, v in dg.items() if k not in ("mismatch", "mechanisms", "residual_rms", "channels",
                                                     "unexplained")}
    if rest:
        body.append(f"<details><summary>Everything else in diagnosis.json</summary>{_any(rest)}</details>")
    return _section("discrepancy", "\n".join(body))


# ----------------------------------------------------------------------------- provenance


def _provenance(rd: ReportData) -> str:
    doc = rd.doc
    motor = doc.get("motor", {})
    fit = doc.get("fit", {})
    inputs = doc.get("inputs") or {}
    items = {
        "bench logs": esc(", ".join(inputs.get("logs") or []) or "—"),
        "motor spec": esc(inputs.get("motor") or "—"),
        "motor": (f"{esc(motor.get('name'))}: {motor.get('pistons')} pistons, D = "
                  f"{fmt.number((motor.get('displacement_m3') or 0) * 1e6)} cm³/rev, J = "
                  f"{fmt.number(motor.get('inertia_kg_m2'))} kg·m², leak phase φ = "
                  f"{fmt.number(math.degrees(motor.get('leak_phase_rad') or 0.0))}°"),
        "least squares": (f"{esc(fit.get('method', ''))}; {fit.get('steps')} steps; converged: "
                          f"{'yes' if fit.get('converged') else 'no'}; χ² = {fmt.number(fit.get('chi2'))} on "
                          f"{fmt.count(fit.get('dof') or 0)} degrees of freedom; "
                          f"{fmt.number(fit.get('seconds'), 3)} s"),
        "mechanisms": esc(", ".join(fit.get("mechanisms") or []) or "none (the 1992 model)"),
        "bands": esc(f"{len(rd.draws)} parameter draws from the {rd.draw_source}" if rd.draws is not None
                     else "none"),
    }
    m = doc.get("mcmc")
    if m:
        items["priors"] = esc(", ".join(f"{k}: {v}" for k, v in (m.get("priors") or {}).items()) or "—")
    items["versions"] = esc(", ".join(f"{k} {v}" for k, v in (doc.get("versions") or {}).items()))
    body = '<dl class="kv">' + "".join(f"<dt>{esc(k)}</dt><dd>{v}</dd>" for k, v in items.items()) + "</dl>"
    return _section("provenance", body)
