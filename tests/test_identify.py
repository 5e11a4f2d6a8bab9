"""Identification from logs: synthetic recovery, identifiability, robustness (issue 4)."""

import numpy as np
import pytest

from conftest import DEMO_TRUTH, simulated
from motorid.identify.extract import extract
from motorid.identify.least_squares import fit_least_squares

TIGHT = {"Kv", "KF", "TFc", "KL0", "KAB"}  # within 2 %
LOOSE = {"KFS", "Ks"}  # within 10 %

EVEN_TRUTH = {"Kv": 3000.0, "KF": 2e-3, "KFS": 1.0e-2, "TFc": 2.0, "Ks": 1.5,
              "KL0": 3e-14, "KL_a1": -0.1, "KL_b1": 0.2, "KAB": 1e-14}


def _fit(pistons, truth):
    frame, spec, params = simulated(pistons=pistons, displacement_cm3=80.0 if pistons % 2 else 60.0,
                                    truth_items=tuple(sorted(truth.items())))
    ds = extract(frame, spec)
    return fit_least_squares(ds, spec), spec, params


@pytest.fixture(scope="module", params=[9, 8], ids=["odd-9", "even-8"])
def recovered(request):
    truth = DEMO_TRUTH if request.param == 9 else EVEN_TRUTH
    return _fit(request.param, truth)


def test_every_parameter_recovered_within_3_sigma_and_tolerance(recovered):
    ls, spec, truth = recovered
    assert ls.converged
    for k, true in truth.items():
        assert ls.identifiable[k], (k, ls.reasons.get(k))
        v, sd = ls.values[k], ls.std[k]
        assert abs(v - true) < 3 * sd, f"{k}: {v:.6g} ± {sd:.3g}, truth {true:.6g}"
        if k in TIGHT:
            assert abs(v - true) < 0.02 * abs(true), k
        elif k in LOOSE:
            assert abs(v - true) < 0.10 * abs(true), k
    assert 0.8 < ls.reduced_chi2 < 1.3


def test_noise_levels_are_estimated_not_guessed(recovered):
    ls, spec, truth = recovered
    # the simulator's torque sensor: 0.05 N·m white noise plus 0.01 N·m quantization
    # (protocols' [sensors] defaults); the estimate must land near it, per channel
    assert set(ls.noise) >= {"torque", "q_a", "q_b", "q_case", "breakaway"}
    assert all(v is not None and v > 0 for v in ls.noise.values())
    assert ls.noise["q_case"] < ls.noise["q_a"]  # case flow meter is the finer one


def test_bayesian_intervals_cover_truth(recovered):
    from motorid.identify.bayes import sample_posterior

    ls, spec, truth = recovered
    post = sample_posterior(ls, spec, seed=3, progress=False)
    assert post.converged and post.steps >= 50 * max(post.tau.values())
    assert post.expansion_gap is not None and post.expansion_gap < 0.05
    draws = post.samples()
    misses = []
    for i, (k, true) in enumerate(truth.items()):
        lo, hi = post.ci95[k]
        if not lo < true < hi:
            misses.append(k)
        # nothing lies outside the 99.9 % interval
        lo3, hi3 = np.percentile(draws[:, post.names.index(k)], [0.05, 99.95])
        assert lo3 < true < hi3, (k, lo3, true, hi3)
        # posterior width and least-squares standard error agree (the prior is weak)
        assert post.std[k] == pytest.approx(ls.std[k], rel=0.15)
    # 95 % intervals: nine of them miss none, or one, 93 % of the time
    assert len(misses) <= 1, misses


def _without(frame, protocols=(), columns=()):
    out = frame[~frame["protocol"].isin(protocols)].copy()
    for c in columns:
        out[c] = np.nan
    return out


