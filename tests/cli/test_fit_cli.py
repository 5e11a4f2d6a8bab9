"""`motorid fit`: result.json end to end, and every bad input refused cleanly (issue 4)."""

import gzip
import json
import subprocess
import sys

import pandas as pd
import pytest

from conftest import REPO
from motorid.cli import main

DEMO = REPO / "synthetic_data" / "demo"
MOTOR = DEMO / "motor.toml"


@pytest.fixture(scope="module")
def small_log(tmp_path_factory):
    """A few runs of the demo campaign, as a plain CSV in the format's units."""
    df = pd.read_csv(DEMO / "campaign.csv.gz")
    keep = df["run_id"].isin(df["run_id"].drop_duplicates().iloc[::6])
    path = tmp_path_factory.mktemp("logs") / "small.csv"
    df[keep].to_csv(path, index=False)
    return path


def _fit(args, capsys):
    rc = main(["fit", *map(str, args)])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_fit_writes_result_json_in_the_documented_form(tmp_path, capsys):
    rc, out, err = _fit([DEMO / "campaign.csv.gz", "--motor", MOTOR, "--out", tmp_path / "r"], capsys)
    assert rc == 0, err
    doc = json.loads((tmp_path / "r" / "result.json").read_text())
    truth = {"Kv": 5000.0, "KF": 3e-3, "KFS": 1.5e-2, "TFc": 3.0, "Ks": 1.0, "KL0": 5e-14,
             "KL_a1": 0.15, "KL_b1": 0.08, "KAB": 2e-14}
    for k, true in truth.items():
        e = doc["parameters"][k]
        assert set(e) >= {"value", "unit", "std", "ci95", "identifiable"}
        assert e["identifiable"] is True
        assert abs(e["value"] - true) < 3.5 * e["std"], k
        assert e["ci95"][0] < e["value"] < e["ci95"][1]
    assert doc["parameters"]["TFc"]["unit"] == "N·m" and doc["parameters"]["KL0"]["unit"] == "m³"
    assert set(doc["noise"]) >= {"torque", "q_a", "q_b", "q_case", "breakaway"}
    assert doc["versions"]["jax"] and doc["versions"]["optimistix"]
    assert doc["data"]["protocols"]["startability"]["runs"] == 54
    # a second run refuses to overwrite, --force does
    rc, _, err = _fit([DEMO / "campaign.csv.gz", "--motor", MOTOR, "--out", tmp_path / "r"], capsys)
    assert rc == 2 and "exists; use --force" in err


def test_bayes_writes_mcmc_and_chain(tmp_path, small_log, capsys):
    rc, out, err = _fit([small_log, "--motor", MOTOR, "--out", tmp_path, "--bayes"], capsys)
    assert rc == 0, err
    doc = json.loads((tmp_path / "result.json").read_text())
    m = doc["mcmc"]
    assert set(m) >= {"tau", "ess", "converged"} and m["converged"] is True
    assert (tmp_path / "chain.npz").exists()
    for k, e in doc["parameters"].items():
        if e["identifiable"]:
            assert e["posterior"]["ci95"][0] < e["posterior"]["median"] < e["posterior"]["ci95"][1]
            assert m["steps"] >= 50 * m["tau"][k]


def _bad_inputs(tmp_path, small_log):
    df = pd.read_csv(small_log)
    cases = {}

    def write(name, frame=None, text=None, binary=None):
        p = tmp_path / name
        if binary is not None:
            p.write_bytes(binary)
        elif text is not None:
            p.write_text(text)
        else:
            frame.to_csv(p, index=False)
        return p

    cases["missing column"] = (write("nocase.csv", df.drop(columns=["q_case_lpm"])), ["nocase.csv", "q_case"])
    t = df.copy().astype({"torque_Nm": object})
    t.loc[t.index[7], "torque_Nm"] = "oops"
    cases["text in numeric"] = (write("text.csv", t), ["text.csv", "torque_Nm", "oops"])
    b = df.copy()
    b.loc[b.index[5], "time_s"] = b.loc[b.index[3], "time_s"]
    cases["time not increasing"] = (write("time.csv", b), ["time.csv", str(b.loc[b.index[5], "run_id"]), "time"])
    u = df.copy()
    u.loc[u.index[0], "protocol"] = "spin_test"
    cases["unknown protocol"] = (write("proto.csv", u), ["proto.csv", "spin_test"])
    cases["empty file"] = (write("empty.csv", text=""), ["empty.csv", "empty"])
    cases["binary file"] = (write("junk.csv.gz", binary=gzip.compress(bytes(range(256)) * 4)), ["junk.csv.gz"])
    return cases


