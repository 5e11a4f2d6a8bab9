"""fleet.json and population.json from the store: populations per motor type, verdicts, trends.

fleet.json follows BENCH_LOG_FORMAT.md ("Campaign folders and fleets") exactly:
``population`` (per motor type and parameter: SI mean, sd and their 95 %
intervals), ``motors`` (serial, motor type, test dates, the parameters judged
out of family with their probability, the trends) and ``failed``.
population.json holds the rest: μ and τ on the model's scale, the motors in
each fit, and every motor's shrunken estimate, deviate and probability.

The population of a motor type uses each motor's latest test date (the last
campaign of that date by name where there are several); parameters not
identifiable from a campaign are left out of it, never filled in.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

from motorid.fleet import store
from motorid.fleet.population import analyse_type
from motorid.fleet.trends import as_date, motor_trends

FLEET_FILE, POPULATION_FILE = "fleet.json", "population.json"


def _latest_campaigns(rows) -> dict:
    """serial -> the campaign name of its latest test date."""
    last = (rows[["serial", "test_date", "campaign"]].drop_duplicates()
            .sort_values(["serial", "test_date", "campaign"]).groupby("serial").tail(1))
    return dict(zip(last["serial"], last["campaign"]))


def analyse(rows) -> dict:
    """Populations, verdicts and trends of the store's rows (pandas, the ``fleet`` view)."""
    out = {"populations": {}, "verdicts": {}, "trends": {}, "types": {}, "dates": {}}
    if rows is None or len(rows) == 0:
        return out
    latest = _latest_campaigns(rows)
    for serial, camp in latest.items():
        out["types"][serial] = str(rows.loc[rows["campaign"] == camp, "motor_type"].iloc[0])
    for serial, grp in rows.groupby("serial"):
        out["dates"][serial] = sorted({as_date(d).isoformat() for d in grp["test_date"]})
    ok = rows[rows["identifiable"] & rows["value"].notna() & rows["std"].notna()]
    at_latest = ok[ok["campaign"].isin(set(latest.values()))]
    for motor_type in sorted(set(out["types"].values())):
        sub = at_latest[at_latest["serial"].map(out["types"]) == motor_type]
        estimates = {}
        for parameter, g in sub.groupby("parameter", sort=True):
            g = g.sort_values("serial")
            estimates[parameter] = (g["serial"].tolist(), g["value"].to_numpy(float), g["std"].to_numpy(float))
        pops, verdicts = analyse_type(motor_type, estimates)
        out["populations"][motor_type] = pops
        for v in verdicts:
            out["verdicts"].setdefault(v.serial, []).append(v)
    for serial, grp in ok.groupby("serial"):
        series = defaultdict(list)
        for r in grp.itertuples():
            series[r.parameter].append((as_date(r.test_date), float(r.value), float(r.std)))
        out["trends"][serial] = motor_trends(serial, series)
    return out


def fleet_document(an: dict, failed: list) -> dict:
    """fleet.json, exactly as BENCH_LOG_FORMAT.md gives it."""
    population = {
        t: {p: {"mean": pop.mean, "sd": pop.sd, "mean_ci95": list(pop.mean_ci95), "sd_ci95": list(pop.sd_ci95)}
            for p, pop in pops.items()}
        for t, pops in an["populations"].items()}
    motors = []
    for serial in sorted(an["types"]):
        motors.append({
            "serial": serial, "motor_type": an["types"][serial], "dates": an["dates"][serial],
            "out_of_family": [{"parameter": v.parameter, "probability": v.probability}
                              for v in an["verdicts"].get(serial, []) if v.out_of_family],
            "trends": [{"parameter": tr.parameter, "per_year": tr.per_year, "ci95": list(tr.ci95),
                        "verdict": tr.verdict} for tr in an["trends"].get(serial, [])],
        })
    return {"population": population, "motors": motors,
            "failed": [{"campaign": f["campaign"], "error": f["error"]} for f in failed]}


def population_document(an: dict) -> dict:
    """population.json: the model's own numbers (see motorid.fleet.population)."""
    doc = {"model": "random-effects meta-analysis per parameter (docs/fleet.md, Eq. P1-P4)", "types": {}}
    for t, pops in an["populations"].items():
        entry = {}
        for p, pop in pops.items():
            entry[p] = {"scale": pop.scale, "n": pop.n, "mu": pop.mu, "tau": pop.tau, "se_mu": pop.se_mu,
                        "mu_ci95": list(pop.mu_ci95), "tau_ci95": list(pop.tau_ci95),
                        "mean": pop.mean, "sd": pop.sd, "band95": list(pop.band()),
                        "motors": pop.motors, "excluded": pop.excluded, "per_motor": []}
        doc["types"][t] = entry
    for serial, vs in an["verdicts"].items():
        t = an["types"][serial]
        for v in vs:
            if v.parameter in doc["types"].get(t, {}):
                doc["types"][t][v.parameter]["per_motor"].append({
                    "serial": serial, "value": v.value, "std": v.std, "shrunk": v.shrunk,
                    "shrunk_std": v.shrunk_std, "z": v.z, "probability": v.probability,
                    "p_value": v.p_value, "threshold": v.threshold, "out_of_family": v.out_of_family})
    return doc


def _clean(doc):
    from motorid.identify.results import json_safe as clean

    return clean(doc)


def write_summary(fleet_dir) -> dict:
    """Analyse the store and write fleet.json and population.json; returns fleet.json's document."""
    from motorid.identify.results import write_json_atomic

    d = Path(fleet_dir)
    failed = store.failures(d)
    rows = store.all_rows(d) if any((d / store.STORE).glob("*.parquet")) else None
    an = analyse(rows)
    doc = _clean(fleet_document(an, failed))
    write_json_atomic(_clean(population_document(an)), d / POPULATION_FILE)
    write_json_atomic(doc, d / FLEET_FILE)
    return doc


def latest_table(rows, an: dict):
    """Motors × parameters at their latest test date (value, std), for the report."""
    latest = _latest_campaigns(rows)
    sub = rows[rows["campaign"].isin(set(latest.values()))]
    return {s: {r.parameter: (r.value, r.std, bool(r.identifiable), r.unit)
                for r in g.itertuples()} for s, g in sub.groupby("serial")}

