"""Speed of the identification, side by side with the peer baseline (benchmarks/baseline.py).

    python benchmarks/run.py --only bench_speed [--quick]

A ~300 k-row campaign (quick: the 70 k-row demo campaign) is simulated from the
repository's protocols with every sample rate scaled up, on the demo motor and
truth.  Then, in one session on one machine:

1. the fit step alone: ``fit_least_squares`` on the extracted dataset (after a
   warm-up call, so that compile is excluded; the first call is reported too)
   against the baseline's ``fit()`` (pandas + numpy model + scipy
   least_squares with finite differences; its seconds exclude reading);
2. end to end, process start to result.json: ``motorid fit`` three times (a
   fresh compile cache for the first run, so the later runs read it) against the
   baseline CLI three times; a later run is the better of runs 2 and 3;
3. ``motorid fit --bayes`` end to end, with the sampler's own figures;
4. the parameters of both fits against the truth.

Timed steps are run two or three times and the best time is kept (the machine is shared);
the fit step three times for motorid and for the baseline alike.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEMO = ROOT / "synthetic_data" / "demo"
MOTOR = DEMO / "motor.toml"
TRUTH = DEMO / "truth.toml"
RATE_FACTOR = 4.3  # 70 k rows of the demo protocols -> about 300 k
SEED = 1
#: the modules `motorid fit` imports before it reads the log (jax, pandas, pyarrow with them)
STARTUP_IMPORTS = ("import motorid.cli.fit, motorid.api, motorid.identify.pipeline, motorid.identify.least_squares, "
                   "motorid.io.logs, motorid.identify.extract, motorid.identify.results")


def _scaled_protocols(dest: Path, factor: float) -> Path:
    """Copies of protocols/*.toml with every sample_rate_Hz multiplied by ``factor``."""
    dest.mkdir(parents=True, exist_ok=True)

    def scale(m):
        v = m.group(2).strip()
        if v.startswith("["):
            nums = [float(x) * factor for x in v.strip("[]").split(",") if x.strip()]
            return m.group(1) + "[" + ", ".join(f"{x:.1f}" for x in nums) + "]"
        return m.group(1) + f"{float(v) * factor:.1f}"

    for p in sorted((ROOT / "protocols").glob("*.toml")):
        text = re.sub(r"^(sample_rate_Hz\s*=\s*)([^#\n]*)", scale, p.read_text(), flags=re.M)
        (dest / p.name).write_text(text)
    return dest


def _wall(cmd, env=None) -> tuple[float, subprocess.CompletedProcess]:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} failed ({proc.returncode}):\n{proc.stderr[-2000:]}")
    return dt, proc


def _best(f, n=2):
    out, best = None, float("inf")
    for _ in range(n):
        t0 = time.perf_counter()
        r = f()
        dt = time.perf_counter() - t0
        if dt < best:
            out, best = r, dt
    return out, best


def _fmt(x: float) -> str:
    return f"{x:.4g}"


#: the fit's compiled programs, by module: (module, attribute, what it does)
_PROGRAMS = (
    ("motorid.identify.compress", "_channel_terms", "expansion: f0, J, H per channel (once a fit)"),
    ("motorid.identify.compress", "_jacobian", "which parameters each channel depends on (256 cells)"),
    ("motorid.identify.compress", "_value", "exactness check of the expansion (256 cells, 2 points)"),
    ("motorid.identify.solver", "_levenberg_marquardt_compressed", "optimistix LM on the compressed residual"),
    ("motorid.identify.problem", "predictions_jit", "per-sample predictions (noise, outliers, residuals)"),
)


def _fit_breakdown(data, spec):
    """Where a warm ``fit_least_squares`` spends its time: its compiled programs, timed
    (synchronized) by wrapping them for one extra fit; the rest is numpy."""
    import importlib

    import jax

    acc = {name: [0, 0.0, what] for _, name, what in _PROGRAMS}
    saved = [(importlib.import_module(m), name) for m, name, _ in _PROGRAMS]
    originals = [getattr(mod, name) for mod, name in saved]

    def wrap(name, f):
        def g(*a, **k):
            t0 = time.perf_counter()
            r = jax.block_until_ready(f(*a, **k))
            acc[name][0] += 1
            acc[name][1] += time.perf_counter() - t0
            return r
        return g

    try:
        for (mod, name), f in zip(saved, originals):
            setattr(mod, name, wrap(name, f))
        from motorid.identify import least_squares as L

        t0 = time.perf_counter()
        L.fit_least_squares(data, spec)
        total = time.perf_counter() - t0
    finally:
        for (mod, name), f in zip(saved, originals):
            setattr(mod, name, f)
    return acc, total


def run(quick: bool = False) -> str:
    py = sys.executable
    tmp = Path(tempfile.mkdtemp(prefix="motorid-bench-speed-"))
    try:
        return _run(quick, py, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _run(quick: bool, py: str, tmp: Path) -> str:
    # ------------------------------------------------------------------ campaign
    if quick:
        log = DEMO / "campaign.csv.gz"
        rows = json.loads((DEMO / "manifest.json").read_text())["rows"]
        campaign_cmd = "synthetic_data/demo/campaign.csv.gz (the shipped demo campaign)"
    else:
        proto = _scaled_protocols(tmp / "protocols", RATE_FACTOR)
        camp = tmp / "campaign"
        sim_s, _ = _wall([py, "-m", "motorid", "simulate", "--protocol", str(proto), "--motor", str(MOTOR),
                          "--truth", str(TRUTH), "--out", str(camp), "--seed", str(SEED)])
        log = camp / "campaign.csv.gz"
        rows = json.loads((camp / "manifest.json").read_text())["rows"]
        campaign_cmd = (f"`motorid simulate --protocol P --motor synthetic_data/demo/motor.toml --truth "
                        f"synthetic_data/demo/truth.toml --seed {SEED}`, P = protocols/*.toml with every "
                        f"sample_rate_Hz × {RATE_FACTOR} ({sim_s:.0f} s)")
    size_mb = log.stat().st_size / 1e6
    truth = tomllib.load(open(TRUTH, "rb"))["parameters"]
    print(f"   campaign: {rows} rows, {size_mb:.1f} MB", flush=True)

    # ------------------------------------------------------------ fit step, in process
    from motorid.identify.extract import extract
    from motorid.identify.least_squares import fit_least_squares
    from motorid.io.logs import read_logs
    from motorid.io.spec import load_motor_spec

    import baseline  # benchmarks/ is on sys.path (run.py)

    spec = load_motor_spec(MOTOR)
    frame, read_s = _best(lambda: read_logs([str(log)], spec))
    data, extract_s = _best(lambda: extract(frame, spec))

    t0 = time.perf_counter()
    ls = fit_least_squares(data, spec)
    first_s = time.perf_counter() - t0
    ls, fit_s = _best(lambda: fit_least_squares(data, spec), 3)
    print(f"   motorid fit step: first {first_s:.2f} s, warm {fit_s:.2f} s", flush=True)
    parts, parts_total = _fit_breakdown(data, spec)

    base_runs = [baseline.fit([str(log)], str(MOTOR)) for _ in range(3)]
    base_params = base_runs[0][0]
    base_fit_s = min(s for _, s in base_runs)
    print(f"   baseline fit step: {base_fit_s:.2f} s", flush=True)

    # ------------------------------------------------------------ end to end
    cache = tmp / "jax-cache"  # a fresh compile cache: run 1 compiles, run 2 reads the cache
    env = {**os.environ, "MOTORID_CACHE_DIR": str(cache)}
    fit_cmd = [py, "-m", "motorid", "fit", str(log), "--motor", str(MOTOR), "--out", str(tmp / "fit"), "--force"]
    e2e = [_wall(fit_cmd, env)[0] for _ in range(3)]
    doc = json.loads((tmp / "fit" / "result.json").read_text())
    base_cmd = [py, str(ROOT / "benchmarks" / "baseline.py"), str(log), "--motor", str(MOTOR),
                "--out", str(tmp / "baseline.json")]
    base_e2e = [_wall(base_cmd)[0] for _ in range(3)]
    # a later run: the better of runs 2 and 3, for both (the machine is shared)
    e2e = [e2e[0], min(e2e[1:])]
    base_e2e = [base_e2e[0], min(base_e2e[1:])]
    # what `motorid fit` imports before it reads a byte (`motorid --help` imports nothing of it since
    # the commands load lazily)
    startup_s = min(_wall([py, "-c", STARTUP_IMPORTS])[0] for _ in range(2))
    print(f"   end to end: motorid {e2e[0]:.1f} / {e2e[1]:.1f} s, baseline {base_e2e[0]:.1f} / {base_e2e[1]:.1f} s",
          flush=True)

    # ------------------------------------------------------------ Bayes
    bayes_cmd = fit_cmd[:-1] + ["--bayes", "--force"]
    bayes_cmd[bayes_cmd.index("--out") + 1] = str(tmp / "fit_bayes")
    bayes_s, _ = _wall(bayes_cmd, env)
    mcmc = json.loads((tmp / "fit_bayes" / "result.json").read_text())["mcmc"]
    print(f"   bayes: {bayes_s:.1f} s end to end, sampler {mcmc['seconds']:.1f} s", flush=True)

    # ------------------------------------------------------------ the section
    fit_ratio = base_fit_s / fit_s
    first_ratio = base_fit_s / first_s
    e2e_ratio = e2e[1] / base_e2e[1]
    tau_max = max(mcmc["tau"].values())
    ok = lambda b: "**met**" if b else "**not met**"  # noqa: E731
    n = ls.problem.n_cells if ls.problem is not None else 0

    L = [
        "## Speed: motorid against the hand-written baseline",
        "",
        f"`python benchmarks/run.py --only bench_speed{' --quick' if quick else ''}`"
        " (study: benchmarks/bench_speed.py; baseline: benchmarks/baseline.py, pandas + numpy model + "
        "scipy.optimize.least_squares with finite-difference Jacobians).",
        "",
        f"Campaign: {rows:,} rows ({size_mb:.1f} MB gzip), demo motor and truth, {campaign_cmd}. "
        f"motorid's extract keeps {data.n_running:,} steady running samples and {data.n_events} breakaway "
        f"events; its optimizer sees {n:,} shaft-angle cell means. Timed steps were run two or three "
        "times (the fit step three, for both) and the best time is kept; the 2-core machine was shared with other jobs, so absolute seconds are noisy, "
        "the side-by-side ratios less so.",
        "",
        "### Goals",
        "",
        "| goal | motorid | baseline | ratio | |",
        "|---|---:|---:|---:|---|",
        f"| fit step ≥ 10× faster (warm, compile excluded) | {fit_s:.2f} s | {base_fit_s:.2f} s | "
        f"{fit_ratio:.2f}× faster | {ok(fit_ratio >= 10)} |",
        f"| `motorid fit` end to end ≤ ½ baseline wall time (a later run) | {e2e[1]:.1f} s | {base_e2e[1]:.1f} s | "
        f"{e2e_ratio:.2f} of the baseline | {ok(e2e_ratio <= 0.5)} |",
        f"| Bayesian fit converged within 60 s (end to end) | {bayes_s:.1f} s, converged: {mcmc['converged']} | — | — "
        f"| {ok(bayes_s <= 60 and mcmc['converged'])} |",
        "",
        f"The end-to-end goal needs ≤ {base_e2e[1] / 2:.2f} s. A later run neither traces nor compiles: "
        "the fit's compiled programs are kept on disk (`motorid._aot`, serialized XLA executables keyed by "
        "the motorid sources, the JAX version, the machine and the argument shapes), so it pays start-up "
        "and imports, reading, extraction and the fit itself.  `make bench` byte-compiles motorid first "
        "(`compileall`, as pip does for a regular install; this machine sets PYTHONDONTWRITEBYTECODE, "
        "under which an editable install would recompile its 0.1 s of sources on every run).",
        "",
        "### Seconds",
        "",
        "| step | motorid | baseline |",
        "|---|---:|---:|",
        f"| read the log | {read_s:.2f} s (`read_logs`, validating) | inside `fit()`, not timed |",
        f"| extract steady samples and breakaways | {extract_s:.2f} s (`extract`) | inside `fit()`, not timed |",
        f"| fit step, first call in the process (trace + compile or cache load) | {first_s:.2f} s | — |",
        f"| fit step, warm | {fit_s:.2f} s ({ls.steps} LM steps, converged: {ls.converged}) | "
        f"{base_fit_s:.2f} s |",
        f"| end to end, first run (empty compile cache) | {e2e[0]:.1f} s | {base_e2e[0]:.1f} s |",
        f"| end to end, a later run (better of runs 2 and 3) | {e2e[1]:.1f} s | {base_e2e[1]:.1f} s |",
        f"| of which process start + imports (`python -c \"{STARTUP_IMPORTS}\"`) | {startup_s:.1f} s | — |",
        f"| of which the rest (loading the compiled programs, writing) | "
        f"{max(e2e[1] - startup_s - read_s - extract_s - fit_s, 0):.1f} s | — |",
        f"| `motorid fit --bayes` end to end | {bayes_s:.1f} s | — |",
        f"| of which emcee | {mcmc['seconds']:.1f} s: {mcmc['steps']} steps × {mcmc['walkers']} walkers, "
        f"τ_max {tau_max:.0f} ({mcmc['steps'] / tau_max:.0f} τ), acceptance {mcmc['acceptance']:.2f}, "
        f"converged: {mcmc['converged']} | — |",
        "",
        f"Likelihood of the sampler: {mcmc['likelihood']}.",
        "",
        "### Where the fit step's time goes",
        "",
        f"One more warm `fit_least_squares` ({parts_total:.2f} s) with its compiled programs timed "
        "(`jax.block_until_ready`):",
        "",
        "| part | calls | seconds | share |",
        "|---|---:|---:|---:|",
        *[f"| `{k}`: {what} | {c} | {t:.3f} | {100 * t / parts_total:.0f} % |"
          for k, (c, t, what) in parts.items()],
        f"| the rest (numpy): cells, noise per run, Hampel test, Gram matrices, covariance, the runs' check | — | "
        f"{parts_total - sum(t for _, t, _ in parts.values()):.3f} | "
        f"{100 * (1 - sum(t for _, t, _ in parts.values()) / parts_total):.0f} % |",
        "",
        f"How: the samples are reduced once to {n:,} shaft-angle cell means; the 1992 model is exactly "
        "quadratic in its parameters, so one pass of forward-mode JAX over the cells (each channel along "
        "only the parameters it depends on) gives an exact expansion, and each noise/outlier round "
        "compresses the weighted problem to a residual of "
        f"{1 + len(ls.free) + len(ls.problem.expansion.pairs) if ls.problem.expansion else '—'} rows "
        "(a Gram matrix, per channel over its few columns) on which optimistix Levenberg-Marquardt takes "
        f"{ls.steps} steps in about a millisecond. What is left grows with the samples: per-sample "
        "predictions for the residuals, per-run noise and the Hampel outlier test, two rounds and the final "
        "one. The baseline evaluates its model at every sample for every finite-difference column of every "
        "step.",
        "",
        "### Same answers?",
        "",
        "Both fits against the truth (error in units of each fit's own standard error).",
        "",
        "| parameter | truth | motorid | ± std | error | baseline | ± std | error |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    worst_m, worst_b, worst_b_name = 0.0, 0.0, ""
    for k, t in truth.items():
        e = doc["parameters"].get(k, {})
        v, s = e.get("value"), e.get("std")
        b = base_params.get(k, {})
        bv, bs = b.get("value"), b.get("std")
        zm = (v - t) / s if v is not None and s else float("nan")
        zb = (bv - t) / bs if bv is not None and bs else float("nan")
        worst_m = max(worst_m, abs(zm))
        if abs(zb) > worst_b:
            worst_b, worst_b_name = abs(zb), k
        L.append(f"| {k} | {_fmt(t)} | {_fmt(v) if v is not None else '—'} | {_fmt(s) if s else '—'} | {zm:+.1f}σ "
                 f"| {_fmt(bv) if bv is not None else '—'} | {_fmt(bs) if bs else '—'} | {zb:+.1f}σ |")
    L += [
        "",
        f"Largest error: motorid {worst_m:.1f}σ, baseline {worst_b:.1f}σ "
        f"(χ²/dof of motorid {doc['fit']['reduced_chi2']:.3f}). "
        + ("Both recover the truth within 3σ on this clean synthetic campaign; the baseline's naive "
           "breakaway detection (first sample above 0.01 rad/s) does not bias it at this sample rate."
           if worst_b < 3 else
           f"motorid is within {worst_m:.1f}σ; the baseline is close but less clean (worst: {worst_b_name}, "
           f"{worst_b:.1f}σ), as expected of its plain 20 % steady-state cut and first-sample-above-0.01 rad/s "
           "breakaway detection; neither is wrong enough to explain the timings."
           if worst_b < 6 else
           f"The baseline is biased (worst: {worst_b_name}, {worst_b:.1f}σ): its plain steady-state cut and "
           "breakaway detection (first sample above 0.01 rad/s) do not hold on this campaign."),
        "",
    ]
    return "\n".join(L)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    print(run(quick="--quick" in sys.argv))
