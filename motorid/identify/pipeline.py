"""From log files to a fit: read, validate, extract, least squares, (emcee)."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from motorid.identify.identifiability import one_back_pressure_warning
from motorid.identify.least_squares import fit_least_squares
from motorid.identify.types import FitOptions, FitResult


@dataclass
class Identification:
    ls: FitResult
    bayes: object  # BayesResult or None
    dataset: object
    frame: object
    seconds: float
    priors: dict


#: above about this many rows a campaign is reduced to cells as it is read (docs/large-logs.md)
CELL_ROWS = 500_000


def cell_rows() -> int:
    """The row count above which :func:`identify` reduces a campaign to cells as it reads it:
    ``MOTORID_CELL_ROWS`` where set, else :data:`CELL_ROWS`."""
    value = os.environ.get("MOTORID_CELL_ROWS", "").strip()
    if value:
        from motorid.errors import InputError

        try:
            return int(float(value))
        except ValueError:
            raise InputError(f"MOTORID_CELL_ROWS must be a number of rows, got '{value}'") from None
    return CELL_ROWS


def load_campaign(paths: Sequence, spec, channels=None, *, cells: bool | None = False,
                  bins_per_pitch: int = 192, outlier_sigma: float = 5.0, progress: bool | None = None):
    """Read and validate the logs, then extract steady samples and breakaway events → (frame, Dataset).

    cells : False keeps every steady sample (the frame is read whole); True streams
    the logs and reduces each run to shaft-angle cells as it arrives
    (:func:`motorid.identify.extract.extract_cells`; the frame is then None); None
    decides by the rows: cells above :func:`cell_rows` (estimated from the file
    sizes, :func:`motorid.io.stream.estimate_rows`).  bins_per_pitch and
    outlier_sigma : the cells and the spike test of that reduction.
    """
    from motorid.identify.extract import extract, extract_cells
    from motorid.io.logs import read_logs

    paths = [str(p) for p in paths]
    if cells is None:
        from motorid.io.stream import estimate_rows

        cells = estimate_rows(paths) > cell_rows()
    if cells:
        from motorid.io.stream import StreamFallback, runs_of_frame, stream_runs

        reduce = lambda runs: extract_cells(runs, spec, bins_per_pitch=bins_per_pitch,  # noqa: E731
                                            outlier_sigma=outlier_sigma, progress=progress)
        try:
            frame, dataset = None, reduce(stream_runs(paths, spec, channels, progress=progress))
        except StreamFallback:  # interleaved runs or a cell to name: read whole (docs/large-logs.md)
            frame = read_logs(paths, spec, channels)
            frame, dataset = None, reduce(runs_of_frame(frame))
    else:
        frame = read_logs(paths, spec, channels)
        dataset = extract(frame, spec)
    check_logs_against_ideal(dataset, spec, paths)
    return frame, dataset


class _SteadySamples:
    """The logs' steady samples as the table checks read a table (SI)."""

    def __init__(self, dataset, spec):
        s = dataset.running
        self.speed, self.p_a, self.p_b = (np.asarray(getattr(s, k), float) for k in ("speed", "p_a", "p_b"))
        self.dp = self.p_a - self.p_b
        self.displacement = np.full(self.speed.shape, float(spec.displacement))
        self.measured = {c: np.asarray(dataset.measured[c], float) for c in ("torque", "q_a", "q_b")}

    def __len__(self) -> int:
        return int(self.speed.size)


def check_logs_against_ideal(dataset, spec, paths) -> None:
    """The ideal-machine checks of a table (:func:`motorid.io.table_checks.check_against_ideal`: the port
    flows against D·ω/2π, the torque against D·ΔP/2π, the power balance) on the logs' steady samples:
    a channel map's forgotten sign or wrong unit factor refused in one line naming the logs, not
    fitted into K_L and K_F."""
    from pathlib import Path

    from motorid.io.table_checks import check_against_ideal

    if dataset.running is None or not dataset.n_running:
        return
    names = ", ".join(Path(p).name for p in paths[:3]) + (f" (and {len(paths) - 3} more)" if len(paths) > 3 else "")
    check_against_ideal(_SteadySamples(dataset, spec), names, counted="samples", whose="the steady samples' ")


