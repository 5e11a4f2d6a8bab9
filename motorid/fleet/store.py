"""The fleet store: Parquet files (pyarrow) queried with DuckDB.

    FLEET_DIR/store/<campaign>.parquet        one row per campaign and parameter
    FLEET_DIR/campaigns/<campaign>/result.json   the campaign's own fit (as `motorid fit` writes it)
    FLEET_DIR/campaigns/<campaign>/diagnosis.json  where --diagnose was asked
    FLEET_DIR/campaigns/<campaign>/task.json     key, options, inputs of the stored result
    FLEET_DIR/campaigns/<campaign>/failed.json   the one-line error of a campaign that failed

One Parquet file per campaign, so that adding a campaign never rewrites the
others and a thousand campaigns are one ``read_parquet('store/*.parquet')``
away.  SQL sees two views: ``fleet`` (the columns of :data:`SCHEMA`) and
``failed`` (campaign, error).
"""

from __future__ import annotations

import datetime as _dt
import io
import json
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from motorid._atomic import write_bytes_atomic
from motorid.errors import InputError

STORE = "store"
CAMPAIGNS = "campaigns"
RESULT_FILE, DIAGNOSIS_FILE, TASK_FILE, FAILED_FILE = "result.json", "diagnosis.json", "task.json", "failed.json"

#: the columns of the ``fleet`` view: (name, arrow type, meaning)
COLUMNS = [
    ("campaign", pa.string(), "the campaign folder's name"),
    ("serial", pa.string(), "the motor's serial number (campaign.toml)"),
    ("test_date", pa.date32(), "the test date (campaign.toml)"),
    ("bench", pa.string(), "the test bench (campaign.toml; null where not given)"),
    ("motor_type", pa.string(), "campaign.toml motor_type, else the [motor] name of motor.toml"),
    ("parameter", pa.string(), "the parameter, named as in result.json (Kv, KF, KFS, TFc, Ks, KL0, KL_a1, …)"),
    ("value", pa.float64(), "least-squares estimate, SI (null where not identifiable)"),
    ("std", pa.float64(), "its standard error, SI (null where not identifiable)"),
    ("unit", pa.string(), "SI unit of value and std"),
    ("identifiable", pa.bool_(), "whether the logs determine the parameter"),
    ("ci95_low", pa.float64(), "result.json's 95 % interval, low end, SI"),
    ("ci95_high", pa.float64(), "result.json's 95 % interval, high end, SI"),
    ("reduced_chi2", pa.float64(), "the campaign fit's χ²/dof"),
    ("motorid_version", pa.string(), "motorid version that made the fit"),
    ("input_hashes", pa.string(), "JSON {file name: SHA-256} of campaign.toml, motor.toml and the logs"),
    ("options", pa.string(), "JSON of the fit options (harmonics, diagnose)"),
    ("key", pa.string(), "SHA-256 of input hashes, version and options: equal keys, equal results"),
    ("fitted_at", pa.timestamp("s", tz="UTC"), "when the fit was stored"),
]
SCHEMA = pa.schema([(n, t) for n, t, _ in COLUMNS])


def campaign_dir(fleet_dir, name: str) -> Path:
    return Path(fleet_dir) / CAMPAIGNS / name


def store_file(fleet_dir, name: str) -> Path:
    return Path(fleet_dir) / STORE / f"{name}.parquet"


def rows_of(result: dict, task: dict) -> list[dict]:
    """The store rows of one campaign: one per parameter of its result.json."""
    now = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0)
    rows = []
    for name, p in result["parameters"].items():
        ok = bool(p.get("identifiable")) and p.get("value") is not None and p.get("std") is not None
        ci = p.get("ci95") or [None, None]
        rows.append({
            "campaign": task["campaign"], "serial": task["serial"],
            "test_date": _dt.date.fromisoformat(task["date"]), "bench": task.get("bench"),
            "motor_type": task["motor_type"], "parameter": name,
            "value": p.get("value") if ok else None, "std": p.get("std") if ok else None,
            "unit": p.get("unit"), "identifiable": ok, "ci95_low": ci[0] if ok else None,
            "ci95_high": ci[1] if ok else None, "reduced_chi2": result["fit"].get("reduced_chi2"),
            "motorid_version": task["motorid_version"],
            "input_hashes": json.dumps(task["input_hashes"], sort_keys=True),
            "options": json.dumps(task["options"], sort_keys=True), "key": task["key"], "fitted_at": now,
        })
    return rows


