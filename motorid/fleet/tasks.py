"""Tasks on Dask distributed: the client, a map with progress, and the fit of one campaign.

:func:`dask_client` gives a client of an embedded ``LocalCluster`` (worker
processes, one thread each, as many as the machine has cores or as asked) or of
a running cluster named by its scheduler address (``tcp://host:8786``).
:func:`map_tasks` runs ``func`` over ``items`` on it and returns the results in
order; a task that raises returns its error as one line instead (the others go
on).  :func:`fit_campaign_task` is the fleet's task: the existing fit pipeline
(least squares, and the discrepancy search where asked) on one campaign,
returning the documents that ``motorid fit`` / ``motorid diagnose`` would
write; the client writes them (workers need read access to the logs only).
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import time
from typing import Callable, Iterable, Sequence

from motorid.errors import InputError


def default_workers(n_tasks: int | None = None) -> int:
    """One worker process per core (at least 1), no more than there are tasks."""
    n = os.cpu_count() or 1
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        pass
    return max(1, min(n, n_tasks) if n_tasks else n)


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None, timeout: str = "20s"):
    """A ``dask.distributed.Client``: of the cluster at ``scheduler`` (``tcp://…``),
    or of an embedded ``LocalCluster`` of ``workers`` processes with one thread each."""
    from dask.distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout=timeout)
        except (OSError, TimeoutError, ValueError) as exc:
            msg = " ".join(str(exc).split()) or type(exc).__name__
            raise InputError(f"--scheduler {scheduler}: cannot connect ({msg})") from None
        try:
            yield client
        finally:
            client.close()
        return
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be at least 1, got {workers}")
    cluster = LocalCluster(n_workers=workers or default_workers(), threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=logging.ERROR)
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def one_line(exc: BaseException) -> str:
    """An exception as one line: InputError's own message, others prefixed with their type."""
    text = " ".join(str(exc).split())
    if isinstance(exc, InputError):
        return text
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


class TaskError:
    """What a failed task returns in place of its result: the one-line error."""

    def __init__(self, error: str):
        self.error = error

    def __repr__(self) -> str:
        return f"TaskError({self.error!r})"


def _guarded(func, item):
    try:
        return func(item)
    except Exception as exc:  # noqa: BLE001  (a failed task must not stop the others)
        return TaskError(one_line(exc))


def map_tasks(func: Callable, items: Sequence, scheduler: str | None = None, workers: int | None = None,
              progress: bool | None = None, client=None, desc: str = "tasks") -> list:
    """``[func(x) for x in items]`` as tasks on Dask distributed, in order.

    scheduler : address of a running scheduler (``tcp://host:port``); None: an
        embedded LocalCluster of ``workers`` processes (default: one per core).
    client : an existing ``dask.distributed.Client`` to use instead (kept open).
    progress : a tqdm bar on stderr; None: only where stderr is a terminal.
    A task that raises gives a :class:`TaskError` (its one-line error) in its place.
    ``func`` and the items must be picklable (a module-level function).
    """
    items = list(items)
    if not items:
        return []
    if client is None:
        with dask_client(scheduler, workers or default_workers(len(items))) as c:
            return map_tasks(func, items, progress=progress, client=c, desc=desc)
    from dask.distributed import as_completed
    from tqdm import tqdm

    show = sys.stderr.isatty() if progress is None else progress
    futures = client.map(_guarded, [func] * len(items), items, pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    out: list = [None] * len(items)
    with tqdm(total=len(items), desc=desc, unit="task", disable=not show, file=sys.stderr) as bar:
        for fut in as_completed(futures):
            try:
                out[index[fut.key]] = fut.result()
            except Exception as exc:  # noqa: BLE001  (a lost worker, an unpicklable result)
                out[index[fut.key]] = TaskError(one_line(exc))
            bar.update(1)
    return out


def map_local(func: Callable, items: Iterable) -> list:
    """The plain sequential loop that :func:`map_tasks` replaces (same guard, same order)."""
    return [_guarded(func, x) for x in items]


def fit_campaign_task(job: dict) -> dict:
    """Fit one campaign (a task): ``job`` holds ``campaign`` (a
    :class:`~motorid.fleet.campaigns.Campaign`), ``options`` ({"harmonics",
    "diagnose"}) and ``key``.  Returns ``{"campaign", "key", "result",
    "diagnosis", "seconds", "worker_pid"}``: the result.json document (and
    diagnosis.json where asked).  Bad input raises :class:`InputError`."""
    from motorid.identify.types import FitOptions
    from motorid.identify.pipeline import identify, load_campaign
    from motorid.identify.results import result_document
    from motorid.io.spec import load_motor_spec

    t0 = time.time()
    camp, options = job["campaign"], job["options"]
    spec = load_motor_spec(camp.motor)
    frame, dataset = load_campaign(list(camp.logs), spec)
    res = identify(list(camp.logs), spec, options=FitOptions(harmonics=options.get("harmonics")),
                   dataset=dataset, frame=frame)
    inputs = {"logs": list(camp.logs), "motor": camp.motor, "campaign": camp.folder}
    doc = result_document(res.ls, spec, res.dataset, None, inputs, res.seconds, res.priors)
    diagnosis = None
    if options.get("diagnose"):
        from motorid.discrepancy.select import diagnose, diagnosis_document

        dg = diagnose(dataset, spec, base=res.ls)
        diagnosis = diagnosis_document(dg, spec)
        diagnosis["inputs"] = inputs
    return {"campaign": camp.name, "key": job["key"], "result": doc, "diagnosis": diagnosis,
            "seconds": time.time() - t0, "worker_pid": os.getpid()}
