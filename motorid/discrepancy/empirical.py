"""Empirical terms: a readable formula for structure that no catalog mechanism explains.

A library of physically shaped candidate terms (in the spirit of pysindy: the
library is kept apart from the optimizer, so a selected term prints as
physics) is regressed on a channel's residuals after the final fit:

- speed factors 1, sgn ω, ω, ω|ω|, ω³, sgn ω·√|ω| (odd in ω, as a friction or a swept flow
  is); for the case drain, whose leak does not reverse with the shaft, 1, |ω|, ω², |ω|³, √|ω|;
- pressure factors 1, ΔP, |ΔP|, √|ΔP|, P_A+P_B, P_A−P_c, P_B−P_c,
  (P_A−P_c)(P_B−P_c), ΔP², sgn ΔP·√|ΔP|, ΔP|ΔP|, (P_A+P_B)² (the odd ones
  for a flow between the ports, which follows the sign of ΔP);
- viscosity factors 1, μ, 1/μ;
- shaft-order harmonics cos kθ, sin kθ (k = 1…4, n, 2n), alone and × ΔP;

every product of one factor of each kind is a term.  The 1992 model's own
shapes (sgn ω, sgn ω·(P_A+P_B), μω for the torque; (P−P_c)/μ and ΔP/μ for the
flows) are carried as unpenalized nuisance columns, so a term cannot be a
base parameter in disguise.  Selection is forward stepwise regression with
held-out selection (a greedy relative of the sparse regressions of pysindy,
Brunton, Proctor & Kutz, PNAS 113, 3932, 2016, which on this strongly
collinear library picks the physical term where thresholding the full least-
squares solution does not): at each step the terms that best explain what the
current columns leave are screened, and the one that most lowers the χ² of
runs held out of the fit (K-fold over runs) is kept if it lowers it by at least
:data:`MIN_STEP_GAIN` of the base χ² — a term must pay for itself on runs it
was not fitted on — at most :data:`MAX_TERMS` terms.  The chosen term is then checked where it was
not fitted: fit on the low half of the speeds, predict the high half, and the
other way round; the same over ΔP.  It is printed with its units and labelled
as an empirical term, never as a named mechanism.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

MAX_TERMS = 3
#: a term must lower the held-out χ² by at least this fraction of the base model's
MIN_STEP_GAIN = 0.01
#: the library has its μ factors where the viscosity's largest value is this many times its smallest
VISCOSITY_SPAN = 1.25

_CH_UNIT = {"torque": ("N·m", {}), "q_a": ("m³/s", {}), "q_b": ("m³/s", {}), "q_case": ("m³/s", {})}
_CH_SYMBOL = {"torque": "ΔT", "q_a": "ΔQ_A", "q_b": "ΔQ_B", "q_case": "ΔQ_case"}
_ENG = {"torque": ("N·m", 1.0), "q_a": ("L/min", 6e4), "q_b": ("L/min", 6e4), "q_case": ("L/min", 6e4)}


@dataclass(frozen=True)
class Factor:
    """One factor of a library term: its formula, its dimension (exponents of Pa and s) and values."""

    text: str
    pa: float
    s: float
    fn: object  # Samples → array


def _speed_factors():
    return [Factor("", 0, 0, lambda x: np.ones_like(x.speed)),
            Factor("sgn ω", 0, 0, lambda x: np.asarray(x.direction, float)),
            Factor("ω", 0, -1, lambda x: x.speed),
            Factor("ω|ω|", 0, -2, lambda x: x.speed * np.abs(x.speed)),
            Factor("ω³", 0, -3, lambda x: x.speed ** 3),
            Factor("sgn ω·√|ω|", 0, -0.5, lambda x: np.asarray(x.direction, float) * np.sqrt(np.abs(x.speed)))]


def _even_speed_factors():
    """A case-drain flow does not reverse with the shaft: its speed factors are even in ω."""
    return [Factor("", 0, 0, lambda x: np.ones_like(x.speed)),
            Factor("|ω|", 0, -1, lambda x: np.abs(x.speed)),
            Factor("ω²", 0, -2, lambda x: x.speed ** 2),
            Factor("|ω|³", 0, -3, lambda x: np.abs(x.speed) ** 3),
            Factor("√|ω|", 0, -0.5, lambda x: np.sqrt(np.abs(x.speed)))]


def _pressure_factors():
    return [Factor("", 0, 0, lambda x: np.ones_like(x.speed)),
            Factor("ΔP", 1, 0, lambda x: x.p_a - x.p_b),
            Factor("|ΔP|", 1, 0, lambda x: np.abs(x.p_a - x.p_b)),
            Factor("√|ΔP|", 0.5, 0, lambda x: np.sqrt(np.abs(x.p_a - x.p_b))),
            Factor("(P_A+P_B)", 1, 0, lambda x: x.p_a + x.p_b),
            Factor("(P_A−P_c)", 1, 0, lambda x: x.p_a - x.p_case),
            Factor("(P_B−P_c)", 1, 0, lambda x: x.p_b - x.p_case),
            Factor("(P_A−P_c)(P_B−P_c)", 2, 0, lambda x: (x.p_a - x.p_case) * (x.p_b - x.p_case)),
            Factor("ΔP²", 2, 0, lambda x: (x.p_a - x.p_b) ** 2),
            # odd in ΔP, as a flow between the ports is: through an orifice, through gaps that open
            Factor("sgn ΔP·√|ΔP|", 0.5, 0, lambda x: np.sign(x.p_a - x.p_b) * np.sqrt(np.abs(x.p_a - x.p_b))),
            Factor("ΔP|ΔP|", 2, 0, lambda x: (x.p_a - x.p_b) * np.abs(x.p_a - x.p_b)),
            Factor("(P_A+P_B)²", 2, 0, lambda x: (x.p_a + x.p_b) ** 2)]


def _viscosity_factors():
    return [Factor("", 0, 0, lambda x: np.ones_like(x.speed)),
            Factor("μ", 1, 1, lambda x: x.viscosity),
            Factor("/μ", -1, -1, lambda x: 1.0 / x.viscosity)]


def _harmonic_factors(pistons: int):
    out = []
    for k in sorted({1, 2, 3, 4, pistons, 2 * pistons}):
        for trig, f in (("cos", np.cos), ("sin", np.sin)):
            kk = "" if k == 1 else str(k)
            out.append(Factor(f"{trig} {kk}θ", 0, 0, (lambda f, k: lambda x: f(k * x.theta))(f, k)))
    return out


@dataclass(frozen=True)
class Term:
    """A library term: the product of its factors."""

    factors: tuple

    @property
    def text(self) -> str:
        parts = [f.text for f in self.factors if f.text and f.text != "/μ"]
        out = "·".join(parts) or "1"
        return out + "/μ" if any(f.text == "/μ" for f in self.factors) else out

    @property
    def dims(self) -> tuple[float, float]:
        return sum(f.pa for f in self.factors), sum(f.s for f in self.factors)

    def values(self, x):
        v = np.ones_like(np.asarray(x.speed, float))
        for f in self.factors:
            v = v * f.fn(x)
        return v


def library(pistons: int, harmonics: bool = True, viscosity: bool = True, channel: str | None = None) -> list[Term]:
    """Every candidate term (see module doc), without the constant; ``harmonics=False`` leaves
    out the shaft-order harmonics (θ-averaged operating points have no shaft angle),
    ``viscosity=False`` the μ factors (data at one viscosity: μ·t and t/μ are t rescaled);
    ``channel="q_case"`` takes the speed factors even in ω (the drain does not reverse with the
    shaft: 1, |ω|, ω², √|ω|)."""
    terms = []
    for a in _even_speed_factors() if channel == "q_case" else _speed_factors():
        for b in _pressure_factors():
            for c in _viscosity_factors() if viscosity else _viscosity_factors()[:1]:
                if a.text or b.text or c.text:
                    terms.append(Term((a, b, c)))
    for h in _harmonic_factors(pistons) if harmonics else ():
        terms.append(Term((h,)))
        terms.append(Term((h, _pressure_factors()[1])))
    return terms


#: per channel: the words and dimensions (exponents of Pa and s, as :attr:`Term.dims`) of the columns
#: of :func:`nuisance`, in its order
NUISANCE_SHAPES = {
    "torque": [("1", 0, 0), ("sgn ω", 0, 0), ("sgn ω·(P_A+P_B)", 1, 0), ("μω", 1, 0)],
    "q_a": [("1", 0, 0), ("(P_A−P_c)/μ", 0, -1), ("ΔP/μ", 0, -1)],
    "q_b": [("1", 0, 0), ("(P_B−P_c)/μ", 0, -1), ("ΔP/μ", 0, -1)],
    "q_case": [("1", 0, 0), ("(P_A+P_B−2P_c)/μ", 0, -1)],
}
#: a proposed term whose own size exceeds this multiple of the change it makes to the fitted curve
#: is printed with the model's own shapes it moves (it works mostly by trading with them)
SHARED_RATIO = 3.0


def nuisance(channel: str, x, spec) -> np.ndarray:
    """Columns of the 1992 model's own shapes in this channel (left unpenalized)."""
    d = np.asarray(x.direction, float)
    if channel == "torque":
        cols = [d, d * (x.p_a + x.p_b), x.viscosity * x.speed]
    elif channel == "q_a":
        cols = [(x.p_a - x.p_case) / x.viscosity, (x.p_a - x.p_b) / x.viscosity]
    elif channel == "q_b":
        cols = [(x.p_b - x.p_case) / x.viscosity, (x.p_a - x.p_b) / x.viscosity]
    else:
        cols = [(x.p_a + x.p_b - 2 * x.p_case) / x.viscosity]
    return np.column_stack([np.ones_like(d)] + cols)


