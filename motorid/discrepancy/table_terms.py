"""Empirical terms on operating-point tables: what the catalog leaves, as a checked formula.

On a table (one row per steady point, θ-averaged, no shaft angle) the structure
that no catalog mechanism explains is searched with the library of
:mod:`motorid.discrepancy.empirical` (shaft-order harmonics left out), K-fold over
the points (or over the recordings where the table names them).  A proposed
term is kept only if it also predicts where it was not fitted: fitted on the
lower half of the speeds it must improve the upper half and the other way round,
and the same over |ΔP|.  A term that helps only inside the cloud of points it
was fitted on (a polynomial that bends away outside it) is not kept.

:class:`MotoridWithTerms` is the held-out comparator that uses it: motorid's one
model (plus the catalog mechanisms diagnose selected) fitted on the training
points, then on each channel the empirical term selected and checked on those
training points alone, its coefficients and the base model's own linear shapes
refitted to the training residuals.  Nothing about the held-out points enters
the choice.
"""

from __future__ import annotations

import types

import numpy as np

from motorid.comparators.evaluate import CHANNELS, MotoridModel
from motorid.discrepancy.empirical import (EmpiricalTerm, cv_sse, fold_labels, nuisance, propose, region_gains,
                                          regions_hold)
from motorid.discrepancy.locate import CHANNEL_WORDS

#: folds over the training points (or their recordings) of the term search
FOLDS = 5
#: a channel needs this many points for a term search (5 folds of at least 4 points)
MIN_POINTS = 20
#: a table term must remove at least this fraction of the held-out χ² (on clean simulated maps
#: a spurious term removes up to about 5 %: benchmarks bench_mapphysics, tests/test_table_terms.py)
MIN_GAIN = 0.10


def point_samples(table, index=None):
    """The table's operating points as the sample fields the term library reads (SI)."""
    idx = slice(None) if index is None else index
    speed = np.asarray(table.speed, float)[idx]
    return types.SimpleNamespace(speed=speed, direction=np.sign(speed), p_a=np.asarray(table.p_a, float)[idx],
                                 p_b=np.asarray(table.p_b, float)[idx],
                                 p_case=np.asarray(table.p_case, float)[idx],
                                 viscosity=np.asarray(table.viscosity, float)[idx])


def _regions(x) -> dict:
    """Halves of the points (True: the lower half) along |ω| and |ΔP|."""
    w, dp = np.abs(x.speed), np.abs(x.p_a - x.p_b)
    return {("low speeds", "high speeds"): w <= np.median(w),
            ("low |ΔP|", "high |ΔP|"): dp <= np.median(dp)}


def _solve(A, y):
    scale = np.sqrt(np.mean(A**2, axis=0))  # columns span 1 … 1e14 in SI: scaled, or lstsq drops some
    scale[scale == 0] = 1.0
    return np.linalg.lstsq(A / scale, y, rcond=None)[0] / scale


def _checked(channel, x, y, w, fold, terms, spec):
    """(held-out gain K-fold, where-not-fitted gains, coefficients) of ``terms`` on top of the
    base model's own shapes (weighted: y, columns × w), by the same K-fold and region checks
    as :func:`~motorid.discrepancy.empirical.propose`."""
    N = nuisance(channel, x, spec) * w[:, None]
    X = np.column_stack([N] + [t.values(x) * w for t, _ in terms])
    scale = np.sqrt(np.mean(X**2, axis=0))  # columns span 1 … 1e14 in SI: scaled, or lstsq drops some
    scale[scale == 0] = 1.0
    Z, k = X / scale, N.shape[1]
    base = cv_sse(Z, y, list(range(k)), fold, FOLDS)
    cv = cv_sse(Z, y, list(range(Z.shape[1])), fold, FOLDS)
    regions = region_gains(Z, y, k, list(range(k, Z.shape[1])), _regions(x))
    coef = (np.linalg.lstsq(Z, y, rcond=None)[0] / scale)[k:]
    return (1.0 - cv / base if base > 0 else 0.0), regions, coef


