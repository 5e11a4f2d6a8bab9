"""What the fit takes from a campaign: steady-state running samples and breakaway events.

Running runs (ISO 4392-1 and -3: constant speed, pressure, flow or torque) give
steady-state samples, with the start-up transient dropped.  Startability runs
(ISO 4392-2) give one breakaway event each: the shaft angle and the port
pressures at the instant the speed leaves rest, and the load torque held while
the shaft was stuck (MODEL.md, "Static and kinetic friction").  The log does not
mark the breakaway; it is found here from the speed alone, with the rest noise
estimated from the log itself, so that logs of any sample rate, noise level,
ramp rate or quantization serve.

Every estimate here is robust (medians, MADs, sustained departures): an isolated
sensor spike neither moves a breakaway nor ends a steady state.  Missing sensor
cells stay NaN in the measured channels; the fit skips them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from motorid.errors import InputError
from motorid.identify.acceleration import aliased_cycles, running_acceleration
from motorid.identify.events import place_limited_onsets, startability_event
from motorid.identify.steady import steady_run
from motorid.identify.types import (MEASURED_CHANNELS, RUNNING_PROTOCOLS, STARTABILITY, VISCOSITY_MODES, Dataset,
                                    ExtractSettings, ViscositySmoothing)
from motorid.identify.viscosity import smooth_viscosity
from motorid.model import MotorSpec, make_samples
from motorid.robust import nanmedian
from motorid.units import SI_COLUMNS

FRAME_NUMERIC = [c for c in SI_COLUMNS if c not in ("run_id", "protocol")]


def _check_frame(frame: pd.DataFrame) -> None:
    missing = [c for c in SI_COLUMNS if c not in frame.columns]
    if missing:
        raise InputError(f"log frame: missing column(s) {', '.join(missing)} (read logs with motorid.io.logs.read_logs)")


def _check_spec(spec) -> None:
    if not isinstance(spec, MotorSpec):
        raise InputError(f"motor spec: expected a MotorSpec, got {type(spec).__name__}")
    if not (isinstance(spec.pistons, (int, np.integer)) and spec.pistons >= 2):
        raise InputError(f"motor spec '{spec.name}': pistons must be an integer >= 2, got {spec.pistons!r}")
    try:
        displacement = float(spec.displacement)
    except (TypeError, ValueError):
        displacement = math.nan
    if not (math.isfinite(displacement) and displacement > 0):
        raise InputError(f"motor spec '{spec.name}': displacement must be > 0, got {spec.displacement!r}")


RUN_COLUMNS = ["run", "protocol", "file", "n_samples", "n_steady", "speed_median_rad_s", "dp_median_Pa",
               "psum_median_Pa", "temp_median_C", "direction", "onset_time_s", "excluded",
               "viscosity_degree", "viscosity_noise_Pa_s"]  # columns of Dataset.runs


class _Runs:
    """The frame's runs by their codes (categoricals from read_logs, or plain text): no string per row."""

    def __init__(self, frame: pd.DataFrame):
        codes, uniques = pd.factorize(frame["run"] if "run" in frame.columns else frame["run_id"])
        self.keys = [str(u) for u in uniques]
        self.order = np.lexsort((frame["time_s"].to_numpy(dtype=float), codes))
        self.bounds = np.searchsorted(codes[self.order], np.arange(len(self.keys) + 1))
        self.numeric = {c: frame[c].to_numpy(dtype=float) for c in FRAME_NUMERIC}
        self.protocol_codes, self.protocol_names = pd.factorize(frame["protocol"])
        self.file_codes, self.file_names = (pd.factorize(frame["file"]) if "file" in frame.columns
                                            else (np.zeros(len(frame), int), [""]))

    def run(self, r: int):
        """(rows of run r in the frame, in time order; its columns; protocol; file)."""
        pos = self.order[self.bounds[r]:self.bounds[r + 1]]
        cols = {c: v[pos] for c, v in self.numeric.items()}
        return (pos, cols, str(self.protocol_names[self.protocol_codes[pos[0]]]),
                str(self.file_names[self.file_codes[pos[0]]]))