def _unit(channel: str, dims) -> str:
    """Unit of a coefficient: channel unit / term dimension (Pa^a s^b)."""
    base = _CH_UNIT[channel][0]
    pa, s = -dims[0], -dims[1]
    if channel != "torque":  # m³/s · s^b
        s = s - 1
        base = "m³"
    num, den = [base], []

    def put(sym, e):
        if e == 0:
            return
        txt = sym if abs(e) == 1 else f"{sym}^{abs(e):g}"
        (num if e > 0 else den).append(txt)

    put("Pa", pa)
    put("s", s)
    unit = "·".join(num)
    if den:
        unit += "/" + ("·".join(den) if len(den) == 1 else "(" + "·".join(den) + ")")
    return unit


@dataclass
class EmpiricalTerm:
    """A proposed empirical term of one channel (never a named mechanism)."""

    channel: str
    terms: list  # [(Term, coefficient SI)]
    held_out_gain: float  # fraction of the held-out residual χ² (over the base) it removes, K-fold over runs
    region_gain: dict = field(default_factory=dict)  # split → fraction removed where not fitted
    size: float = 0.0  # RMS of the change it makes to the fitted curve over the data [SI]
    #: [(words, dims, coefficient change SI)]: the 1992 model's own shapes that move with the term,
    #: listed where the term alone is more than SHARED_RATIO times ``size`` (see :func:`propose`; each
    #: shape whose own change is ≥ 5 % of ``size``)
    shapes: list = field(default_factory=list)
    alone: float = 0.0  # RMS of the term's own columns over the data [SI]

    @property
    def formula(self) -> str:
        parts = [f"{c:+.3g} {_unit(self.channel, t.dims)} · {t.text}" for t, c in self.terms]
        text = f"{_CH_SYMBOL[self.channel]} ≈ " + " ".join(parts).lstrip("+")
        if self.shapes:
            moved = " ".join(f"{c:+.3g} {_unit(self.channel, (pa, sec))}" + ("" if w == "1" else f" · {w}")
                             for w, pa, sec, c in self.shapes)
            text += (f", together with the model's own shapes refitted by {moved} (the term alone is "
                     f"{self.alone / self.size:.3g}× the change it makes: read them as one)")
        return text

    def as_dict(self) -> dict:
        unit, f = _ENG[self.channel]
        return {"label": "empirical term (not a named mechanism)", "channel": self.channel,
                "formula": self.formula,
                "terms": [{"term": t.text, "coefficient": c, "unit": _unit(self.channel, t.dims)} for t, c in self.terms],
                "size_rms": self.size, "size_words": f"{self.size * f:.3g} {unit} RMS over the logged points",
                "model_shapes_moved": [{"term": w, "coefficient": c, "unit": _unit(self.channel, (pa, sec))}
                                       for w, pa, sec, c in self.shapes],
                "held_out_gain": self.held_out_gain, "region_gain": self.region_gain}


