"""Population model and wear trends on per-motor estimates with a known truth (no fits: fast)."""

import datetime as dt
import math

import numpy as np
import pytest
from scipy import stats

from motorid.fleet.population import analyse_type, fit_random_effects, predictive_test
from motorid.fleet.trends import motor_trends, wls_slope

# a population of 12 motors of one type: (parameter, centre SI, spread, scale)
POP = {"KL0": (5e-14, 0.15, "log"), "Kv": (5000.0, 0.08, "log"), "KL_a1": (0.15, 0.02, "linear")}


def _fleet(rng, k=12, outlier=None):
    """Per-motor estimates drawn from POP with per-motor relative errors of 1-5 % (2-4 % for KL_a1)."""
    est, truth = {}, {}
    serials = [f"SN-{i:02d}" for i in range(k)]
    for p, (centre, spread, scale) in POP.items():
        if scale == "log":
            theta = rng.normal(math.log(centre), spread, k)
            if outlier and p == outlier[1]:
                theta[outlier[0]] += math.log(outlier[2])
            true = np.exp(theta)
            std = rng.uniform(0.01, 0.05, k) * true
        else:
            true = rng.normal(centre, spread, k)
            std = np.full(k, 0.003)
        truth[p] = true
        est[p] = (serials, true + rng.normal(0, std), std)
    return est, truth


def test_population_recovered_outlier_flagged_clean_not():
    """One fleet (six 95 % intervals: one of them misses in about a quarter of fleets; their coverage
    over many fleets is test_intervals_cover_at_their_level)."""
    rng = np.random.default_rng(21)
    est, _ = _fleet(rng, outlier=(4, "KL0", 4.0))
    pops, verdicts = analyse_type("A2FM-80", est)
    for p, (centre, spread, scale) in POP.items():
        pop = pops[p]
        mu = math.log(centre) if scale == "log" else centre
        assert pop.mu_ci95[0] <= mu <= pop.mu_ci95[1], (p, pop.mu_ci95, mu)
        assert pop.tau_ci95[0] <= spread <= pop.tau_ci95[1], (p, pop.tau_ci95, spread)
        assert pop.mu_ci95[0] < pop.mu < pop.mu_ci95[1] and pop.tau_ci95[0] <= pop.tau < pop.tau_ci95[1]
        # the SI mean's interval holds the true population mean (log-normal: exp(μ + τ²/2))
        true_mean = math.exp(mu + spread**2 / 2) if scale == "log" else mu
        assert pop.mean_ci95[0] <= true_mean <= pop.mean_ci95[1]
    flagged = [(v.serial, v.parameter) for v in verdicts if v.out_of_family]
    assert flagged == [("SN-04", "KL0")]
    v = next(v for v in verdicts if v.out_of_family)
    assert v.probability > 1 - v.threshold and v.threshold == pytest.approx(0.01 / 36)
    # the outlier is left out of the population it was judged against
    assert pops["KL0"].excluded == ["SN-04"] and pops["KL0"].n == 11


def test_intervals_cover_at_their_level():
    """The 95 % intervals of μ (HKSJ) and τ (REML profile) over 150 clean 12-motor fleets: near their
    level (binomial spread ±3.6 points; bench_fleet measures it over more fleets)."""
    from motorid.fleet.population import fit_population

    rng = np.random.default_rng(23)
    n = 150
    hits = {p: [0, 0] for p in POP}
    for _ in range(n):
        est, _ = _fleet(rng)
        for p, (centre, spread, scale) in POP.items():
            pop = fit_population("A", p, *est[p])
            mu = math.log(centre) if scale == "log" else centre
            hits[p][0] += pop.mu_ci95[0] <= mu <= pop.mu_ci95[1]
            hits[p][1] += pop.tau_ci95[0] <= spread <= pop.tau_ci95[1]
    for p, (h_mu, h_tau) in hits.items():
        assert 0.89 <= h_mu / n <= 0.995 and 0.89 <= h_tau / n <= 0.995, (p, h_mu, h_tau)


def test_shrinkage_is_the_empirical_bayes_posterior():
    rng = np.random.default_rng(3)
    est, _ = _fleet(rng)
    pops, verdicts = analyse_type("A2FM-80", est)
    pop = pops["KL0"]
    for v in (v for v in verdicts if v.parameter == "KL0"):
        y, s = math.log(v.value), v.std / v.value
        B = s**2 / (s**2 + pop.tau**2)
        assert math.log(v.shrunk) == pytest.approx((1 - B) * y + B * pop.mu, rel=1e-12)
        # between the motor's own estimate and the population centre
        lo, hi = sorted((y, pop.mu))
        assert lo - 1e-12 <= math.log(v.shrunk) <= hi + 1e-12
        assert v.shrunk_std < v.std  # pooling never loses information


