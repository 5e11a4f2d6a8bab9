"""Fisher information, Cramér–Rao bound and experiment design (motorid.experiment_design)."""

import math
from functools import lru_cache

import numpy as np
import pytest

from motorid import experiment_design as design, model
from motorid.model import MotorSpec, OilSpec
from conftest import DEMO_TRUTH, REPO

SPEC = MotorSpec(name="test-9", pistons=9, displacement=80e-6, inertia=0.005, oil=OilSpec())


def test_crb_of_the_torque_channel_is_the_linear_closed_form():
    # running torque is linear in Kv, KF, TFc: T = Tp − Jα + Kv·(−Dμω) + KF·(−D(PA+PB)dir) + TFc·(−dir),
    # so the Fisher information is XᵀWX and the bound (XᵀWX)⁻¹, whatever the values
    rng = np.random.default_rng(4)
    n = 400
    speed = rng.uniform(1.0, 250.0, n) * rng.choice([-1.0, 1.0], n)
    direction = np.sign(speed)
    p_a, p_b = rng.uniform(5e5, 3e7, n), rng.uniform(5e5, 3e6, n)
    mu = rng.uniform(0.01, 0.05, n)
    s = model.make_samples(SPEC, rng.uniform(0, 2 * np.pi, n), speed, p_a, p_b, 7e4, mu, direction=direction)
    sigma = rng.uniform(0.05, 0.3, n)
    names = ["Kv", "KF", "TFc"]
    info = design.fisher_information(DEMO_TRUTH, SPEC, None, {"torque": sigma}, names=names, running=s)
    D = SPEC.displacement
    X = np.column_stack([-D * mu * speed, -D * (p_a + p_b) * direction, -direction])
    expected = X.T @ (X / sigma[:, None] ** 2)
    np.testing.assert_allclose(info, expected, rtol=1e-10)
    std, cov = design.cramer_rao(info, names)
    closed = np.linalg.inv(expected)
    np.testing.assert_allclose(cov, closed, rtol=1e-8)
    for i, k in enumerate(names):
        assert std[k] == pytest.approx(math.sqrt(closed[i, i]), rel=1e-8)
    # a channel without σ (or with NaN σ) carries nothing; a sample with NaN σ neither
    half = sigma.copy()
    half[::2] = np.nan
    info_half = design.fisher_information(DEMO_TRUTH, SPEC, None, {"torque": half}, names=names, running=s)
    odd = X[1::2] / sigma[1::2, None]
    np.testing.assert_allclose(info_half, odd.T @ odd, rtol=1e-10)


def test_cramer_rao_marks_unseen_directions_infinite():
    info = np.array([[4.0, 0.0, 0.0], [0.0, 1.0, 1.0], [0.0, 1.0, 1.0]])
    std, _ = design.cramer_rao(info, ["a", "b", "c"])
    assert std["a"] == pytest.approx(0.5)
    assert math.isinf(std["b"]) and math.isinf(std["c"])


@lru_cache(maxsize=1)
def _fast_runs_only():
    """Constant speed at 100-2500 rpm only: no slow run, no startability."""
    from motorid.bench.protocols import parse_protocol, read_toml
    from motorid.bench.simulate import simulate_campaign
    from motorid.bench.truth import parse_truth
    from motorid.identify.extract import extract
    from motorid.identify.least_squares import fit_least_squares

    table = read_toml(REPO / "synthetic_data" / "concealed" / "protocols" / "iso4392-1_constant_speed.toml", "p")
    table["set_points"].update(speed_rpm=[100.0, 1000.0, 2500.0], pressure_difference_bar=[50.0, 250.0])
    table["timing"]["sample_rate_Hz"] = 50.0
    camp = simulate_campaign([parse_protocol(table, "fast constant speed")], SPEC,
                             parse_truth({"parameters": DEMO_TRUTH}, "truth"), seed=3)
    data = extract(camp.frame, SPEC)
    return camp, data, fit_least_squares(data, SPEC)


