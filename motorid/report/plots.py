"""The report's figures (matplotlib, Agg), each returned as an embedded image.

Every ``plot_*`` function returns a :class:`Plot`: ``img`` is an ``<img>`` tag
whose source is a base64 PNG ``data:`` URI (the report opens offline), ``facts``
holds numbers for the caption.  PNGs are drawn at a modest resolution and
reduced to a 256-colour palette so that a whole report stays well under 2 MB.
Units on the axes are the bench's: rpm, bar, N·m, L/min, degrees.
"""

from __future__ import annotations

import base64
import html
import io
import math
from typing import NamedTuple

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from motorid.report.evaluate import (  # noqa: E402
    Ensemble, ReportData, cluster, concat_samples, grid_samples, pressure_levels, reference_conditions, revolution,
    running_runs,
)
from motorid.units import CHANNELS, LPM_PER_M3S, PA_PER_BAR, RPM_PER_RAD_S  # noqa: E402

DPI = 88
MAX_POINTS = 4000  # residual points drawn per channel (outliers always drawn)
MODEL_COLOR = "#222222"
STYLE = {
    "font.size": 9, "axes.titlesize": 9.5, "axes.labelsize": 9, "legend.fontsize": 7.5,
    "xtick.labelsize": 8, "ytick.labelsize": 8, "axes.grid": True, "grid.alpha": 0.3,
    "axes.spines.top": False, "axes.spines.right": False, "figure.dpi": DPI,
}


class Plot(NamedTuple):
    img: str  # <img src="data:image/png;base64,...">
    facts: dict


def embed_png(fig, alt: str) -> str:
    """A figure as an ``<img>`` tag with a base64 PNG data URI (palette-reduced)."""
    from PIL import Image

    from matplotlib.layout_engine import ConstrainedLayoutEngine

    buf = io.BytesIO()
    # a constrained layout already fits every label and legend in the figure: "tight" would draw it twice
    tight = None if isinstance(fig.get_layout_engine(), ConstrainedLayoutEngine) else "tight"
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches=tight, facecolor="white")
    plt.close(fig)
    buf.seek(0)
    img = Image.open(buf).convert("RGB").quantize(colors=256)
    out = io.BytesIO()
    img.save(out, format="PNG", optimize=True)
    data = base64.b64encode(out.getvalue()).decode("ascii")
    return (f'<img src="data:image/png;base64,{data}" alt="{html.escape(alt)}" '
            f'width="{img.width}" height="{img.height}">')


def new_figure(*args, **kwargs):
    kwargs.setdefault("layout", "constrained")
    with plt.rc_context(STYLE):
        return plt.subplots(*args, **kwargs)


def _colors(n: int):
    cmap = plt.get_cmap("tab10")
    return [cmap(i % 10) for i in range(n)]


def _band(ax, x, lo, hi, color, alpha=0.25, label=None):
    ax.fill_between(x, np.minimum(lo, hi), np.maximum(lo, hi), color=color, alpha=alpha, lw=0, label=label)


def _predictive(center, lo, hi, sigma):
    """95 % band of one reading: the model band widened by the channel's noise."""
    half = np.sqrt((0.5 * np.abs(hi - lo)) ** 2 + (1.96 * (sigma or 0.0)) ** 2)
    mid = 0.5 * (hi + lo)
    return mid - half, mid + half


# ----------------------------------------------------------------------------- model against data


def _level_curves(rd: ReportData, ens: Ensemble, levels, n_grid: int = 40):
    """θ-averaged model curves over speed at each level and direction, and at each run's speed."""
    theta = revolution(rd.spec, 12)
    k = theta.size
    blocks, pieces = [], []
    for li, lev in enumerate(levels):
        for d in sorted({r.direction for r in lev.runs}, reverse=True):
            rs = [r for r in lev.runs if r.direction == d]
            w_runs = np.array([abs(r.speed) for r in rs])
            w = np.geomspace(max(w_runs.min(), 1e-4) * 0.8, w_runs.max() * 1.25, n_grid)
            speeds = np.concatenate([w, w_runs])
            p_a = 0.5 * (lev.psum + d * lev.dp)
            p_b = 0.5 * (lev.psum - d * lev.dp)
            pieces.append(grid_samples(rd.spec, theta[None, :], d * speeds[:, None], p_a, p_b, lev.p_case,
                                       lev.viscosity, d, lev.temperature))
            blocks.append((li, d, rs, w, speeds.size))
    samples = concat_samples(pieces)
    center, lo, hi = ens.running(samples, average=k)
    out, start = [], 0
    for li, d, rs, w, m in blocks:
        sl = slice(start, start + m)
        out.append((li, d, rs, w, center[:, sl], lo[:, sl], hi[:, sl]))
        start += m
    return out