def cv_sse(Z, y, cols, fold, folds: int) -> float:
    """Sum of squared held-out residuals, K-fold over runs, of least squares on columns ``cols``."""
    total = 0.0
    for f in range(folds):
        tr = fold != f
        b = np.linalg.lstsq(Z[tr][:, cols], y[tr], rcond=None)[0]
        total += float(np.sum((y[~tr] - Z[~tr][:, cols] @ b) ** 2))
    return total


def _forward(Z, y, k_free: int, fold, folds: int, max_terms: int = MAX_TERMS, screen: int = 6):
    """Forward stepwise selection: at each step the library terms that best explain what the
    current columns leave (after projecting those columns out) are screened, the one with the
    smallest held-out χ² is taken if it lowers it by at least MIN_STEP_GAIN.  Returns the chosen
    column indices and the held-out χ² before and after."""
    cols = list(range(k_free))
    base = cur = cv_sse(Z, y, cols, fold, folds)
    chosen: list[int] = []
    lib = np.arange(k_free, Z.shape[1])
    norms0 = np.sqrt(np.sum(Z[:, lib] ** 2, axis=0))
    for _ in range(max_terms):
        Q, _r = np.linalg.qr(Z[:, cols])
        r = y - Q @ (Q.T @ y)
        Zc = Z[:, lib] - Q @ (Q.T @ Z[:, lib])
        norm = np.sqrt(np.sum(Zc**2, axis=0))
        usable = (norm > 1e-6 * norms0) & ~np.isin(lib, chosen)
        score = np.where(usable, (Zc.T @ r) ** 2 / np.where(usable, norm**2, 1.0), -np.inf)
        best, best_cv = None, cur
        for j in np.argsort(-score)[:screen]:
            if not np.isfinite(score[j]):
                continue
            cv = cv_sse(Z, y, cols + [int(lib[j])], fold, folds)
            if cv < best_cv:
                best, best_cv = int(lib[j]), cv
        if best is None or best_cv > cur - MIN_STEP_GAIN * base:
            break
        chosen.append(best)
        cols.append(best)
        cur = best_cv
    return chosen, base, cur