def viscosity_model_warning(frame, dataset, ls) -> str:
    """A warning where the viscosity of running samples came from the oil model, not a
    viscometer: K_v scales with μ and K_L0, K_AB with 1/μ, one for one, and the
    standard errors do not hold the oil model's own error ("" where it did not)."""
    from motorid.io.logs import TEMPERATURE_ASSUMED, VISCOSITY_FROM_OIL

    assumed = ""
    if frame is not None and TEMPERATURE_ASSUMED in frame.columns and dataset.n_running \
            and getattr(dataset, "cells", None) is None:
        flags = frame[TEMPERATURE_ASSUMED].to_numpy(dtype=bool)[dataset.frame_index]
        if flags.any():
            t_spec = frame["oil_temp_C"].to_numpy()[dataset.frame_index][flags][0]
            assumed = (f"; the logs hold no oil temperature for {100 * flags.mean():.0f} % of them, where the "
                       f"spec's assumed [oil] temp_C = {t_spec:g} °C stands for every sample (a few kelvin off "
                       f"moves μ by some 10 %)")
    if getattr(dataset, "cells", None) is not None and dataset.n_running:
        share = dataset.cells.viscosity_from_oil / max(float(dataset.cells.n.sum()), 1.0)
    elif frame is None or VISCOSITY_FROM_OIL not in frame.columns or not dataset.n_running:
        return ""
    else:
        share = float(frame[VISCOSITY_FROM_OIL].to_numpy()[dataset.frame_index].mean())
    affected = [k for k in ("Kv", "KL0", "KAB") if ls.identifiable.get(k)]
    if share <= 0 or not affected:
        return ""
    return (f"the viscosity of {100 * share:.0f} % of the running samples comes from oil_temp_C and the spec's "
            f"[oil] (Walther, ASTM D341; density ρ15/(1 + β(T − 15 °C))), not a viscometer: "
            f"{', '.join(affected)} carry that model's error one for one (K_v ∝ μ, K_L0 and K_AB ∝ 1/μ), "
            f"and their std does not include it{assumed}")


def torque_gain_warning(dataset, ls) -> str:
    """:func:`~motorid.identify.identifiability.one_back_pressure_warning` over the running samples."""
    s = getattr(dataset, "running", None)
    if not ls.identifiable.get("KF") or s is None or not np.size(s.speed):
        return ""
    low = np.minimum(np.asarray(s.p_a, float), np.asarray(s.p_b, float))
    return one_back_pressure_warning(low, ls.values["KF"])


def add_fit_warnings(ls: FitResult, dataset, frame) -> FitResult:
    """Append to ``ls.warnings`` what the data behind a fit warn of (the oil model's viscosity, one
    back pressure) → ``ls``."""
    for note in (viscosity_model_warning(frame, dataset, ls), torque_gain_warning(dataset, ls)):
        if note and note not in ls.warnings:
            ls.warnings.append(note)
    return ls


def identify(paths: Sequence, spec, bayes: bool = False, options: FitOptions | None = None,
             mechanisms: Sequence = (), seed: int = 0, progress: bool | None = None,
             dataset=None, frame=None, channels=None) -> Identification:
    """The main job: a least-squares fit of every parameter the logs identify, and
    with ``bayes`` an emcee posterior started from it.  A campaign of more than
    :func:`cell_rows` rows is reduced to cells as it is read (:func:`load_campaign`)
    and fitted from them (:func:`motorid.identify.cell_fit.fit_cells`)."""
    t0 = time.time()
    opt = options or FitOptions()
    if dataset is None:
        frame, dataset = load_campaign(paths, spec, channels, cells=None, bins_per_pitch=opt.bins_per_pitch,
                                       outlier_sigma=opt.outlier_sigma, progress=progress)
    if getattr(dataset, "cells", None) is not None:
        from motorid.identify.cell_fit import fit_cells

        ls = fit_cells(dataset, spec, mechanisms=mechanisms, options=options)
    else:
        ls = fit_least_squares(dataset, spec, mechanisms=mechanisms, options=options)
    add_fit_warnings(ls, dataset, frame)
    post, priors = None, {}
    if bayes and ls.free:
        from motorid.identify.bayes import prior_scale, sample_posterior

        post = sample_posterior(ls, spec, seed=seed, progress=progress)
        priors = {k: (f"HalfNormal(scale={prior_scale(k, spec, ls.mechanisms):.3g})"
                      if not k.startswith("KL_") else "Normal(0, 1)") for k in ls.free}
    return Identification(ls, post, dataset, frame, time.time() - t0, priors)