def plot_torque_speed(rd: ReportData, ens: Ensemble) -> Plot | None:
    """Running torque, and the torque loss D|ΔP|/2π − |T|, against speed at each pressure level."""
    levels = pressure_levels(running_runs(rd))
    if not levels:
        return None
    curves, colors, D = _level_curves(rd, ens, levels), _colors(len(levels)), rd.spec.displacement
    fig, axes = new_figure(1, 2, figsize=(12, 4.6))
    band_max, corr_max = 0.0, 0.0
    for li, d, rs, w, c, lo, hi in curves:
        lev, col = levels[li], colors[li]
        g = w.size
        t_c, t_lo, t_hi = d * c[0], d * lo[0], d * hi[0]
        ideal = D * lev.dp / (2 * np.pi)
        x = w * RPM_PER_RAD_S
        ls = "-" if d > 0 else "--"
        label = lev.label if d > 0 or all(r.direction < 0 for r in lev.runs) else None
        axes[0].plot(x, t_c[:g], ls, color=col, lw=1.2, label=label)
        _band(axes[0], x, t_lo[:g], t_hi[:g], col)
        axes[1].plot(x, ideal - t_c[:g], ls, color=col, lw=1.2)
        _band(axes[1], x, ideal - t_lo[:g], ideal - t_hi[:g], col)
        band_max = max(band_max, float(np.max(np.abs(t_hi - t_lo))) / 2)
        y = t_c[g:] + d * np.array([r.mean_resid["torque"] for r in rs])
        xr = np.array([abs(r.speed) for r in rs]) * RPM_PER_RAD_S
        mk = dict(marker="o" if d > 0 else "s", ms=4.5, ls="none", mec=col,
                  mfc=col if d > 0 else "white", mew=1.0)
        axes[0].plot(xr, y, **mk)
        axes[1].plot(xr, ideal - y, **mk)
        for r, model_here in zip(rs, t_c[g:]):
            own = d * float(np.mean(rd.pred["torque"][r.samples]))
            corr_max = max(corr_max, abs(model_here - own))
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel("shaft speed |n| [rpm]")
    axes[0].set_ylabel("shaft torque T·sgn(n) [N·m]")
    axes[0].set_title("running torque against speed")
    axes[1].set_ylabel("torque loss D|ΔP|/2π − |T| [N·m]")
    axes[1].set_title("torque loss (friction and viscous drag)")
    handles = axes[0].get_legend_handles_labels()
    from matplotlib.lines import Line2D

    extra = [Line2D([], [], marker="o", ls="none", color="grey", label="data, positive direction"),
             Line2D([], [], marker="s", ls="none", mfc="white", color="grey", label="data, negative direction"),
             Line2D([], [], color="grey", label="model (—  +, - - −)")]
    axes[1].legend(handles[0] + extra, handles[1] + [h.get_label() for h in extra],
                   loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    return Plot(embed_png(fig, "running torque and torque loss against speed"),
                {"levels": len(levels), "band": band_max, "correction": corr_max})


def plot_flows_speed(rd: ReportData, ens: Ensemble) -> Plot | None:
    """Inlet flow, inlet loss, outlet deficit and case-drain flow against speed at each level."""
    levels = pressure_levels(running_runs(rd))
    if not levels:
        return None
    curves, colors, D = _level_curves(rd, ens, levels), _colors(len(levels)), rd.spec.displacement
    fig, axes = new_figure(2, 2, figsize=(13, 7.6))
    ax_in, ax_loss, ax_out, ax_case = axes.ravel()
    band_max = 0.0
    for li, d, rs, w, c, lo, hi in curves:
        lev, col = levels[li], colors[li]
        g = w.size
        i_in, i_out = (1, 2) if d > 0 else (2, 1)
        ch_in, ch_out = ("q_a", "q_b") if d > 0 else ("q_b", "q_a")
        swept = D * np.concatenate([w, [abs(r.speed) for r in rs]]) / (2 * np.pi)
        series = {
            ax_in: (c[i_in], lo[i_in], hi[i_in], ch_in, 1.0),
            ax_loss: (c[i_in] - swept, lo[i_in] - swept, hi[i_in] - swept, ch_in, 1.0),
            ax_out: (swept + c[i_out], swept + lo[i_out], swept + hi[i_out], ch_out, 1.0),
            ax_case: (c[3], lo[3], hi[3], "q_case", 1.0),
        }
        x = w * RPM_PER_RAD_S
        xr = np.array([abs(r.speed) for r in rs]) * RPM_PER_RAD_S
        ls = "-" if d > 0 else "--"
        label = lev.label if d > 0 or all(r.direction < 0 for r in lev.runs) else None
        for ax, (cc, ll, hh, ch, _) in series.items():
            ax.plot(x, cc[:g] * LPM_PER_M3S, ls, color=col, lw=1.2, label=label if ax is ax_in else None)
            _band(ax, x, ll[:g] * LPM_PER_M3S, hh[:g] * LPM_PER_M3S, col)
            y = cc[g:] + np.array([r.mean_resid[ch] for r in rs])
            ax.plot(xr, y * LPM_PER_M3S, marker="o" if d > 0 else "s", ms=4.5, ls="none", mec=col,
                    mfc=col if d > 0 else "white")
            band_max = max(band_max, float(np.max(np.abs(hh - ll))) / 2 * LPM_PER_M3S)
    ax_in.set_yscale("log")
    titles = {ax_in: ("flow into the inlet port", "inlet flow [L/min]"),
              ax_loss: ("inlet flow beyond the swept flow D|n|", "Q_in − D|ω|/2π [L/min]"),
              ax_out: ("outlet flow short of the swept flow", "D|ω|/2π − |Q_out| [L/min]"),
              ax_case: ("case-drain flow", "case-drain flow [L/min]")}
    for ax, (title, ylabel) in titles.items():
        ax.set_xscale("log")
        ax.set_title(title)
        ax.set_ylabel(ylabel)
        ax.set_xlabel("shaft speed |n| [rpm]")
    fig.legend(*ax_in.get_legend_handles_labels(), loc="outside right upper", frameon=False)
    return Plot(embed_png(fig, "port and case-drain flows against speed"), {"band": band_max})


def _ripple_runs(rd: ReportData, max_levels: int = 4):
    """At each pressure level (and oil temperature), the slowest run that covers a whole piston pitch and resolves the
    ripple (the shaft turns less than 1/24 pitch between readings); positive direction first."""
    pitch = 2 * np.pi / rd.spec.pistons
    time = np.asarray(rd.dataset.running.time, dtype=float)

    def step(r):
        dt = np.diff(time[r.samples])
        dt = dt[dt > 0]
        return abs(r.speed) * (float(np.median(dt)) if dt.size else np.inf)

    covering = [r for r in running_runs(rd) if r.theta_span >= 0.9]
    runs = [r for r in covering if step(r) <= pitch / 24] or covering
    if not runs:
        return []
    chosen = [min(lev.runs, key=lambda r: (r.direction < 0, abs(r.speed))) for lev in pressure_levels(runs)]
    if len(chosen) > max_levels:
        pick = np.unique(np.round(np.linspace(0, len(chosen) - 1, max_levels)).astype(int))
        chosen = [chosen[i] for i in pick]
    return chosen


def plot_ripple(rd: ReportData, ens: Ensemble) -> Plot | None:
    """Torque ripple and case-drain flow against shaft angle in slow runs, with the model."""
    chosen = _ripple_runs(rd)
    if not chosen:
        return None
    theta = np.linspace(0.0, 2 * np.pi, 721)
    s = rd.dataset.running
    cols = {k: np.asarray(getattr(s, k), dtype=float) for k in ("theta", "p_a", "p_b", "p_case", "viscosity",
                                                                "temperature", "speed")}
    pieces = []
    for r in chosen:
        med = {k: float(np.median(v[r.samples])) for k, v in cols.items()}
        # the curve, then the model at each reading's shaft angle under the same median conditions
        for th in (theta, cols["theta"][r.samples]):
            pieces.append(grid_samples(rd.spec, th, med["speed"], med["p_a"], med["p_b"], med["p_case"],
                                       med["viscosity"], r.direction, med["temperature"]))
    center, lo, hi = ens.running(concat_samples(pieces))
    fig, axes = new_figure(len(chosen), 2, figsize=(12, 2.7 * len(chosen) + 0.4), squeeze=False)
    deg = np.degrees(theta)
    sig_t, sig_c = rd.sigma("torque"), rd.sigma("q_case")
    start = 0
    for i, r in enumerate(chosen):
        sl = slice(start, start + theta.size)
        at = slice(start + theta.size, start + theta.size + r.samples.size)
        start += theta.size + r.samples.size
        th = np.degrees(np.mod(cols["theta"][r.samples], 2 * np.pi))
        for j, (ch, row, factor, sig, unit) in enumerate((("torque", 0, 1.0, sig_t, "N·m"),
                                                          ("q_case", 3, LPM_PER_M3S, sig_c, "L/min"))):
            ax = axes[i, j]
            meas = (center[row, at] + rd.resid[ch][r.samples]) * factor
            ax.plot(th, meas, ".", ms=2.0, color="#1f77b4", alpha=0.5, label="data", rasterized=True)
            c, l, h = center[row, sl] * factor, lo[row, sl] * factor, hi[row, sl] * factor
            pl, ph = _predictive(c, l, h, (sig or 0.0) * factor)
            _band(ax, deg, pl, ph, "#ff7f0e", 0.18, "95 % band of one reading")
            _band(ax, deg, l, h, "#d62728", 0.5, "95 % band of the model")
            ax.plot(deg, c, color=MODEL_COLOR, lw=1.0, label="model", zorder=3)
            ax.set_xlim(0, 360)
            ax.set_xticks(np.arange(0, 361, 45))
            name = "shaft torque" if ch == "torque" else "case-drain flow"
            ax.set_ylabel(f"{name} [{unit}]")
            ax.set_title(f"{name} at {abs(r.speed) * RPM_PER_RAD_S:.3g} rpm, ΔP {r.dp / PA_PER_BAR:.0f} bar")
            if i == len(chosen) - 1:
                ax.set_xlabel("shaft angle θ [deg]")
    axes[0, 1].legend(loc="upper right", frameon=True, framealpha=0.8)
    return Plot(embed_png(fig, "torque ripple and case-drain flow against shaft angle"),
                {"runs": [_run_name(rd, r) for r in chosen]})


def _run_name(rd: ReportData, r) -> str:
    runs = getattr(rd.dataset, "runs", None)
    try:
        return str(runs.iloc[r.index]["run"])
    except (AttributeError, KeyError, IndexError, TypeError):
        return str(r.index)


def _event_cols(rd: ReportData) -> dict:
    ev = rd.dataset.events
    cols = {k: np.asarray(getattr(ev, k), dtype=float) for k in
            ("theta", "p_a", "p_b", "p_case", "viscosity", "direction", "temperature", "time")}
    d = np.where(cols["direction"] >= 0, 1.0, -1.0)
    cols["d"] = d
    cols["dp"] = np.abs(cols["p_a"] - cols["p_b"])
    cols["p_out"] = np.where(d > 0, cols["p_b"], cols["p_a"])
    cols["held"] = np.asarray(rd.dataset.held_torque, dtype=float)
    return cols


def plot_breakaway(rd: ReportData, ens: Ensemble) -> Plot | None:
    """Breakaway torque against ΔP, the static friction against P_A + P_B, and the starting
    torque efficiency against shaft angle."""
    if not rd.has_events:
        return None
    from motorid.physics.torque import pressure_torque

    e = _event_cols(rd)
    D, n = rd.spec.displacement, rd.spec.pistons
    pitch = 2 * np.pi / n
    ok = np.isfinite(e["held"])
    ideal = D * e["dp"] / (2 * np.pi)
    c_ev, lo_ev, hi_ev = ens.breakaway(rd.dataset.events)
    fig, (ax, ax1, ax2) = new_figure(1, 3, figsize=(13.5, 4.4))
    pos, neg = ok & (e["d"] > 0), ok & (e["d"] < 0)
    # (a) held torque against ΔP; grey: the model over all shaft angles
    dps = np.linspace(0.8 * e["dp"][ok].min(), 1.1 * e["dp"][ok].max(), 60)
    th = (np.arange(48) + 0.5) * pitch / 48
    p_out, p_case = float(np.median(e["p_out"])), float(np.median(e["p_case"]))
    mu, temp = float(np.median(e["viscosity"])), float(np.median(e["temperature"]))
    env = grid_samples(rd.spec, th[None, :], 0.0, p_out + dps[:, None], p_out, p_case, mu, 1.0, temp)
    c_env, _, _ = ens.breakaway(env, band=False)
    c_env = c_env.reshape(dps.size, th.size)
    ax.fill_between(dps / PA_PER_BAR, c_env.min(1), c_env.max(1), color="#999999", alpha=0.35, lw=0,
                    label="model over all shaft angles")
    for sel, mk, name in ((pos, "o", "data, positive direction"), (neg, "s", "data, negative direction")):
        if sel.any():
            ax.plot(e["dp"][sel] / PA_PER_BAR, (e["d"] * e["held"])[sel], mk, ms=4.5, color="#1f77b4",
                    mfc="#1f77b4" if mk == "o" else "white", label=name)
    ax.plot(e["dp"][ok] / PA_PER_BAR, (e["d"] * c_ev)[ok], "x", color=MODEL_COLOR, ms=4, label="model at each event")
    ax.set_xlabel("pressure difference |ΔP| at breakaway [bar]")
    ax.set_ylabel("held torque at breakaway T·sgn(n) [N·m]")
    ax.set_title("breakaway torque against pressure")
    ax.legend(loc="upper left", frameon=False)
    # (b) static friction at breakaway: the pressure torque (parameter-free) less the held torque
    ev = rd.dataset.events
    t_p = np.asarray(pressure_torque(ev.theta, ev.p_a, ev.p_b, D, n, port_sum=ev.port_sum))
    psum = e["p_a"] + e["p_b"]
    grid = np.linspace(0.0, 1.1 * psum[ok].max(), 50)
    line = grid_samples(rd.spec, float(np.median(e["theta"])), 0.0, grid / 2, grid / 2, p_case, mu, 1.0, temp)
    c_l, lo_l, hi_l = ens.breakaway(line)
    ax1.plot(grid / PA_PER_BAR, -c_l, color=MODEL_COLOR, lw=1.1, label="model: T_break(P_A + P_B)")
    _band(ax1, grid / PA_PER_BAR, -lo_l, -hi_l, "#d62728", 0.45, "95 % band of the model")
    fl, fh = _predictive(-c_l, -lo_l, -hi_l, rd.sigma("breakaway") or 0.0)
    _band(ax1, grid / PA_PER_BAR, fl, fh, "#ff7f0e", 0.18, "95 % band of one reading")
    for sel, mk in ((pos, "o"), (neg, "s")):
        if sel.any():
            ax1.plot(psum[sel] / PA_PER_BAR, (e["d"] * (t_p - e["held"]))[sel], mk, ms=4.5, color="#1f77b4",
                     mfc="#1f77b4" if mk == "o" else "white")
    ax1.set_xlim(0, grid[-1] / PA_PER_BAR)
    ax1.set_xlabel("port pressure sum P_A + P_B at breakaway [bar]")
    ax1.set_ylabel("static friction torque [N·m]")
    ax1.set_title("static friction at breakaway: T_p(θ, ΔP) − T_held")
    ax1.legend(loc="upper left", frameon=False)
    # starting torque efficiency against shaft angle, per pressure level
    labels = cluster(e["dp"], lambda v: 0.1 * v)
    colors = _colors(int(labels.max()) + 1)
    theta = np.linspace(0.0, pitch, 97)
    pieces, levels = [], []
    for lab in np.unique(labels):
        sel = (labels == lab) & ok
        if not sel.any():
            continue
        for d in sorted(set(e["d"][sel]), reverse=True):
            s2 = sel & (e["d"] == d)
            dp = float(np.median(e["dp"][s2]))
            po = float(np.median(e["p_out"][s2]))
            p_a, p_b = (po + dp, po) if d > 0 else (po, po + dp)
            pieces.append(grid_samples(rd.spec, theta, 0.0, p_a, p_b, float(np.median(e["p_case"][s2])),
                                       float(np.median(e["viscosity"][s2])), d,
                                       float(np.median(e["temperature"][s2]))))
            levels.append((lab, d, dp, s2))
    samples = concat_samples(pieces)
    c, lo, hi = ens.breakaway(samples)
    sig = rd.sigma("breakaway") or 0.0
    deg = np.degrees(theta)
    for i, (lab, d, dp, s2) in enumerate(levels):
        sl = slice(i * theta.size, (i + 1) * theta.size)
        scale = D * dp / (2 * np.pi)
        col = colors[lab]
        cc, ll, hh = d * c[sl] / scale, d * lo[sl] / scale, d * hi[sl] / scale
        pl, ph = _predictive(cc, ll, hh, sig / scale)
        _band(ax2, deg, pl, ph, col, 0.15)
        _band(ax2, deg, ll, hh, col, 0.45)
        ax2.plot(deg, cc, "-" if d > 0 else "--", color=col, lw=1.1,
                 label=f"ΔP ≈ {dp / PA_PER_BAR:.0f} bar" + ("" if d > 0 else ", negative direction"))
        ax2.plot(np.degrees(np.mod(e["theta"][s2], pitch)), (e["d"] * e["held"])[s2] / ideal[s2],
                 "o" if d > 0 else "s", color=col, mfc=col if d > 0 else "white", ms=4.5, ls="none")
    ax2.set_xlim(0, np.degrees(pitch))
    ax2.set_xlabel("shaft angle θ within a piston pitch [deg]")
    ax2.set_ylabel("starting torque efficiency T_held / (D|ΔP|/2π)")
    ax2.set_title("starting torque efficiency against shaft angle")
    ax2.legend(loc="lower right", frameon=True, framealpha=0.8, fontsize=7)
    return Plot(embed_png(fig, "breakaway torque against pressure and shaft angle"),
                {"events": int(ok.sum()), "band": float(np.max(np.abs(hi_ev - lo_ev))) / 2})


# ----------------------------------------------------------------------------- residuals


def plot_residuals(rd: ReportData) -> Plot | None:
    """Normalized residuals (measured − model)/σ of every channel against speed, ΔP, shaft angle and time."""
    chans = [c for c in CHANNELS if c in rd.resid
             and np.isfinite(rd.resid[c]).any()]
    if not chans:
        return None
    rng = np.random.default_rng(1)
    fig, axes = new_figure(len(chans), 4, figsize=(12.5, 1.95 * len(chans) + 0.5), squeeze=False)
    shown, beyond = {}, {}
    for i, ch in enumerate(chans):
        with np.errstate(invalid="ignore", divide="ignore"):
            r = rd.resid[ch] / rd.sample_sigma[ch]
        if ch == "breakaway":
            e = _event_cols(rd)
            xs = [None, (e["p_a"] - e["p_b"]) / PA_PER_BAR, np.degrees(np.mod(e["theta"], 2 * np.pi)), e["time"]]
        else:
            s = rd.dataset.running
            xs = [np.asarray(s.speed) * RPM_PER_RAD_S, np.asarray(s.p_a - s.p_b) / PA_PER_BAR,
                  np.degrees(np.mod(np.asarray(s.theta), 2 * np.pi)), np.asarray(s.time)]
        finite = np.flatnonzero(np.isfinite(r))
        flag = rd.flagged.get(ch, np.zeros(r.shape, bool))
        keep = finite[~flag[finite]]
        beyond[ch] = float(np.mean(np.abs(r[keep]) > 2.0)) if keep.size else float("nan")
        if keep.size > MAX_POINTS:
            keep = np.sort(rng.choice(keep, MAX_POINTS, replace=False))
        out = np.flatnonzero(flag)
        shown[ch] = (int(keep.size + out.size), int(finite.size))
        lim = max(4.0, min(float(np.max(np.abs(r[keep]))) * 1.1 if keep.size else 4.0, 8.0))
        for j, x in enumerate(xs):
            ax = axes[i, j]
            if x is None:
                ax.text(0.5, 0.5, "at rest (speed 0)", ha="center", va="center", transform=ax.transAxes,
                        color="grey")
                ax.set_yticks([])
                ax.set_xticks([])
                ax.grid(False)
                continue
            x = np.asarray(x, dtype=float)
            ax.plot(x[keep], r[keep], ".", ms=1.6, color="#1f77b4", alpha=0.45, rasterized=True)
            if out.size:
                ax.plot(x[out], np.clip(r[out], -lim, lim), "x", ms=4, color="#d62728")
            for sgn in (-2, 2):
                ax.axhline(sgn, color="#ff7f0e", lw=0.8, ls="--")
            ax.axhline(0.0, color=MODEL_COLOR, lw=0.6)
            ax.set_ylim(-lim, lim)
            if j == 0:
                ax.set_xscale("symlog", linthresh=1.0)
                ax.set_xticks([-1000, -10, 0, 10, 1000], ["−1000", "−10", "0", "10", "1000"])
                ax.set_ylabel(f"{ch}\nresidual / σ")
            if i == len(chans) - 1 or (ch == "breakaway"):
                ax.set_xlabel(["speed n [rpm]", "ΔP = P_A − P_B [bar]", "shaft angle θ [deg]",
                               "time in run [s]"][j])
            if j == 2:
                ax.set_xlim(0, 360)
                ax.set_xticks(np.arange(0, 361, 90))
    return Plot(embed_png(fig, "residuals against speed, pressure, shaft angle and time"),
                {"shown": shown, "beyond2": beyond})


def plot_discrepancy_residuals(path) -> Plot | None:
    """Residuals over σ before and after the discrepancy search, against speed and shaft angle."""
    try:
        data = np.load(path)
    except (OSError, ValueError):
        return None
    chans = [c for c in CHANNELS if f"{c}__before" in data.files
             and data[f"{c}__before"].size]
    if not chans:
        return None
    rng = np.random.default_rng(2)
    fig, axes = new_figure(len(chans), 2, figsize=(10.5, 1.9 * len(chans) + 0.5), squeeze=False)
    for i, ch in enumerate(chans):
        before, after = data[f"{ch}__before"], data[f"{ch}__after"]
        keep = np.arange(before.size)
        if keep.size > MAX_POINTS:
            keep = np.sort(rng.choice(keep, MAX_POINTS, replace=False))
        lim = max(4.0, min(float(np.max(np.abs(before[keep]))) * 1.1, 30.0))
        first = ((data[f"{ch}__speed"] / PA_PER_BAR, "P_A + P_B at breakaway [bar]") if ch == "breakaway"
                 else (data[f"{ch}__speed"] * RPM_PER_RAD_S, "speed n [rpm]"))
        for j, (x, label) in enumerate((first, (np.degrees(data[f"{ch}__theta"]), "shaft angle θ [deg]"))):
            ax = axes[i, j]
            ax.plot(x[keep], np.clip(before[keep], -lim, lim), ".", ms=1.6, color="#bbbbbb",
                    label="base model", rasterized=True)
            ax.plot(x[keep], np.clip(after[keep], -lim, lim), ".", ms=1.6, color="#1f77b4", alpha=0.5,
                    label="with the mechanisms found", rasterized=True)
            ax.axhline(0.0, color=MODEL_COLOR, lw=0.6)
            ax.set_ylim(-lim, lim)
            ax.set_xlabel(label)
            if j == 0:
                if ch != "breakaway":
                    ax.set_xscale("symlog", linthresh=1.0)
                ax.set_ylabel(f"{ch}\nresidual / σ")
            else:
                ax.set_xlim(0, 360)
                ax.set_xticks(np.arange(0, 361, 90))
    axes[0, 0].legend(loc="upper right", fontsize=7, markerscale=4)
    return Plot(embed_png(fig, "residuals before and after the discrepancy search"), {"channels": chans})


# ----------------------------------------------------------------------------- uncertainty


def plot_correlation(names: list, matrix) -> Plot | None:
    """The parameter correlation matrix of the least-squares fit, with its numbers."""
    if not names or matrix is None:
        return None
    m = np.array(matrix, dtype=float)
    k = len(names)
    fig, ax = new_figure(figsize=(0.62 * k + 2.2, 0.55 * k + 1.2))
    ax.grid(False)
    im = ax.imshow(m, cmap="RdBu_r", vmin=-1, vmax=1)
    ax.set_xticks(range(k), names, rotation=45, ha="right")
    ax.set_yticks(range(k), names)
    for i in range(k):
        for j in range(k):
            if np.isfinite(m[i, j]):
                ax.text(j, i, f"{m[i, j]:.2f}", ha="center", va="center", fontsize=6.5,
                        color="white" if abs(m[i, j]) > 0.6 else "black")
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.03)
    ax.set_title("correlation of the least-squares estimates")
    return Plot(embed_png(fig, "parameter correlation matrix"), {})