def search(channel: str, table, residual, sigma, where, spec, groups=None):
    """The empirical term of ``channel`` on the points ``where``, or None.

    residual, sigma : over all points [SI]; where : boolean mask of the points to use;
    groups : per-point recording labels (folds over recordings), or None (folds over points).
    The terms of :func:`~motorid.discrepancy.empirical.propose` are kept, the last dropped
    first, while the where-not-fitted checks fail: fitted on the lower half (of the speeds, of
    |ΔP|) a term must predict the upper half better than the base model does, and its gains
    over the four checks must not average below zero, none below −25 % (fitted on the upper
    half, a small term may lose a little to the noise below); and it must remove :data:`MIN_GAIN` of the
    held-out χ².
    """
    ok = np.asarray(where, bool) & np.isfinite(residual) & np.isfinite(sigma) & (np.asarray(sigma) > 0)
    if ok.sum() < MIN_POINTS:
        return None
    idx = np.flatnonzero(ok)
    x = point_samples(table, idx)
    if groups is not None and np.unique(np.asarray(groups)[idx]).size >= 2 * FOLDS:
        run_of = np.unique(np.asarray(groups)[idx], return_inverse=True)[1]
    else:  # each point its own "run", in a seeded random order (the folds interleave the grid)
        run_of = np.random.default_rng(0).permutation(idx.size)
    r, sig = np.asarray(residual, float)[idx], np.asarray(sigma, float)[idx]
    term = propose(channel, x, r, sig, run_of, spec, folds=FOLDS, harmonics=False)
    if term is None:
        return None
    fold = fold_labels(run_of, FOLDS)
    w = 1.0 / sig
    for k in range(len(term.terms), 0, -1):
        terms = term.terms[:k]
        gain, regions, coef = _checked(channel, x, r * w, w, fold, terms, spec)
        outward = [v for name, v in regions.items() if name.startswith("fit on low")]
        if gain >= MIN_GAIN and outward and min(outward) > 0.0 and regions_hold(regions):
            terms = [(t, float(c)) for (t, _), c in zip(terms, coef)]
            # its size: how far it moves the fitted curve (the base model's own shapes refitted with
            # and without it), not the term alone, which a shape it shares with them would inflate
            N = nuisance(channel, x, spec)
            X = np.column_stack([N] + [t.values(x) for t, _ in terms])
            with_it = X @ _solve(X * w[:, None], r * w)
            without = N @ _solve(N * w[:, None], r * w)
            size = float(np.sqrt(np.mean((with_it - without) ** 2)))
            return EmpiricalTerm(channel, terms, float(gain), regions, size)
    return None


def _columns(channel, term, x, spec) -> np.ndarray:
    return np.column_stack([nuisance(channel, x, spec)] + [t.values(x)[:, None] for t, _ in term.terms])


class MotoridWithTerms(MotoridModel):
    """motorid (+ ``mechanisms``) + on each channel the empirical term its training points support."""

    def __init__(self, spec, mechanisms=(), label: str | None = None, groups=None):
        super().__init__(spec, mechanisms, label)
        self.groups = groups

    def _fit_split(self, table, train):  # MotoridModel.fit_split gives a split asked again back
        base = super()._fit_split(table, train)
        pred = base.predict(table)
        out = _FittedWithTerms(base)
        for c in CHANNELS:
            y = np.asarray(table.measured[c], float)
            if not np.isfinite(y).any() or not np.isfinite(pred[c]).any():
                continue
            r = y - pred[c]
            sigma = np.asarray(base.fit.table_sigma[c], float)
            term = search(c, table, r, sigma, train, self.spec, self.groups)
            if term is None:
                continue
            ok = np.asarray(train, bool) & np.isfinite(r)
            x = point_samples(table, np.flatnonzero(ok))
            A = _columns(c, term, x, self.spec) / sigma[ok][:, None]
            out.terms[c] = (term, _solve(A, r[ok] / sigma[ok]))
        return out


class TermsLeftOut:
    """The model of a :class:`MotoridWithTerms` without its empirical terms, on the same fits (each
    split's fit is the with-terms model's own base fit): the held-out row that shows what the terms add
    when every parameter is refitted per fold."""

    reference = MotoridModel.reference

    def __init__(self, with_terms: MotoridWithTerms, label: str):
        self.inner, self.name = with_terms, label

    def fit(self, table):
        return self.fit_split(table, np.ones(len(table), bool))

    def fit_split(self, table, train):
        return self.inner.fit_split(table, train).base


