"""Exports: agreement of the FMU, the Python module and the Simscape tables with the model, and their cost.

    python benchmarks/run.py --only bench_export

The demo fit (reports/demo) alone, and with a diagnosis accepting six catalog
mechanisms (as tests/test_export.py).  Agreement is measured at random
operating points over the motor's range against the model itself (JAX,
``motorid.export.motor.evaluate``); the FMU through FMPy's Model Exchange
simulation.  Then the antenna example's three ramps.
"""

from __future__ import annotations

import importlib.util
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
MECHANISMS = {
    "stribeck_friction": {"T_s": 1.5, "K_p": 2e-3, "w_s": 0.4},
    "misalignment_ripple": {"A1": 0.8, "B1": -0.5, "A2": 0.3, "B2": 0.2},
    "hydrodynamic_torque": {"C_h": 4e-5},
    "case_pressure_friction": {"K_c": 0.05},
    "turbulent_leakage": {"C_t": 4e-10},
    "pressure_viscosity": {"alpha": 1.2e-8},
}


def _result_dir(tmp: Path, mechanisms: bool) -> Path:
    d = tmp / ("mech" if mechanisms else "base")
    d.mkdir()
    doc = json.loads((ROOT / "reports" / "demo" / "result.json").read_text())
    doc["inputs"]["motor"] = str(ROOT / "synthetic_data" / "demo" / "motor.toml")
    (d / "result.json").write_text(json.dumps(doc))
    if mechanisms:
        after = {k: {"value": e["value"], "std": e["std"]} for k, e in doc["parameters"].items()}
        mechs = [{"id": mid, "parameters": {f"{mid}.{k}": {"value": v} for k, v in vals.items()}}
                 for mid, vals in MECHANISMS.items()]
        (d / "diagnosis.json").write_text(json.dumps({"mechanisms": mechs, "parameters_after": after}))
    return d


def _points(n, seed=0):
    rng = np.random.default_rng(seed)
    return {"p_A": rng.uniform(0, 350e5, n), "p_B": rng.uniform(0, 350e5, n), "p_case": rng.uniform(0, 5e5, n),
            "omega": rng.choice([-1, 1], n) * np.exp(rng.uniform(np.log(1e-3), np.log(320.0), n)),
            "theta": rng.uniform(-20, 20, n), "T_oil": rng.uniform(285, 360, n)}


def _rel(got, ref):
    """(largest |got − ref| / (|ref| + 10⁻³·max|ref|), largest |got − ref| / max|ref|)."""
    ref = np.asarray(ref)
    d = np.abs(got - ref)
    return float(np.max(d / (np.abs(ref) + 1e-3 * np.max(np.abs(ref))))), float(np.max(d) / np.max(np.abs(ref)))


def _worst(got, ref, names):
    pairs = [_rel(got[k], ref[k]) for k in names]
    return max(p[0] for p in pairs), max(p[1] for p in pairs)