def _design(channel, x, spec, terms):
    N = nuisance(channel, x, spec)
    L = np.column_stack([t.values(x) for t in terms])
    return N, L


def _prepared(channel, x, residual, sigma, run_of, spec, folds: int, harmonics: bool, extra=None):
    """The weighted, scaled design of :func:`propose` → (Z, y, k, terms, N, L, ok, scale, fold), or None
    where the runs are too few for its folds; ``extra``: one more column (SI, per sample), weighted and
    scaled alike and put last."""
    mu = np.asarray(x.viscosity, float)
    # the μ factors only where the viscosity spans enough to tell t/μ from t: within one oil temperature
    # and its drift (0.4 % on a probe's bench) the two are one column, and a term printed with /μ would
    # say a viscosity law the data never saw
    varies = bool(np.nanmax(mu) > VISCOSITY_SPAN * np.nanmin(mu))
    terms = library(spec.pistons, harmonics, viscosity=varies, channel=channel)
    N, L = _design(channel, x, spec, terms)
    w = 1.0 / np.asarray(sigma, float)
    y = np.asarray(residual, float) * w
    X = np.column_stack([N, L]) * w[:, None]
    ok = np.all(np.isfinite(X), axis=1) & np.isfinite(y)
    if extra is not None:
        ok &= np.isfinite(extra)
    X, y, run_of = X[ok], y[ok], np.asarray(run_of)[ok]
    k = N.shape[1]
    distinct = _distinct_columns(X[:, k:])  # on data of one sign of ΔP, sgn ΔP·√|ΔP| is ±√|ΔP|: one of the two
    terms, L = [terms[i] for i in distinct], L[:, distinct]
    X = X[:, list(range(k)) + [k + i for i in distinct]]
    if extra is not None:
        X = np.column_stack([X, (np.asarray(extra, float) * w)[ok]])
    scale = np.sqrt(np.mean(X**2, axis=0))
    scale[scale == 0] = 1.0
    Z = X / scale
    if np.unique(run_of).size < 2 * folds:
        return None
    return Z, y, k, terms, N, L, ok, scale, fold_labels(run_of, folds)