@dataclass
class _Gathered:
    """What the runs give, run by run, before it is joined into a :class:`Dataset`."""

    n_runs: int
    accel_orders: tuple = (1, 2)  # shaft orders of the speed ripple resolved in the acceleration
    excluded: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    rows: list = field(default_factory=list)
    picks: list = field(default_factory=list)  # frame rows of the steady samples, per run
    accel: list = field(default_factory=list)
    run_of_sample: list = field(default_factory=list)
    directions: list = field(default_factory=list)
    visc: list = field(default_factory=list)
    events: list = field(default_factory=list)
    pending: list = field(default_factory=list)  # (event, columns) of onsets on a speed limit
    angle_ratios: list = field(default_factory=list)  # (run, shaft-angle rate / logged speed)
    theta_mean_torque: float = math.nan  # an angle where the pressure torque equals its mean over θ
    theta_assumed: list = field(default_factory=list)  # startability runs with no shaft angle

    def __post_init__(self):
        self.visc_center, self.visc_half = np.zeros(self.n_runs), np.ones(self.n_runs)
        self.visc_factor = np.zeros((self.n_runs, VISCOSITY_MODES, VISCOSITY_MODES))

    def grow(self, r: int) -> None:
        """Room for run ``r`` (runs that arrive one by one: their number is not known beforehand)."""
        if r >= self.n_runs:
            more = max(r + 1 - self.n_runs, self.n_runs, 16)
            self.visc_center = np.r_[self.visc_center, np.zeros(more)]
            self.visc_half = np.r_[self.visc_half, np.ones(more)]
            self.visc_factor = np.concatenate([self.visc_factor,
                                               np.zeros((more, VISCOSITY_MODES, VISCOSITY_MODES))])
            self.n_runs += more


def _add_startability(g: _Gathered, r: int, key, cols, row: dict, settings) -> None:
    theta = None
    if not np.isfinite(cols["theta_rad"]).any() and np.isfinite(g.theta_mean_torque):
        g.theta_assumed.append(key)  # no shaft angle: the pressure torque's mean over θ (mean_torque_angle)
        theta = g.theta_mean_torque
    event, why = startability_event(key, cols, settings, g.excluded, g.notes, theta=theta)
    row["excluded"] = why
    if event is not None:
        event["run"], event["run_index"] = key, r
        g.events.append(event)
        row.update(direction=event["direction"])
        if event["breakaway"].limited is not None:
            g.pending.append((event, cols))


def _accel_orders(settings, spec) -> tuple:
    """The shaft orders of the speed ripple resolved in the acceleration: the settings' orders, and
    the piston order n where ``settings.piston_order_ripple`` (the motor's own torque ripple)."""
    orders = tuple(int(k) for k in settings.shaft_orders)
    if settings.piston_order_ripple and int(spec.pistons) not in orders:
        orders += (int(spec.pistons),)
    return orders


def _add_running(g: _Gathered, r: int, key, pos, cols, row: dict, settings, cells=None):
    """The steady samples of a running run, their acceleration and smoothed viscosity → the
    positions used for the run's medians (every sample where none is steady).  With
    ``cells`` (:class:`motorid.identify.cells.CellReducer`) the run's steady samples are
    reduced to its shaft-angle cells at once instead of kept."""
    chosen, direction, why = steady_run(key, cols, settings, g.excluded, g.notes)
    row.update(direction=direction, excluded=why)
    if chosen is None:
        return np.arange(pos.size)
    _angle_against_speed(g, key, cols, chosen)
    steady = np.zeros(pos.size, bool)
    steady[chosen] = True
    acc = running_acceleration(cols["time_s"], cols["speed_rad_s"], cols["theta_rad"], steady,
                               settings.accel_window, g.accel_orders)
    _note_in_step(g.notes, key, cols["time_s"][chosen], cols["speed_rad_s"][chosen], settings.shaft_orders)
    mu = cols["viscosity_Pa_s"][chosen]
    if settings.smooth_viscosity:
        mu, degree, noise, factor, g.visc_center[r], g.visc_half[r] = smooth_viscosity(
            cols["time_s"][chosen], mu, settings.viscosity_max_degree)
        g.visc_factor[r] = factor
        row.update(viscosity_degree=degree, viscosity_noise_Pa_s=noise)
    row["n_steady"] = int(chosen.size)
    if cells is not None:
        cells.add_run(r, cols, chosen, acc[chosen], mu, direction, g.visc_center[r], g.visc_half[r])
        return chosen
    g.picks.append(pos[chosen])
    g.accel.append(acc[chosen])
    g.visc.append(mu)
    g.run_of_sample.append(np.full(chosen.size, r))
    g.directions.append(np.full(chosen.size, direction))
    return chosen