def test_reml_is_the_marginal_likelihood_of_tau():
    """REML's τ̂ maximizes ∫ L(μ, τ) dμ (the restricted likelihood is μ integrated out, flat prior)."""
    from scipy import integrate, optimize

    rng = np.random.default_rng(5)
    y, s = rng.normal(1.0, 0.3, 8), rng.uniform(0.05, 0.2, 8)
    mu, tau, se, lhat = fit_random_effects(y, s)

    def integrated(t):
        var = t**2 + s**2
        f = lambda m: np.exp(-0.5 * np.sum(np.log(2 * np.pi * var) + (y - m) ** 2 / var))  # noqa: E731
        return integrate.quad(f, mu - 3, mu + 3, points=[mu], epsabs=0, epsrel=1e-11)[0]

    r = optimize.minimize_scalar(lambda t: -np.log(integrated(t)), bounds=(1e-4, 2.0), method="bounded",
                                 options={"xatol": 1e-9})
    assert tau == pytest.approx(r.x, rel=1e-4)
    w = 1 / (tau**2 + s**2)
    assert mu == pytest.approx(np.sum(w * y) / np.sum(w), rel=1e-12) and se == pytest.approx(np.sum(w) ** -0.5)


def test_clean_fleets_rarely_flag_anything():
    """Family-wise rate: over 60 clean 10-motor fleets (3 parameters each), flags stay near α = 1 %."""
    rng = np.random.default_rng(11)
    fleets_with_flags = 0
    for _ in range(60):
        est, _ = _fleet(rng, k=10)
        _, verdicts = analyse_type("A", est)
        fleets_with_flags += any(v.out_of_family for v in verdicts)
    assert fleets_with_flags <= 3  # P(> 3 | rate 1 %) < 0.3 %


def test_predictive_deviate_is_student_t_under_the_family():
    """Eq. P4's p-value is uniform for a motor drawn from the family (KS test over 400 draws)."""
    rng = np.random.default_rng(2)
    ps = []
    for _ in range(400):
        y = rng.normal(0.0, 0.2, 9)
        s = np.full(9, 0.05)
        y = y + rng.normal(0, s)
        ps.append(predictive_test(y[0], s[0], y[1:], s[1:])[1])
    assert stats.kstest(ps, "uniform").pvalue > 0.01
    assert np.mean(np.asarray(ps) < 0.05) <= 0.08


def test_trends_rising_for_wear_stable_for_clean_and_two_date_difference():
    rng = np.random.default_rng(8)
    dates = [dt.date(2024, 1, 10), dt.date(2024, 9, 1), dt.date(2025, 6, 20)]
    t = np.array([(d - dates[0]).days / 365.25 for d in dates])
    kl0 = 5e-14 * (1 + 0.4 * t)  # leakage up 40 % a year
    s_kl0 = 0.01 * kl0
    series = {"KL0": [(d, x + rng.normal(0, s), s) for d, x, s in zip(dates, kl0, s_kl0)],
              "Kv": [(d, 5000 + rng.normal(0, 20), 20.0) for d in dates]}
    trends = {tr.parameter: tr for tr in motor_trends("SN-7", series)}
    assert trends["KL0"].verdict == "rising"
    assert trends["KL0"].ci95[0] <= 0.4 * 5e-14 <= trends["KL0"].ci95[1]
    assert trends["Kv"].verdict == "stable"
    # two dates: the difference over the time between them, SE from both standard errors
    two = {"KAB": [(dt.date(2025, 1, 1), 2.0e-14, 1e-16), (dt.date(2026, 1, 1), 2.1e-14, 2e-16)]}
    (tr,) = motor_trends("SN-8", two)
    dt_years = 365 / 365.25
    assert tr.per_year == pytest.approx(0.1e-14 / dt_years, rel=1e-9)
    assert tr.se == pytest.approx(math.hypot(1e-16, 2e-16) / dt_years, rel=1e-9)
    assert tr.verdict == "rising"


def test_trend_interval_covers_and_birge_widens():
    """The 95 % interval of the slope covers the truth at its level (300 re-tested motors)."""
    rng = np.random.default_rng(4)
    t = np.array([0.0, 0.5, 1.0, 1.5])
    hit = 0
    for _ in range(300):
        x = 1.0 + 0.1 * t + rng.normal(0, 0.05, 4)
        b, se, dof = wls_slope(t, x, np.full(4, 0.05))
        q = stats.t.isf(0.025, dof)
        hit += b - q * se <= 0.1 <= b + q * se
    assert 0.93 <= hit / 300 <= 1.0
    # scatter beyond the stated errors widens the interval (Birge ratio)
    x = 1.0 + 0.1 * t + np.array([0.3, -0.3, 0.3, -0.3])
    b, se, _ = wls_slope(t, x, np.full(4, 0.05))
    assert se > 1.0 / math.sqrt(np.sum((t - t.mean()) ** 2) / 0.05**2) * 1.5