#: a named law is a stand-in by its shape (:func:`law_shape_check`) where, once the library's terms that
#: what it leaves asks for are in, it adds less than this share of what those terms add beside it ...
REDUNDANT_SHARE = 0.1
#: ... and those terms lower the held-out χ² by at least this much
MIN_SHAPE_GAIN = 50.0
#: a law whose column lies within this share (RMS) of the model's own shapes in its channel is one of them
OWN_SHAPE_SHARE = 1e-3


def own_shape(shapes, column) -> bool:
    """Whether ``column`` (a law's change, weighted and scaled like the design) is, on these samples,
    one of the 1992 model's own shapes ``shapes`` (the design's first columns, which take a constant):
    a meter's zero offset is the constant itself, so the terms cannot make it redundant by its shape,
    nor can its shape be judged against them (a probe's flow-meter zero on port A, true and 5σ, was
    refused as "adding 0" beside a leftover ∝ ω of another cause)."""
    norm = float(np.sqrt(np.mean(column**2)))
    if norm == 0:
        return True
    coef = np.linalg.lstsq(shapes, column, rcond=None)[0]
    return float(np.sqrt(np.mean((column - shapes @ coef) ** 2))) < OWN_SHAPE_SHARE * norm


def law_shape_check(channel: str, x, residual, change, sigma, run_of, spec, folds: int = 3,
                    harmonics: bool = True) -> dict | None:
    """Whether a named mechanism's law has the shape of what it was named for, on one channel.

    ``change``: what the mechanism adds to the channel in the final fit (its values against its neutral
    ones, the other parameters held) [SI, per sample]; ``residual``: the final fit's.  What is to be
    explained without it (residual + change) is fitted, on held-out runs (K-fold), by the 1992 model's
    shapes and the law's change at a free scale; the library's terms that what they leave asks for are
    selected (:func:`propose`'s forward selection).  The law is a stand-in by its shape where those terms
    lower the held-out χ² by :data:`MIN_SHAPE_GAIN` and, with them in, the law adds less than
    :data:`REDUNDANT_SHARE` of that: the terms explain what it was named for without it.  A churning law
    ∝ ω|ω| fitted to a torque loss ∝ ω³ leaves a located spread, the term ω³ takes it, and ω|ω| then adds
    nothing.  A true law with a second effect beside it is kept: the terms take the second effect, and
    the law stays needed beside them.
    → {stand_in, terms, law_left, both_left, terms_left} (held-out χ² of the model's shapes with the law,
    with the law and the terms, with the terms alone), or None (too few runs, no term chosen, or a law
    that is itself one of the model's shapes there: :func:`own_shape`, a meter's zero offset)."""
    target = np.asarray(residual, float) + np.asarray(change, float)
    prep = _prepared(channel, x, target, sigma, run_of, spec, folds, harmonics, extra=change)
    if prep is None:
        return None
    Z, y, k, terms, *_rest, fold = prep
    g = Z.shape[1] - 1  # the law's column, last: moved beside the model's shapes, free like them
    if own_shape(Z[:, :k], Z[:, g]):  # a meter's zero is the shapes' constant: its shape cannot be judged
        return None
    order = list(range(k)) + [g] + list(range(k, g))
    chosen, law_left, both_left = _forward(Z[:, order], y, k + 1, fold, folds)
    if not chosen:
        return None
    chosen = [order[j] for j in chosen]
    terms_left = cv_sse(Z, y, list(range(k)) + chosen, fold, folds)
    gain = law_left - both_left
    stand_in = gain > MIN_SHAPE_GAIN and terms_left - both_left < REDUNDANT_SHARE * gain
    return {"stand_in": bool(stand_in), "terms": [terms[j - k].text for j in chosen], "law_left": law_left,
            "both_left": both_left, "terms_left": terms_left}


