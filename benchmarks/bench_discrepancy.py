"""Detection rate of the discrepancy search against effect size, and false alarms.

    python benchmarks/run.py --only bench_discrepancy

For each catalog mechanism the concealed campaign of synthetic_data/concealed/
is re-simulated at fractions of its size with new seeds (light ISO 4392-1/-2
protocols of synthetic_data/concealed/protocols), put through `diagnose`, and
counted: named right (exactly that mechanism), named wrong (another or an extra
one), or missed.  Clean campaigns (no extra physics, odd and even piston
counts, new seeds) give the false-alarm rate.  A last table checks shapes of
the same physics that the catalog does not write that way (a Gaussian Stribeck
curve, windage ∝ |ω|^1.7) and another bench's sampling and noise.
"""

from __future__ import annotations

import sys
import time
import tomllib
from pathlib import Path

import jax.numpy as jnp

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "synthetic_data" / "concealed"))

from generate import CASES, EVEN, MOTOR_8, ODD  # noqa: E402

from motorid.bench.protocols import load_protocol, parse_protocol, read_toml  # noqa: E402
from motorid.bench.simulate import simulate_campaign  # noqa: E402
from motorid.bench.truth import Truth  # noqa: E402
from motorid.physics import registry  # noqa: E402
from motorid.physics.friction import StribeckFriction  # noqa: E402
from motorid.physics.hydrodynamic import HydrodynamicTorque  # noqa: E402
from motorid.discrepancy.select import diagnose  # noqa: E402
from motorid.identify.extract import extract  # noqa: E402
from motorid.io.spec import load_motor_spec, parse_motor_spec  # noqa: E402

PROTOCOLS = sorted((ROOT / "synthetic_data" / "concealed" / "protocols").glob("*.toml"))
SPEC_9 = load_motor_spec(ROOT / "synthetic_data" / "demo" / "motor.toml")
SPEC_8 = parse_motor_spec(tomllib.loads(MOTOR_8), "concealed-8")
SINGLE = ["stribeck_friction", "hydrodynamic_torque", "turbulent_leakage", "compressibility_flow",
          "misalignment_ripple", "torque_offset"]


class GaussianStribeck(StribeckFriction):
    """Stribeck curve of another shape: exp(−(ω/ω_s)²), constant amplitude."""

    def running(self, params, spec, samples, ch):
        shape = jnp.exp(-(samples.speed / self.param(params, "w_s")) ** 2)
        return ch._replace(torque=ch.torque - samples.direction * self.param(params, "T_s") * shape)


class PowerWindage(HydrodynamicTorque):
    """Windage loss ∝ |ω|^1.7 instead of ω²."""

    def running(self, params, spec, samples, ch):
        w = samples.speed
        return ch._replace(torque=ch.torque - self.param(params, "C_h") * 13.0 * jnp.sign(w) * jnp.abs(w) ** 1.7)


def _campaign(pistons, mechanisms: dict, seed, objects=None, protocols=None):
    base = dict(ODD if pistons % 2 else EVEN)
    params = dict(base)
    mechs = []
    for mid, values in mechanisms.items():
        params.update({f"{mid}.{k}": v for k, v in values.items()})
        mechs.append((objects or {}).get(mid, registry.get(mid)))
    spec = SPEC_9 if pistons % 2 else SPEC_8
    protos = protocols or [load_protocol(p) for p in PROTOCOLS]
    frame = simulate_campaign(protos, spec, Truth(params, tuple(mechs), "bench"), seed=seed).frame
    return extract(frame, spec), spec


def _outcome(ds, spec, expected: set) -> str:
    dg = diagnose(ds, spec)
    found = {c.mechanism.id for c in dg.accepted}
    if found == expected and not (dg.unexplained and not expected):
        return "right"
    if not found and not dg.mismatch:
        return "missed"
    if not found:
        return "unexplained only"
    return "wrong: " + ",".join(sorted(found))


def _scaled(values: dict, factor: float) -> dict:
    keep = {"w_s"}  # a characteristic speed is not a size
    return {k: (v if k in keep else v * factor) for k, v in values.items()}


def _faster_noisier():
    """The light protocols with doubled sample rates and doubled sensor noise."""
    out = []
    for path in PROTOCOLS:
        data = read_toml(path, "protocol")
        rate = data["timing"]["sample_rate_Hz"]
        data["timing"]["sample_rate_Hz"] = [2 * r for r in rate] if isinstance(rate, list) else 2 * rate
        data.setdefault("sensors", {})
        for col, noise in (("torque_Nm", 0.1), ("q_a_lpm", 0.02), ("q_b_lpm", 0.02), ("q_case_lpm", 0.004)):
            data["sensors"].setdefault(col, {})["noise"] = noise
        out.append(parse_protocol(data, str(path), path.stem))
    return out


VARIANT_OBJECTS = {"gaussian_stribeck": ("stribeck_friction", GaussianStribeck),
                   "power_windage": ("hydrodynamic_torque", PowerWindage)}


def replicate(job: dict) -> dict:
    """One replication (a task for motorid.fleet.map_tasks): simulate, diagnose, judge."""
    objects = None
    if job.get("objects"):
        mid, cls = VARIANT_OBJECTS[job["objects"]]
        objects = {mid: cls()}
    ds, spec = _campaign(job["pistons"], job["mechanisms"], job["seed"], objects,
                         _faster_noisier() if job.get("faster") else None)
    if job["kind"] == "clean":
        dg = diagnose(ds, spec)
        names = (",".join(c.mechanism.id for c in dg.accepted) or dg.unexplained[0].where) if dg.mismatch else ""
        return {"mismatch": bool(dg.mismatch), "names": names}
    return {"outcome": _outcome(ds, spec, set(job["expected"]))}


