"""Standard errors that the runs' own scatter widens (motorid/identify/run_scatter.py): the 1992
model's parameters too, with the smoothed viscosity's run-level error counted before anything is
called scatter (issue 15: an honest uncertainty where transducer zeros change from run to run)."""

import numpy as np

from conftest import concealed
from motorid.identify.run_scatter import birge_ratio


def test_the_viscosity_error_explains_the_leakage_runs_scatter_on_a_clean_campaign():
    """K_L0 goes as 1/μ, and each run's smoothed viscosity has an error common to its samples: its
    runs' own K_L0 estimates scatter about 1.7× beyond their noise alone on this clean campaign,
    which a check that forgot the viscosity would call a disagreement.  Counted, they agree, and the
    fit widens nothing."""
    _, ds, fit, _ = concealed("clean_9_seed102")
    assert not any("scatter" in w or "motorid diagnose" in w for w in fit.warnings), fit.warnings
    shifts = fit.viscosity_shifts
    assert shifts is not None and shifts.shape[2] == len(fit.free)
    noise_only, runs = birge_ratio(fit, "KL0", ds)
    counted, _ = birge_ratio(fit, "KL0", ds, shifts)
    assert runs >= 30 and noise_only > 1.5**2 and counted < 1.35**2
    for k in ("Kv", "KF", "TFc", "KAB"):  # every other base parameter's runs agree too
        assert birge_ratio(fit, k, ds, shifts)[0] < 1.5**2


def test_per_run_transducer_zeros_widen_the_base_parameters_to_honest_errors():
    """Zeros of the torque and flow meters that change from run to run (σ 0.25 N·m, 1e-6 m³/s): no
    term of the 1992 model holds them, so the runs disagree about K_F, T_Fc, K_v, K_L0 and K_AB by
    many times their noise.  Their standard errors are widened by the runs' scatter, and every
    parameter's truth then lies within 3 of them (before: K_F tens of standard errors away)."""
    _, _, fit, truth = concealed("causes_per_run_offsets")
    widened = {w.split(":")[0]: float(w.split("scatter ")[1].split("×")[0]) for w in fit.warnings if "scatter" in w}
    assert {"KF", "TFc", "KL0", "KAB"} <= set(widened) and min(widened[k] for k in ("KF", "TFc")) > 10
    z = {k: (fit.values[k] - v) / fit.std[k] for k, v in truth["parameters"].items()}
    assert max(abs(v) for v in z.values()) < 3.0, z
    assert abs(z["KF"]) * widened["KF"] > 10  # with the noise's error alone: far off
    # runs that disagree tenfold send the user to diagnose (a probe's churning torque: K_v 3.9× off, silent)
    assert len([w for w in fit.warnings if "`motorid diagnose`" in w]) == 1  # once (here by the χ²/dof line)


def test_the_bayesian_fit_spreads_its_draws_as_the_runs_scatter_widened_the_standard_errors():
    """The sampler works at the likelihood's own width (a start 38× too wide would have to contract
    first) and then spreads each widened parameter's draws by its factor: a widened parameter's
    posterior standard deviation stands to its least-squares one as an unwidened parameter's does
    (about 1/√(χ²/dof) here: the least-squares fit also scales its covariance by χ²/dof = 5.1, which
    the posterior does not)."""
    from motorid.identify.bayes import sample_posterior

    spec, _, fit, _ = concealed("causes_per_run_offsets")
    post = sample_posterior(fit, spec, seed=3, max_seconds=120)
    assert post.converged
    assert fit.run_scatter["KF"] > 10 and "KFS" not in fit.run_scatter
    plain = post.std["KFS"] / fit.std["KFS"]
    assert abs(plain - 1 / np.sqrt(fit.chi2 / fit.dof)) < 0.1
    for k in ("KF", "TFc", "KL0", "KAB"):
        assert 0.8 < post.std[k] / fit.std[k] / plain < 1.25, (k, post.std[k], fit.std[k])
    assert any(w.startswith("KF: the draws are spread") for w in post.warnings)


def test_runs_that_disagree_tenfold_send_the_user_to_diagnose():
    """A churning torque ∝ ω² concealed (χ²/dof under the lack-of-fit warning's limit): K_v's runs
    disagree more than tenfold beyond their errors, and the fit says what to do about it, once (a
    probe's plain `motorid fit` gave K_v 3.9× its truth, z +13, with no word on diagnose)."""
    _, _, fit, _ = concealed("hydrodynamic_torque")
    assert fit.run_scatter["Kv"] > 10
    pointer = [w for w in fit.warnings if "`motorid diagnose`" in w]
    assert len(pointer) == 1, fit.warnings
    worst = max(fit.run_scatter, key=fit.run_scatter.get)
    assert f"disagree on {worst} {fit.run_scatter[worst]:.3g}×" in pointer[0]
