"""Bench logs without a shaft angle → operating points (a bench with no shaft encoder).

The 1992 model's torque and flow ripple, and the K_L(θ) harmonics, are functions of the
shaft angle θ (MODEL.md, Eq. 1-7 and 29-37); their means over the shaft angle are not:
T_p averages to D·ΔP/2π, the swept flow to D·ω/2π, the leakage to K_L0·(P − P_c)/μ.  A
log that holds no shaft angle is therefore fitted as what its steady stretches are,
operating points of the model averaged over θ (the operating-point table path,
identify/tables.py), and K_L's harmonics are reported as not identifiable.

A running run becomes

* **one point** where its steady samples (:func:`motorid.identify.steady.steady_run`, the
  same test as for a fit of samples) hold speed and ΔP within a narrow band: the mean of
  every channel over them, with the count and each output's spread (``n_samples``,
  ``*_std_*``: the table's relative weights), the spread widened by what the sampling leaves
  of the shaft-angle ripple in the mean (a rate in step with the pitch frequency sees it at a
  few phases only: :func:`ripple_coverage`, :func:`ripple_bias`);
* **quasi-steady points** where it is a recording of continuous motion (a wave-energy test
  machine, a duty cycle): the samples that turn (|ω| ≥ :data:`MIN_SPEED_SHARE` of the
  campaign's speed) and barely accelerate (|dω/dt| ≤ the campaign's speed per
  :data:`ACCEL_TIME_S`) are binned in a (speed, ΔP) grid of :data:`GRID` cells over the
  campaign's range, and a cell of :data:`MIN_DURATION_S` of samples or more is a point.

Where the spec gives the inertia J, each point's torque has the inertia torque of its mean
acceleration taken out (+J·ᾱ, Eq. 17), so that it is the steady torque the table model holds.
A point whose means give power out at both the shaft and the ports (T·ω > 0 and
ΔP·Q_A < 0) breaks the first law for a steady point and is left out with a note.
Startability runs stay with the log fit, which takes their breakaways at the pressure torque's
mean over the angle (identify/extract.py, ``mean_torque_angle``); the points and the
breakaways are fitted jointly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from motorid.identify.steady import steady_run
from motorid.identify.types import RUNNING_PROTOCOLS, STARTABILITY, ExtractSettings
from motorid.robust import nanmedian

#: the file the points are written to, in the output folder
POINTS_FILE = "points_from_logs.csv"
#: a steady run is one point where its steady samples' moving-median speed and ΔP stay within this
#: share of their level (5-95 % range), else its samples are binned as a recording of motion
STEADY_SPREAD = 0.10
#: quasi-steady binning: cells per axis over the campaign's 99th-percentile |speed| and |ΔP|
GRID = 12
#: quasi-steady binning: samples turning at less than this share of the campaign's speed are left out
MIN_SPEED_SHARE = 0.05
#: quasi-steady binning: |dω/dt| at most the campaign's 99th-percentile |speed| per this many seconds
ACCEL_TIME_S = 10.0
#: quasi-steady binning: a cell needs samples of this many seconds in all (and 25 samples)
MIN_DURATION_S = 0.5
MIN_CELL_SAMPLES = 25
#: the moving mean of the speed whose derivative is the acceleration [s]
SMOOTH_S = 0.1

_OUTPUTS = (("torque_Nm", "torque_Nm", 1.0), ("q_a_lpm", "q_a_m3_s", 6e4), ("q_b_lpm", "q_b_m3_s", 6e4),
            ("q_case_lpm", "q_case_m3_s", 6e4))


def logs_lack_shaft_angle(paths, channels=None) -> bool:
    """Whether no log of ``paths`` holds a shaft angle, known without reading them whole: a channel
    map (given, or beside a file) that lists ``shaft_angle_deg`` under ``absent``; a plain CSV whose
    header has no shaft-angle column, or whose column is empty (its first rows, then the whole
    column).  Any file that may hold one: False."""
    from motorid.io.formats import find_channel_map, needs_foreign_reader
    from motorid.io.channel_map import load_channel_map

    files = _log_files(paths)
    if not files:
        return False
    for p in files:
        cmap_path = channels if channels is not None else find_channel_map(p)
        if cmap_path is not None:
            cmap = cmap_path if hasattr(cmap_path, "absent") else load_channel_map(cmap_path)
            if "shaft_angle_deg" not in cmap.absent:
                return False
            continue
        if needs_foreign_reader(p) or not _csv_lacks_angle(p):
            return False
    return True


def _log_files(paths) -> list:
    out = []
    for p in map(Path, paths):
        if p.is_dir():
            from motorid.io.formats import data_files_in

            out += list(data_files_in(p))
        elif p.exists():
            out.append(p)
    return out


#: rows read first to see whether a CSV's shaft-angle column holds any value (the rest only if not)
ANGLE_PROBE_ROWS = 20_000


def _csv_lacks_angle(path: Path) -> bool:
    """Whether a plain CSV log has no shaft-angle column, or an empty one: its header from the
    file's head, then the column alone, its first :data:`ANGLE_PROBE_ROWS` rows before the rest."""
    from motorid.errors import InputError
    from motorid.io.logs import _map_columns, _split_header
    from motorid.io.table_columns import _head_text

    try:
        fields, delim, _, header_line = _split_header(path, _head_text(path))
        found, _ = _map_columns(path, fields)
    except (InputError, OSError, IndexError):
        return False  # the log reader says what is wrong with it
    if "theta_rad" not in found:
        return True
    j = found["theta_rad"][0]
    for rows in (ANGLE_PROBE_ROWS, None):
        try:
            column = pd.read_csv(path, sep=delim, header=None, skiprows=header_line, usecols=[j], nrows=rows,
                                 skipinitialspace=True, dtype=str, keep_default_na=False)[j]
        except (ValueError, OSError, pd.errors.ParserError):
            return False
        if np.isfinite(pd.to_numeric(column.str.strip(), errors="coerce").to_numpy(dtype=float)).any():
            return False
        if rows is not None and len(column) < rows:
            break
    return True