def run(quick: bool = False, scheduler: str | None = None) -> str:
    """Every replication runs as a task on Dask (motorid.fleet.map_tasks: an embedded LocalCluster,
    or the cluster at ``scheduler``, default $MOTORID_BENCH_SCHEDULER); same seeds, same outcomes as the
    plain loop."""
    import os

    from motorid.fleet import map_tasks

    scheduler = scheduler or os.environ.get("MOTORID_BENCH_SCHEDULER") or None

    reps = 1 if quick else 3
    fractions = [0.1, 0.25, 0.5, 1.0] if not quick else [0.25, 1.0]
    t0 = time.time()
    lines = ["## Discrepancy search: detection rate against effect size, false alarms",
             "",
             "Command: `python benchmarks/run.py --only bench_discrepancy`"
             + (" (quick)" if quick else "") + ".  Each cell: campaigns named right / campaigns, "
             f"{reps} new seeds per cell; light ISO 4392-1/-2 protocols (about 25 k rows a campaign).  "
             "Size 1 is the concealed campaign's size in synthetic_data/concealed/truths/ "
             "(Stribeck 2 N·m + 0.002·D(P_A+P_B) below 0.5 rad/s; windage 2 N·m at 2500 rpm; turbulent "
             "leakage 0.12 L/min a port at 250 bar; compressibility 1.2 L/min at 250 bar and 2500 rpm; "
             "misalignment 0.7 N·m at 1× and 0.4 N·m at 2×; torque offset 0.8 N·m).  The replications "
             "run as tasks on Dask (motorid.fleet.map_tasks).",
             "",
             "| mechanism | " + " | ".join(f"size × {f:g}" for f in fractions) + " | wrong names |",
             "|---|" + "---|" * (len(fractions) + 1)]
    seed = 1000
    jobs = []
    for mid in SINGLE:
        pistons, _, mechs = CASES[mid]
        for f in fractions:
            for _ in range(reps):
                seed += 1
                jobs.append({"kind": "single", "mid": mid, "fraction": f, "pistons": pistons,
                             "mechanisms": {mid: _scaled(mechs[mid], f)}, "seed": seed, "expected": [mid]})
    n_clean = 4 if quick else 16
    for i in range(n_clean):
        seed += 1
        jobs.append({"kind": "clean", "pistons": 9 if i % 2 == 0 else 8, "mechanisms": {}, "seed": seed})
    variants = [
        ("Gaussian Stribeck curve, constant 3 N·m amplitude, ω_s 0.6 rad/s", "stribeck_friction",
         {"stribeck_friction": {"T_s": 3.0, "K_p": 0.0, "w_s": 0.6}}, "gaussian_stribeck", False),
        ("windage ∝ ω^1.7 (2 N·m at 2500 rpm)", "hydrodynamic_torque",
         {"hydrodynamic_torque": {"C_h": 1.2e-5}}, "power_windage", False),
        ("torque offset 0.8 N·m, sample rates ×2 and sensor noise ×2", "torque_offset",
         {"torque_offset": {"T0": 0.8}}, None, True),
        ("clean motor, sample rates ×2 and sensor noise ×2", None, {}, None, True),
    ]
    n_var = 1 if quick else 2
    for k, (words, expect, mechs, objects, faster) in enumerate(variants):
        for _ in range(n_var):
            seed += 1
            jobs.append({"kind": "variant", "variant": k, "pistons": 9, "mechanisms": mechs, "seed": seed,
                         "objects": objects, "faster": faster, "expected": [expect] if expect else []})
    results = map_tasks(replicate, jobs, scheduler=scheduler, desc="replications")
    for job, res in zip(jobs, results):
        if not isinstance(res, dict):
            raise RuntimeError(f"replication seed {job['seed']}: {res.error}")
    done = list(zip(jobs, results))
    for mid in SINGLE:
        cells, wrong = [], []
        for f in fractions:
            outs = [r["outcome"] for j, r in done if j["kind"] == "single" and j["mid"] == mid and j["fraction"] == f]
            cells.append(f"{sum(o == 'right' for o in outs)}/{reps}")
            wrong += [f"×{f:g}: {o[7:]}" for o in outs if o.startswith("wrong")]
        lines.append(f"| `{mid}` | " + " | ".join(cells) + f" | {'; '.join(wrong) or '—'} |")
    clean = [r for j, r in done if j["kind"] == "clean"]
    alarms = sum(r["mismatch"] for r in clean)
    names = [r["names"] for r in clean if r["mismatch"]]
    lines += ["", f"False alarms on clean campaigns (odd and even piston counts, new seeds): "
                  f"**{alarms}/{n_clean}**" + (f" ({'; '.join(names)})" if names else "") + "."]
    lines += ["", "Other shapes of the same physics and another bench (named right / campaigns):", "",
              "| case | result |", "|---|---|"]
    for k, (words, *_rest) in enumerate(variants):
        right = sum(r["outcome"] == "right" for j, r in done if j["kind"] == "variant" and j["variant"] == k)
        lines.append(f"| {words} | {right}/{n_var} |")
    lines += ["", f"Study time {time.time() - t0:.0f} s."]
    return "\n".join(lines)


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