def propose(channel: str, x, residual, sigma, run_of, spec, folds: int = 3, regions: dict | None = None,
            harmonics: bool = True):
    """The sparsest library term that explains ``residual`` on held-out runs, or None.

    x : Samples (numpy) of the channel's inlier samples; residual, sigma [SI]; run_of : run index per sample.
    regions : name → boolean mask (True: first part) for the where-not-fitted check.
    """
    prep = _prepared(channel, x, residual, sigma, run_of, spec, folds, harmonics)
    if prep is None:
        return None
    Z, y, k, terms, N, L, ok, scale, fold = prep
    chosen_idx, base, best = _forward(Z, y, k, fold, folds)
    if not chosen_idx:
        return None
    cols = list(range(k)) + chosen_idx
    beta = np.zeros(Z.shape[1])
    beta[cols] = np.linalg.lstsq(Z[:, cols], y, rcond=None)[0]
    beta = beta / scale * 1.0
    chosen = [(terms[i - k], float(beta[i])) for i in chosen_idx]
    # coefficients in SI: the columns were divided by σ (weights) and by their RMS (scale)
    # its size: how far it moves the fitted curve (the base shapes refitted without it), not the term
    # alone, which a base shape it shares would inflate
    without = np.zeros(Z.shape[1])
    without[:k] = np.linalg.lstsq(Z[:, :k], y, rcond=None)[0] / scale[:k]
    design = np.column_stack([N, L])[ok]
    size = float(np.sqrt(np.mean((design @ (beta - without)) ** 2)))
    # the term alone: where it is far larger than the change it makes, it works by trading with the
    # model's own shapes (on a bench whose low port sits at one pressure, a ΔP term is K_F's shape
    # sgn ω·(P_A+P_B) moved), and its formula alone would overstate it: those shapes are printed too
    rms = lambda v: float(np.sqrt(np.mean(v**2)))  # noqa: E731
    alone = rms(design[:, chosen_idx] @ beta[chosen_idx])
    shapes = []
    if size > 0 and alone > SHARED_RATIO * size:
        shift = beta[:k] - without[:k]
        for j, (words, pa, sec) in enumerate(NUISANCE_SHAPES[channel][:k]):
            if rms(design[:, j] * shift[j]) >= 0.05 * size:  # every shape that moves 5 % of the change
                shapes.append((words, pa, sec, float(shift[j])))
    gain = 1.0 - best / base if base > 0 else 0.0
    region_gain = region_gains(Z, y, k, list(chosen_idx), {n: np.asarray(m)[ok] for n, m in (regions or {}).items()})
    return EmpiricalTerm(channel, chosen, float(gain), region_gain, size, shapes, alone)