def confirm_by_refit(entries: list, comparison: dict, with_terms: MotoridWithTerms, table, label: str) -> None:
    """Add motorid's row without the empirical terms to ``comparison`` (after the with-terms rows, on their
    fits) and say in each ``entries``' term whether it lowers its channel's K-fold error there, where
    every parameter is refitted per fold: the term's own held-out gain is measured on the residuals of
    the model held fixed, and a term whose shape the refitted parameters take over gains nothing once
    they are free (``empirical_term["confirmed_by_refit"]``, the two errors in % of span)."""
    from motorid.comparators.evaluate import held_out

    rows = comparison["models"]
    without = held_out(TermsLeftOut(with_terms, label), table)
    without["reference"] = TermsLeftOut.reference
    names = list(rows)
    at = max(i for i, n in enumerate(names) if n.startswith(with_terms.name)) + 1
    comparison["models"] = {**{n: rows[n] for n in names[:at]}, label: without, **{n: rows[n] for n in names[at:]}}
    for e in entries:
        term = e.get("empirical_term")
        if not term:
            continue
        c = e["channel"]
        a = (without["kfold"].get(c) or {}).get("percent_of_span")
        b = (rows[with_terms.name]["kfold"].get(c) or {}).get("percent_of_span")
        if a is None or b is None:
            continue
        term["refit_kfold_percent_of_span"] = {"without": a, "with": b}
        term["confirmed_by_refit"] = bool(b < a)
        if b >= a:
            e["description"] += (f"; but with every parameter refitted per fold it does not lower the 5-fold error of "
                                 f"the {CHANNEL_WORDS[c]} ({a:.3g} → {b:.3g} % of span): the model's own parameters "
                                 "take most of it up, so it is not confirmed")


class _FittedWithTerms:
    def __init__(self, base):
        self.base = base
        self.fit = base.fit
        self.terms: dict = {}

    def predict(self, table) -> dict:
        out = self.base.predict(table)
        x = point_samples(table)
        for c, (term, coef) in self.terms.items():
            out[c] = out[c] + _columns(c, term, x, self.base.owner.spec) @ coef
        return out


def unexplained_table_entries(fit, spec) -> list:
    """``unexplained`` entries of a table diagnosis: per channel, the empirical term its residuals
    support after the final fit (every point), in words and numbers; where no term holds but the
    residuals still run along an operating variable beyond the noise
    (:func:`~motorid.discrepancy.table_structure.table_structures`), that structure in words and
    numbers, with no formula; [] where neither."""
    from motorid.discrepancy.table_structure import shape_words, table_structures

    table = fit.table
    entries = []
    located = table_structures(fit)
    for c in CHANNELS:
        r = np.asarray(fit.table_residuals[c], float)
        if not np.isfinite(r).any():
            continue
        sigma = np.asarray(fit.table_sigma[c], float)
        term = search(c, table, r, sigma, np.ones(len(table), bool), spec)
        mine = [s for s in located if s["channel"] == c]
        if term is None and mine:
            big = max(mine, key=lambda s: s["effect_sigma"])
            shape = shape_words(mine)
            variables = list(dict.fromkeys(s["variable"] for s in mine))
            text = (f"the {CHANNEL_WORDS[c]} differs from the model along {', '.join(variables)}: "
                    f"{big['where']}" + (f"; {shape}" if shape else "")
                    + "; no catalog mechanism and no term of the empirical library explains it")
            entries.append({"channel": c, "description": text, "empirical_term": None,
                            "residual_rms": float(np.sqrt(np.nanmean(r**2))), "variables": variables,
                            "where": big["where"], "p_value": mine[0]["p_value"], "effect": big["effect"],
                            "effect_sigma": big["effect_sigma"], "shape": shape,
                            "structures": [s["where"] for s in mine]})
        if term is None:
            continue
        d = term.as_dict()
        checks = ", ".join(f"{k}: {100 * v:.0f} %" for k, v in term.region_gain.items())
        text = (f"the {CHANNEL_WORDS[c]} differs from the model by {d['size_words']}, in a shape no catalog mechanism "
                f"takes; proposed empirical term (not a named mechanism): {term.formula}; it removes "
                f"{100 * term.held_out_gain:.0f} % of the held-out residual (5-fold over the points) and, "
                f"where it was not fitted, {checks}")
        entries.append({"channel": c, "description": text, "empirical_term": d,
                        "residual_rms": float(np.sqrt(np.nanmean(r**2)))})
    return entries