def operating_points(frame: pd.DataFrame, spec=None, settings: ExtractSettings | None = None):
    """The runs of a canonical SI log frame (:func:`motorid.io.logs.read_logs`) → (points in the
    operating-point table format of BENCH_LOG_FORMAT.md as a DataFrame, notes in words).

    Columns: ``point_id`` (the run, or ``run:k`` for a run's k-th quasi-steady cell), ``speed_rpm``,
    ``p_a_bar``, ``p_b_bar``, ``p_case_bar``, the outputs the log holds (``torque_Nm``, ``q_a_lpm``,
    ``q_b_lpm``, ``q_case_lpm``), ``oil_temp_C`` where measured, ``viscosity_mPas`` where a viscometer
    gave it, ``n_samples`` and the outputs' ``*_std_*``; ``recording`` (the source file) where the
    logs are several files; ``accel_rpm_s`` (the mean dω/dt, what inertia could add to the torque)
    and ``source`` ("steady run" / "quasi-steady cell"), kept and ignored by the table reader.
    """
    from motorid.io.logs import TEMPERATURE_ASSUMED, VISCOSITY_FROM_OIL

    settings = settings or ExtractSettings()
    runs = frame["run"] if "run" in frame.columns else frame["run_id"]
    codes, keys = pd.factorize(runs)
    t_all = frame["time_s"].to_numpy(dtype=float)
    order = np.lexsort((t_all, codes))
    bounds = np.searchsorted(codes[order], np.arange(len(keys) + 1))
    numeric = [c for c in ("time_s", "speed_rad_s", "p_a_Pa", "p_b_Pa", "p_case_Pa", "torque_Nm", "q_a_m3_s",
                           "q_b_m3_s", "q_case_m3_s", "oil_temp_C", "viscosity_Pa_s") if c in frame.columns]
    arrays = {c: frame[c].to_numpy(dtype=float) for c in numeric}
    for flag in (TEMPERATURE_ASSUMED, VISCOSITY_FROM_OIL):
        arrays[flag] = (frame[flag].to_numpy(dtype=bool) if flag in frame.columns
                        else np.zeros(len(frame), bool))
    notes = []
    if not np.isfinite(arrays["p_case_Pa"]).any():  # no case transducer: 0 bar gauge, as in a table
        arrays["p_case_Pa"] = np.zeros(len(frame))
        notes.append("no case pressure in these logs: taken as 0 bar gauge (the leakage to the case follows "
                     "P − P_c)")
    temp = arrays["oil_temp_C"]
    spec_temp = getattr(getattr(spec, "oil", None), "temp_C", None)
    if (spec_temp is not None and temp.size and np.isfinite(temp).all() and np.ptp(temp) == 0
            and float(temp[0]) == float(spec_temp) and arrays[VISCOSITY_FROM_OIL].all()):
        # one temperature to the last digit over the whole campaign, the spec's own: a constant someone
        # typed (a channel map's [constants], an assumed value), not a reading; the points then carry none,
        # as a table that records none (a viscosity per recording may then be tried: docs/maps.md)
        arrays[TEMPERATURE_ASSUMED] = np.ones(len(frame), bool)
        notes.append(f"the logs' oil temperature is one constant, {float(temp[0]):g} °C, the spec's [oil] temp_C, "
                     f"for every sample: taken as assumed, not recorded")
    protocols = frame["protocol"].astype(str).to_numpy()
    files = frame["file"].astype(str).to_numpy() if "file" in frame.columns else np.full(len(frame), "")
    several_files = len(set(files)) > 1
    running = np.isin(protocols, RUNNING_PROTOCOLS)
    speed_scale = float(np.nanquantile(np.abs(arrays["speed_rad_s"][running]), 0.99)) if running.any() else 0.0
    dp_all = arrays["p_a_Pa"] - arrays["p_b_Pa"]
    dp_scale = float(np.nanquantile(np.abs(dp_all[running]), 0.99)) if running.any() else 0.0
    rows, excluded = [], {}
    n_start = 0
    for r, key in enumerate(keys):
        pos = order[bounds[r]:bounds[r + 1]]
        protocol = protocols[pos[0]]
        if protocol == STARTABILITY:
            n_start += 1
            continue
        if protocol not in RUNNING_PROTOCOLS:
            continue
        cols = {c: v[pos] for c, v in arrays.items()}
        recording = Path(files[pos[0]]).name if several_files else None
        quiet: list = []
        chosen, _, why = steady_run(str(key), cols, settings, excluded, quiet,
                                    inputs=("speed_rad_s", "p_a_Pa", "p_b_Pa", "p_case_Pa", "viscosity_Pa_s"))
        if chosen is not None and _holds_still(cols, chosen):
            rows.append(_point(str(key), cols, chosen, recording, "steady run", spec))
            continue
        cells = _quasi_steady_cells(cols, speed_scale, dp_scale)
        if not cells:
            notes.append(f"run {key}: no steady stretch and no quasi-steady cell (" + (why or "speed or ΔP moves "
                         "through the run") + ")")
        for k, idx in enumerate(cells, start=1):
            rows.append(_point(f"{key}:{k}", cols, idx, recording, "quasi-steady cell", spec))
    points = pd.DataFrame(rows)
    points.attrs["startability_runs"] = n_start
    if points.empty:
        return points, notes
    drop = _first_law_breaches(points)
    for pid in points.loc[drop, "point_id"]:
        notes.append(f"point {pid} left out: its means give power out at both the shaft and the ports (first law; "
                     f"a transient the reduction did not remove, or pressures read away from the ports)")
    points = points.loc[~drop].reset_index(drop=True).dropna(axis=1, how="all")
    points.attrs["startability_runs"] = n_start
    return points, notes


