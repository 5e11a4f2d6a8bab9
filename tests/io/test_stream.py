"""Streamed reading (motorid.io.stream): the same SI frame as the whole-file reader, blocks that split
runs, and a bad cell in the middle of a stream refused with the whole-file reader's one line."""

import numpy as np
import pandas as pd
import pytest

from conftest import REPO
from motorid.errors import InputError
from motorid.io import logs, stream
from motorid.io.spec import load_motor_spec

DEMO = REPO / "synthetic_data" / "demo"
SPEC = load_motor_spec(DEMO / "motor.toml")
NUMERIC = [c for c in logs.SI_COLUMNS if c not in ("run_id", "protocol")] + [logs.VISCOSITY_FROM_OIL]


@pytest.fixture(scope="module")
def table():
    """Every fourth run of the demo campaign, in the format's units (as a bench writes it)."""
    df = pd.read_csv(DEMO / "campaign.csv.gz")
    keep = df["run_id"].isin(df["run_id"].drop_duplicates().iloc[::4])
    return df[keep].reset_index(drop=True)


@pytest.fixture
def small_blocks(monkeypatch):
    """Blocks of a few hundred rows, so that runs are split across blocks as in a long log."""
    monkeypatch.setattr(stream, "BLOCK_BYTES", 1 << 14)
    monkeypatch.setattr(stream, "PARQUET_BATCH_ROWS", 700)


def _same(streamed: pd.DataFrame, whole: pd.DataFrame):
    assert len(streamed) == len(whole)
    order = np.lexsort((whole["time_s"].to_numpy(), pd.factorize(whole["run_id"])[0]))
    whole = whole.iloc[order].reset_index(drop=True)
    for c in NUMERIC:
        np.testing.assert_array_equal(streamed[c].to_numpy(dtype=float), whole[c].to_numpy(dtype=float), err_msg=c)
    for c in ("run_id", "protocol", "run"):
        assert list(streamed[c].astype(str)) == list(whole[c].astype(str)), c


@pytest.mark.parametrize("name", ["log.csv", "log.csv.gz"])
def test_streamed_csv_is_the_whole_file_frame(tmp_path, table, small_blocks, name):
    path = tmp_path / name
    table.to_csv(path, index=False)  # pandas writes the .gz too
    _same(stream.read_streamed([path], SPEC), logs.read_logs([path], SPEC))


def test_streamed_units_and_a_column_order_of_its_own(tmp_path, table, small_blocks):
    t = table.copy()
    t["p_a_psi"] = t.pop("p_a_bar") * 14.503773773
    t["q_case_gpm"] = t.pop("q_case_lpm") / 3.785411784
    t["oil_temp_K"] = t.pop("oil_temp_C") + 273.15
    t = t.drop(columns="viscosity_mPas")  # the spec's oil gives it
    t["bench_note"] = "x"  # an extra column: ignored
    path = tmp_path / "units.csv"
    t[list(t.columns[::-1])].to_csv(path, index=False, sep=";")
    whole = logs.read_logs([path], SPEC)
    assert whole[logs.VISCOSITY_FROM_OIL].all()
    _same(stream.read_streamed([path], SPEC), whole)


def test_streamed_parquet_is_the_whole_file_frame(tmp_path, table, small_blocks):
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = tmp_path / "log.parquet"
    pq.write_table(pa.Table.from_pandas(table, preserve_index=False), path, row_group_size=1000)
    _same(stream.read_streamed([path], SPEC), logs.read_logs([path], SPEC))


def test_a_run_id_in_two_files_is_keyed_by_file(tmp_path, table):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    table.to_csv(a, index=False)
    table.to_csv(b, index=False)
    keys = [r.key for r in stream.stream_runs([a, b], SPEC, progress=False)]
    first = table["run_id"].iloc[0]
    assert keys.count(first) == 1 and keys.count(f"b.csv:{first}") == 1


def test_interleaved_runs_stop_the_stream_and_read_whole(tmp_path, table):
    from motorid.identify.pipeline import load_campaign

    runs = table["run_id"].drop_duplicates()
    a, b = (table[table["run_id"] == r] for r in runs.iloc[:2])
    # each run's second half comes after the other run's first half
    mixed = pd.concat([a.iloc[:len(a) // 2], b.iloc[:len(b) // 2], a.iloc[len(a) // 2:], b.iloc[len(b) // 2:]])
    path = tmp_path / "mixed.csv"
    mixed.to_csv(path, index=False)
    with pytest.raises(stream.StreamFallback, match="comes back"):
        list(stream.stream_runs([path], SPEC, progress=False))
    _, data = load_campaign([path], SPEC, cells=True)  # read whole instead: both runs there
    assert list(data.runs["run"]) == list(runs.iloc[:2])


def test_a_bad_cell_mid_stream_is_one_line_naming_file_line_and_column(tmp_path, table, small_blocks):
    from motorid.identify.pipeline import load_campaign

    bad = table.astype({"torque_Nm": object})
    row = len(bad) * 2 // 3
    bad.loc[row, "torque_Nm"] = "12.5Nm"
    path = tmp_path / "bad.csv"
    bad.to_csv(path, index=False)
    with pytest.raises(InputError) as whole:
        logs.read_logs([path], SPEC)
    with pytest.raises(InputError) as streamed:
        load_campaign([path], SPEC, cells=True)
    msg = str(streamed.value)
    assert msg == str(whole.value)
    assert "\n" not in msg and str(path) in msg and "torque_Nm" in msg and f"line {row + 2}" in msg


def test_the_cli_refuses_a_bad_streamed_log_without_output(tmp_path, table, small_blocks, monkeypatch, capsys):
    from motorid.cli import main

    bad = table.astype({"time_s": object})
    bad.loc[len(bad) // 2, "time_s"] = ""
    path = tmp_path / "bad.csv.gz"
    bad.to_csv(path, index=False)
    monkeypatch.setenv("MOTORID_CELL_ROWS", "1")  # the streamed, reduced path
    rc = main(["fit", str(path), "--motor", str(DEMO / "motor.toml"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and str(path) in err and "time_s" in err and "empty cell" in err
    assert not (tmp_path / "out" / "result.json").exists()


def test_estimated_rows_are_near_the_true_count(tmp_path, table):
    plain, packed = tmp_path / "a.csv", tmp_path / "b.csv.gz"
    table.to_csv(plain, index=False)
    table.to_csv(packed, index=False)
    for p in (plain, packed):
        assert abs(stream.estimate_rows([p]) / len(table) - 1.0) < 0.1
