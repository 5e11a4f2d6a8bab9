"""A recording of many set points in one run, as a bench script logs a whole test into one file with no run
column and no pause (motorid.io.set_points), and an oil temperature logged slower than the rest
(motorid.io.temperature_gaps)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from motorid.io.set_points import set_point_pieces
from motorid.io.temperature_gaps import TEMPERATURE_GAP_S, fill_temperature_gaps

REPO = Path(__file__).resolve().parents[2]
DEMO = REPO / "synthetic_data" / "demo"
RPM = 2 * np.pi / 60


def _steps(levels, hold=1.5, ramp=0.5, rate=1000.0, seed=0):
    """(t, speed, ΔP) of plateaus at ``levels`` (rpm, bar) joined by smoothstep ramps, with noise."""
    rng = np.random.default_rng(seed)
    t, w, p, where = [], [], [], []
    now = 0.0
    for k, (rpm, bar) in enumerate(levels):
        if k:
            s = np.arange(0, ramp, 1 / rate) / ramp
            s = s * s * (3 - 2 * s)
            w0, p0 = levels[k - 1]
            t.append(now + s * 0 + np.arange(s.size) / rate)
            w.append(w0 + (rpm - w0) * s)
            p.append(p0 + (bar - p0) * s)
            where.append(np.full(s.size, -1))
            now += ramp
        n = int(hold * rate)
        t.append(now + np.arange(n) / rate)
        w.append(np.full(n, float(rpm)))
        p.append(np.full(n, float(bar)))
        where.append(np.full(n, k))
        now += hold
    t, w, p, where = (np.concatenate(x) for x in (t, w, p, where))
    w = w * RPM * (1 + 0.002 * np.sin(2 * np.pi * 1.5 * t)) + 0.002 * rng.normal(size=t.size)
    return t, w, p * 1e5 + 0.05e5 * rng.normal(size=t.size), where


def test_a_run_of_many_set_points_is_cut_at_its_ramps():
    """Speeds from 10 to 2500 rpm in both directions at three ΔP, joined by 0.5 s ramps: one piece per
    set point, each within its plateau (no ramp sample), in order; a run at one set point, and one whose
    ΔP sweeps without a plateau, are left whole."""
    levels = [(s * d, p) for d in (1, -1) for s in (10, 30, 100, 1000, 2500) for p in (50, 250)]
    t, w, dp, where = _steps(levels)
    pieces = set_point_pieces("constant_speed", t, w, dp)
    assert pieces is not None and len(pieces) == len(levels)
    for k, idx in enumerate(pieces):
        assert np.all(where[idx] == k), (k, np.unique(where[idx]))
        assert idx.size >= 0.8 * 1500
    one = _steps([(300, 150)])
    assert set_point_pieces("constant_pressure", *one[:3]) is None
    sweep_t = np.arange(0, 20, 1e-3)
    assert set_point_pieces("constant_speed", sweep_t, np.full(sweep_t.size, 100 * RPM),
                            (20 + 14 * sweep_t) * 1e5) is None


def test_back_to_back_breakaways_become_one_run_each_starting_at_rest():
    """Three startability cycles logged back to back (hold at rest, break away, run at 10 rpm, stop):
    three pieces, each starting with the shaft at rest and holding its own breakaway; a single
    breakaway, and a stop shorter than a second between two motions (stick-slip), are left whole."""
    rate = 1000.0
    parts, t0 = [], 0.0
    for cycle in range(3):
        rest = np.zeros(int(2.0 * rate))
        up = np.linspace(0, 10 * RPM, int(0.1 * rate))
        run = np.full(int(1.0 * rate), 10 * RPM)
        down = np.linspace(10 * RPM, 0, int(0.3 * rate))
        parts.append(np.concatenate([rest, up, run, down]))
    w = np.concatenate(parts)
    t = np.arange(w.size) / rate
    w = w + 2e-4 * np.random.default_rng(1).normal(size=w.size)
    pieces = set_point_pieces("startability", t, w, np.full(w.size, 50e5))
    assert pieces is not None and len(pieces) == 3
    for idx in pieces:
        assert abs(w[idx[0]]) < 0.01 and np.max(np.abs(w[idx])) > 0.9 * 10 * RPM
    single = parts[0]
    assert set_point_pieces("startability", np.arange(single.size) / rate, single, np.full(single.size, 5e6)) is None
    stick = np.concatenate([np.zeros(2000), np.full(500, 0.5), np.zeros(300), np.full(500, 0.5)])
    assert set_point_pieces("startability", np.arange(stick.size) / rate, stick, np.full(stick.size, 5e6)) is None


def test_a_slow_temperature_is_filled_between_its_readings_and_not_over_long_gaps():
    """A temperature read once a second at 1 kHz: every row gets the line between the readings around it;
    the carry takes a run on into the next block; a gap longer than TEMPERATURE_GAP_S stays empty, and a
    reading of one run never fills another's rows."""
    t = np.arange(0, 10, 1e-3)
    true = 40 + 0.5 * t
    temp = np.where(np.arange(t.size) % 1000 == 0, true, np.nan)
    filled, carry = fill_temperature_gaps(t, temp, np.zeros(t.size, int))
    inside = t <= 9.0
    np.testing.assert_allclose(filled[inside], true[inside], atol=1e-9)
    assert np.all(filled[~inside] == true[9000])  # held after the last reading
    nxt, _ = fill_temperature_gaps(t[:5] + 10, np.full(5, np.nan), np.zeros(5, int), carry)
    assert np.all(nxt == true[9000])
    other, _ = fill_temperature_gaps(t[:5] + 10, np.full(5, np.nan), np.ones(5, int), carry)
    assert np.all(np.isnan(other))
    far = np.array([0.0, 1.0, 2.0 + TEMPERATURE_GAP_S * 2])
    out, _ = fill_temperature_gaps(far, np.array([40.0, np.nan, 41.0]), np.zeros(3, int))
    assert np.isnan(out[1])