def _holds_still(cols: dict, chosen: np.ndarray) -> bool:
    """Whether a run's steady samples hold speed and ΔP within :data:`STEADY_SPREAD` of their level
    (on the medians of about 1000 blocks of samples, smoothed by a moving median of 5)."""
    import warnings

    from motorid.robust import moving_median

    n = chosen.size
    size = max(1, n // 1000)
    m = n // size
    for x, floor in ((cols["speed_rad_s"][chosen], 0.5), ((cols["p_a_Pa"] - cols["p_b_Pa"])[chosen], 2e5)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # an all-empty block
            blocks = np.nanmedian(x[:m * size].reshape(m, size), axis=1)
        smooth = moving_median(blocks, min(5, m) | 1)
        if not np.isfinite(smooth).any():
            continue
        lo, hi = np.nanquantile(smooth, [0.05, 0.95])
        if hi - lo > max(STEADY_SPREAD * abs(nanmedian(smooth)), floor):
            return False
    return True


def _quasi_steady_cells(cols: dict, speed_scale: float, dp_scale: float) -> list:
    """Index arrays of a run's quasi-steady cells (module docstring)."""
    t = cols["time_s"]
    if t.size < MIN_CELL_SAMPLES or speed_scale <= 0:
        return []
    step = float(np.median(np.diff(t))) if t.size > 1 else math.inf
    w = max(3, int(round(SMOOTH_S / step)) | 1) if step > 0 else 3
    speed = cols["speed_rad_s"]
    filled = pd.Series(speed).interpolate(limit_direction="both").to_numpy()
    smooth = pd.Series(filled).rolling(w, center=True, min_periods=1).mean().to_numpy()
    accel = np.gradient(smooth, t)
    cols["accel_rad_s2"] = accel  # the cells' mean acceleration (_point: the inertia torque taken out)
    dp = cols["p_a_Pa"] - cols["p_b_Pa"]
    # binned on the moving means: on the readings, a cell at an edge the motion dwells on collects the
    # samples whose noise lies on its side, and its means are off by that noise
    dp_smooth = pd.Series(dp).interpolate(limit_direction="both").rolling(w, center=True,
                                                                         min_periods=1).mean().to_numpy()
    ok = (np.isfinite(speed) & np.isfinite(dp) & np.isfinite(cols["p_case_Pa"])
          & np.isfinite(cols["viscosity_Pa_s"])
          & (np.abs(speed) >= MIN_SPEED_SHARE * speed_scale) & (np.abs(accel) <= speed_scale / ACCEL_TIME_S))
    if not ok.any():
        return []
    ds = speed_scale / GRID
    dd = max(dp_scale / GRID, 1e5)
    cell = np.floor(smooth / ds) * 100003 + np.floor(dp_smooth / dd)
    need = max(MIN_CELL_SAMPLES, int(math.ceil(MIN_DURATION_S / step)) if step > 0 else 0)
    idx = np.flatnonzero(ok)
    out = []
    for c in np.unique(cell[idx]):
        members = idx[cell[idx] == c]
        if members.size >= need:
            out.append(members)
    return out


def _point(point_id: str, cols: dict, idx: np.ndarray, recording, source: str, spec=None) -> dict:
    """The means of one point's samples in the table format's units, and their spreads (for a steady
    run, widened by what its sampling leaves of the ripple in the mean: :func:`ripple_bias`)."""
    def mean(x):
        x = x[idx]
        good = np.isfinite(x)
        return float(x[good].mean()) if good.sum() >= max(2, 0.5 * idx.size) else math.nan

    row = {"point_id": point_id}
    if recording is not None:
        row["recording"] = recording
    row.update(speed_rpm=mean(cols["speed_rad_s"]) * 30.0 / math.pi, p_a_bar=mean(cols["p_a_Pa"]) / 1e5,
               p_b_bar=mean(cols["p_b_Pa"]) / 1e5, p_case_bar=mean(cols["p_case_Pa"]) / 1e5)
    outputs = {name: cols[si][idx] * scale for name, si, scale in _OUTPUTS if si in cols}
    spreads = {}
    for name, x in outputs.items():
        good = np.isfinite(x)
        row[name] = float(x[good].mean()) if good.sum() >= max(2, 0.5 * idx.size) else math.nan
        spreads[name] = float(np.std(x[good], ddof=1)) if good.sum() >= 2 else math.nan
    if spec is not None and source == "steady run":
        # what the sampling leaves of the shaft-angle ripple in the mean: widened into the spread, so that
        # spread/√n_samples is the point's standard error (the table's relative weight)
        coverage = ripple_coverage(cols["time_s"][idx], cols["speed_rad_s"][idx], int(spec.pistons))
        bias = ripple_bias(row, spreads, coverage, spec)
        for name in spreads:
            spreads[name] = math.sqrt(spreads[name] ** 2 + idx.size * bias[name] ** 2)
        row["ripple_coverage"] = coverage
    from motorid.io.logs import TEMPERATURE_ASSUMED, VISCOSITY_FROM_OIL

    if not cols[TEMPERATURE_ASSUMED][idx].any():
        row["oil_temp_C"] = mean(cols["oil_temp_C"])
    if not cols[VISCOSITY_FROM_OIL][idx].any():
        row["viscosity_mPas"] = mean(cols["viscosity_Pa_s"]) * 1e3
    row["n_samples"] = int(idx.size)
    for name in outputs:
        spread = spreads[name]
        row[name.replace("_Nm", "_std_Nm").replace("_lpm", "_std_lpm")] = spread if spread > 0 else math.nan
    t = cols["time_s"][idx]
    alpha = math.nan  # the point's mean acceleration [rad/s²]
    if source == "steady run" and t.size >= 2 and np.ptp(t) > 0:
        speed = cols["speed_rad_s"][idx]
        good = np.isfinite(speed)
        alpha = float(np.polyfit(t[good], speed[good], 1)[0]) if good.sum() >= 2 else math.nan
    elif "accel_rad_s2" in cols:
        alpha = float(np.nanmean(cols["accel_rad_s2"][idx]))
    row["accel_rpm_s"] = alpha * 30.0 / math.pi
    inertia = float(getattr(spec, "inertia", 0.0) or 0.0)
    if inertia > 0 and np.isfinite(alpha) and np.isfinite(row.get("torque_Nm", math.nan)):
        row["torque_Nm"] += inertia * alpha  # the steady torque: the model's T_J = −J·α taken out (Eq. 17)
    row["source"] = source
    return row


#: the multiples of the piston-pitch order n whose ripple a steady run's sampling may not average out
RIPPLE_MULTIPLES = 4
#: the pitch frequency is taken as uncertain by this share (a speed sensor's gain error)
RIPPLE_FREQUENCY_SPAN = 0.003
#: where the leakage's own ripple (K_L(θ)'s harmonics) must be bounded without data: this share of it
LEAK_RIPPLE_SHARE = 0.5


def ripple_coverage(t, speed, pistons: int) -> float:
    """How far the samples of a steady run are from seeing every phase of the shaft-angle ripple:
    max over the orders k·n (k = 1 … :data:`RIPPLE_MULTIPLES`) and over the pitch frequency within
    ±:data:`RIPPLE_FREQUENCY_SPAN` of |mean exp(i·k·n·φ)|, φ = ∫ω dt the angle up to a constant
    (0: the ripple averages out of the mean; 1: every sample at one phase, the ripple reads as a
    constant).  A run sampled in step with the pitch frequency (a rate that divides n·ω/2π) comes
    out near 1."""
    t, speed = np.asarray(t, float), np.asarray(speed, float)
    good = np.isfinite(t) & np.isfinite(speed)
    if pistons <= 0 or good.sum() < 2:
        return 1.0
    t, speed = t[good], speed[good]
    phase = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))]) * pistons
    total = max(abs(phase[-1]), 1e-9)
    turns = total / (2 * np.pi)
    k = np.arange(1, RIPPLE_MULTIPLES + 1)[:, None]
    # blocks of samples over which the frequency offsets turn the phase by under 0.05 rad: their sums of
    # exp(i·k·φ) are rotated for each offset (cost: samples + offsets × blocks, not their product)
    length = max(1, int(0.05 * phase.size / (RIPPLE_MULTIPLES * RIPPLE_FREQUENCY_SPAN * total)))
    blocks = -(-phase.size // length)
    step = 1.0 / (8.0 * RIPPLE_MULTIPLES * turns)
    # offsets 1/8 of the top order's peak apart, at most 601 (and fewer over very many blocks: a run of
    # 10⁵ pitch cycles and more is searched more coarsely)
    most = int(max(61, min(601, 4e7 / (RIPPLE_MULTIPLES * blocks))))
    count = int(min(2 * math.ceil(RIPPLE_FREQUENCY_SPAN / step) + 1, most)) | 1  # odd: the logged speed itself
    offsets = np.linspace(-RIPPLE_FREQUENCY_SPAN, RIPPLE_FREQUENCY_SPAN, max(count, 1)) if count > 1 else np.zeros(1)
    pad = blocks * length - phase.size
    ph = np.r_[phase, np.full(pad, np.nan)].reshape(blocks, length)
    sums = np.nansum(np.exp(1j * k[:, :, None] * ph[None, :, :]), axis=2)  # (orders, blocks)
    centre = np.nanmean(ph, axis=1)
    worst = 0.0
    for off in offsets:
        z = np.abs(np.sum(sums * np.exp(1j * k * off * centre[None, :]), axis=1)) / phase.size
        worst = max(worst, float(z.max()))
    return min(worst, 1.0)


def _port_sum_ripple(pistons: int) -> float:
    """Half the peak-to-peak of the port sum S(θ) (physics/kinematics.port_a_sum) over its mean n/π."""
    from motorid.physics.kinematics import port_a_sum

    total = np.asarray(port_a_sum(np.linspace(0.0, 2 * np.pi / max(pistons, 1), 2001), pistons))
    return float((total.max() - total.min()) / 2 / (pistons / np.pi))


def ripple_bias(row: dict, spreads: dict, coverage: float, spec) -> dict:
    """The standard error a steady run's mean carries from the ripple its sampling leaves in it, per
    output [the output's unit]: (R·D)/√2 with D the :func:`ripple_coverage` and R the ripple's
    amplitude, √2 × the output's spread where the samples see the ripple (D ≤ 0.5), else at least
    the 1992 model's own: the pressure torque's D·|ΔP|/2π × the port sum's ripple, the swept flow's
    D·|ω|/2π × the same, and :data:`LEAK_RIPPLE_SHARE` of the case flow for K_L(θ)'s harmonics."""
    n = int(spec.pistons)
    a_s = _port_sum_ripple(n)
    disp = float(spec.displacement)
    dp = abs(row["p_a_bar"] - row["p_b_bar"]) * 1e5
    w = abs(row["speed_rpm"]) * math.pi / 30.0
    leak = abs(row.get("q_case_lpm", math.nan))
    leak = 0.0 if not np.isfinite(leak) else leak
    model = {"torque_Nm": disp * dp / (2 * math.pi) * a_s,
             "q_a_lpm": disp * w / (2 * math.pi) * a_s * 6e4 + LEAK_RIPPLE_SHARE * leak,
             "q_b_lpm": disp * w / (2 * math.pi) * a_s * 6e4 + LEAK_RIPPLE_SHARE * leak,
             "q_case_lpm": LEAK_RIPPLE_SHARE * leak}
    out = {}
    for name, spread in spreads.items():
        seen = math.sqrt(2.0) * spread if np.isfinite(spread) else 0.0
        amplitude = seen if coverage <= 0.5 else max(seen, model.get(name, 0.0))
        out[name] = amplitude * coverage / math.sqrt(2.0)
    return out


def _first_law_breaches(points: pd.DataFrame) -> np.ndarray:
    """True where a point gives power out at both its shaft (T·ω > 0) and its ports (ΔP·Q_A < 0)."""
    if "torque_Nm" not in points or "q_a_lpm" not in points:
        return np.zeros(len(points), bool)
    shaft_out = (points["torque_Nm"] * points["speed_rpm"] > 0).to_numpy()
    ports_out = ((points["p_a_bar"] - points["p_b_bar"]) * points["q_a_lpm"] < 0).to_numpy()
    return shaft_out & ports_out


@dataclass
class LogPoints:
    """Logs reduced to operating points: the CSV written, and what the reduction did."""

    path: Path
    notes: list
    steady_runs: int  # points that are a whole steady run
    cells: int  # points that are a quasi-steady cell of a run in motion
    startability_runs: int  # left out

    scope: str = "these logs"  # which logs the points came from, in words
    sources: tuple = ()  # those logs

    def summary(self) -> str:
        """One sentence for the user and for result.json's warnings."""
        return (f"no shaft angle in {self.scope}: fitted as {self.steady_runs + self.cells} operating points "
                f"({self.steady_runs} steady runs, {self.cells} quasi-steady cells of runs in motion; "
                f"identify/log_points.py), with the model averaged over the shaft angle"
                + (f", jointly with the breakaways of their {self.startability_runs} startability run(s) (the "
                   f"pressure torque at rest taken at its mean over the angle: the ripple about it widens the "
                   f"breakaway channel's noise)" if self.startability_runs else ""))

    def logs_for_breakaways(self, logs) -> list:
        """The logs to fit jointly with the points: the same logs where they hold startability runs (the
        log fit takes their breakaways; their running runs, without an angle, it leaves out), else none."""
        return list(logs) if self.startability_runs else []

    def annotate(self, doc: dict, logs) -> None:
        """Say in a result document (result.json, diagnosis.json) that its table is these logs' points:
        ``inputs.reduced_logs``, the parameters' reasons, the first warning."""
        doc.setdefault("inputs", {})["reduced_logs"] = [str(Path(p).resolve()) for p in logs]
        reasons = self.reasons()
        for name, entry in doc.get("parameters", {}).items():
            why = reasons.get(name) or reasons.get(name.rstrip("0123456789"))
            if why and not entry.get("identifiable", True):
                entry["reason"] = why
        fit = doc.get("fit")
        if isinstance(fit, dict) and self.summary() not in fit.get("warnings", []):
            fit["warnings"] = [self.summary(), *self.notes, *fit.get("warnings", [])]

    def move_into(self, doc: dict, folder) -> None:
        """Copy the points into ``folder`` (a result folder) and name that copy in ``doc``'s inputs."""
        import shutil

        folder = Path(folder)
        source, target = Path(self.path).resolve(), (folder / POINTS_FILE).resolve()
        if source != target:
            folder.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, target)
        inputs = doc.setdefault("inputs", {})
        inputs["tables"] = [str(target) if Path(t).resolve() == source else t for t in inputs.get("tables", [])]

    def reasons(self) -> dict:
        """Why a parameter is not identified, in the words of these logs (replacing a table's)."""
        out = {k: ("these logs hold no shaft angle: they are fitted as operating points (means over the shaft "
                   "angle), and the K_L(θ) harmonics need flows recorded against it") for k in ("KL_a", "KL_b")}
        if not self.startability_runs:  # not "an operating-point table": the user gave logs
            out.update({k: ("these logs hold no startability run (ISO 4392-2) with a breakaway: static friction "
                            "needs one") for k in ("KFS", "Ks")})
        return out