def run(quick: bool = False) -> str:
    import fmpy

    from motorid.export import export
    from motorid.export.fmu import require_compiler
    from motorid.export.motor import INPUTS, OUTPUTS, evaluate
    from motorid.export.source import load_identified

    n = 2000 if quick else 20000
    rows, tables, ss_rows = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for mechanisms in (False, True):
            rd = _result_dir(tmp, mechanisms)
            motor = load_identified(rd)
            label = "demo + 6 mechanisms" if mechanisms else "demo (1992 model)"
            x = _points(n)
            t0 = time.perf_counter()
            ref = {k: np.asarray(v) for k, v in evaluate(motor, **x).items()}
            t_jax = time.perf_counter() - t0
            t0 = time.perf_counter()
            py = export(rd, "python", tmp / f"m_{int(mechanisms)}.py")
            t_py_export = time.perf_counter() - t0
            spec = importlib.util.spec_from_file_location(f"m_{int(mechanisms)}", py)
            mod = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(mod)
            t0 = time.perf_counter()
            got = mod.evaluate(**x)
            t_py = time.perf_counter() - t0
            rows.append((label, "python", t_py_export, n / t_py, *_worst(got, ref, [p.name for p in OUTPUTS])))
            if require_compiler() is None:
                t0 = time.perf_counter()
                fmu = export(rd, "fmu", tmp / f"m_{int(mechanisms)}.fmu")
                t_fmu_export = time.perf_counter() - t0
                sig = np.zeros(n, dtype=[("time", float)] + [(p.name, float) for p in INPUTS])
                sig["time"] = np.arange(n, dtype=float)
                for p in INPUTS:
                    sig[p.name] = x[p.name]
                t0 = time.perf_counter()
                res = fmpy.simulate_fmu(str(fmu), fmi_type="ModelExchange", stop_time=n - 1.0, step_size=1.0,
                                        output_interval=1.0, input=sig, output=[p.name for p in OUTPUTS])
                t_fmu = time.perf_counter() - t0
                rows.append((label, "fmu (FMPy ME)", t_fmu_export, n / t_fmu,
                             *_worst(res, ref, [p.name for p in OUTPUTS])))
            rows.append((label, "model (JAX, jit)", float("nan"), n / t_jax, 0.0, 0.0))

            t0 = time.perf_counter()
            out = export(rd, "simscape", tmp / f"ss_{int(mechanisms)}")
            t_ss = time.perf_counter() - t0
            from scipy.interpolate import RegularGridInterpolator
            from scipy.io import loadmat

            from motorid.export.simscape import theta_averaged, _evaluator

            mat = loadmat(out / "simscape_losses.mat")
            dp, w = mat["pressure_drop_Pa"].ravel(), mat["shaft_speed_rad_s"].ravel()
            rng = np.random.default_rng(1)
            m = 400 if quick else 2000
            pd = rng.uniform(dp[0], dp[-1], m)
            pw = rng.choice([-1, 1], m) * np.exp(rng.uniform(np.log(mat["speed_min_rad_s"].item()),
                                                             np.log(w[-1]), m))
            ev = _evaluator(motor)
            errs = []
            for i in range(m):
                exact = theta_averaged(motor, ev, pd[i:i + 1], pw[i:i + 1], mat["temperature_K"].item(),
                                       mat["low_side_pressure_Pa"].item(), mat["case_pressure_Pa"].item())
                errs.append([abs(RegularGridInterpolator((dp, w), mat[k])([[pd[i], pw[i]]])[0] - e[0, 0])
                             for k, e in zip(("torque_loss_Nm", "volumetric_loss_m3_s", "case_flow_m3_s"), exact)])
            errs = np.max(np.array(errs), axis=0)
            ss_rows.append((label, t_ss, len(dp), len(w), mat["torque_loss_error_bound_Nm"].item(), errs[0],
                            np.max(np.abs(mat["torque_loss_Nm"])), mat["volumetric_loss_error_bound_m3_s"].item(),
                            errs[1], np.max(np.abs(mat["volumetric_loss_m3_s"]))))

    sys.path.insert(0, str(ROOT / "examples"))
    import antenna_servo as ex

    motor = ex.identified_motor(ROOT / "reports" / "demo")
    seconds = 20.0 if quick else 60.0
    runs = {(r, ideal): ex.simulate(motor, ex.Axis(), r, seconds, ideal) for r in ex.RATES for ideal in (False, True)}

    lines = ["## Exports (`motorid export`)", "",
             f"Command: `python benchmarks/run.py --only bench_export`{' --quick' if quick else ''}. "
             f"Agreement with the model itself (JAX) at {n} random operating points (0-350 bar per port, "
             "0-5 bar case, ±10⁻³…320 rad/s, 285-360 K, any θ): the largest |export − model| / "
             "(|model| + 10⁻³·max|model|) over the five outputs (relative, with a floor where a port "
             "flow's terms cancel), and the largest |export − model| / max|model|. Export time includes tracing, code "
             "generation, and for the FMU the CMake build and FMPy's validation.", "",
             "| motor | format | export [s] | points/s | max rel. deviation | max dev. / range |",
             "|---|---|---|---|---|---|"]
    for label, fmt, t_exp, rate, dev, dev_range in rows:
        lines.append(f"| {label} | {fmt} | {'—' if math.isnan(t_exp) else f'{t_exp:.2f}'} | {rate:.3g} | "
                     f"{dev:.2g} | {dev_range:.2g} |")
    lines += ["", "Simscape tables (defaults: ±350 bar, ±3000 rpm, 40 °C): breakpoints after refinement, "
              f"the bound README.txt states and the largest error found at {m} random points between "
              "breakpoints (|ω| ≥ 0.1 rpm).", "",
              "| motor | export [s] | Δp × ω | torque bound [N·m] | torque max err | max |torque loss| | "
              "vol. bound [m³/s] | vol. max err | max |vol. loss| |", "|---|---|---|---|---|---|---|---|---|"]
    for label, t, a, b, tb, te, tm, vb, ve, vm in ss_rows:
        lines.append(f"| {label} | {t:.1f} | {a} × {b} | {tb:.2g} | {te:.2g} | {tm:.3g} | {vb:.2g} | {ve:.2g} | "
                     f"{vm:.3g} |")
    lines += ["", f"Antenna example (`examples/antenna_servo.py`, demo fit, {seconds:g} s per run; error after "
              f"{seconds / 4:g} s):", "", "```", *ex.summary(runs, settle=seconds / 4), "```"]
    return "\n".join(lines)


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