def _angle_against_speed(g: _Gathered, key, cols, chosen) -> None:
    """The rate at which the logged shaft angle advances over the logged speed, in a run where the
    angle is sampled finely enough to follow (median step < π/2) over half a revolution or more:
    1 where the speed's and the time's units are what the map or the header says (rpm logged as
    rad/s gives 1/9.55, seconds logged as ms 1000) → ``g.angle_ratios``."""
    idx = np.asarray(chosen)
    if idx.size < 20:
        return
    t, th, w = cols["time_s"], cols["theta_rad"], cols["speed_rad_s"]
    # consecutive samples only (a gap where unsteady samples were left out may hide whole turns)
    a, b = idx[:-1], idx[1:]
    dt = t[b] - t[a]
    pair = (b - a == 1) & np.isfinite(dt) & (dt > 0) & np.isfinite(th[a]) & np.isfinite(th[b])
    if pair.sum() < 20:
        return
    a, b, dt = a[pair], b[pair], dt[pair]
    pair = dt <= 1.5 * np.median(dt)
    a, b, dt = a[pair], b[pair], dt[pair]
    step = np.angle(np.exp(1j * (th[b] - th[a])))
    moving = np.abs(step) > 0
    speed = float(np.nanmedian(w[idx]))
    # a speed that turns the shaft more than π/2 between samples aliases the angle: where the wrapped
    # steps are the speed's own steps wrapped, the units agree (20 Hz at 1330 rpm steps 7.0 rad, read
    # as 0.72: a ratio of 0.10 that looked like a speed in rad/s read as rpm)
    wrapped = np.angle(np.exp(1j * (step - w[a] * dt)))
    if (np.nanmedian(np.abs(w[a] * dt)) > np.pi / 2 and np.isfinite(wrapped).all()
            and np.median(np.abs(wrapped)) < 0.1):
        g.angle_ratios.append((key, 1.0))
        return
    # an angle that follows: the steps it does take well below π/2 (an aliased step would wrap), and
    # half a revolution turned in all
    if (abs(speed) < 0.05 or moving.sum() < 10 or np.quantile(np.abs(step[moving]), 0.9) > np.pi / 2
            or abs(step.sum()) < np.pi):
        return
    g.angle_ratios.append((key, float(step.sum() / dt.sum() / speed)))


#: |median rate ratio| outside this band: the speed's or the time's unit is not what the log says
ANGLE_RATIO_BAND = (0.8, 1.25)


def _check_angle_rate(g: _Gathered) -> None:
    """Refuse a campaign whose shaft angle advances at another rate than its speed says, in the median
    over its runs, by the factor of a unit mistake in a channel map or a header (the fit would be
    meaningless); note another factor (an encoder on another shaft), and an angle that runs against
    the speed (the ripple's phase then comes out mirrored)."""
    if len(g.angle_ratios) < 2:
        return
    ratio = float(np.median([r for _, r in g.angle_ratios]))
    lo, hi = ANGLE_RATIO_BAND
    if not lo <= abs(ratio) <= hi:
        hint = ""
        for factor, words in ((60 / (2 * np.pi), "a speed in rad/s read as rpm"),
                              (2 * np.pi / 60, "a speed in rpm read as rad/s"), (1e3, "a time in s read as ms"),
                              (1e-3, "a time in ms read as s"), (180 / np.pi, "an angle in degrees read as rad"),
                              (np.pi / 180, "an angle in rad read as degrees")):
            if abs(abs(ratio) / factor - 1) < 0.1:
                hint = f" (as for {words})"
        if not hint:  # no unit mistake it matches (a gearbox between encoder and motor?): said, not refused
            g.notes.append(f"the shaft angle advances at {abs(ratio):.4g}× the rate the logged speed gives, in the "
                           f"median over {len(g.angle_ratios)} runs: is the encoder on the motor's shaft?")
            return
        raise InputError(f"the shaft angle advances at {abs(ratio):.4g}× the rate the logged speed gives, in the "
                         f"median over {len(g.angle_ratios)} runs{hint}: check the units of speed_rpm, time_s and "
                         "shaft_angle_deg (header suffixes or channel map)")
    if ratio < 0:
        g.notes.append(f"the shaft angle runs against the logged speed in the median over {len(g.angle_ratios)} "
                       "runs: the encoder counts the other way (the K_L(θ) harmonics' phase comes out mirrored)")