@pytest.mark.parametrize("drop,columns,expect", [
    (("startability",), (), {"KFS", "Ks"}),
    ((), ("q_case_m3_s", "q_a_m3_s", "q_b_m3_s"), {"KL0", "KL_a1", "KL_b1", "KAB"}),
    ((), ("torque_Nm",), {"Kv", "KF", "TFc"}),
])
def test_missing_data_makes_parameters_not_identifiable(drop, columns, expect):
    frame, spec, truth = simulated()
    ds = extract(_without(frame, drop, columns), spec)
    ls = fit_least_squares(ds, spec)
    for k in ls.names:
        if k in expect:
            assert not ls.identifiable[k] and ls.values[k] is None and ls.reasons[k], k
        elif k in {"KFS", "Ks"} and "torque_Nm" in columns:
            continue  # static friction is measured relative to the running friction
        else:
            assert ls.identifiable[k], (k, ls.reasons.get(k))
            assert abs(ls.values[k] - truth[k]) < 4 * ls.std[k], k


def test_one_pressure_level_cannot_split_KF_from_TFc():
    frame, spec, truth = simulated()
    running = frame["protocol"] != "startability"
    dp = (frame["p_a_Pa"] - frame["p_b_Pa"]).abs()
    keep = ~running | ((dp > 140e5) & (dp < 160e5) & (frame["protocol"] == "constant_speed"))
    ds = extract(frame[keep], spec)
    ls = fit_least_squares(ds, spec)
    assert not ls.identifiable["KF"] and "single port-pressure sum" in ls.reasons["KF"]
    # K_F held at its start, T_Fc carries K_F·D·(P_A+P_B) of that one sum: the friction there and
    # K_v come out right (with both held, K_v took what they missed: 117σ off on a probe's campaign)
    held_kf = ls.params_all["KF"]
    psum = float(np.median(np.asarray(ds.running.p_a + ds.running.p_b)))
    expected = truth["TFc"] + (truth["KF"] - held_kf) * spec.displacement * psum
    assert ls.identifiable["TFc"] and abs(ls.values["TFc"] - expected) < 0.01 * expected
    assert any("T_Fc is the Coulomb friction at the one port-pressure sum" in w for w in ls.warnings)
    assert ls.identifiable["Kv"] and abs(ls.values["Kv"] - truth["Kv"]) < 4 * ls.std["Kv"]
    assert ls.identifiable["KL0"] and ls.chi2 / ls.dof < 1.2


def test_isolated_spikes_do_not_wreck_the_fit():
    frame, spec, truth = simulated()
    spiky = frame.copy()
    rng = np.random.default_rng(5)
    rows = rng.choice(len(spiky), size=60, replace=False)
    spiky.loc[spiky.index[rows[:30]], "torque_Nm"] += rng.choice([-1, 1], 30) * 80.0
    spiky.loc[spiky.index[rows[30:]], "q_case_m3_s"] *= 5.0
    ds = extract(spiky, spec)
    ls = fit_least_squares(ds, spec)
    used = set(np.asarray(ds.frame_index).tolist())
    in_fit = [sum(int(r) in used for r in rows[:30]), sum(int(r) in used for r in rows[30:])]
    assert min(in_fit) >= 10  # the spikes hit steady samples the fit uses
    assert in_fit[0] <= ls.outliers["torque"] <= in_fit[0] + 10
    assert in_fit[1] <= ls.outliers["q_case"] <= in_fit[1] + 10
    for k in ("Kv", "KF", "TFc", "KL0", "KAB"):
        assert abs(ls.values[k] - truth[k]) < 0.02 * truth[k], k


def test_breakaways_without_a_held_torque_say_so():
    frame, spec, truth = simulated()
    out = frame.copy()
    out.loc[out["protocol"] == "startability", "torque_Nm"] = np.nan
    ds = extract(out, spec)
    assert ds.n_events > 0
    ls = fit_least_squares(ds, spec)
    for k in ("KFS", "Ks"):
        assert not ls.identifiable[k]
        assert f"{ds.n_events} breakaway(s) found" in ls.reasons[k] and "torque" in ls.reasons[k]
    assert ls.identifiable["KF"] and ls.identifiable["Kv"]