def plot_corner(rd: ReportData, max_params: int = 12) -> Plot | None:
    """Corner plot of the posterior, each axis in posterior standard deviations from the median."""
    if rd.posterior is None or rd.posterior.shape[0] < 10:
        return None
    names = rd.draw_names[:max_params]
    x = rd.posterior[:, :len(names)]
    med, sd = np.median(x, axis=0), np.std(x, axis=0)
    sd = np.where(sd > 0, sd, 1.0)
    z = (x - med) / sd
    params = rd.doc.get("parameters", {})
    k = len(names)
    size = min(1.05 * k + 1.0, 12.5)
    fig, axes = new_figure(k, k, figsize=(size, size), squeeze=False, layout=None)
    lim = (-4.5, 4.5)
    grid = np.linspace(*lim, 200)
    for i in range(k):
        for j in range(k):
            ax = axes[i, j]
            ax.grid(False)
            if j > i:
                ax.axis("off")
                continue
            if i == j:
                ax.hist(z[:, i], bins=36, range=lim, density=True, color="#8fb3d9", edgecolor="none")
                e = params.get(names[i], {})
                if e.get("value") is not None and e.get("std"):
                    m0, s0 = (e["value"] - med[i]) / sd[i], e["std"] / sd[i]
                    ax.plot(grid, np.exp(-0.5 * ((grid - m0) / s0) ** 2) / (s0 * math.sqrt(2 * math.pi)),
                            color="#ff7f0e", lw=1.0)
                ax.set_yticks([])
                ax.set_title(names[i], fontsize=8)
            else:
                ax.hist2d(z[:, j], z[:, i], bins=28, range=[lim, lim], cmap="Blues")
                ax.set_ylim(lim)
            ax.set_xlim(lim)
            ax.set_xticks([-3, 0, 3])
            if i < k - 1:
                ax.set_xticklabels([])
            else:
                ax.set_xlabel(names[j], fontsize=8)
            if j > 0 or i == 0:
                if i != j:
                    ax.set_yticklabels([])
            else:
                ax.set_yticks([-3, 0, 3])
                ax.set_ylabel(names[i], fontsize=8)
            ax.tick_params(labelsize=7)
    fig.subplots_adjust(wspace=0.06, hspace=0.06)
    return Plot(embed_png(fig, "corner plot of the posterior"), {"draws": int(x.shape[0]), "shown": k,
                                                                 "total": len(rd.draw_names)})