def _note_in_step(notes: list, key, time, speed, orders) -> None:
    """A note where the sampling is in step with a shaft order over a run that turns two revolutions or more."""
    cycles = aliased_cycles(time, speed, orders)
    in_step = [k for k, c in cycles.items() if c < 1.0]
    if in_step and np.ptp(time) * abs(nanmedian(speed)) > 4 * np.pi:
        notes.append(f"run {key}: sampled in step with shaft order {', '.join(map(str, in_step))} "
                     f"(it folds to under one cycle over the run): a speed ripple locked to the "
                     f"shaft at that order would read as a constant, and its acceleration would "
                     f"bias this run's torque; a sample rate not in step with the speed avoids it")


def _join(parts, dtype=float) -> np.ndarray:
    return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype=dtype)


def _running_samples(spec, numeric: dict, g: _Gathered, runs: pd.DataFrame):
    """The steady samples of every running run → (Samples, measured channels, frame rows, run of each)."""
    index = _join(g.picks, int)
    run_of_sample = _join(g.run_of_sample, int)
    all_temp = nanmedian(numeric["oil_temp_C"])
    temperature = numeric["oil_temp_C"][index]
    run_temp = runs["temp_median_C"].to_numpy(dtype=float)[run_of_sample]
    temperature = np.where(np.isfinite(temperature), temperature,
                           np.where(np.isfinite(run_temp), run_temp, all_temp if math.isfinite(all_temp) else 40.0))
    running = make_samples(spec, numeric["theta_rad"][index], numeric["speed_rad_s"][index],
                           numeric["p_a_Pa"][index], numeric["p_b_Pa"][index], numeric["p_case_Pa"][index],
                           _join(g.visc), acceleration=_join(g.accel),
                           direction=_join(g.directions), temperature=temperature, time=numeric["time_s"][index])
    measured = {name: numeric[col][index] for name, col in MEASURED_CHANNELS.items()}
    return running, measured, index, run_of_sample


def _event_samples(spec, events: list):
    """The breakaway events as Samples at their onsets (speed 0) → (Samples, column getter)."""
    ev = lambda c: np.array([e[c] for e in events], dtype=float)  # noqa: E731
    ev_temp = ev("oil_temp_C")
    samples = make_samples(spec, ev("theta_rad"), np.zeros(len(events)), ev("p_a_Pa"), ev("p_b_Pa"),
                           ev("p_case_Pa"), ev("viscosity_Pa_s"), acceleration=np.zeros(len(events)),
                           direction=ev("direction"),
                           temperature=np.where(np.isfinite(ev_temp), ev_temp, 40.0), time=ev("onset"))
    return samples, ev


def extract(frame: pd.DataFrame, spec: MotorSpec, settings: ExtractSettings | None = None) -> Dataset:
    """Steady-state running samples and breakaway events of a campaign.

    frame : canonical SI frame of :func:`motorid.io.logs.read_logs` (its ``run``
        column, else ``run_id``, names the runs); spec : the motor (pistons for
        S(θ)); settings : tolerances, :class:`ExtractSettings` by default.
    """
    settings = settings or ExtractSettings()
    _check_frame(frame)
    _check_spec(spec)
    index = _Runs(frame)
    g = _Gathered(len(index.keys), accel_orders=_accel_orders(settings, spec),
                  theta_mean_torque=mean_torque_angle(int(spec.pistons)))
    for r, key in enumerate(index.keys):
        pos, cols, protocol, file = index.run(r)
        _extract_run(g, r, key, pos, cols, protocol, file, settings)
    return _finish(spec, g, lambda runs: _running_samples(spec, index.numeric, g, runs))


def _extract_run(g: _Gathered, r: int, key, pos, cols, protocol, file, settings, cells=None) -> None:
    """One run → its row of ``Dataset.runs``, and its steady samples or breakaway event into ``g``."""
    row = {"run": key, "protocol": protocol, "file": file, "n_samples": pos.size, "n_steady": 0,
           "direction": 0.0, "onset_time_s": math.nan, "excluded": "", "viscosity_degree": -1,
           "viscosity_noise_Pa_s": math.nan}
    used = np.arange(pos.size)
    if protocol == STARTABILITY:
        _add_startability(g, r, key, cols, row, settings)
    elif protocol in RUNNING_PROTOCOLS:
        used = _add_running(g, r, key, pos, cols, row, settings, cells)
    else:
        raise InputError(f"run {key}: unknown protocol '{protocol}'")
    p_a, p_b = cols["p_a_Pa"][used], cols["p_b_Pa"][used]
    row.update(speed_median_rad_s=nanmedian(cols["speed_rad_s"][used]), dp_median_Pa=nanmedian(p_a - p_b),
               psum_median_Pa=nanmedian(p_a + p_b), temp_median_C=nanmedian(cols["oil_temp_C"][used]))
    g.rows.append(row)


