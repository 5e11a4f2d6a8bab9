"""Whether the data tell two candidate names apart.

Two mechanisms whose signatures coincide on a campaign (a Stribeck curve in speed and
one in the Sommerfeld number μω/ΔP where every slow run is at one pressure) fit it
almost alike.  Which one then wins by a few units of χ² out of a gain of a million is
decided by the noise, and a wrong name is worse than none: diagnose names neither.

Two tests, either enough for a tie (unless the two are shown to be two effects, not
one: :func:`complementary`):

* the fixed one (:func:`tied`): the first beats the second by less than
  ``min_evidence`` in ΔBIC or in Δχ²;
* a run-level Vuong test (:func:`run_vuong_z`): the difference of the two χ² is
  summed per run, and the sum over runs is compared with its own run-to-run
  scatter, z = Σ_r d_r / √(Σ_r d_r²) (the sign-flip statistic: under "the data do
  not prefer either", each run's d_r is as likely to favour one as the other).  The
  runs, not the samples, are the units: a run's samples share its operating point,
  its temperature and its transducer zeros, so their residuals are not independent
  and a per-sample test would call a run-to-run accident evidence.  z below
  :data:`TIE_Z` is a tie.  Vuong, Econometrica 57 (1989) 307-333, for non-nested
  models; clustered by run as in Cameron & Miller, J. Human Resources 50 (2015) 317.

On an operating-point table (a loss map) the points are the units (:func:`point_vuong_z`): each
is its own steady test, averaged over many samples.
"""

from __future__ import annotations

import numpy as np

#: a name must beat the runner-up by this many run-level standard errors (one-sided 2.3 %)
TIE_Z = 2.0
#: runs (holding data) below which the runs cannot judge (z could not reach TIE_Z unless nearly
#: every run agreed; a log of one set point is one run): the fixed rule decides alone
MIN_RUNS = 10
#: points (holding data) below which a table's points cannot judge; the fixed rule decides alone
MIN_POINTS = 10


def chi2_by_run(fit, dataset, screen=None) -> np.ndarray | None:
    """χ² of ``fit`` summed per run of ``dataset`` (breakaway events with the run they
    belong to) → [runs], or None where the fit's residuals cannot be put to runs.

    ``fit``: a :class:`~motorid.identify.types.FitResult` (per-sample residuals, its own
    σ and inliers) or a :class:`~motorid.discrepancy.screen.CellFit` (its cells, through
    ``screen``)."""
    if fit is None:
        return None
    if hasattr(fit, "residuals"):
        n_runs = len(dataset.runs)
        run_of = {"breakaway": np.asarray(getattr(dataset, "run_of_event", np.zeros(0, int)), dtype=int)}
        samples = np.asarray(dataset.run_of_sample, dtype=int)
        out = np.zeros(n_runs)
        for c, r in fit.residuals.items():
            r = np.asarray(r, dtype=float)
            runs = run_of.get(c, samples)
            if runs.size != r.size:
                return None
            s = np.asarray(fit.sigma[c], dtype=float)
            ok = np.asarray(fit.inliers[c], dtype=bool) & np.isfinite(r) & np.isfinite(s) & (s > 0)
            out += np.bincount(runs[ok], (r[ok] / s[ok]) ** 2, minlength=n_runs)[:n_runs]
        return out
    return None if screen is None else screen.chi2_by_run(fit)


def run_vuong_z(first, second, dataset, screen=None) -> float | None:
    """z of "``first`` fits better than ``second``", the runs as units (module doc);
    None where either's χ² cannot be put to runs, fewer than :data:`MIN_RUNS` runs hold data,
    or the two fit every run alike."""
    a, b = chi2_by_run(first.fit, dataset, screen), chi2_by_run(second.fit, dataset, screen)
    if a is None or b is None or a.shape != b.shape or np.count_nonzero((a > 0) | (b > 0)) < MIN_RUNS:
        return None
    d = b - a
    scale = float(np.sqrt(np.sum(d * d)))
    return float(np.sum(d) / scale) if scale > 0 else None