def plot_traces(rd: ReportData, walkers: int = 10) -> Plot | None:
    """Chain traces of a few walkers, standardized, with the burn-in shaded."""
    if rd.chain is None:
        return None
    chain = rd.chain
    steps, nw, k = chain.shape
    kept = chain[rd.burn:].reshape(-1, k)
    med, sd = np.median(kept, axis=0), np.std(kept, axis=0)
    sd = np.where(sd > 0, sd, 1.0)
    pick = np.linspace(0, nw - 1, min(walkers, nw)).astype(int)
    fig, axes = new_figure(k, 1, figsize=(12, 0.62 * k + 0.9), sharex=True, squeeze=False, layout=None)
    for i in range(k):
        ax = axes[i, 0]
        ax.plot((chain[:, pick, i] - med[i]) / sd[i], lw=0.4, alpha=0.7, rasterized=True)
        ax.axvspan(0, rd.burn, color="#cccccc", alpha=0.6, lw=0)
        ax.set_ylim(-5, 5)
        ax.set_yticks([-3, 0, 3])
        ax.set_ylabel(rd.draw_names[i], rotation=0, ha="right", va="center", fontsize=8)
    axes[-1, 0].set_xlabel("step (grey: burn-in, discarded)")
    fig.subplots_adjust(hspace=0.1)
    return Plot(embed_png(fig, "chain traces"), {"walkers": len(pick)})


