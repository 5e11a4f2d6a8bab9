"""The population model of one motor type: random-effects meta-analysis, parameter by parameter.

Each motor i's parameter (in log space for the positive parameters, see
:func:`scale_of`) is a draw from the population, and its estimate carries its
own standard error [Eq. P1]::

    θ_i ~ N(μ, τ²),     y_i | θ_i ~ N(θ_i, s_i²)      ⇒   y_i ~ N(μ, τ² + s_i²)

(y_i = log x̂_i and s_i = σ_i / x̂_i for a positive parameter, the delta method;
y_i = x̂_i, s_i = σ_i otherwise).  The marginal likelihood is [Eq. P2]::

    ℓ(μ, τ) = −½ Σ_i [ log 2π(τ² + s_i²) + (y_i − μ)² / (τ² + s_i²) ]

and τ is fitted by restricted maximum likelihood (REML, Viechtbauer 2005, J. Educ.
Behav. Stat. 30:261) [Eq. P2']::

    ℓ_R(τ) = ℓ(μ̂(τ), τ) − ½ log Σ_i w_i(τ),   w_i = 1/(τ² + s_i²),   μ̂(τ) = Σ w_i y_i / Σ w_i

(plain ML under-states τ by about a factor √((k−1)/k) with k motors), with a 95 %
interval from the restricted profile likelihood, {2(ℓ_R(τ̂) − ℓ_R(τ)) ≤
χ²₁(0.95)}; μ's 95 % interval is Hartung-Knapp-Sidik-Jonkman's, μ̂ ± t_{k−1}·
√(max(1, q)/Σw_i) with q = Σw_i(y_i − μ̂)²/(k − 1) (IntHout et al. 2014, BMC Med.
Res. Methodol. 14:25: near its level with a dozen motors, where the Wald or ML
profile interval is too short).  The SI mean and sd of the population (a
log-normal family: mean = exp(μ + τ²/2), sd = mean·√(exp τ² − 1)) take the
corners of the (μ, τ) interval box.  Why not MCMC: one scalar μ and τ per
parameter; these closed forms and one-dimensional profiles are exact to the
solver's tolerance, free of sampler noise, and stay cheap for a thousand motors;
their coverage is measured in benchmarks/bench_fleet.py.

Per-motor shrunken estimates are the empirical-Bayes posterior (Morris 1983,
JASA 78:47) [Eq. P3]::

    B_i = s_i² / (s_i² + τ̂²),   θ̃_i = (1 − B_i) y_i + B_i μ̂,   var θ̃_i = (1 − B_i) s_i² + B_i² var μ̂

Out of family [Eq. P4]: motor i is compared with the population fitted on the
*other* motors (μ₋ᵢ, τ₋ᵢ, SE(μ₋ᵢ)); under "motor i belongs to the family" its
estimate follows the predictive distribution (Higgins, Thompson & Spiegelhalter
2009, J. R. Stat. Soc. A 172:137)::

    (y_i − μ₋ᵢ) / √(τ₋ᵢ² + SE(μ₋ᵢ)² + s_i²)  ~  t_{k−3}        (k motors in all, k−1 in the fit)

p_i is its two-sided tail probability and ``probability`` = 1 − p_i, the
posterior-predictive probability that a motor of the family lies nearer the
population centre than this one.  A motor is out of family where p_i <
α / (M·P) with α = 0.01 over the M motors × P parameters of its type
(Bonferroni): at most a 1 % chance that a fleet of clean motors shows any flag,
whatever the fleet's size.  (A rule "true value outside the central 99 %" would
flag 1 % of clean motors by construction: ten in a fleet of a thousand.)
Flagged motors are left out of the population and the test is repeated on the
rest until no new flag appears, so one outlier cannot mask another.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, stats

#: parameters that are positive by their physics: modelled in log space
POSITIVE = frozenset({"Kv", "KF", "KFS", "TFc", "Ks", "KL0", "KAB"})
CHI2_95 = float(stats.chi2.ppf(0.95, 1))
FAMILY_ALPHA = 0.01
MIN_MOTORS = 3  # for a population fit
MIN_MOTORS_VERDICT = 4  # for an out-of-family verdict (the other motors make a population of 3)


def scale_of(parameter: str, values) -> str:
    """"log" for a positive parameter whose estimates are all > 0, else "linear"."""
    v = np.asarray(values, float)
    return "log" if parameter in POSITIVE and v.size and np.all(v > 0) else "linear"


def to_scale(values, stds, scale: str):
    """(y, s) of Eq. P1: log value and relative std for the log scale."""
    v, s = np.asarray(values, float), np.asarray(stds, float)
    return (np.log(v), s / v) if scale == "log" else (v, s)


def _loglik(y, s, mu, tau):
    var = tau * tau + s * s
    return -0.5 * float(np.sum(np.log(2 * np.pi * var) + (y - mu) ** 2 / var))


def _mu_hat(y, s, tau):
    w = 1.0 / (tau * tau + s * s)
    return float(np.sum(w * y) / np.sum(w)), float(1.0 / math.sqrt(np.sum(w)))


def restricted_loglik(y, s, tau) -> float:
    """Eq. P2': the restricted (REML) log-likelihood of τ, ℓ(μ̂(τ), τ) − ½ log Σ w_i (up to a constant)."""
    mu, se = _mu_hat(y, s, tau)
    return _loglik(y, s, mu, tau) + math.log(se)