def _distinct_columns(X) -> list:
    """Indices of the columns of ``X`` that are not ± an earlier one (the first of each such set kept):
    on the data at hand two library terms can be one column (sgn ΔP·√|ΔP| and √|ΔP| where ΔP has one
    sign), and the formula must not claim the one the data cannot tell from the other."""
    gram = X.T @ X  # one pass over the rows (they are the samples: up to a few hundred thousand)
    norms = np.sqrt(np.maximum(np.diag(gram), 0.0))
    keep = []
    for j in range(X.shape[1]):
        if norms[j] == 0:
            continue
        if keep and np.any(np.abs(gram[keep, j]) > (1.0 - 1e-12) * norms[keep] * norms[j]):
            continue
        keep.append(j)
    return keep


def fold_labels(run_of, folds: int) -> np.ndarray:
    """Fold index (0 … folds−1) of each sample: the runs, in sorted order, dealt round the folds."""
    runs, inverse = np.unique(np.asarray(run_of), return_inverse=True)
    return (np.arange(runs.size) % folds)[inverse]


#: a term may lose at most this share of a region's held-out χ² where it was not fitted (fitted on the
#: upper half, a small term may lose a little to the noise below)
REGION_LOSS_LIMIT = -0.25


def regions_hold(region_gain: dict) -> bool:
    """Whether a term's where-not-fitted gains (:func:`region_gains`) average above zero with none below
    :data:`REGION_LOSS_LIMIT` (no regions to split: nothing against it)."""
    gains = list(region_gain.values())
    return not gains or (float(np.mean(gains)) > 0.0 and min(gains) > REGION_LOSS_LIMIT)


#: a split counts only where its training part knows each chosen term's coefficient to this share of it
DETERMINED_REL_STD = 0.5


def _determined(A, y, b, rank: int, which) -> bool:
    """Whether least squares of ``y`` on ``A`` (solution ``b``) determines the coefficients ``which``:
    each standard error (from (AᵀA)⁻¹ and the residual variance) below DETERMINED_REL_STD of its value."""
    if rank < A.shape[1]:
        return False
    dof = max(A.shape[0] - A.shape[1], 1)
    s2 = float(np.sum((y - A @ b) ** 2)) / dof
    try:
        cov = np.linalg.inv(A.T @ A) * s2
    except np.linalg.LinAlgError:
        return False
    return all(np.sqrt(max(cov[j, j], 0.0)) < DETERMINED_REL_STD * abs(b[j]) for j in which)


def region_gains(Z, y, k: int, idx: list, regions: dict) -> dict:
    """Where-not-fitted check: for each region split (name (first, second) → mask, True: first) and
    each way round, the fraction of the held-out part's residual χ² that the columns ``idx`` remove
    when added to the first ``k`` (the nuisance columns), both fitted on the other part; a way round
    whose training part does not determine the terms' coefficients (:func:`_determined`) is left out."""
    out = {}
    cols = list(range(k)) + list(idx)
    for name, m in regions.items():
        for tr_mask, label in ((m, f"fit on {name[0]}, predict {name[1]}"), (~m, f"fit on {name[1]}, predict {name[0]}")):
            te_mask = ~tr_mask
            if tr_mask.sum() < 10 or te_mask.sum() < 10:
                continue
            b_with, _res, rank, _sv = np.linalg.lstsq(Z[tr_mask][:, cols], y[tr_mask], rcond=None)
            if not _determined(Z[tr_mask][:, cols], y[tr_mask], b_with, rank, range(k, len(cols))):
                continue  # an ω³ term fitted on the slow runs alone is not known there: it predicts nothing
            b_without = np.linalg.lstsq(Z[tr_mask][:, :k], y[tr_mask], rcond=None)[0]
            r_with = float(np.sum((y[te_mask] - Z[te_mask][:, cols] @ b_with) ** 2))
            r_without = float(np.sum((y[te_mask] - Z[te_mask][:, :k] @ b_without) ** 2))
            out[label] = 1.0 - r_with / r_without if r_without > 0 else 0.0
    return out