def test_suggest_runs_asks_for_slow_runs_for_leakage_harmonics_and_startability_for_static_friction():
    _, data, ls = _fast_runs_only()
    grid = [design.constant_speed_candidate(SPEC, rpm, 250.0, d) for rpm in (0.3, 3.0, 100.0, 1000.0, 2500.0)
            for d in (1, -1)]
    for k in ("KL_a1", "KL_b1"):
        plan = design.suggest_runs(ls, data, SPEC, candidates=grid, top=10, parameter=k)
        best = plan["suggestions"][0]
        assert best.candidate.protocol.startswith("ISO 4392-1 constant speed")
        assert best.candidate.setting["speed_rpm"] <= 3.0  # a slow run, which sees K_L(θ) over the pitch
        assert best.std_after < 0.6 * best.std_now
        # every fast candidate helps less than the best slow one
        assert all(s.gain <= best.gain for s in plan["suggestions"])
    plan = design.suggest_runs(ls, data, SPEC, top=5)
    assert plan["worst"] in ls.free
    gains = [s.gain for s in plan["suggestions"]]
    assert gains == sorted(gains, reverse=True) and gains[0] > 0
    assert set(plan["unidentified"]) == {"KFS", "Ks"}
    assert "ISO 4392-2" in plan["unidentified"]["KFS"]["add"]
    assert "≥ 2 load levels" in plan["unidentified"]["KFS"]["add"]
    assert plan["unidentified"]["KFS"]["best_single_run"]["protocol"].startswith("ISO 4392-2")
    text = design.format_plan(plan, ls)
    assert "worst-determined parameter" in text and "no startability runs" in text


def test_plan_cli(tmp_path, capsys):
    import json

    from motorid.cli import main
    from motorid.io.logs import write_log

    camp, _, _ = _fast_runs_only()
    log = write_log(camp.frame, tmp_path / "fast.csv")
    motor = tmp_path / "motor.toml"
    motor.write_text('[motor]\nname = "test-9"\npistons = 9\ndisplacement_cm3 = 80.0\ninertia_kg_m2 = 0.005\n'
                     '[oil]\nname = "VG46"\nnu40_cSt = 46.0\nnu100_cSt = 6.8\ndensity15_kg_m3 = 875.0\n')
    assert main(["plan", str(log), "--motor", str(motor), "--top", "2", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["suggestions"]) == 2 and doc["worst"] in doc["std_now"]
    assert "KFS" in doc["unidentified"]
    # bad input: one line, exit 2
    assert main(["plan", str(tmp_path / "missing.csv"), "--motor", str(motor)]) == 2
    assert main(["plan", str(log), "--motor", str(motor), "--top", "0"]) == 2
    assert main(["plan", str(log), "--motor", str(motor), "--parameter", "KFS"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("motorid plan: error:") for line in err)


def test_plan_counts_the_viscosity_share_of_the_standard_errors():
    """A leakage coefficient's standard error holds the smoothed viscosity's run-level
    error; the plan's present std must too (it would otherwise promise runs that
    cannot shrink what the viscometer sets)."""
    from conftest import simulated
    from motorid.identify.extract import extract
    from motorid.identify.least_squares import fit_least_squares

    frame, spec, _ = simulated(seed=1)
    data = extract(frame, spec)
    ls = fit_least_squares(data, spec)
    plan = design.suggest_runs(ls, data, spec, candidates=[design.constant_speed_candidate(spec, 100.0, 250.0, 1)],
                               parameter="KL0")
    data_only, _ = design.cramer_rao(design.campaign_information(ls, data, spec), ls.free)
    assert plan["std_now"]["KL0"] > 1.1 * data_only["KL0"]
    assert plan["std_now"]["KL0"] == pytest.approx(ls.std["KL0"], rel=0.1)