def _tau_scale(y, s) -> float:
    return float(max(np.ptp(y), np.max(s), 1e-300))


def fit_random_effects(y, s) -> tuple[float, float, float, float]:
    """(μ̂, τ̂, SE(μ̂), ℓ_R(τ̂)): τ̂ maximizes the restricted likelihood (Eq. P2', τ̂ ≥ 0), μ̂ is the
    inverse-variance mean at τ̂ and SE(μ̂) = 1/√Σw_i."""
    y, s = np.asarray(y, float), np.asarray(s, float)
    big = 10 * _tau_scale(y, s)

    def neg(tau):
        return -restricted_loglik(y, s, tau)

    r = optimize.minimize_scalar(neg, bounds=(0.0, big), method="bounded", options={"xatol": 1e-10 * big})
    tau = float(r.x) if neg(r.x) < neg(0.0) else 0.0
    mu, se = _mu_hat(y, s, tau)
    return mu, tau, se, restricted_loglik(y, s, tau)


def _root(f, a, step, limit=60):
    """The first b beyond a (in the direction of step) where f changes sign; bisected."""
    b = a + step
    for _ in range(limit):
        if f(b) < 0:
            return optimize.brentq(f, a, b, xtol=1e-14 + 1e-12 * abs(b))
        a, b = b, b + (b - a) * 2
    return b


def profile_intervals(y, s, mu, tau, se, lhat):
    """95 % intervals: τ from the restricted profile likelihood, {2(ℓ_R(τ̂) − ℓ_R(τ)) ≤ χ²₁(0.95)};
    μ by Hartung-Knapp-Sidik-Jonkman, μ̂ ± t_{k−1} √(max(1, q) / Σw_i), q = Σw_i(y_i − μ̂)²/(k − 1)."""
    y, s = np.asarray(y, float), np.asarray(s, float)
    drop = CHI2_95 / 2

    def g_tau(t):
        return restricted_loglik(y, s, t) - (lhat - drop)

    tau_lo = 0.0 if g_tau(0.0) >= 0 else optimize.brentq(g_tau, 0.0, tau, xtol=1e-14 + 1e-12 * tau)
    tau_hi = _root(g_tau, tau, max(tau, se, 1e-300))
    k = y.size
    w = 1.0 / (tau * tau + s * s)
    q = float(np.sum(w * (y - mu) ** 2) / (k - 1))
    half = float(stats.t.isf(0.025, k - 1)) * math.sqrt(max(1.0, q) / np.sum(w))
    return (mu - half, mu + half), (tau_lo, tau_hi)


def si_moments(mu, tau, scale: str):
    """The population's SI mean and sd: log-normal moments on the log scale."""
    mu, tau = np.asarray(mu, float), np.asarray(tau, float)
    if scale == "log":
        mean = np.exp(mu + tau * tau / 2)
        return mean, mean * np.sqrt(np.expm1(tau * tau))
    return mu, tau


def si_intervals(mu_ci, tau_ci, scale: str):
    """Intervals of the SI mean and sd from those of μ and τ: both moments grow with μ and τ, so
    the corners of the box bound them (conservative where μ and τ are not both at an end)."""
    if scale != "log":
        return tuple(mu_ci), tuple(tau_ci)
    lo, hi = si_moments(mu_ci[0], tau_ci[0], scale), si_moments(mu_ci[1], tau_ci[1], scale)
    return (float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1]))


@dataclass
class Population:
    """The fitted population of one parameter of one motor type (Eq. P1-P2)."""

    motor_type: str
    parameter: str
    scale: str  # "log" or "linear"
    n: int  # motors in the fit
    mu: float
    tau: float
    se_mu: float
    mu_ci95: tuple
    tau_ci95: tuple
    mean: float  # SI
    sd: float  # SI
    mean_ci95: tuple
    sd_ci95: tuple
    motors: list = field(default_factory=list)  # serials in the fit
    excluded: list = field(default_factory=list)  # serials judged out of family, left out

    def band(self, z: float = 1.959963984540054):
        """The central interval of the family, SI: (low, centre, high)."""
        lo, c, hi = self.mu - z * self.tau, self.mu, self.mu + z * self.tau
        return tuple(math.exp(v) for v in (lo, c, hi)) if self.scale == "log" else (lo, c, hi)