@pytest.mark.parametrize("case", ["missing column", "text in numeric", "time not increasing",
                                  "unknown protocol", "empty file", "binary file"])
def test_bad_log_is_one_line_exit_2_and_nothing_written(case, tmp_path, small_log, capsys):
    path, words = _bad_inputs(tmp_path, small_log)[case]
    out = tmp_path / "out"
    rc, _, err = _fit([small_log, path, "--motor", MOTOR, "--out", out], capsys)
    assert rc == 2
    line = err.strip()
    assert "\n" not in line and "Traceback" not in line
    for w in words:
        assert w in line, (w, line)
    assert not (out / "result.json").exists()


@pytest.mark.parametrize("text,words", [
    ("[motor]\npistons = 1\ndisplacement_cm3 = 80\n", ["pistons"]),
    ("[motor]\npistons = 9\ndisplacement_cm3 = -5\n", ["displacement_cm3"]),
    ("[motor]\npistons = 9\n", ["displacement_cm3", "missing"]),
    ("[motor]\npistons = 9\ndisplacement_cm3 = 80\n[oil]\nnu40_cSt = 46\nnu100_cSt = 60\ndensity15_kg_m3 = 875\n",
     ["nu100_cSt"]),
    ("pistons = [", ["TOML"]),
])
def test_impossible_spec_is_refused(text, words, tmp_path, small_log, capsys):
    spec = tmp_path / "bad.toml"
    spec.write_text(text)
    rc, _, err = _fit([small_log, "--motor", spec, "--out", tmp_path / "o"], capsys)
    assert rc == 2 and "bad.toml" in err and "\n" not in err.strip()
    for w in words:
        assert w in err
    assert not (tmp_path / "o" / "result.json").exists()


def test_process_exit_status_and_no_traceback(tmp_path):
    bad = tmp_path / "x.csv"
    bad.write_text("time_s,run_id\n0,a\n")
    r = subprocess.run([sys.executable, "-m", "motorid", "fit", str(bad), "--motor", str(MOTOR),
                        "--out", str(tmp_path / "o")], capture_output=True, text=True)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert "x.csv" in r.stderr


def test_startability_runs_alone_give_reasons_not_a_crash(tmp_path, capsys):
    """A campaign of breakaway tests only: the fit has no running samples at all; every
    parameter gets its reason (the static friction is measured against the running one)."""
    df = pd.read_csv(DEMO / "campaign.csv.gz")
    log = tmp_path / "startability.csv"
    df[df["protocol"] == "startability"].to_csv(log, index=False)
    rc, out, err = _fit([log, "--motor", MOTOR, "--out", tmp_path / "r"], capsys)
    assert rc == 0, err
    doc = json.loads((tmp_path / "r" / "result.json").read_text())
    params = doc["parameters"]
    assert not any(p["identifiable"] for p in params.values())
    assert "running" in params["KF"]["reason"] and "K_F" in params["KFS"]["reason"]


def test_viscosity_from_the_oil_model_is_said_in_the_warnings(tmp_path, small_log, capsys):
    df = pd.read_csv(small_log)
    without = tmp_path / "no_viscometer.csv"
    df.drop(columns=["viscosity_mPas"]).to_csv(without, index=False)
    for log, out, expect in ((small_log, "with", False), (without, "without", True)):
        rc, text, err = _fit([log, "--motor", MOTOR, "--out", tmp_path / out], capsys)
        assert rc == 0, err
        warnings = json.loads((tmp_path / out / "result.json").read_text())["fit"]["warnings"]
        said = [w for w in warnings if "oil_temp_C" in w and "viscometer" in w]
        assert bool(said) == expect, warnings
        assert ("viscometer" in text) == expect
    assert "100 %" in said[0] and "KL0" in said[0]


def test_a_reader_that_goes_away_is_no_error(tmp_path):
    """`motorid … | head`: the pipe closes before motorid has printed; it printed a BrokenPipeError
    traceback (and a --report after the summary would not have been written). Now it goes quiet."""
    p = subprocess.Popen([sys.executable, "-m", "motorid", "fit", str(DEMO / "campaign.csv.gz"), "--motor",
                          str(MOTOR), "--out", str(tmp_path / "o"), "--quiet", "--report"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=600) == 0, err
    assert "Traceback" not in err and "BrokenPipe" not in err
    assert (tmp_path / "o" / "result.json").exists() and (tmp_path / "o" / "report.html").exists()
