"""fleet_report.html: one self-contained page of a fleet (the single-motor report's style and PNG helper).

Sections: the fleet table (each motor at its latest test date), each
parameter's spread across motors against the population's central 95 % band,
the motors judged out of family, the trends over test dates, failures.
"""

from __future__ import annotations

import datetime as _dt
import math
from pathlib import Path

import numpy as np

from motorid._atomic import write_bytes_atomic
from motorid.fleet import store
from motorid.fleet.summary import analyse, latest_table
from motorid.report import format as fmt
from motorid.report.html import CSS, esc
from motorid.report.plots import new_figure, embed_png

REPORT_FILE = "fleet_report.html"
FLAG, CLEAN, BAND = "#b3261e", "#2f6fdf", "#2f6fdf"


def _spread_plot(motor_type: str, pop, verdicts: list) -> str:
    """One parameter across motors: estimate ± 2 SE, the population's centre and 95 % band."""
    vs = sorted(verdicts, key=lambda v: v.value)
    x = np.arange(len(vs))
    fig, ax = new_figure(figsize=(max(4.0, 0.32 * len(vs) + 2), 2.6))
    lo, mid, hi = pop.band()
    ax.axhspan(lo, hi, color=BAND, alpha=0.12, label="population, central 95 %")
    ax.axhline(mid, color=BAND, lw=1, label="population median" if pop.scale == "log" else "population mean")
    for i, v in enumerate(vs):
        c = FLAG if v.out_of_family else CLEAN
        ax.errorbar(i, v.value, yerr=2 * v.std, fmt="o", ms=4, color=c, capsize=2)
    ax.set_xticks(x, [v.serial for v in vs], rotation=60, ha="right", fontsize=7)
    if pop.scale == "log":
        ax.set_yscale("log")
    ax.set_ylabel(pop.parameter + " [SI]")
    ax.set_title(f"{motor_type}: {pop.parameter} per motor (latest test, ±2 SE; red: out of family)", fontsize=8.5)
    ax.legend(loc="best")
    return embed_png(fig, f"{pop.parameter} across motors")


def _trend_plot(serial: str, trends: list) -> str:
    n = len(trends)
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig, axes = new_figure(rows, cols, figsize=(3.3 * cols, 2.3 * rows), squeeze=False)
    for ax, tr in zip(axes.flat, trends):
        d = np.array([np.datetime64(x) for x in tr.dates])
        c = {"rising": FLAG, "falling": "#e39b00"}.get(tr.verdict, CLEAN)
        ax.errorbar(d, tr.values, yerr=2 * np.asarray(tr.stds), fmt="o-", ms=4, color=c, capsize=2)
        ax.set_title(f"{tr.parameter}: {tr.verdict}", fontsize=8.5)
        ax.tick_params(axis="x", labelrotation=30, labelsize=7)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    fig.suptitle(f"{serial}: estimates over test dates (±2 SE)", fontsize=9)
    return embed_png(fig, f"trends of {serial}")


def _fleet_table(rows, an) -> str:
    table = latest_table(rows, an)
    params = sorted({p for s in table.values() for p in s})
    flagged = {(v.serial, v.parameter) for vs in an["verdicts"].values() for v in vs if v.out_of_family}
    head = "".join(f"<th>{esc(p)}</th>" for p in params)
    body = []
    for serial in sorted(table):
        cells = []
        for p in params:
            val = table[serial].get(p)
            if val is None:
                cells.append("<td></td>")
            elif not val[2]:
                cells.append('<td class="no">not identifiable</td>')
            else:
                style = ' style="color:#b3261e;font-weight:600"' if (serial, p) in flagged else ""
                cells.append(f'<td class="num"{style} data-value="{fmt.attr(val[0])}">'
                             f'{fmt.number(val[0])} ± {fmt.number(val[1], 2)}</td>')
        dates = ", ".join(an["dates"].get(serial, []))
        body.append(f"<tr><td>{esc(serial)}</td><td>{esc(an['types'].get(serial, ''))}</td>"
                    f"<td>{esc(dates)}</td>{''.join(cells)}</tr>")
    return (f'<div class="wide"><table id="fleet-table"><tr><th>serial</th><th>motor type</th><th>test dates</th>'
            f'{head}</tr>{"".join(body)}</table></div>')


def _population_table(motor_type, pops) -> str:
    out = ["<table><tr><th>parameter</th><th>scale</th><th>motors</th><th>mean (SI)</th><th>95 % interval</th>"
           "<th>sd (SI)</th><th>95 % interval</th><th>left out (out of family)</th></tr>"]
    for p, pop in sorted(pops.items()):
        out.append(f"<tr><td>{esc(p)}</td><td>{pop.scale}</td><td class='num'>{pop.n}</td>"
                   f"<td class='num'>{fmt.number(pop.mean)}</td><td>{fmt.interval(pop.mean_ci95)}</td>"
                   f"<td class='num'>{fmt.number(pop.sd)}</td><td>{fmt.interval(pop.sd_ci95)}</td>"
                   f"<td>{esc(', '.join(pop.excluded)) or '—'}</td></tr>")
    out.append("</table>")
    return "".join(out)


