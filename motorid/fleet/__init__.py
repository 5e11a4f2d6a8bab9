"""Fleets: many motors and test dates fitted as Dask tasks, a DuckDB/Parquet store,
a population model per motor type and wear trends (docs/fleet.md).

    campaigns.py   campaign folders, input hashes, the re-run key
    tasks.py       Dask client, map_tasks (also for benchmark replications), the fit task
    fitting.py     motorid fleet fit: tasks → store → fleet.json
    store.py       Parquet rows, DuckDB views `fleet` and `failed`
    population.py  random-effects population, shrinkage, out-of-family verdicts
    trends.py      wear trends by weighted least squares over test dates
    summary.py     fleet.json and population.json from the store
    report.py      fleet_report.html
"""

from motorid.fleet.tasks import map_tasks  # noqa: F401