@dataclass
class MotorVerdict:
    """One motor, one parameter: its estimate, shrunken estimate (Eq. P3) and verdict (Eq. P4)."""

    serial: str
    parameter: str
    value: float
    std: float
    shrunk: float  # SI (the posterior median on the log scale)
    shrunk_std: float  # SI (delta method on the log scale)
    z: float | None  # standardized predictive deviate; None where no verdict could be made
    probability: float | None  # 1 − p
    p_value: float | None
    threshold: float | None  # the p below which it is flagged, α/(M·P)
    out_of_family: bool


def fit_population(motor_type: str, parameter: str, serials, values, stds, scale: str | None = None) -> Population:
    """Eq. P1-P2 on the per-motor estimates (values, stds in SI)."""
    scale = scale or scale_of(parameter, values)
    y, s = to_scale(values, stds, scale)
    mu, tau, se, lhat = fit_random_effects(y, s)
    mu_ci, tau_ci = profile_intervals(y, s, mu, tau, se, lhat)
    mean_ci, sd_ci = si_intervals(mu_ci, tau_ci, scale)
    mean, sd = si_moments(mu, tau, scale)
    return Population(motor_type, parameter, scale, len(y), mu, tau, se, mu_ci, tau_ci, float(mean), float(sd),
                      mean_ci, sd_ci, list(serials))


def predictive_test(y_i, s_i, y_rest, s_rest):
    """Eq. P4: (z, two-sided p) of y_i against the population of the others."""
    mu, tau, se, _ = fit_random_effects(y_rest, s_rest)
    z = (y_i - mu) / math.sqrt(tau * tau + se * se + s_i * s_i)
    dof = max(len(y_rest) - 2, 1)
    return float(z), float(2 * stats.t.sf(abs(z), dof))


def analyse_type(motor_type: str, estimates: dict, alpha: float = FAMILY_ALPHA):
    """The population of one motor type.

    estimates : {parameter: (serials, values, stds)}, SI, one identifiable
        estimate per motor (its latest test date).
    Returns ({parameter: Population}, [MotorVerdict]); parameters with fewer
    than MIN_MOTORS motors get no population, fewer than MIN_MOTORS_VERDICT no verdict.
    """
    tests = sum(len(v[0]) for v in estimates.values() if len(v[0]) >= MIN_MOTORS_VERDICT)
    threshold = alpha / max(tests, 1)
    pops, verdicts = {}, []
    for parameter, (serials, values, stds) in estimates.items():
        serials = list(serials)
        values, stds = np.asarray(values, float), np.asarray(stds, float)
        k = len(serials)
        if k < MIN_MOTORS:
            continue
        scale = scale_of(parameter, values)
        y, s = to_scale(values, stds, scale)
        flagged: set = set()
        z, p = np.full(k, np.nan), np.full(k, np.nan)
        if k >= MIN_MOTORS_VERDICT:
            while True:  # test each motor against the others not (yet) judged out of family
                for i in range(k):
                    rest = [j for j in range(k) if j != i and j not in flagged]
                    if len(rest) < MIN_MOTORS:
                        continue
                    z[i], p[i] = predictive_test(y[i], s[i], y[rest], s[rest])
                new = {i for i in range(k) if p[i] < threshold} - flagged
                if not new or len(flagged | new) > k - MIN_MOTORS:
                    break
                flagged |= new
        keep = [i for i in range(k) if i not in flagged]
        pop = fit_population(motor_type, parameter, [serials[i] for i in keep], values[keep], stds[keep], scale)
        pop.excluded = [serials[i] for i in sorted(flagged)]
        pops[parameter] = pop
        for i in range(k):
            B = s[i] ** 2 / (s[i] ** 2 + pop.tau ** 2) if (s[i] > 0 or pop.tau > 0) else 0.0
            th = (1 - B) * y[i] + B * pop.mu
            var = (1 - B) * s[i] ** 2 + B * B * pop.se_mu ** 2
            shrunk, shrunk_std = (math.exp(th), math.exp(th) * math.sqrt(var)) if scale == "log" \
                else (th, math.sqrt(var))
            has = bool(np.isfinite(p[i]))
            verdicts.append(MotorVerdict(serials[i], parameter, float(values[i]), float(stds[i]), shrunk, shrunk_std,
                                         float(z[i]) if has else None, float(1 - p[i]) if has else None,
                                         float(p[i]) if has else None, threshold if has else None, i in flagged))
    return pops, verdicts