# ----------------------------------------------------------------------------- derived figures


def plot_efficiency_maps(rd: ReportData, ens: Ensemble) -> Plot | None:
    """Mechanical-hydraulic, volumetric and overall efficiency over speed and ΔP (model)."""
    if not rd.has_running:
        return None
    ref = reference_conditions(rd)
    D = rd.spec.displacement
    s = rd.dataset.running
    w_abs = np.abs(np.asarray(s.speed))
    dp_abs = np.abs(np.asarray(s.p_a - s.p_b))
    w = np.geomspace(max(np.nanmin(w_abs), 0.1 / RPM_PER_RAD_S), np.nanmax(w_abs), 48)
    dp_max = float(np.nanmax(dp_abs))
    dps = np.linspace(max(0.1 * dp_max, 5 * PA_PER_BAR), dp_max, 32)
    theta = revolution(rd.spec, 8)
    samples = grid_samples(rd.spec, theta[None, None, :], w[None, :, None], ref["p_low"] + dps[:, None, None],
                           ref["p_low"], ref["p_case"], ref["viscosity"], 1.0, ref["temperature"])
    c, _, _ = ens.running(samples, average=theta.size, band=False)
    torque = c[0].reshape(dps.size, w.size)
    q_a = c[1].reshape(dps.size, w.size)
    eta_hm = torque / (D * dps[:, None] / (2 * np.pi))
    with np.errstate(divide="ignore", invalid="ignore"):
        eta_v = np.where(q_a > 0, (D * w[None, :] / (2 * np.pi)) / q_a, 0.0)
    eta_v = np.clip(eta_v, 0.0, 1.0)
    eta_t = np.clip(eta_hm, 0.0, 1.0) * eta_v
    fig, axes = new_figure(1, 3, figsize=(13, 4.1))
    x, y = w * RPM_PER_RAD_S, dps / PA_PER_BAR
    runs = running_runs(rd)
    from matplotlib.ticker import MaxNLocator

    for ax, eta, title in ((axes[0], eta_hm, r"mechanical-hydraulic $\eta_{hm} = T\,/\,(D\Delta P/2\pi)$"),
                           (axes[1], eta_v, r"volumetric $\eta_v = (D\omega/2\pi)\,/\,Q_A$"),
                           (axes[2], eta_t, r"overall $\eta_t = \eta_{hm}\,\eta_v$")):
        lo = max(float(np.nanpercentile(eta, 3)), 0.0)
        hi = float(np.nanmax(eta))
        levels = MaxNLocator(12).tick_values(lo, hi) if hi > lo else np.linspace(0, 1, 11)
        levels = levels[(levels >= lo - 1e-12) & (levels <= hi + 1e-12)]
        if levels.size < 3:
            levels = np.linspace(lo, hi, 8) if hi > lo else np.linspace(0, 1, 11)
        cf = ax.contourf(x, y, eta, levels=levels, cmap="viridis", extend="both")
        lines = _nice_levels(lo, hi)
        if lines:
            cs = ax.contour(x, y, eta, levels=lines, colors="white", linewidths=0.7)
            ax.clabel(cs, fmt=lambda v: f"{v:.3g}", fontsize=7)
        fig.colorbar(cf, ax=ax, pad=0.01, format="%.3g")
        ax.plot([abs(r.speed) * RPM_PER_RAD_S for r in runs], [r.dp / PA_PER_BAR for r in runs], ".", color="white", ms=3,
                mec="k", mew=0.3)
        ax.set_xscale("log")
        ax.set_xlim(x[0], x[-1])
        ax.set_ylim(y[0], y[-1])
        ax.grid(False)
        ax.set_title(title)
        ax.set_xlabel("shaft speed n [rpm]")
    axes[0].set_ylabel("pressure difference ΔP [bar]")
    i_ref = int(np.argmin(np.abs(dps - 0.8 * dp_max)))
    j_ref = int(np.argmin(np.abs(w * RPM_PER_RAD_S - min(1000.0, 0.5 * w[-1] * RPM_PER_RAD_S))))
    return Plot(embed_png(fig, "efficiency maps"), {
        "ref": ref, "point": (float(x[j_ref]), float(y[i_ref]), float(eta_hm[i_ref, j_ref]),
                              float(eta_v[i_ref, j_ref]), float(eta_t[i_ref, j_ref]))})


