"""What the report shows, computed once: the fit, the data, the model on plotting grids.

:func:`gather` collects the result (``result.json``), the extracted data and the
parameter draws, either from an in-memory :class:`~motorid.identify.pipeline.Identification`
or from a result folder (the campaign is re-read and the model re-evaluated at
the parameters of ``result.json``; nothing is refitted).  :class:`Ensemble`
evaluates :func:`motorid.model.predict` at the point estimate and over the
parameter draws (``jax.vmap`` inside ``lax.map``) for the bands of the plots.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from motorid import model
from motorid.errors import InputError
from motorid.io.results import read_diagnosis_beside, read_json
from motorid.robust import robust_std as _robust_std
from motorid.units import PA_PER_BAR, RUNNING_CHANNELS

RUNNING = RUNNING_CHANNELS
DRAWS = 200  # parameter draws for the bands
OUTLIER_SIGMA = 5.0  # beyond this many σ a residual is flagged (the fit's default)


@dataclass
class ReportData:
    """Everything the report needs, SI inside."""

    out_dir: Path
    doc: dict  # result.json
    spec: object
    dataset: object  # extracted data (None when the logs could not be read)
    params: dict  # every parameter, for predictions (held ones at the fit's start values)
    mechanisms: tuple
    draw_names: list
    draws: np.ndarray | None  # (k, len(draw_names)) parameter draws for the bands
    draw_source: str  # words: where the draws come from
    chain: np.ndarray | None = None  # (steps, walkers, ndim), natural units
    burn: int = 0
    thin: int = 1
    posterior: np.ndarray | None = None  # flat posterior draws after burn-in and thinning
    inliers: dict | None = None  # channel → mask of samples the fit used
    diagnosis: dict | None = None
    truth: dict | None = None
    notes: list = field(default_factory=list)
    # filled by :func:`evaluate_data`
    pred: dict = field(default_factory=dict)
    resid: dict = field(default_factory=dict)
    flagged: dict = field(default_factory=dict)
    sample_sigma: dict = field(default_factory=dict)  # channel → σ of each reading [SI]

    @property
    def has_running(self) -> bool:
        return self.dataset is not None and self.dataset.running is not None and \
            int(np.asarray(self.dataset.running.theta).size) > 0

    @property
    def has_events(self) -> bool:
        return self.dataset is not None and getattr(self.dataset, "events", None) is not None and \
            int(np.asarray(self.dataset.held_torque).size) > 0

    def sigma(self, channel: str) -> float | None:
        entry = self.doc.get("noise", {}).get(channel)
        return None if not entry or entry.get("sigma") is None else float(entry["sigma"])


# ----------------------------------------------------------------------------- gathering


def _same_fit(doc: dict, ls) -> bool:
    params = doc.get("parameters", {})
    if set(params) != set(ls.names):
        return False
    for k in ls.names:
        a, b = params[k].get("value"), ls.values[k]
        if (a is None) != (b is None) or (a is not None and not math.isclose(a, b, rel_tol=1e-9, abs_tol=0.0)):
            return False
    return True


def _mechanisms(ids, notes) -> tuple:
    if not ids:
        return ()
    from motorid.bench.truth import resolve_mechanism

    out = []
    for mech_id in ids:
        try:
            out.append(resolve_mechanism(mech_id, "result.json fit.mechanisms"))
        except InputError as exc:
            notes.append(f"{exc}; the model curves leave this mechanism out")
    return tuple(out)


def _start_value(name: str, mechanisms) -> float:
    """The value the fit holds a parameter at when the logs cannot identify it."""
    if name.startswith("KL_"):
        return 0.0
    for mech in mechanisms:
        if name in getattr(mech, "parameters", {}):
            return float(mech.initial()[name])
    try:
        return float(model.parameter_info(name, mechanisms).typical)
    except KeyError:
        return 0.0


def _truth_beside(logs) -> dict | None:
    """True parameters of a synthetic campaign (``truth.toml`` beside its first log)."""
    if not logs:
        return None
    path = Path(logs[0]).parent / "truth.toml"
    try:
        table = tomllib.loads(path.read_text()).get("parameters")
    except (OSError, tomllib.TOMLDecodeError):
        return None
    if not isinstance(table, dict):
        return None
    return {k: float(v) for k, v in table.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def _gaussian_draws(doc: dict, rng) -> tuple[list, np.ndarray | None]:
    """Draws from the least-squares estimate and covariance (Laplace approximation)."""
    corr = doc.get("correlation") or {}
    names = list(corr.get("names") or [])
    params = doc.get("parameters", {})
    if not names or any(params.get(k, {}).get("std") is None for k in names):
        return names, None
    mean = np.array([params[k]["value"] for k in names], dtype=float)
    std = np.array([params[k]["std"] for k in names], dtype=float)
    c = np.array(corr.get("matrix"), dtype=float) if corr.get("matrix") is not None else np.eye(len(names))
    c = np.nan_to_num(c, nan=0.0)
    np.fill_diagonal(c, 1.0)
    cov = c * np.outer(std, std)
    w, v = np.linalg.eigh(cov)
    root = v * np.sqrt(np.clip(w, 0.0, None))
    return names, mean + rng.standard_normal((DRAWS, len(names))) @ root.T


def _pick(flat: np.ndarray, rng) -> np.ndarray:
    if flat.shape[0] <= DRAWS:
        return flat
    return flat[np.sort(rng.choice(flat.shape[0], DRAWS, replace=False))]


def gather(out_dir, identification=None, spec=None, logs=None, motor=None) -> ReportData:
    """Collect what the report shows (see the module docstring).

    out_dir : result folder (``result.json``, optional ``chain.npz`` and ``diagnosis.json``)
    identification : the fit in memory (skips re-reading the logs); spec : its motor
    logs, motor : override the inputs named in ``result.json`` (when the files moved)
    """
    from motorid.identify.results import CHAIN_FILE, RESULT_FILE

    out = Path(out_dir)
    notes: list = []
    rng = np.random.default_rng(0)
    result_path = out / RESULT_FILE
    if identification is not None:
        from motorid.identify.results import result_document

        ls = identification.ls
        if spec is None:
            raise InputError("write_report: an identification needs its motor spec")
        doc = read_json(result_path, "result.json") if result_path.exists() else None
        if doc is None or not _same_fit(doc, ls):
            doc = json.loads(json.dumps(result_document(ls, spec, identification.dataset, identification.bayes,
                                                        {}, identification.seconds, identification.priors)))
        dataset = identification.dataset
        mechanisms = tuple(ls.mechanisms)
        params = {k: float(v) for k, v in ls.params_all.items()}
        inliers = {k: np.asarray(v, bool) for k, v in (ls.inliers or {}).items()}
        bayes = identification.bayes
        chain = burn = thin = posterior = None
        if bayes is not None:
            names, posterior = list(bayes.names), np.asarray(bayes.samples())
            chain, burn, thin = np.asarray(bayes.chain), int(bayes.burn), int(bayes.thin)
            draws, source = _pick(posterior, rng), "posterior (emcee)"
        else:
            names, draws = _gaussian_draws(doc, rng)
            source = "least-squares estimate and covariance (Gaussian approximation)"
    else:
        if not result_path.exists():
            raise InputError(f"{out}: no {RESULT_FILE} here; run `motorid fit LOG... --motor SPEC --out {out}` first")
        doc = read_json(result_path, "result.json")
        if "parameters" not in doc:
            raise InputError(f"{result_path}: not a motorid result (no 'parameters')")
        inputs = doc.get("inputs") or {}
        motor = motor or inputs.get("motor")
        logs = list(logs or inputs.get("logs") or [])
        if spec is None:
            if not motor:
                raise InputError(f"{result_path}: names no motor spec; pass --motor SPEC.toml")
            from motorid.io.spec import load_motor_spec

            spec = load_motor_spec(motor)
        mechanisms = _mechanisms(doc.get("fit", {}).get("mechanisms") or [], notes)
        params = {}
        for k, e in doc["parameters"].items():
            params[k] = float(e["value"]) if e.get("value") is not None else _start_value(k, mechanisms)
        dataset = None
        missing = [p for p in logs if not Path(p).exists()]
        if not logs or missing:
            notes.append("the bench logs " + (", ".join(missing) if missing else "(none named)")
                         + " could not be found, so the plots of data and model are left out; "
                         "pass them with `motorid report DIR --logs LOG...`")
        else:
            from motorid.identify.pipeline import load_campaign

            _, dataset = load_campaign(logs, spec)
        inliers = None
        chain = burn = thin = posterior = None
        chain_path = out / CHAIN_FILE
        names, draws, source = [], None, ""
        if "mcmc" in doc and chain_path.exists():
            with np.load(chain_path) as z:
                names = [str(n) for n in z["names"]]
                chain, burn, thin = np.asarray(z["chain"]), int(z["burn"]), int(z["thin"])
            if set(names) <= set(params):
                posterior = chain[burn::thin].reshape(-1, len(names))
                draws, source = _pick(posterior, rng), "posterior (emcee)"
            else:
                notes.append(f"{chain_path.name} does not match {RESULT_FILE}; posterior plots left out")
                chain = posterior = None
        if draws is None:
            names, draws = _gaussian_draws(doc, rng)
            source = "least-squares estimate and covariance (Gaussian approximation)"
    if draws is None:
        source = ""
    truth = _truth_beside((doc.get("inputs") or {}).get("logs"))
    diagnosis, unreadable = read_diagnosis_beside(out)
    if unreadable:
        notes.append(unreadable)
    rd = ReportData(out, doc, spec, dataset, params, mechanisms, list(names), draws, source, chain,
                    burn or 0, thin or 1, posterior, inliers, diagnosis, truth, notes)
    evaluate_data(rd, identification.ls if identification is not None else None)
    return rd


# ----------------------------------------------------------------------------- the model on grids


class Ensemble:
    """The model at the point estimate and over the parameter draws."""

    def __init__(self, rd: ReportData):
        self.spec, self.mechanisms = rd.spec, tuple(rd.mechanisms)
        self.names = [n for n in rd.draw_names if n in rd.params]
        cols = [rd.draw_names.index(n) for n in self.names]
        self.draws = None if rd.draws is None or not self.names else jnp.asarray(rd.draws[:, cols])
        self.base = {k: jnp.asarray(v, dtype=jnp.float64) for k, v in rd.params.items()}
        self.point = jnp.asarray([rd.params[n] for n in self.names], dtype=jnp.float64)

    def _params(self, vec):
        p = dict(self.base)
        p.update({n: vec[i] for i, n in enumerate(self.names)})
        return p

    def _evaluate(self, fn, samples, band: bool):
        f = jax.jit(fn)
        center = np.asarray(f(self.point, samples))
        if not band or self.draws is None:
            return center, center, center
        many = np.asarray(jax.jit(lambda d, s: jax.lax.map(lambda v: fn(v, s), d, batch_size=8))(self.draws, samples))
        lo, hi = np.percentile(many, [2.5, 97.5], axis=0)
        return center, lo, hi

    def running(self, samples: model.Samples, average: int = 1, band: bool = True):
        """Running channels → (center, lo, hi), each (4, N/average): torque, q_a, q_b, q_case.

        average : consecutive groups of this many samples are averaged (a θ grid
        over a revolution: the run-mean model)."""

        def fn(vec, s):
            ch = model.predict(self._params(vec), self.spec, s, self.mechanisms)
            out = jnp.stack([ch.torque, ch.q_a, ch.q_b, ch.q_case])
            return out.reshape(4, -1, average).mean(-1) if average > 1 else out

        return self._evaluate(fn, samples, band)

    def breakaway(self, events: model.Samples, band: bool = True):
        """Held torque at breakaway → (center, lo, hi)."""

        def fn(vec, s):
            return model.predict_breakaway(self._params(vec), self.spec, s, self.mechanisms)

        return self._evaluate(fn, events, band)


def grid_samples(spec, theta, speed, p_a, p_b, p_case, viscosity, direction, temperature=40.0):
    """:class:`motorid.model.Samples` on a plotting grid (arrays broadcast to one shape)."""
    arrs = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in
                                 (theta, speed, p_a, p_b, p_case, viscosity, direction, temperature)))
    flat = [a.ravel() for a in arrs]
    return model.make_samples(spec, flat[0], flat[1], flat[2], flat[3], flat[4], flat[5],
                              direction=flat[6], temperature=flat[7])


def concat_samples(pieces) -> model.Samples:
    """One :class:`motorid.model.Samples` of several, end to end (one model evaluation)."""
    return model.Samples(*[jnp.concatenate([jnp.asarray(getattr(p, f)) for p in pieces])
                           for f in model.Samples._fields])


def revolution(spec, per_pitch: int = 16) -> np.ndarray:
    """Shaft angles evenly over one revolution (for run-mean model values) [rad]."""
    k = per_pitch * spec.pistons
    return (np.arange(k) + 0.5) * 2.0 * np.pi / k


# ----------------------------------------------------------------------------- data, residuals, runs


def _run_sigma(resid: np.ndarray, run_of: np.ndarray, pooled: float | None) -> np.ndarray:
    """σ of each sample: the robust σ of its run's residuals, at least a tenth of the pooled σ
    (the fit's own estimator, for a report made without the fit in memory)."""
    runs = np.unique(run_of)
    sig = np.array([_robust_std(resid[run_of == r]) for r in runs])
    fill = pooled if pooled else (float(np.nanmedian(sig)) if np.isfinite(sig).any() else 1.0)
    sig = np.where(np.isfinite(sig) & (sig > 0), sig, fill)
    sig = np.maximum(sig, 0.1 * fill)
    return sig[np.searchsorted(runs, run_of)]


def evaluate_data(rd: ReportData, ls=None) -> None:
    """Point predictions, residuals and each reading's σ at every sample and event; flag the outliers.

    ls : the least-squares result when in memory (its σ and outlier masks are used as they are)."""
    if rd.dataset is None:
        return
    ens = Ensemble(rd)
    if rd.has_running:
        c, _, _ = ens.running(rd.dataset.running, band=False)
        for i, ch in enumerate(RUNNING):
            rd.pred[ch] = c[i]
            rd.resid[ch] = np.asarray(rd.dataset.measured[ch], dtype=float) - c[i]
    if rd.has_events:
        c, _, _ = ens.breakaway(rd.dataset.events, band=False)
        rd.pred["breakaway"] = c
        rd.resid["breakaway"] = np.asarray(rd.dataset.held_torque, dtype=float) - c
    run_of = np.asarray(rd.dataset.run_of_sample, dtype=int) if rd.has_running else None
    fit_sigma = getattr(ls, "sigma", None) or {}
    for ch, r in rd.resid.items():
        finite = np.isfinite(r)
        sig = fit_sigma.get(ch)
        if sig is not None and np.shape(sig) == r.shape:
            rd.sample_sigma[ch] = np.asarray(sig, dtype=float)
        elif ch == "breakaway":
            rd.sample_sigma[ch] = np.full(r.shape, rd.sigma(ch) or _robust_std(r) or 1.0)
        else:
            rd.sample_sigma[ch] = _run_sigma(r, run_of, rd.sigma(ch))
        if rd.inliers and ch in rd.inliers and rd.inliers[ch].shape == r.shape:
            rd.flagged[ch] = finite & ~rd.inliers[ch]
        else:
            with np.errstate(invalid="ignore"):
                rd.flagged[ch] = finite & (np.abs(r) > OUTLIER_SIGMA * rd.sample_sigma[ch])


@dataclass
class Run:
    """One running run, summarized."""

    index: int
    samples: np.ndarray  # indices into the running samples
    speed: float  # median [rad/s]
    direction: float
    dp: float  # |P_A − P_B| median [Pa]
    psum: float
    p_case: float
    viscosity: float
    temperature: float
    theta_span: float  # fraction of a piston pitch covered [-]
    mean_resid: dict  # channel → mean residual over the inliers


def running_runs(rd: ReportData) -> list[Run]:
    if not rd.has_running:
        return []
    s = rd.dataset.running
    run_of = np.asarray(rd.dataset.run_of_sample, dtype=int)
    cols = {k: np.asarray(getattr(s, k), dtype=float) for k in
            ("theta", "speed", "direction", "p_a", "p_b", "p_case", "viscosity", "temperature")}
    pitch = 2.0 * np.pi / rd.spec.pistons
    out = []
    for r in np.unique(run_of):
        idx = np.flatnonzero(run_of == r)
        med = {k: float(np.nanmedian(v[idx])) for k, v in cols.items()}
        phase = np.mod(cols["theta"][idx], pitch)
        bins = np.unique(np.floor(phase / pitch * 24).astype(int))
        mean_resid = {}
        for ch in RUNNING:
            res = rd.resid[ch][idx]
            ok = np.isfinite(res) & ~rd.flagged[ch][idx]
            mean_resid[ch] = float(res[ok].mean()) if ok.any() else math.nan
        direction = med["direction"] if med["direction"] != 0 else float(np.sign(med["speed"]) or 1.0)
        out.append(Run(int(r), idx, med["speed"], float(np.sign(direction)), abs(med["p_a"] - med["p_b"]),
                       med["p_a"] + med["p_b"], med["p_case"], med["viscosity"], med["temperature"],
                       bins.size / 24.0, mean_resid))
    return out


def cluster(values, gap) -> np.ndarray:
    """Labels of 1-D values chained while consecutive sorted values differ by ≤ gap(value)."""
    values = np.asarray(values, dtype=float)
    order = np.argsort(values)
    labels = np.zeros(values.size, int)
    label = 0
    for j in range(1, order.size):
        a, b = values[order[j - 1]], values[order[j]]
        if b - a > gap(a):
            label += 1
        labels[order[j]] = label
    return labels


@dataclass
class Level:
    """Running runs at one pressure difference and oil temperature."""

    runs: list
    dp: float
    psum: float
    p_case: float
    viscosity: float
    temperature: float

    @property
    def label(self) -> str:
        return f"ΔP {self.dp / PA_PER_BAR:.0f} bar, {self.temperature:.0f} °C"


def pressure_levels(runs: list[Run]) -> list[Level]:
    """Group running runs by |ΔP| (within 2 % or 2 bar) and temperature (within 3 °C)."""
    if not runs:
        return []
    dp_label = cluster([r.dp for r in runs], lambda v: max(0.02 * v, 2 * PA_PER_BAR))
    levels = []
    for lab in np.unique(dp_label):
        members = [r for r, l in zip(runs, dp_label) if l == lab]
        t_label = cluster([r.temperature for r in members], lambda v: 3.0)
        for tl in np.unique(t_label):
            rs = [r for r, l in zip(members, t_label) if l == tl]
            med = lambda a: float(np.median([getattr(r, a) for r in rs]))  # noqa: E731
            levels.append(Level(rs, med("dp"), med("psum"), med("p_case"), med("viscosity"), med("temperature")))
    levels.sort(key=lambda v: (v.dp, v.temperature))
    return levels


def noise_by_run(rd: ReportData) -> dict:
    """channel → (lowest, highest) σ of a run's readings [SI]."""
    out = {}
    if rd.has_running:
        run_of = np.asarray(rd.dataset.run_of_sample, dtype=int)
        for ch in RUNNING:
            sig = rd.sample_sigma.get(ch)
            has = np.isfinite(rd.resid.get(ch, np.zeros(0)))
            if sig is None or not has.any():
                continue
            per_run = [float(np.median(sig[(run_of == r) & has])) for r in np.unique(run_of[has])]
            out[ch] = (min(per_run), max(per_run))
    return out


def reference_conditions(rd: ReportData) -> dict:
    """Back pressure, case pressure, temperature and viscosity the derived figures use."""
    s = rd.dataset.running if rd.has_running else None
    ref = {"p_low": 7 * PA_PER_BAR, "p_case": 0.7 * PA_PER_BAR, "temperature": 40.0}
    if s is not None:
        p_low = np.minimum(np.asarray(s.p_a), np.asarray(s.p_b))
        ref.update(p_low=float(np.nanmedian(p_low)), p_case=float(np.nanmedian(np.asarray(s.p_case))),
                   temperature=float(np.nanmedian(np.asarray(s.temperature))))
    oil = getattr(rd.spec, "oil", None)
    if oil is not None:
        ref["viscosity"] = float(oil.viscosity(ref["temperature"]))
    elif s is not None:
        ref["viscosity"] = float(np.nanmedian(np.asarray(s.viscosity)))
    else:
        ref["viscosity"] = 0.04
    return ref