#: the reason extract gives a running run that has no shaft angle (identify/steady.py)
NO_ANGLE = "missing a shaft angle"


def runs_without_angle(dataset) -> tuple[int, int]:
    """(running runs left out for want of a shaft angle, running runs) of an extracted dataset."""
    runs = getattr(dataset, "runs", None)
    if runs is None or "excluded" not in getattr(runs, "columns", ()):
        return 0, 0
    running = runs["protocol"].astype(str) != STARTABILITY
    return int((runs.loc[running, "excluded"].astype(str) == NO_ANGLE).sum()), int(running.sum())


def angle_missing_everywhere(dataset) -> bool:
    """Whether an extracted dataset has no running sample because no running run holds a shaft angle
    (a format or channel map the cheap test of :func:`logs_lack_shaft_angle` cannot see into)."""
    missing, running = runs_without_angle(dataset)
    return not dataset.n_running and running > 0 and missing == running


def mixed_angle_warning(dataset) -> str:
    """A warning where some running runs hold a shaft angle and others none (those are left out)."""
    missing, running = runs_without_angle(dataset)
    if not missing or missing == running:
        return ""
    return (f"{missing} of {running} running runs hold no shaft angle and are left out of this fit: fit the logs "
            f"without an angle on their own (they are then fitted as operating points, docs/maps.md), or "
            f"give them their angle channel")