def _continuous(frame: pd.DataFrame, protocol: str, ramp_s: float = 0.5, rate: float = 100.0) -> pd.DataFrame:
    """The runs of one protocol logged back to back into one table: time running on, each run joined to
    the next by a ramp of every channel (a smoothstep over ``ramp_s``), the shaft angle carried along."""
    runs = [g.sort_values("time_s") for _, g in frame[frame["protocol"] == protocol].groupby("run_id", sort=True)]
    out, now = [], 0.0
    chans = ["speed_rpm", "torque_Nm", "p_a_bar", "p_b_bar", "p_case_bar", "q_a_lpm", "q_b_lpm", "q_case_lpm",
             "oil_temp_C"]
    for k, g in enumerate(runs):
        g = g.copy()
        if k:
            prev = out[-1].iloc[-1]
            s = np.arange(1, int(ramp_s * rate)) / (ramp_s * rate)
            s = s * s * (3 - 2 * s)
            ramp = pd.DataFrame({c: prev[c] + (g[c].iloc[0] - prev[c]) * s for c in chans})
            ramp["time_s"] = now + np.arange(1, s.size + 1) / rate
            ramp["shaft_angle_deg"] = (prev["shaft_angle_deg"] + np.cumsum(ramp["speed_rpm"] * 6 / rate)) % 360
            out.append(ramp)
            now = ramp["time_s"].iloc[-1] + 1 / rate
        g["time_s"] = g["time_s"] - g["time_s"].iloc[0] + now
        now = g["time_s"].iloc[-1] + 1 / rate
        out.append(g[["time_s", "shaft_angle_deg"] + chans])
    return pd.concat(out, ignore_index=True)