def write_rows(fleet_dir, name: str, rows: list[dict]) -> Path:
    """Write one campaign's rows as ``store/<name>.parquet`` (whole or not at all)."""
    buf = io.BytesIO()
    pq.write_table(pa.Table.from_pylist(rows, schema=SCHEMA), buf)
    return write_bytes_atomic(store_file(fleet_dir, name), buf.getvalue())


def stored_key(fleet_dir, name: str) -> str | None:
    """The key of the result stored for campaign ``name`` (None where there is none)."""
    task = campaign_dir(fleet_dir, name) / TASK_FILE
    if not task.is_file() or not store_file(fleet_dir, name).is_file() \
            or not (campaign_dir(fleet_dir, name) / RESULT_FILE).is_file():
        return None
    try:
        return json.loads(task.read_text()).get("key")
    except (OSError, ValueError):
        return None


def failures(fleet_dir) -> list[dict]:
    """[{"campaign", "error"}] of every campaign whose last fit failed, by name."""
    out = []
    for p in sorted((Path(fleet_dir) / CAMPAIGNS).glob(f"*/{FAILED_FILE}")):
        try:
            out.append(json.loads(p.read_text()))
        except (OSError, ValueError):
            out.append({"campaign": p.parent.name, "error": f"{p}: unreadable"})
    return out


def check_fleet_dir(fleet_dir) -> Path:
    d = Path(fleet_dir)
    if not d.is_dir():
        raise InputError(f"{d}: no such fleet folder (make one with `motorid fleet fit … --out {d}`)")
    if not any((d / STORE).glob("*.parquet")) and not failures(d):
        raise InputError(f"{d}: not a fleet folder (no {STORE}/*.parquet and no failed campaign)")
    return d


def connect(fleet_dir):
    """An in-memory DuckDB connection with the views ``fleet`` and ``failed``."""
    import duckdb
    import pandas as pd

    d = check_fleet_dir(fleet_dir)
    con = duckdb.connect(":memory:")
    if any((d / STORE).glob("*.parquet")):
        pattern = str((d / STORE).resolve() / "*.parquet").replace("'", "''")
        con.execute(f"CREATE VIEW fleet AS SELECT * FROM read_parquet('{pattern}', union_by_name = true)")
    else:  # only failures so far: an empty view of the same columns
        con.register("_empty", pa.Table.from_pylist([], schema=SCHEMA))
        con.execute("CREATE VIEW fleet AS SELECT * FROM _empty")
    fail = pd.DataFrame(failures(d), columns=["campaign", "error"])
    con.register("_failed", fail)
    con.execute("CREATE VIEW failed AS SELECT * FROM _failed")
    return con


DEFAULT_QUERY = ("SELECT campaign, serial, test_date, motor_type, parameter, value, std, identifiable "
                 "FROM fleet ORDER BY serial, test_date, campaign, parameter")


def query(fleet_dir, sql: str | None = None):
    """Run ``sql`` (default: the fleet table) on the store; a pandas DataFrame.
    SQL that DuckDB rejects raises :class:`InputError` with DuckDB's first line."""
    import duckdb

    con = connect(fleet_dir)
    try:
        return con.execute(sql or DEFAULT_QUERY).df()
    except duckdb.Error as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise InputError(f"--sql: {first}") from None
    finally:
        con.close()


def all_rows(fleet_dir):
    """Every row of the store (pandas), sorted by serial, date, campaign, parameter."""
    return query(fleet_dir, "SELECT * FROM fleet ORDER BY serial, test_date, campaign, parameter")
