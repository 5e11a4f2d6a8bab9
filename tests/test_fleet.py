"""End to end: a small simulated fleet fitted on Dask (embedded and a real cluster of separate
processes), the Parquet/DuckDB store, fleet.json, a broken campaign, the re-run, the report."""

import datetime as dt
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from conftest import DEMO_TRUTH, PROTOCOLS
from motorid.cli import main
from motorid.fleet import store
from motorid.fleet.fitting import fit_fleet
from motorid.model import MotorSpec, OilSpec

SPEC = MotorSpec(name="A2FM-80", pistons=9, displacement=80e-6, inertia=0.005, oil=OilSpec())
WEAR_PER_YEAR = 0.5  # SN-1's leakage K_L0 grows 50 % a year


def _motor(rng):
    p = dict(DEMO_TRUTH)
    for k, spread in (("Kv", 0.1), ("KL0", 0.15), ("KAB", 0.1), ("KF", 0.1)):
        p[k] *= math.exp(rng.normal(0, spread))
    return p


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory):
    """Four motors; SN-1 re-tested a year later with its leakage up 50 %, SN-2 re-tested unchanged;
    and a campaign whose log is broken."""
    from motorid.fleet.simulated import small_protocols, write_simulated_campaign

    root = tmp_path_factory.mktemp("fleet")
    prots = small_protocols(PROTOCOLS, every=6)
    rng = np.random.default_rng(2026)
    motors = {f"SN-{i}": _motor(rng) for i in range(1, 5)}
    d0 = dt.date(2025, 3, 1)
    folders = []
    for i, (serial, p) in enumerate(motors.items()):
        folders.append(write_simulated_campaign(root / f"{serial}_{d0}", p, prots, SPEC, serial, d0, seed=i,
                                                bench="bench-1"))
    d1 = d0 + dt.timedelta(days=365)
    worn = dict(motors["SN-1"], KL0=motors["SN-1"]["KL0"] * (1 + WEAR_PER_YEAR))
    folders.append(write_simulated_campaign(root / f"SN-1_{d1}", worn, prots, SPEC, "SN-1", d1, seed=11,
                                            bench="bench-2"))
    folders.append(write_simulated_campaign(root / f"SN-2_{d1}", motors["SN-2"], prots, SPEC, "SN-2", d1,
                                            seed=12, bench="bench-2"))
    bad = write_simulated_campaign(root / "SN-9_broken", motors["SN-3"], prots[:1], SPEC, "SN-9", d0, seed=9)
    text = (bad / "campaign.csv.gz").read_bytes()
    (bad / "campaign.csv.gz").unlink()
    import gzip

    lines = gzip.decompress(text).decode().splitlines()
    lines[5] = lines[5].replace(",", ",oops,", 1)  # a row with one cell too many
    (bad / "campaign.csv").write_text("\n".join(lines[:50]) + "\n")
    return {"root": root, "folders": folders, "bad": bad, "motors": motors}


@pytest.fixture(scope="module")
def fleet(campaigns, tmp_path_factory):
    out = tmp_path_factory.mktemp("fleet_out")
    run = fit_fleet([*campaigns["folders"], campaigns["bad"]], out, workers=1, progress=False)
    return {"out": out, "run": run}


def test_fleet_fits_all_but_the_broken_campaign(fleet, campaigns):
    run = fleet["run"]
    assert sorted(run.fitted) == sorted(f.name for f in campaigns["folders"])
    assert [f["campaign"] for f in run.failed] == ["SN-9_broken"]
    err = run.failed[0]["error"]
    assert "\n" not in err and "campaign.csv" in err
    doc = json.loads((fleet["out"] / "fleet.json").read_text())
    assert doc["failed"] == [{"campaign": "SN-9_broken", "error": err}]
    # each campaign's own result.json is kept, as `motorid fit` writes it
    for f in campaigns["folders"]:
        res = json.loads((fleet["out"] / "campaigns" / f.name / "result.json").read_text())
        assert res["parameters"]["KL0"]["identifiable"]
    assert not (fleet["out"] / "store" / "SN-9_broken.parquet").exists()


def test_fleet_json_contract_trends_and_population(fleet, campaigns):
    doc = json.loads((fleet["out"] / "fleet.json").read_text())
    assert set(doc) == {"population", "motors", "failed"}
    pop = doc["population"]["A2FM-80"]
    for entry in pop.values():
        assert set(entry) == {"mean", "sd", "mean_ci95", "sd_ci95"}
        assert entry["mean_ci95"][0] <= entry["mean"] <= entry["mean_ci95"][1]
    motors = {m["serial"]: m for m in doc["motors"]}
    assert sorted(motors) == ["SN-1", "SN-2", "SN-3", "SN-4"]
    for m in motors.values():
        assert set(m) == {"serial", "motor_type", "dates", "out_of_family", "trends"}
        assert m["out_of_family"] == []  # four motors drawn from one family
    assert motors["SN-1"]["dates"] == ["2025-03-01", "2026-03-01"]
    kl0 = next(t for t in motors["SN-1"]["trends"] if t["parameter"] == "KL0")
    assert kl0["verdict"] == "rising"
    true_rate = WEAR_PER_YEAR * campaigns["motors"]["SN-1"]["KL0"] * 365.25 / 365  # per year of 365.25 d
    assert kl0["ci95"][0] <= true_rate <= kl0["ci95"][1]
    # the motor re-tested unchanged: nothing moved beyond its uncertainty
    assert [t["verdict"] for t in motors["SN-2"]["trends"]] == ["stable"] * len(motors["SN-2"]["trends"])
    assert len(motors["SN-2"]["trends"]) == 9
    # the population uses SN-1's latest test: its K_L0 there is the worn one
    detail = json.loads((fleet["out"] / "population.json").read_text())["types"]["A2FM-80"]["KL0"]
    sn1 = next(m for m in detail["per_motor"] if m["serial"] == "SN-1")
    assert sn1["value"] == pytest.approx(campaigns["motors"]["SN-1"]["KL0"] * (1 + WEAR_PER_YEAR), rel=0.01)