#: the temporary points folders this process made (:func:`remove_temporary_folders`)
_TEMPORARY: list = []


def _temporary_folder() -> str:
    """A new temporary folder for a campaign's points, removed when the process ends: at exit, or by
    the ``motorid`` command itself (:func:`remove_temporary_folders`), whose prompt exit skips the
    exit handlers."""
    import atexit
    import tempfile

    if not _TEMPORARY:
        atexit.register(remove_temporary_folders)
    folder = tempfile.mkdtemp(prefix="motorid-points-")
    _TEMPORARY.append(folder)
    return folder


def remove_temporary_folders() -> None:
    """Remove the temporary points folders this process made (what a result keeps was copied into it)."""
    import shutil

    while _TEMPORARY:
        shutil.rmtree(_TEMPORARY.pop(), ignore_errors=True)


def points_from_logs(paths, spec, channels=None, folder=None, known: bool = False) -> LogPoints | None:
    """Where no log of ``paths`` holds a shaft angle: read them, reduce them to operating points,
    write ``folder/`` :data:`POINTS_FILE` (a new temporary folder where ``folder`` is None) →
    :class:`LogPoints`; None where a log may hold a shaft angle (``known``: the caller found
    none in the extracted logs, :func:`angle_missing_everywhere`)."""
    from motorid.errors import InputError
    from motorid.io.logs import read_logs

    if not known and not logs_lack_shaft_angle(paths, channels):
        return None
    frame = read_logs([str(p) for p in paths], spec, channels)
    points, notes = operating_points(frame, spec)
    if points.empty or not any(c in points for c in ("torque_Nm", "q_a_lpm", "q_b_lpm", "q_case_lpm")):
        raise InputError("these logs hold no shaft angle, and no steady run or quasi-steady stretch of them gives an "
                         "operating point: " + ("; ".join(notes[:3]) or "no running run"))
    if folder is None:  # until a result is saved (LogPoints.move_into); gone when the process ends
        folder = _temporary_folder()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / POINTS_FILE
    points.to_csv(path, index=False, float_format="%.9g", lineterminator="\n")
    _check_points(path, spec, paths)
    steady = int((points["source"] == "steady run").sum())
    return LogPoints(path, notes, steady, len(points) - steady, int(points.attrs.get("startability_runs", 0)),
                     sources=tuple(str(p) for p in paths))