def render(fleet_dir) -> str:
    d = Path(fleet_dir)
    failed = store.failures(d)
    rows = store.all_rows(d) if any((d / store.STORE).glob("*.parquet")) else None
    an = analyse(rows)
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>Fleet report: {esc(d.name)}</title>"
             f"<style>{CSS}</style></head><body>",
             f"<h1>Fleet report: {esc(d.name)}</h1>",
             f"<p class='meta'>{len(an['types'])} motors, "
             f"{0 if rows is None else rows['campaign'].nunique()} campaigns, {len(failed)} failed; "
             f"made {_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d %H:%M} UTC from {esc(d)}. "
             "Model and verdict rules: docs/fleet.md.</p>"]
    flags = [(s, v) for s, vs in an["verdicts"].items() for v in vs if v.out_of_family]
    moving = [tr for trs in an["trends"].values() for tr in trs if tr.verdict != "stable"]
    verdict = (f"Out of family: {', '.join(sorted({s for s, _ in flags}))}. " if flags else
               "No motor out of family. ")
    verdict += (f"Wearing or drifting: {', '.join(sorted({f'{t.serial} ({t.parameter} {t.verdict})' for t in moving}))}."
                if moving else "No parameter moved beyond its uncertainty between test dates.")
    parts.append(f"<p class='verdict{' warn' if flags or moving else ''}'>{esc(verdict)}</p>")
    if rows is not None:
        parts.append("<h2 id='fleet'>Fleet table (latest test of each motor)</h2>")
        parts.append(_fleet_table(rows, an))
    for motor_type, pops in an["populations"].items():
        parts.append(f"<h2 id='population-{esc(motor_type)}'>Population of {esc(motor_type)}</h2>")
        parts.append(_population_table(motor_type, pops))
        for p, pop in sorted(pops.items()):
            vs = [v for s, vv in an["verdicts"].items() for v in vv if v.parameter == p and an["types"][s] == motor_type]
            parts.append(f"<figure>{_spread_plot(motor_type, pop, vs)}<figcaption>{esc(p)}: each motor's estimate at "
                         f"its latest test (±2 SE) against the population's central 95 % band "
                         f"({pop.scale} scale, {pop.n} motors).</figcaption></figure>")
    parts.append("<h2 id='out-of-family'>Out of family</h2>")
    if flags:
        parts.append("<table><tr><th>serial</th><th>parameter</th><th>estimate</th><th>deviate z</th>"
                     "<th>probability</th><th>flag below p</th></tr>" + "".join(
                         f"<tr><td>{esc(s)}</td><td>{esc(v.parameter)}</td><td class='num'>{fmt.number(v.value)}</td>"
                         f"<td class='num'>{v.z:.2f}</td><td class='num'>{v.probability:.6f}</td>"
                         f"<td class='num'>{v.threshold:.2g}</td></tr>" for s, v in sorted(flags, key=lambda x: x[0]))
                     + "</table>")
    else:
        parts.append("<p>None: every motor's estimates are what the population of the others predicts.</p>")
    parts.append("<h2 id='trends'>Trends over test dates</h2>")
    any_trend = False
    for serial, trs in sorted(an["trends"].items()):
        if not trs:
            continue
        any_trend = True
        rows_html = "".join(f"<tr><td>{esc(t.parameter)}</td><td class='num'>{fmt.number(t.per_year)}</td>"
                            f"<td>{fmt.interval(t.ci95)}</td><td>{t.verdict}</td></tr>" for t in trs)
        parts.append(f"<h3>{esc(serial)}</h3><table><tr><th>parameter</th><th>change per year (SI/a)</th>"
                     f"<th>95 % interval</th><th>verdict</th></tr>{rows_html}</table>")
        shown = [t for t in trs if t.verdict != "stable" or t.parameter == "KL0"]
        if shown:
            parts.append(f"<figure>{_trend_plot(serial, shown)}<figcaption>Parameters that moved, and K_L0 "
                         f"(leakage: the classical sign of wear).</figcaption></figure>")
    if not any_trend:
        parts.append("<p>No motor was tested on two dates.</p>")
    if failed:
        parts.append("<h2 id='failed'>Failed campaigns</h2><ul class='warnings'>" + "".join(
            f"<li><code>{esc(f['campaign'])}</code>: {esc(f['error'])}</li>" for f in failed) + "</ul>")
    parts.append("</body></html>")
    return "\n".join(parts)


def write_fleet_report(fleet_dir) -> Path:
    """Write FLEET_DIR/fleet_report.html (whole or not at all)."""
    d = store.check_fleet_dir(fleet_dir)
    path = d / REPORT_FILE
    write_bytes_atomic(path, render(d).encode("utf-8"))
    return path