def test_duckdb_query_over_the_parquet_store(fleet):
    out = fleet["out"]
    df = store.query(out, "SELECT serial, count(DISTINCT campaign) AS n, avg(value) AS kv FROM fleet "
                          "WHERE parameter = 'Kv' GROUP BY serial ORDER BY serial")
    assert df["serial"].tolist() == ["SN-1", "SN-2", "SN-3", "SN-4"] and df["n"].tolist() == [2, 2, 1, 1]
    # the same numbers from the campaigns' own result.json files
    for serial, kv in zip(df["serial"], df["kv"]):
        vals = []
        for p in (out / "campaigns").glob(f"{serial}_*/result.json"):
            vals.append(json.loads(p.read_text())["parameters"]["Kv"]["value"])
        assert kv == pytest.approx(np.mean(vals), rel=1e-12)
    # the store's files are Parquet that pyarrow reads back with the documented columns
    import pyarrow.parquet as pq

    tbl = pq.read_table(next((out / "store").glob("*.parquet")))
    assert tbl.schema.names == [c for c, _, _ in store.COLUMNS]
    assert store.query(out, "SELECT campaign FROM failed")["campaign"].tolist() == ["SN-9_broken"]


def test_fleet_table_cli(fleet, capsys):
    out = fleet["out"]
    assert main(["fleet", "table", str(out), "--csv"]) == 0
    import io

    df = pd.read_csv(io.StringIO(capsys.readouterr().out))
    assert len(df) == 6 * 9 and set(df["parameter"]) >= {"Kv", "KL0", "KAB"}
    assert main(["fleet", "table", str(out), "--sql", "SELEC nonsense"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("motorid fleet: error: --sql:") and "\n" not in err
    assert main(["fleet", "table", str(out / "nope")]) == 2


def test_rerun_skips_stored_campaigns(fleet, campaigns):
    t0 = time.time()
    run = fit_fleet(campaigns["folders"], fleet["out"], workers=1, progress=False)
    assert run.fitted == [] and sorted(run.skipped) == sorted(f.name for f in campaigns["folders"])
    assert time.time() - t0 < 5  # no cluster started, nothing re-fitted


def test_fleet_report_is_one_self_contained_page(fleet):
    from motorid.fleet.report import write_fleet_report

    page = write_fleet_report(fleet["out"]).read_text()
    assert page.count("data:image/png;base64,") >= 5
    assert "src=\"http" not in page and "<script" not in page
    assert "SN-1 (KL0 rising)" in page and "SN-9_broken" in page


@pytest.fixture
def dask_cluster(tmp_path):
    """`dask scheduler` and two `dask worker` processes on 127.0.0.1."""
    exe = Path(sys.executable).parent / "dask"
    sched_file = tmp_path / "scheduler.json"
    env = dict(os.environ)
    procs = [subprocess.Popen([str(exe), "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                               "--scheduler-file", str(sched_file)], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        for _ in range(300):
            if sched_file.exists() and sched_file.stat().st_size:
                break
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        for _ in range(2):
            procs.append(subprocess.Popen([str(exe), "worker", address, "--nthreads", "1", "--nworkers", "1",
                                           "--no-dashboard", "--host", "127.0.0.1"], env=env,
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from dask.distributed import Client

        with Client(address, timeout="30s") as c:
            c.wait_for_workers(2, timeout=60)
            pids = set(c.run(os.getpid).values())
        yield address, pids
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=2)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def test_real_cluster_gives_the_same_table(fleet, campaigns, dask_cluster, tmp_path):
    address, pids = dask_cluster
    out = tmp_path / "fleet_cluster"
    assert main(["fleet", "fit", *map(str, campaigns["folders"]), str(campaigns["bad"]), "--out", str(out),
                 "--scheduler", address, "--quiet"]) == 0
    used = {json.loads((out / "campaigns" / f.name / "task.json").read_text())["worker_pid"]
            for f in campaigns["folders"]}
    assert used == pids  # the campaigns ran in the two worker processes, not here
    cols = "campaign, serial, test_date, parameter, value, std, identifiable"
    a = store.query(fleet["out"], f"SELECT {cols} FROM fleet ORDER BY campaign, parameter")
    b = store.query(out, f"SELECT {cols} FROM fleet ORDER BY campaign, parameter")
    pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-9)
    fa = json.loads((fleet["out"] / "fleet.json").read_text())
    fb = json.loads((out / "fleet.json").read_text())
    assert fa["failed"] == fb["failed"]
    assert [[(t["parameter"], t["verdict"]) for t in m["trends"]] for m in fa["motors"]] == \
        [[(t["parameter"], t["verdict"]) for t in m["trends"]] for m in fb["motors"]]


def test_bad_scheduler_address_is_one_line():
    from motorid.errors import InputError
    from motorid.fleet.tasks import dask_client

    with pytest.raises(InputError, match=r"^--scheduler tcp://127.0.0.1:9: cannot connect \(") as exc:
        with dask_client("tcp://127.0.0.1:9", timeout="1s"):
            pass
    assert "\n" not in str(exc.value)