def _nice_levels(lo: float, hi: float) -> list:
    cands = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.92, 0.94, 0.95, 0.96, 0.97, 0.98, 0.99, 0.995]
    return [v for v in cands if lo < v < hi][-7:]


def plot_starting_efficiency(rd: ReportData, ens: Ensemble) -> Plot | None:
    """Starting torque efficiency against ΔP: the model's mean and worst shaft angle, and the data."""
    ref = reference_conditions(rd)
    D, n = rd.spec.displacement, rd.spec.pistons
    pitch = 2 * np.pi / n
    if rd.has_events:
        e = _event_cols(rd)
        ok = np.isfinite(e["held"])
        dp_hi = float(np.max(e["dp"][ok])) * 1.2
        p_low, mu, temp = float(np.median(e["p_out"])), float(np.median(e["viscosity"])), \
            float(np.median(e["temperature"]))
    elif rd.has_running:
        dp_hi = float(np.nanmax(np.abs(np.asarray(rd.dataset.running.p_a - rd.dataset.running.p_b))))
        p_low, mu, temp, e = ref["p_low"], ref["viscosity"], ref["temperature"], None
    else:
        return None
    dps = np.linspace(0.05 * dp_hi, dp_hi, 40)
    th = (np.arange(48) + 0.5) * pitch / 48
    samples = grid_samples(rd.spec, th[None, :], 0.0, p_low + dps[:, None], p_low, ref["p_case"], mu, 1.0, temp)
    c, lo, hi = ens.breakaway(samples)
    scale = (D * dps / (2 * np.pi))[:, None]
    c, lo, hi = (v.reshape(dps.size, th.size) / scale for v in (c, lo, hi))
    fig, ax = new_figure(figsize=(7.5, 4.2))
    x = dps / PA_PER_BAR
    ax.plot(x, c.mean(1), color="#1f77b4", label="model, mean over shaft angle")
    _band(ax, x, lo.mean(1), hi.mean(1), "#1f77b4", 0.3)
    ax.plot(x, c.min(1), color="#d62728", label="model, worst shaft angle")
    _band(ax, x, lo.min(1), hi.min(1), "#d62728", 0.3)
    if e is not None:
        ax.plot(e["dp"][ok] / PA_PER_BAR, (e["d"] * e["held"])[ok] / (D * e["dp"][ok] / (2 * np.pi)), "o", ms=3.5,
                color="k", alpha=0.6, label="breakaway events (data)")
    ax.set_xlabel("pressure difference |ΔP| [bar]")
    ax.set_ylabel("starting torque efficiency")
    ax.set_title("starting torque efficiency T_start / (D|ΔP|/2π) (ISO 4392-2)")
    ax.legend(loc="lower right", frameon=False)
    i = int(np.argmin(np.abs(x - 0.8 * x[-1] / 1.2)))
    return Plot(embed_png(fig, "starting torque efficiency against pressure"),
                {"point": (float(x[i]), float(c.mean(1)[i]), float(c.min(1)[i]))})