@pytest.fixture(scope="module")
def continuous_campaign(tmp_path_factory):
    d = tmp_path_factory.mktemp("continuous")
    frame = pd.read_csv(DEMO / "campaign.csv.gz")
    speed_runs = sorted(frame.loc[frame["protocol"] == "constant_speed", "run_id"].unique())
    # the fast set points (the 0.3-3 rpm runs last minutes each) and every breakaway
    keep = frame["run_id"].isin([r for r in speed_runs if frame.loc[frame["run_id"] == r, "speed_rpm"].abs().median() > 5])
    keep |= frame["protocol"] == "startability"
    frame = frame[keep]
    frame.to_csv(d / "native.csv", index=False)
    names = {"time_s": "s", "shaft_angle_deg": "deg", "speed_rpm": "rpm", "torque_Nm": "N*m", "p_a_bar": "bar",
             "p_b_bar": "bar", "p_case_bar": "bar", "q_a_lpm": "l/min", "q_b_lpm": "l/min", "q_case_lpm": "l/min",
             "oil_temp_C": "degC"}
    for protocol, stem in (("constant_speed", "speeds"), ("startability", "breakaways")):
        _continuous(frame, protocol).rename(columns=lambda c: f"ch_{c}").to_csv(d / f"{stem}.csv", index=False)
        (d / f"{stem}.channels.toml").write_text(f'[constants]\nprotocol = "{protocol}"\n[channels]\n' + "".join(
            f'{c} = {{name = "ch_{c}", unit = "{u}"}}\n' for c, u in names.items()))
    cmd = [sys.executable, "-m", "motorid", "fit", "--motor", str(DEMO / "motor.toml"), "--quiet"]
    runs = {}
    for name, files in (("native", ["native.csv"]), ("continuous", ["speeds.csv", "breakaways.csv"])):
        out = subprocess.run(cmd + [str(d / f) for f in files] + ["--out", str(d / name)], capture_output=True,
                             text=True, cwd=d)
        assert out.returncode == 0, out.stderr
        runs[name] = json.loads((d / name / "result.json").read_text())
    return frame, runs


def test_a_continuous_recording_fits_as_its_runs_do(continuous_campaign):
    """The demo's constant-speed runs and breakaways logged back to back with ramps between them, no run
    column, no pause (a channel map per file): cut into as many runs as were logged, and the fit gives
    every parameter within one standard error of the fit of the runs as written (the ramps left out;
    read as one run, the reverse half was dropped and the ramps taken as steady)."""
    frame, runs = continuous_campaign
    native, cont = runs["native"], runs["continuous"]
    for protocol in ("constant_speed", "startability"):
        assert cont["data"]["protocols"][protocol]["runs"] == frame.loc[frame["protocol"] == protocol,
                                                                         "run_id"].nunique()
    for k, e in native["parameters"].items():
        if not e["identifiable"]:
            continue
        c = cont["parameters"][k]
        assert c["identifiable"], k
        assert abs(c["value"] - e["value"]) < e["std"], (k, c["value"], e["value"], e["std"])


def test_short_plateaus_get_the_temperature_read_between_them(tmp_path):
    """Plateaus of 0.8 s with the temperature read every 2 s: the temperature is filled before the ramps
    are cut away, so every plateau's samples keep a viscosity (a plateau between two readings had none)."""
    from motorid.io.logs import read_log
    from motorid.io.spec import load_motor_spec

    t, w, dp, _ = _steps([(500, 50), (1000, 150), (1500, 250), (2000, 100)], hold=0.8)
    temp = np.where(np.isclose(np.mod(t, 2.0), 0.0, atol=5e-4), 45 + t, np.nan)
    pd.DataFrame({"t": t, "ang": np.degrees(np.cumsum(w) * 1e-3) % 360, "n": w / RPM, "M": 50.0, "pa": dp / 1e5 + 7,
                  "pb": 7.0, "pc": 0.5, "qa": 10.0, "qb": -9.8, "qc": 0.2, "T": temp}).to_csv(tmp_path / "log.csv",
                                                                                              index=False)
    cols = {"time_s": ("t", "s"), "shaft_angle_deg": ("ang", "deg"), "speed_rpm": ("n", "rpm"),
            "torque_Nm": ("M", "N*m"), "p_a_bar": ("pa", "bar"), "p_b_bar": ("pb", "bar"), "p_case_bar": ("pc", "bar"),
            "q_a_lpm": ("qa", "l/min"), "q_b_lpm": ("qb", "l/min"), "q_case_lpm": ("qc", "l/min"),
            "oil_temp_C": ("T", "degC")}
    (tmp_path / "log.channels.toml").write_text('[constants]\nprotocol = "constant_speed"\n[channels]\n' + "".join(
        f'{k} = {{name = "{n}", unit = "{u}"}}\n' for k, (n, u) in cols.items()))
    frame = read_log(tmp_path / "log.csv", load_motor_spec(DEMO / "motor.toml"))
    assert frame["run_id"].nunique() == 4
    assert frame["viscosity_Pa_s"].notna().all() and frame["oil_temp_C"].notna().all()