def _check_points(path: Path, spec, logs) -> None:
    """The table checks (the ideal machine: a unit's factor, a pump's signs) on the points, a refusal
    naming the logs they came from rather than the temporary points file."""
    from motorid.errors import InputError
    from motorid.io.table_checks import check_against_ideal
    from motorid.io.tables import read_table

    try:
        check_against_ideal(read_table(path, spec), path)
    except InputError as exc:
        names = ", ".join(Path(p).name for p in logs)
        raise InputError(str(exc).replace(str(path), f"the operating points of {names}")
                         .replace(path.name, f"the operating points of {names}")) from None


def reduce_logs_without_angle(logs, spec, channels=None):
    """Split a campaign's logs by whether they hold a shaft angle → (the logs for the log fit, LogPoints of
    those that hold none, or None).  Every log without an angle (the cheap test of
    :func:`logs_lack_shaft_angle`, file by file) is reduced to points; the logs for the log fit are the
    others, plus the angle-free ones where they hold startability runs (their breakaways)."""
    free = [p for p in logs if logs_lack_shaft_angle([p], channels)]
    if not free:
        return list(logs), None
    reduced = points_from_logs(free, spec, channels, known=True)
    if len(free) < len(logs):
        reduced.scope = f"{len(free)} of the {len(logs)} logs ({', '.join(Path(p).name for p in free[:3])}" + (
            ", …)" if len(free) > 3 else ")")
    kept = [p for p in logs if p not in free]
    return kept + reduced.logs_for_breakaways(free), reduced