def point_vuong_z(first, second, sigma: dict) -> float | None:
    """z of "table fit ``first`` fits the points better than table fit ``second``", the points as units
    (module doc), each point's χ² summed over its channels in one noise (``sigma``: channel → σ per
    point, the current model's); None where fewer than :data:`MIN_POINTS` points hold data in both or
    the two fit every point alike."""
    d, seen = None, None
    for c, s in sigma.items():
        r1, r2 = first.table_residuals.get(c), second.table_residuals.get(c)
        if r1 is None or r2 is None:
            continue
        r1, r2, s = (np.asarray(x, dtype=float) for x in (r1, r2, s))
        ok = np.isfinite(r1) & np.isfinite(r2) & np.isfinite(s) & (s > 0)
        term = np.where(ok, (np.where(ok, r2, 0.0) ** 2 - np.where(ok, r1, 0.0) ** 2) / np.where(ok, s, 1.0) ** 2,
                        0.0)
        d, seen = (term, ok) if d is None else (d + term, seen | ok)
    if d is None or int(np.count_nonzero(seen)) < MIN_POINTS:
        return None
    scale = float(np.sqrt(np.sum(d * d)))
    return float(np.sum(d) / scale) if scale > 0 else None


def tied(scored: list, min_evidence: float, dataset=None, screen=None) -> bool:
    """Whether the two best candidates both earn their place (ΔBIC > ``min_evidence``) and
    the data do not tell them apart: the first beats the second by less than ``min_evidence``
    in ΔBIC or in Δχ² (the fit itself — where both fit alike, one parameter fewer must not
    decide the name), or by less than :data:`TIE_Z` run-level standard errors
    (:func:`run_vuong_z`, where ``dataset`` is given).  Mechanisms whose signatures coincide
    on these data tie; a wrong name is worse than none, so diagnose then names neither."""
    if len(scored) < 2 or scored[1].delta_bic <= min_evidence:
        return False
    a, b = scored[0], scored[1]
    if min(a.delta_bic - b.delta_bic, a.delta_chi2 - b.delta_chi2) < min_evidence:
        return True
    if dataset is None:
        return False
    z = run_vuong_z(a, b, dataset, screen)
    return z is not None and z < TIE_Z


def cells_of(cand):
    """A candidate's fit on the screening cells (kept as ``cells`` where it was refitted on every
    sample), or None where it was only ranked."""
    cells = getattr(cand, "cells", None)
    if cells is not None:
        return cells
    return cand.fit if cand.fit is not None and not hasattr(cand.fit, "residuals") else None


def complementary(screen, current_cells, current_mechs, first, second, min_evidence: float) -> bool:
    """Whether the two best explain *different* structure (two effects, each to be named in
    turn) rather than the same structure alike (a tie): fitted together on the cells, the
    second still adds more than ``min_evidence`` and more than half of what it gains alone
    beyond the current model.  Two true effects of like size in different runs (a friction
    at low speed, a leak at high pressure) look like a tie to :func:`run_vuong_z` — each run
    prefers the one that explains it — and are not one."""
    a, b = cells_of(first), cells_of(second)
    if screen is None or a is None or b is None or current_cells is None:
        return False
    start = {**b.values, **a.values}
    both = screen.fit(list(current_mechs) + [first.mechanism, second.mechanism], start)
    if not np.isfinite(both.chi2):
        return False
    added = a.chi2 - both.chi2
    alone = current_cells.chi2 - b.chi2
    return added > min_evidence and added > 0.5 * alone


def near_tie(scored: list, min_evidence: float) -> bool:
    """The two best are close enough that the coarse cells could order them wrongly."""
    return (len(scored) >= 2 and scored[1].delta_bic > min_evidence
            and min(scored[0].delta_bic - scored[1].delta_bic, scored[0].delta_chi2 - scored[1].delta_chi2)
            < 3 * min_evidence)
