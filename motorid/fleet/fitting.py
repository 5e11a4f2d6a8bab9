"""`motorid fleet fit`: every campaign a task on Dask, results into the store, then fleet.json.

A campaign whose stored result has the same key (input file hashes, motorid
version, options; see :func:`~motorid.fleet.campaigns.campaign_key`) is
skipped.  A campaign that fails (unreadable folder, bad log, a fit that
raises) gets ``campaigns/<name>/failed.json`` with its one-line error, its
stale rows leave the store, and the others go on.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

from motorid import __version__
from motorid.errors import InputError
from motorid.fleet import store
from motorid.fleet.campaigns import campaign_key, read_campaign
from motorid.fleet.tasks import TaskError, fit_campaign_task, map_tasks


@dataclass
class FleetRun:
    fitted: list = field(default_factory=list)  # campaign names fitted now
    skipped: list = field(default_factory=list)  # campaign names whose stored result was kept
    failed: list = field(default_factory=list)  # [{"campaign", "error"}] of this run
    seconds: float = 0.0
    workers: dict = field(default_factory=dict)  # campaign -> worker process id


def _json(path: Path, doc: dict) -> None:
    from motorid.identify.results import write_json_atomic

    write_json_atomic(doc, path)


def _forget(fleet_dir: Path, name: str, keep_failed: bool) -> None:
    """Remove a campaign's stored rows and files (before storing anew, or after a failure)."""
    cdir = store.campaign_dir(fleet_dir, name)
    files = [store.store_file(fleet_dir, name), cdir / store.RESULT_FILE, cdir / store.DIAGNOSIS_FILE,
             cdir / store.TASK_FILE]
    if not keep_failed:
        files.append(cdir / store.FAILED_FILE)
    for p in files:
        p.unlink(missing_ok=True)


def _record_failure(fleet_dir: Path, name: str, error: str) -> dict:
    _forget(fleet_dir, name, keep_failed=True)
    entry = {"campaign": name, "error": error}
    _json(store.campaign_dir(fleet_dir, name) / store.FAILED_FILE, entry)
    return entry


def _record_result(fleet_dir: Path, camp, options: dict, out: dict) -> None:
    name = camp.name
    cdir = store.campaign_dir(fleet_dir, name)
    _forget(fleet_dir, name, keep_failed=False)
    task = {"campaign": name, "folder": camp.folder, "serial": camp.serial, "date": camp.date.isoformat(),
            "bench": camp.bench, "motor_type": camp.motor_type, "key": out["key"], "options": options,
            "motorid_version": __version__, "input_hashes": camp.hashes, "seconds": out["seconds"],
            "worker_pid": out["worker_pid"]}
    _json(cdir / store.RESULT_FILE, out["result"])
    if out.get("diagnosis") is not None:
        _json(cdir / store.DIAGNOSIS_FILE, out["diagnosis"])
    store.write_rows(fleet_dir, name, store.rows_of(out["result"], task))
    _json(cdir / store.TASK_FILE, task)  # last: its key marks the result complete


def fit_fleet(campaign_dirs, out_dir, scheduler: str | None = None, workers: int | None = None,
              diagnose: bool = False, harmonics: int | None = None, progress: bool | None = None) -> FleetRun:
    """Fit every campaign folder as a Dask task and store the results in ``out_dir``;
    then write ``fleet.json`` and ``population.json`` (see :mod:`motorid.fleet.summary`)."""
    from motorid.fleet.summary import write_summary

    t0 = time.time()
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a folder")
    if harmonics is not None and not 0 <= harmonics <= 10:
        raise InputError(f"--harmonics must be between 0 and 10, got {harmonics}")
    names: dict = {}
    for d in campaign_dirs:
        name = Path(d).resolve().name
        if name in names and Path(names[name]).resolve() != Path(d).resolve():
            raise InputError(f"two campaign folders named '{name}' ({names[name]} and {d}): "
                             "a fleet keys its campaigns by folder name")
        names[name] = d
    options = {"harmonics": harmonics, "diagnose": bool(diagnose)}
    run = FleetRun()
    jobs, camps = [], {}
    out.mkdir(parents=True, exist_ok=True)
    for name, d in names.items():
        try:
            camp = read_campaign(d)
        except InputError as exc:
            run.failed.append(_record_failure(out, name, str(exc)))
            continue
        key = campaign_key(camp, options, __version__)
        if store.stored_key(out, name) == key:
            run.skipped.append(name)
            continue
        camps[name] = camp
        jobs.append({"campaign": camp, "options": options, "key": key})
    results = map_tasks(fit_campaign_task, jobs, scheduler=scheduler, workers=workers, progress=progress,
                        desc="campaigns")
    for job, res in zip(jobs, results):
        name = job["campaign"].name
        if isinstance(res, TaskError):
            run.failed.append(_record_failure(out, name, res.error))
        else:
            _record_result(out, job["campaign"], options, res)
            run.fitted.append(name)
            run.workers[name] = res["worker_pid"]
    write_summary(out)
    run.seconds = time.time() - t0
    return run


def describe_run(run: FleetRun, out_dir) -> str:
    """What a fleet fit did, in a few lines."""
    lines = [f"fitted {len(run.fitted)}, skipped {len(run.skipped)} (result already there), "
             f"failed {len(run.failed)} in {run.seconds:.1f} s"]
    for f in run.failed:
        lines.append(f"failed {f['campaign']}: {f['error']}")
    lines.append(f"wrote {Path(out_dir) / 'fleet.json'}")
    return "\n".join(lines)


def load_fleet_json(fleet_dir) -> dict:
    p = Path(fleet_dir) / "fleet.json"
    try:
        return json.loads(p.read_text())
    except OSError as exc:
        raise InputError(f"{p}: cannot read ({exc.strerror or exc}); run `motorid fleet fit` first") from None
    except ValueError as exc:
        raise InputError(f"{p}: not valid JSON ({exc})") from None
