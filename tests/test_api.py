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
