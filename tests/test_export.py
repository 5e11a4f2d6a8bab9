"""motorid export: the FMU, the Python module and the Simscape tables against the model itself.

The fixture is the demo fit (reports/demo/result.json) with a diagnosis.json
beside it that accepts several catalog mechanisms (friction, ripple, churning,
case-pressure seal friction, orifice and Barus leakage) and a torque
transducer offset, which the exports must leave out.
"""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from motorid.export import export
from motorid.export.motor import INPUTS, OUTPUTS, evaluate
from motorid.export.source import load_identified

REPO = Path(__file__).resolve().parent.parent
DEMO = REPO / "reports" / "demo"

MECHANISMS = {
    "stribeck_friction": {"T_s": 1.5, "K_p": 2e-3, "w_s": 0.4},
    "misalignment_ripple": {"A1": 0.8, "B1": -0.5, "A2": 0.3, "B2": 0.2},
    "hydrodynamic_torque": {"C_h": 4e-5},
    "case_pressure_friction": {"K_c": 0.05},
    "turbulent_leakage": {"C_t": 4e-10},
    "pressure_viscosity": {"alpha": 1.2e-8},
    "torque_offset": {"T0": 1.7},
}


def _diagnosis(result: dict) -> dict:
    after = {k: {"value": e["value"] * 1.01, "std": e["std"]} for k, e in result["parameters"].items()}
    mechs = [{"id": mid, "name": mid, "parameters": {f"{mid}.{k}": {"value": v, "std": 0.0, "unit": "-"}
                                                      for k, v in values.items()}}
             for mid, values in MECHANISMS.items()]
    return {"mismatch": True, "mechanisms": mechs, "parameters_after": after}


@pytest.fixture(scope="module")
def result_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("fit")
    doc = json.loads((DEMO / "result.json").read_text())
    doc["inputs"]["motor"] = str(REPO / "synthetic_data" / "demo" / "motor.toml")
    (d / "result.json").write_text(json.dumps(doc))
    (d / "diagnosis.json").write_text(json.dumps(_diagnosis(doc)))
    return d


@pytest.fixture(scope="module")
def motor(result_dir):
    return load_identified(result_dir)


def _grid(n=48, seed=3):
    """Operating points over the motor's whole range, both directions, slow and fast, hot and cold."""
    rng = np.random.default_rng(seed)
    speed = rng.choice([-1, 1], n) * np.exp(rng.uniform(np.log(1e-3), np.log(320.0), n))
    return {"p_A": rng.uniform(0, 350e5, n), "p_B": rng.uniform(0, 350e5, n), "p_case": rng.uniform(0, 5e5, n),
            "omega": speed, "theta": rng.uniform(-20, 20, n), "T_oil": rng.uniform(285, 360, n)}


def _close(got, ref, rtol):
    """|got − ref| ≤ rtol·(|ref| + 1e-3·max|ref|): relative, with a floor at 10⁻³ of the channel's range.

    A port flow is the swept flow plus leakages of either sign; where they cancel
    to 10⁻⁵ of the channel the rounding of the terms (10⁻¹⁶ of them) is 10⁻¹¹ of
    the difference: the floor keeps the test on the model, not on cancellation
    (benchmarks/bench_export.py: the largest deviation over 20 000 points is
    10⁻¹⁴ of the channel's range).
    """
    ref = np.asarray(ref)
    return np.abs(got - ref) <= rtol * (np.abs(ref) + 1e-3 * np.max(np.abs(ref)))


def test_mechanisms_read_from_the_diagnosis_and_the_sensor_left_out(motor):
    ids = {m.id for m in motor.mechanisms}
    assert ids == set(MECHANISMS) - {"torque_offset"}
    assert any("torque_offset" in n and "sensor" in n for n in motor.notes)
    # base parameters from the diagnosis' joint refit, not result.json's
    demo = json.loads((DEMO / "result.json").read_text())["parameters"]
    assert motor.params["Kv"] == pytest.approx(demo["Kv"]["value"] * 1.01, rel=1e-14)


