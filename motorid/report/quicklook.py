"""Quick-look figures of a fit and of a diagnosis, returned as matplotlib figures (for notebooks).

The HTML report (:mod:`motorid.report.html`) is the full account; these are the
one-glance views behind ``FitResult.plot()`` and ``DiagnosisResult.plot()`` of
:mod:`motorid.api`.  Model values come from :func:`motorid.model.predict` and
:func:`motorid.model.predict_breakaway`, the functions the fit used.
"""

from __future__ import annotations

import numpy as np

from motorid.units import LPM_PER_M3S, PA_PER_BAR, RPM_PER_RAD_S

#: running channels drawn against speed: channel, axis label, factor from SI
_RUNNING = (("torque", "shaft torque [N·m]", 1.0), ("q_a", "port A flow [L/min]", LPM_PER_M3S),
            ("q_case", "case-drain flow [L/min]", LPM_PER_M3S))


def fit_figure(dataset, spec, params: dict, mechanisms=(), title: str = ""):
    """Data and model of a fit: running torque, port-A and case-drain flows against speed [rpm],
    and the held breakaway torque against the model's [N·m].  Returns the figure."""
    import matplotlib.pyplot as plt

    from motorid import model

    fig, axes = plt.subplots(2, 2, figsize=(10, 7), constrained_layout=True)
    s = dataset.running
    speed = np.asarray(s.speed) * RPM_PER_RAD_S
    if speed.size:
        ch = model.predict(model.as_jax(params), spec, s, mechanisms)
    for ax, (name, label, factor) in zip(axes.flat, _RUNNING):
        measured = np.asarray(dataset.measured.get(name, np.full(speed.shape, np.nan)))
        if speed.size:
            ax.plot(speed, measured * factor, ".", ms=2, color="0.6", label="data")
            ax.plot(speed, np.asarray(getattr(ch, name)) * factor, ".", ms=2, color="C3", label="model")
        ax.set_xlabel("speed [rpm]")
        ax.set_ylabel(label)
    axes[0, 0].legend(loc="best", markerscale=4)
    ax = axes[1, 1]
    held = np.asarray(dataset.held_torque)
    if held.size:
        pred = np.asarray(model.predict_breakaway(model.as_jax(params), spec, dataset.events, mechanisms))
        ax.plot(pred, held, "o", ms=3, color="C0")
        lim = [float(min(pred.min(), held.min())), float(max(pred.max(), held.max()))]
        ax.plot(lim, lim, "-", color="0.3", lw=0.8)
    ax.set_xlabel("model breakaway torque [N·m]")
    ax.set_ylabel("held torque at breakaway [N·m]")
    if title:
        fig.suptitle(title)
    return fig


def diagnosis_figure(arrays: dict, title: str = ""):
    """Residuals over σ before (grey) and after (colour) the discrepancy search, per channel, against
    speed [rpm] (breakaway: against P_A + P_B [bar]).  ``arrays`` as
    :func:`motorid.discrepancy.select.residual_arrays`.  Returns the figure."""
    import matplotlib.pyplot as plt

    chans = [k[: -len("__before")] for k in arrays if k.endswith("__before")]
    fig, axes = plt.subplots(len(chans) or 1, 1, figsize=(8, 2.2 * max(len(chans), 1)), squeeze=False,
                             constrained_layout=True)
    for ax, c in zip(axes[:, 0], chans):
        at_rest = c == "breakaway"
        x = np.asarray(arrays[f"{c}__speed"]) * (1.0 / PA_PER_BAR if at_rest else RPM_PER_RAD_S)
        ax.plot(x, arrays[f"{c}__before"], ".", ms=2, color="0.7", label="before")
        ax.plot(x, arrays[f"{c}__after"], ".", ms=2, color="C2", label="after")
        ax.set_ylabel(f"{c} residual / σ")
        ax.set_xlabel("P_A + P_B [bar]" if at_rest else "speed [rpm]")
    if chans:
        axes[0, 0].legend(loc="best", markerscale=4)
    if title:
        fig.suptitle(title)
    return fig
