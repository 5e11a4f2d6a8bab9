"""The Python API (motorid.api) against the command line: the quickstart's calls give the CLI's numbers."""

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

import motorid
from motorid.cli import main

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "synthetic_data" / "demo"


def _quickstart():
    spec = importlib.util.spec_from_file_location("quickstart", REPO / "examples" / "quickstart.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("api")
    logs = sorted(DEMO.glob("*.csv.gz"))
    assert main(["fit", *map(str, logs), "--motor", str(DEMO / "motor.toml"), "--out", str(tmp / "cli")]) == 0
    fit = _quickstart().main(tmp / "api")
    return json.loads((tmp / "cli" / "result.json").read_text()), fit, tmp


def test_quickstart_fit_is_the_cli_fit_number_for_number(both):
    cli, fit, tmp = both
    saved = json.loads((tmp / "api" / "result.json").read_text())
    for doc in (fit.document, saved):
        assert doc["parameters"] == cli["parameters"]
        assert doc["noise"] == cli["noise"] and doc["correlation"] == cli["correlation"]
        assert {k: v for k, v in doc["fit"].items() if k != "seconds"} == {
            k: v for k, v in cli["fit"].items() if k != "seconds"}
    assert fit.params == {k: e["value"] for k, e in cli["parameters"].items() if e["identifiable"]}
    assert all(math.isfinite(s) and s > 0 for s in fit.std.values())


def test_result_prints_renders_plots_and_loads(both):
    cli, fit, tmp = both
    text = str(fit)
    assert "χ²/dof" in text and f"{cli['parameters']['Kv']['value']:.5g}" in text
    page = fit._repr_html_()
    assert page.count("<tr>") == len(cli["parameters"]) + 1 and "Kv" in page
    fig = fit.plot()
    torque_axis = fig.axes[0]
    data, model = (line.get_ydata() for line in torque_axis.lines[:2])
    assert len(data) == len(model) > 100
    # the model follows the data: residual RMS at the fit's torque noise level, far below the torque's spread
    rms = float(((data - model) ** 2).mean() ** 0.5)
    assert rms < 0.05 * float(data.std())
    loaded = motorid.load_result(tmp / "api")
    assert loaded.params == fit.params and str(loaded) == text


def test_import_motorid_is_light_and_lazy():
    code = ("import sys, motorid; heavy = [m for m in ('jax', 'pandas', 'matplotlib') if m in sys.modules]; "
            "assert not heavy, heavy; assert callable(motorid.fit) and 'jax' in sys.modules; "
            "assert motorid.MotorSpec.__module__ == 'motorid.model'")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    with pytest.raises(AttributeError, match="no attribute 'fitt'"):
        motorid.fitt


def test_predict_from_a_fit_of_logs_notes_the_points_outside_its_runs(both, tmp_path):
    """A fit of logs keeps the steady running region it saw (result.json data.ranges): predict notes a
    point beyond its fastest run as extrapolated, and none inside."""
    import pandas as pd

    from motorid.identify.predict import load_result, predict_points
    from motorid.io.tables import read_tables

    cli, _, tmp = both
    lo, hi = cli["data"]["ranges"]["speed_rad_s"]
    inside, outside = 0.5 * (lo + hi) * 60 / (2 * math.pi), 3.0 * hi * 60 / (2 * math.pi)
    pd.DataFrame({"point_id": ["inside", "outside"], "speed_rpm": [inside, outside], "p_a_bar": [100.0, 100.0],
                  "p_b_bar": [0.0, 0.0], "oil_temp_C": [cli_temp(cli)] * 2}).to_csv(tmp_path / "pts.csv", index=False)
    result = load_result(tmp / "cli")
    pred = predict_points(result, read_tables([tmp_path / "pts.csv"], result[1], require_outputs=False))
    pred = pred.set_index("point_id")
    assert "speed" not in pred.loc["inside", "note"]
    assert f"extrapolated: speed {outside:.4g} rpm outside the fitted" in pred.loc["outside", "note"]


def cli_temp(doc) -> float:
    """A run's median oil temperature of the fitted campaign [°C]."""
    return float(next(r["temp_median_C"] for r in doc["data"]["runs"] if r.get("n_steady")))