def test_mechanisms_change_what_the_model_exports(motor):
    """The mechanisms are in the exported function, by the physics of each (so the agreement tests have teeth)."""
    from motorid.export.motor import IdentifiedMotor

    x = _grid()
    bare = IdentifiedMotor(motor.spec, motor.params, ())
    full, base = evaluate(motor, **x), evaluate(bare, **x)
    K_c = MECHANISMS["case_pressure_friction"]["K_c"]
    np.testing.assert_allclose(np.asarray(full["torque_breakaway"] - base["torque_breakaway"]),
                               K_c * motor.spec.displacement * x["p_case"], rtol=1e-9, atol=1e-12)
    assert np.max(np.abs(np.asarray(full["torque"] - base["torque"]))) > 0.5  # ripple, friction, churning
    assert np.max(np.abs(np.asarray(full["q_case"] - base["q_case"]))) > 1e-6  # orifice leakage


def test_python_export_agrees_with_the_model_and_needs_numpy_only(motor, result_dir, tmp_path):
    path = export(result_dir, "python", tmp_path / "identified_motor.py")
    spec = importlib.util.spec_from_file_location("identified_motor", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    x = _grid(2000)
    ref, got = evaluate(motor, **x), mod.evaluate(**x)
    for p in OUTPUTS:
        ok = _close(got[p.name], ref[p.name], 1e-12)
        assert ok.all(), (p.name, np.max(np.abs(got[p.name] - np.asarray(ref[p.name]))))
    one = mod.evaluate(20e6, 1e6, 2e5, 10.0, 0.1, 320.0)  # scalars give 0-d arrays
    assert one["torque"].shape == () and np.isfinite(one["torque"])
    code = (f"import sys; sys.path.insert(0, {str(tmp_path)!r}); import identified_motor as m; "
            "m.evaluate(1e7, 0, 0, 1.0, 0.0, 313.15); "
            "bad = [k for k in sys.modules if k.split('.')[0] in ('jax', 'motorid', 'scipy')]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=tmp_path)


def _no_compiler_reason():
    from motorid.export.fmu import require_compiler

    return require_compiler()


@pytest.mark.skipif(_no_compiler_reason() is not None, reason=f"FMU not built: {_no_compiler_reason()}")
def test_fmu_passes_fmpy_validation_and_simulates_as_the_model(motor, result_dir, tmp_path):
    import fmpy

    from motorid.export.fmu import validate

    path = export(result_dir, "fmu", tmp_path / "motor.fmu")
    assert validate(path) == []
    md = fmpy.read_model_description(str(path))
    assert md.fmiVersion == "2.0" and md.modelExchange is not None and md.coSimulation is not None
    table = {v.name: (v.causality, v.unit) for v in md.modelVariables}
    assert table == {"p_A": ("input", "Pa"), "p_B": ("input", "Pa"), "p_case": ("input", "Pa"),
                     "omega": ("input", "rad/s"), "theta": ("input", "rad"), "T_oil": ("input", "K"),
                     "torque": ("output", "N.m"), "q_A": ("output", "m3/s"), "q_B": ("output", "m3/s"),
                     "q_case": ("output", "m3/s"), "torque_breakaway": ("output", "N.m")}

    x = _grid(300)
    n = len(x["omega"])
    signal = np.zeros(n, dtype=[("time", np.float64)] + [(p.name, np.float64) for p in INPUTS])
    signal["time"] = np.arange(n, dtype=float)
    for p in INPUTS:
        signal[p.name] = x[p.name]
    ref = evaluate(motor, **x)
    names = [p.name for p in OUTPUTS]
    me = fmpy.simulate_fmu(str(path), fmi_type="ModelExchange", start_time=0.0, stop_time=n - 1.0,
                           step_size=1.0, output_interval=1.0, input=signal, output=names)
    assert len(me) == n
    for name in names:
        ok = _close(me[name], ref[name], 1e-9)
        assert ok.all(), (name, np.max(np.abs(me[name] - np.asarray(ref[name]))))
    # Co-Simulation holds each input over its step: the output at point k is the model at point k − 1
    cs = fmpy.simulate_fmu(str(path), fmi_type="CoSimulation", start_time=0.0, stop_time=n - 1.0,
                           step_size=1.0, output_interval=1.0, input=signal, output=names)
    for name in names:
        assert _close(cs[name][1:n], np.asarray(ref[name])[:-1], 1e-9).all(), name


def test_simscape_tables_within_their_stated_interpolation_error(motor, result_dir, tmp_path):
    from scipy.interpolate import RegularGridInterpolator
    from scipy.io import loadmat

    from motorid.export.simscape import theta_nodes

    out = export(result_dir, "simscape", tmp_path / "tables", max_pressure=300e5, max_speed=250.0,
                 rel_tol=5e-3, max_points=41)
    mat = loadmat(out / "simscape_losses.mat")
    dp, w = mat["pressure_drop_Pa"].ravel(), mat["shaft_speed_rad_s"].ravel()
    readme = (out / "README.txt").read_text()
    assert "Mechanical loss table" in readme and f"{mat['torque_loss_error_bound_Nm'].item():.3g}" in readme
    csv = np.loadtxt(out / "torque_loss.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(csv[:, 0], dp)
    np.testing.assert_array_equal(csv[:, 1:], mat["torque_loss_Nm"])

    # the model itself (JAX), θ-averaged, at random points between the breakpoints, |ω| ≥ speed_min
    rng = np.random.default_rng(7)
    m = 60
    w_min = mat["speed_min_rad_s"].item()
    pts_dp = rng.uniform(dp[0], dp[-1], m)
    pts_w = rng.choice([-1, 1], m) * np.exp(rng.uniform(np.log(w_min), np.log(w[-1]), m))
    theta, weights = theta_nodes(motor.spec.pistons)
    T, p_low, p_case = (mat[k].item() for k in ("temperature_K", "low_side_pressure_Pa", "case_pressure_Pa"))
    p_a = p_low + np.maximum(pts_dp, 0)[:, None]
    p_b = p_low + np.maximum(-pts_dp, 0)[:, None]
    ref = {k: np.asarray(v) @ weights for k, v in evaluate(
        motor, p_A=p_a, p_B=p_b, p_case=p_case, omega=pts_w[:, None], theta=theta[None, :], T_oil=T).items()}
    D = motor.spec.displacement
    swept = D * pts_w / (2 * np.pi)
    model_torque_loss = D * pts_dp / (2 * np.pi) - ref["torque"]
    model_vol_loss = np.where(pts_dp >= 0, ref["q_A"] - swept, -(ref["q_B"] + swept))
    where = np.column_stack([pts_dp, pts_w])
    for table, model, bound in (("torque_loss_Nm", model_torque_loss, "torque_loss_error_bound_Nm"),
                                ("volumetric_loss_m3_s", model_vol_loss, "volumetric_loss_error_bound_m3_s"),
                                ("case_flow_m3_s", ref["q_case"], "case_flow_error_bound_m3_s")):
        approx = RegularGridInterpolator((dp, w), mat[table])(where)
        err = np.max(np.abs(approx - model))
        assert err <= mat[bound].item(), (table, err, mat[bound].item())
        assert mat[bound].item() < 1e-2 * np.max(np.abs(mat[table])), table  # a bound worth stating
    # the conventions the README states: friction opposes motion, leakage runs from high to low pressure
    tl, vl = mat["torque_loss_Nm"], mat["volumetric_loss_m3_s"]
    assert (tl[:, w > 0] > 0).all() and (tl[:, w < 0] < 0).all()
    assert (vl[dp > 0] > 0).all() and (vl[dp < 0] < 0).all()


def test_a_measured_rotor_inertia_is_the_one_exported(result_dir, tmp_path):
    """Diagnose's inertia_error is ΔJ·α in the torque; the exports leave J·α to the load model, so the
    measured J = spec J + ΔJ is what they write (the servo loop's load needs it), not a torque term."""
    d = tmp_path / "fit"
    shutil.copytree(result_dir, d)
    diag = json.loads((d / "diagnosis.json").read_text())
    diag["mechanisms"].append({"id": "inertia_error", "name": "inertia_error",
                               "parameters": {"inertia_error.dJ": {"value": 0.011, "std": 0.001, "unit": "kg·m²"}}})
    (d / "diagnosis.json").write_text(json.dumps(diag))
    spec_j = load_identified(result_dir).spec.inertia
    motor = load_identified(d)
    assert motor.spec.inertia == pytest.approx(spec_j + 0.011, rel=1e-12)
    assert "inertia_error" not in {m.id for m in motor.mechanisms}
    assert "inertia_error.dJ" not in motor.params
    assert any("measured rotor inertia" in n for n in motor.notes)
    out = tmp_path / "m.py"
    export(d, "python", out)
    assert f"INERTIA = {spec_j + 0.011!r}" in out.read_text()


def test_bad_result_dir_is_one_line_and_exit_2(tmp_path, capsys):
    from motorid.cli import main

    out = tmp_path / "m.py"
    assert main(["export", str(tmp_path / "missing"), "--format", "python", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "missing" in err and "RESULT_DIR" in err
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "result.json").write_text("{not json")
    assert main(["export", str(bad), "--format", "fmu", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "result.json" in err
    nospec = tmp_path / "nospec"
    nospec.mkdir()
    doc = json.loads((DEMO / "result.json").read_text())
    doc["inputs"]["motor"] = "elsewhere/motor.toml"
    (nospec / "result.json").write_text(json.dumps(doc))
    assert main(["export", str(nospec), "--format", "python", "--out", str(out)]) == 2
    assert "--motor" in capsys.readouterr().err
    assert not out.exists()
    # with --motor the same folder exports
    shutil.copy(REPO / "synthetic_data" / "demo" / "motor.toml", tmp_path / "spec.toml")
    assert main(["export", str(nospec), "--format", "python", "--out", str(out),
                 "--motor", str(tmp_path / "spec.toml")]) == 0 and out.exists()


def test_unknown_primitive_is_refused_by_name():
    import jax
    import jax.numpy as jnp

    from motorid.export.jaxpr_c import emit_c_function
    from motorid.export.jaxpr_flat import UnsupportedPrimitive

    jaxpr = jax.make_jaxpr(lambda x: jnp.sum(jnp.cumsum(jnp.ones(3) * x)))(1.0)
    with pytest.raises(UnsupportedPrimitive, match="cumsum"):
        emit_c_function(jaxpr)


def fitted_map(tmp_path, quadrants: int, seed: int):
    """A simulated map of a 9-piston 80 cm³/rev motor (``tmp_path``/map.csv, its spec motor.toml)
    fitted by ``motorid fit`` into ``tmp_path``/fit → (spec, the fit's folder, the map)."""
    from motorid.bench.maps import map_grid, simulate_map
    from motorid.cli import main
    from motorid.model import MotorSpec, OilSpec

    spec = MotorSpec("map-9", 9, 80e-6, 0.005, oil=OilSpec(temp_C=50.0))
    (tmp_path / "motor.toml").write_text(spec.to_toml())
    truth = {"Kv": 5000.0, "KF": 3e-3, "KFS": 1.5e-2, "TFc": 3.0, "Ks": 1.0, "KL0": 5e-14, "KL_a1": 0.15,
             "KL_b1": 0.08, "KAB": 2e-14}
    df = simulate_map(spec, truth, map_grid([100, 400, 1000, 2000], [20, 100, 200, 300], quadrants),
                      noise={"torque_Nm": 0.3, "q_a_lpm": 0.05, "q_b_lpm": 0.05, "q_case_lpm": 0.02},
                      rng=np.random.default_rng(seed))
    df.to_csv(tmp_path / "map.csv", index=False)
    d = tmp_path / "fit"
    assert main(["fit", str(tmp_path / "map.csv"), "--motor", str(tmp_path / "motor.toml"), "--out", str(d)]) == 0
    return spec, d, df


def test_a_map_fit_exports_its_losses_and_asks_for_the_static_friction_it_lacks(tmp_path, capsys):
    """A loss map holds no breakaway: K_FS and K_s have no value.  The Simscape tables never use them
    (byte for byte the same whatever is assumed), and the K_L harmonics the fit held at 0 are 0; an
    export that does use them (the Python module's breakaway torque, the FMU's) asks for them by name,
    writes nothing, and takes them with --assume."""
    from motorid.cli import main

    spec, d, _ = fitted_map(tmp_path, quadrants=2, seed=5)
    doc = json.loads((d / "result.json").read_text())
    assert doc["parameters"]["KFS"]["value"] is None and doc["parameters"]["Ks"]["value"] is None
    capsys.readouterr()

    s1, s2 = tmp_path / "s1", tmp_path / "s2"
    assert main(["export", str(d), "--format", "simscape", "--out", str(s1), "--max-speed", "2000"]) == 0
    assert main(["export", str(d), "--format", "simscape", "--out", str(s2), "--max-speed", "2000",
                 "--assume", "KFS=0.05", "--assume", "Ks=2"]) == 0
    for name in ("torque_loss.csv", "volumetric_loss.csv", "case_flow.csv"):
        assert (s1 / name).read_bytes() == (s2 / name).read_bytes()
    readme = (s1 / "README.txt").read_text()
    assert "KFS: not determined" in readme and "KL_a1 = 0, as the fit held it" in readme
    assert "KFS = 0.05 assumed (--assume)" in (s2 / "README.txt").read_text()

    py = tmp_path / "m.py"
    capsys.readouterr()
    assert main(["export", str(d), "--format", "python", "--out", str(py)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "'KFS'" in err and "--assume KFS=" in err and not py.exists()
    assert main(["export", str(d), "--format", "python", "--out", str(py), "--assume", "KFS=0.012",
                 "--assume", "Ks=0.8"]) == 0
    m = importlib.util.module_from_spec(importlib.util.spec_from_file_location("map_motor", py))
    m.__spec__.loader.exec_module(m)
    p_a, p_b = 200e5, 10e5
    got = m.evaluate(p_a, p_b, 0.0, 0.0, 0.3, 323.15)["torque_breakaway"]
    kf, tfc = doc["parameters"]["KF"]["value"], doc["parameters"]["TFc"]["value"]
    want = spec.displacement * (p_a + p_b) * (kf + 0.012) + tfc * (1 + 0.8)  # MODEL.md: T_break
    assert float(got) == pytest.approx(want, rel=1e-9)
    # refused in one line: a parameter the fit determined; not KEY=VALUE
    for bad, words in ((["--assume", "KF=3"], "the fit determined KF"), (["--assume", "KFS"], "KEY=VALUE"),
                       (["--assume", "KFS=0.02"], "given twice")):
        assert main(["export", str(d), "--format", "python", "--out", str(py), "--force", "--assume", "KFS=0.012",
                     "--assume", "Ks=0.8", *bad]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and words in err
    # below the bound the model keeps (K_FS ≥ 0): refused, nothing written
    assert main(["export", str(d), "--format", "python", "--out", str(tmp_path / "neg.py"), "--assume", "KFS=-0.01",
                 "--assume", "Ks=0.8"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "KFS is ≥ 0" in err and not (tmp_path / "neg.py").exists()


def test_a_variable_unit_exports_at_the_setting_asked_for(tmp_path, capsys):
    """A fit of a variable unit's map (a displacement per point) is the model at each point's D: the
    export is at the spec's D with a note saying so, or at --displacement; there the exported module,
    averaged over shaft angle, gives what ``motorid predict`` gives at that displacement.  A fixed
    unit refuses --displacement in one line."""
    import pandas as pd

    from motorid.bench.maps import map_grid, simulate_map
    from motorid.cli import main
    from motorid.model import MotorSpec, OilSpec

    spec = MotorSpec("var-9", 9, 80e-6, 0.005, oil=OilSpec(temp_C=50.0))
    (tmp_path / "motor.toml").write_text(spec.to_toml())
    truth = {"Kv": 5000.0, "KF": 3e-3, "KFS": 1.5e-2, "TFc": 3.0, "Ks": 1.0, "KL0": 5e-14, "KL_a1": 0.0,
             "KL_b1": 0.0, "KAB": 2e-14}
    grid = map_grid([300, 1000, 2000], [50, 150, 250], 2)
    grid = np.concatenate([grid, grid])
    disp = np.repeat([80.0, 45.0], len(grid) // 2)
    simulate_map(spec, truth, grid, noise={"torque_Nm": 0.2, "q_a_lpm": 0.05, "q_b_lpm": 0.05,
                                           "q_case_lpm": 0.02}, rng=np.random.default_rng(4),
                 displacement_cm3=disp).to_csv(tmp_path / "var.csv", index=False)
    d = tmp_path / "fit"
    assert main(["fit", str(tmp_path / "var.csv"), "--motor", str(tmp_path / "motor.toml"), "--out", str(d)]) == 0
    py, py50 = tmp_path / "m.py", tmp_path / "m50.py"
    common = ["--assume", "KFS=0.015", "--assume", "Ks=1.0"]
    assert main(["export", str(d), "--format", "python", "--out", str(py), *common]) == 0
    assert "variable unit" in py.read_text() and "--displacement" in py.read_text()
    assert main(["export", str(d), "--format", "python", "--out", str(py50), "--displacement", "50", *common]) == 0
    assert "at the displacement setting 50 cm3/rev" in py50.read_text()
    (tmp_path / "pts.csv").write_text("speed_rpm,p_a_bar,p_b_bar,displacement_cm3\n1500,200,5,50\n1500,200,5,80\n")
    assert main(["predict", str(d), str(tmp_path / "pts.csv"), "--out", str(tmp_path / "pred.csv")]) == 0
    want = pd.read_csv(tmp_path / "pred.csv")["torque_Nm"].to_numpy()
    theta = np.linspace(0, 2 * np.pi, 4096, endpoint=False)
    for path, expected in ((py50, want[0]), (py, want[1])):
        mod = importlib.util.module_from_spec(importlib.util.spec_from_file_location(path.stem, path))
        mod.__spec__.loader.exec_module(mod)
        got = np.mean(mod.evaluate(200e5, 5e5, 0.0, 1500 * 2 * np.pi / 60, theta, 323.15)["torque"])
        assert got == pytest.approx(expected, rel=2e-3)
    assert abs(want[0] / want[1] - 50 / 80) < 0.05  # the setting matters: the check could fail
    # a fixed unit: one line, nothing written
    (tmp_path / "fixed").mkdir()
    _, fixed, _ = fitted_map(tmp_path / "fixed", quadrants=2, seed=5)
    capsys.readouterr()
    out = tmp_path / "f.py"
    assert main(["export", str(fixed), "--format", "python", "--out", str(out), "--displacement", "50", *common]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "fixed-displacement unit" in err and not out.exists()


def test_a_relative_motor_path_run_from_elsewhere_finds_the_right_spec(tmp_path, monkeypatch, capsys):
    """result.json names the spec as the fit was given it ('motor.toml', relative): exported from
    another folder that holds another motor's motor.toml, that file is passed over (its geometry
    disagrees) and the spec the table fit kept in result.json is used; a log fit, which keeps none,
    names the disagreement in one line."""
    from motorid.cli import main
    from motorid.model import MotorSpec, OilSpec

    monkeypatch.chdir(tmp_path)
    (tmp_path / "a").mkdir()
    fitted_map(tmp_path / "a", quadrants=2, seed=5)
    doc = json.loads((tmp_path / "a" / "fit" / "result.json").read_text())
    doc["inputs"]["motor"] = "motor.toml"
    (tmp_path / "a" / "fit" / "result.json").write_text(json.dumps(doc))
    (tmp_path / "motor.toml").write_text(MotorSpec("other", 7, 28e-6, 0.001, oil=OilSpec(temp_C=40.0)).to_toml())
    out = tmp_path / "m.py"
    assert main(["export", str(tmp_path / "a" / "fit"), "--format", "python", "--out", str(out),
                 "--assume", "KFS=0.015", "--assume", "Ks=1"]) == 0
    assert "result.json motor_spec" in out.read_text()
    log = tmp_path / "log"
    log.mkdir()
    demo = json.loads((DEMO / "result.json").read_text())
    demo["inputs"]["motor"] = "motor.toml"
    (log / "result.json").write_text(json.dumps(demo))
    capsys.readouterr()
    assert main(["export", str(log), "--format", "python", "--out", str(tmp_path / "l.py")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "does not match" in err and "pistons" in err