def test_breakaway_scatter_the_variance_model_cannot_follow_widens_KFS():
    """The events' σ follow σ₀²(1 + γ x²), growing with pressure; here the low-pressure
    events scatter ten times the others, which no γ ≥ 0 can follow, and the model-based
    standard error of K_FS falls short of its spread (over 100 draws of this: 0.74 of
    it; the widened one 0.96).  Over a dozen draws the sandwich must widen it clearly;
    on the simulator's own events, which follow the model, hardly."""
    import dataclasses

    from motorid import model

    frame, spec, truth = simulated()
    ds = extract(frame, spec)
    psum = np.asarray(ds.events.p_a + ds.events.p_b)
    low = psum < np.median(psum)
    exact = np.asarray(model.predict_breakaway(model.as_jax(truth), spec, ds.events))
    rng = np.random.default_rng(1)

    def variances(held):
        ls = fit_least_squares(dataclasses.replace(ds, held_torque=held), spec)
        i = ls.free.index("KFS")
        added = 0.0 if ls.covariance_breakaway is None else ls.covariance_breakaway[i, i]
        return ls.covariance[i, i], ls.covariance[i, i] - added

    wide = np.array([variances(exact + rng.standard_normal(psum.size) * np.where(low, 0.2, 0.02))
                     for _ in range(12)])
    assert wide[:, 0].mean() > 1.3 * wide[:, 1].mean()
    even = np.array([variances(exact + rng.standard_normal(psum.size) * 0.03) for _ in range(6)])
    assert even[:, 0].mean() < 1.2 * even[:, 1].mean()


def test_a_model_that_misses_the_logs_by_far_says_so():
    """χ²/dof of 144 was printed without a word (a probe's campaign, 2026-11-26): a fit whose model
    misses the logs far beyond their noise now warns, and a clean fit does not."""
    frame, spec, truth = simulated()
    clean = fit_least_squares(extract(frame, spec), spec)
    assert clean.chi2 / clean.dof < 1.2 and not any(w.startswith("χ²/dof") for w in clean.warnings)
    windage = frame.copy()  # a churning torque ∝ ω² the 1992 model lacks: 4 N·m at the fastest runs
    w = windage["speed_rad_s"].to_numpy()
    windage["torque_Nm"] = windage["torque_Nm"] - 4.0 * np.sign(w) * (w / np.abs(w).max()) ** 2
    missed = fit_least_squares(extract(windage, spec), spec)
    assert any(x.startswith("χ²/dof") and "in the running torque" in x and "motorid diagnose" in x
               for x in missed.warnings), missed.warnings


def test_band_limited_noise_widens_the_errors_by_its_correlation_time():
    """Noise correlated over ~10 samples (a sensor's filter, a DAQ sampling above the sensor's
    bandwidth) gave errors too small by 3× (RMS z 3.15 over a probe's 36 estimates, white 0.82):
    the residuals' correlation time widens them, and white noise of the same power does not."""
    from scipy.signal import lfilter

    frame, spec, truth = simulated()
    rng = np.random.default_rng(3)
    runs = frame["run_id"].to_numpy()
    fits = {}
    for kind in ("white", "band-limited"):
        noisy = frame.copy()
        e = rng.standard_normal(len(frame))
        if kind == "band-limited":  # a first-order filter of ~10 samples, run by run, at the same power
            a = np.exp(-1 / 10)
            for r in np.unique(runs):
                sel = runs == r
                e[sel] = lfilter([np.sqrt(1 - a * a)], [1, -a], e[sel])
        noisy["torque_Nm"] = noisy["torque_Nm"] + 0.3 * e
        fits[kind] = fit_least_squares(extract(noisy, spec), spec)
    white, colored = fits["white"], fits["band-limited"]
    assert not any("correlated in time" in w for w in white.warnings)
    said = [w for w in colored.warnings if "correlated in time" in w]
    assert said and "running torque: τ = " in said[0]
    tau = float(said[0].split("running torque: τ = ")[1].split()[0])
    assert 8 < tau < 30  # 1 + 2Σa^k = (1 + a)/(1 − a) = 19 for this filter, less the noise already there
    for k in ("Kv", "TFc"):  # the torque's parameters: errors widened by about √τ
        assert colored.std[k] > 2.0 * white.std[k], k
        assert abs(colored.values[k] - truth[k]) < 4 * colored.std[k], k