def mean_torque_angle(pistons: int) -> float:
    """A shaft angle θ* where the port sum S(θ) = Σ_{cos θᵢ > 0} cos θᵢ equals its mean n/π over the
    angle (MODEL.md Eq. 1-7: there the pressure torque is D·ΔP/2π, its mean) [rad]."""
    from motorid.physics.kinematics import port_a_sum

    if pistons < 2:
        return math.nan
    theta = np.linspace(0.0, 2 * np.pi / pistons, 4001)
    s = np.asarray(port_a_sum(theta, pistons)) - pistons / np.pi
    cross = np.flatnonzero(np.sign(s[1:]) != np.sign(s[:-1]))
    if not cross.size:
        return float(theta[np.argmin(np.abs(s))])
    i = int(cross[0])
    return float(theta[i] - s[i] * (theta[i + 1] - theta[i]) / (s[i + 1] - s[i]))


def _note_assumed_angle(g: _Gathered) -> None:
    """Say where startability runs had no shaft angle (their breakaways taken at θ*)."""
    assumed = set(g.theta_assumed)
    used = [e for e in g.events if e["run"] in assumed]
    if used:
        g.notes.append(f"{len(used)} breakaway(s) without a shaft angle: the pressure torque is taken at its mean over "
                       f"the angle (D·ΔP/2π); the ripple about it, which these logs cannot place, widens the "
                       f"breakaway channel's noise (K_FS and K_s carry it in their std)")


def _finish(spec, g: _Gathered, running_samples, cells=None) -> Dataset:
    """The gathered runs → :class:`Dataset` (``running_samples(runs)`` gives its running part)."""
    _check_angle_rate(g)
    _note_assumed_angle(g)
    place_limited_onsets(g.events, g.pending)
    for e in g.events:
        g.rows[e["run_index"]]["onset_time_s"] = e["onset"]
    runs = pd.DataFrame(g.rows, columns=RUN_COLUMNS)
    n = len(g.rows)
    center, half, factor = g.visc_center[:n], g.visc_half[:n], g.visc_factor[:n]
    running, measured, rows, run_of_sample = running_samples(runs)
    events, ev = _event_samples(spec, g.events)
    return Dataset(
        running=running, measured=measured, run_of_sample=run_of_sample, frame_index=rows, runs=runs,
        events=events, held_torque=ev("held"), event_runs=[e["run"] for e in g.events],
        run_of_event=np.array([e["run_index"] for e in g.events], dtype=int), onset_time=ev("onset"),
        excluded={k: v for k, v in g.excluded.items() if v}, notes=g.notes,
        viscosity_error=(ViscositySmoothing(center, half, factor) if np.any(factor) else None),
        cells=None if cells is None else cells.statistics(len(runs)))


def extract_cells(runs, spec: MotorSpec, settings: ExtractSettings | None = None, bins_per_pitch: int = 192,
                  outlier_sigma: float = 5.0, progress: bool | None = None) -> Dataset:
    """Steady-state running samples reduced to shaft-angle cells run by run, and breakaway events.

    runs : an iterable of :class:`motorid.io.stream.RunColumns` (a campaign read as a
    stream); each running run's steady samples go into cell sums as the run arrives
    (:class:`motorid.identify.cells.CellReducer`), so that memory is set by the cells,
    not the rows.  Returns a :class:`Dataset` whose running rows are cells, with their
    sufficient statistics in ``Dataset.cells``.
    """
    from motorid.identify.cells import CellReducer, give_back_free_memory
    from motorid.progress import bar

    settings = settings or ExtractSettings()
    _check_spec(spec)
    g = _Gathered(0, accel_orders=_accel_orders(settings, spec), theta_mean_torque=mean_torque_angle(int(spec.pistons)))
    cells = CellReducer(spec, bins_per_pitch, outlier_sigma)
    with bar(desc="extracting", unit="run", progress=progress) as pbar:
        for r, run in enumerate(runs):
            g.grow(r)
            cells.rows += run.n
            _extract_run(g, r, run.key, np.arange(run.n), run.columns, run.protocol, run.file, settings, cells)
            pbar.update(1)
            if run.n > 50_000:
                del run
                give_back_free_memory()
    if not g.rows:
        raise InputError("no runs in these logs")
    data = _finish(spec, g, cells.running_samples, cells)
    give_back_free_memory()
    return data
