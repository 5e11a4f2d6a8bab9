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
from motorid.units import SI_COLUMNS
from motorid.model import Samples, make_samples
from motorid.model import MotorSpec

RUNNING_PROTOCOLS = ("constant_speed", "constant_pressure", "constant_flow", "constant_torque")
STARTABILITY = "startability"
MEASURED_CHANNELS = {"torque": "torque_Nm", "q_a": "q_a_m3_s", "q_b": "q_b_m3_s", "q_case": "q_case_m3_s"}
FRAME_NUMERIC = [c for c in SI_COLUMNS if c not in ("run_id", "protocol")]
_INPUTS = ("theta_rad", "speed_rad_s", "p_a_Pa", "p_b_Pa", "p_case_Pa", "viscosity_Pa_s")

# keys of Dataset.excluded
MISSING_INPUT = "samples with a missing input channel"
INPUT_SPIKE = "samples with a spike in an input channel"
START_TRANSIENT = "start-transient samples"
UNSTEADY = "unsteady samples after the start"
NO_STEADY_SPEED = "samples with no steady speed"
SHORT_RUN = "runs with too few samples"
FEW_STEADY = "runs with too few steady samples"
NO_BREAKAWAY = "startability runs without a breakaway"
NO_HELD_TORQUE = "breakaway events without a torque reading"

_MAD = 1.4826  # MAD → standard deviation of a normal distribution


@dataclass(frozen=True)
class ExtractSettings:
    """Tolerances of the extraction (none is tuned to one simulator).

    rest_speed : a run whose median |speed| is below this has no steady speed, and
        a startability run must depart from rest by at least this much (and by ten
        rest-noise deviations) to count as broken away [rad/s]
    min_samples : fewest samples a run needs [-]
    min_steady : fewest steady samples a running run needs [-]
    band_sigmas : half-width of the steady band in robust deviations of the
        settled signal (ripple and noise) [-]
    rel_tol : smallest half-width of the steady band, relative to the settled level [-]
    speed_floor : smallest half-width of the speed band [rad/s]
    pressure_floor : smallest half-width of the pressure bands [Pa]
    accel_window : window of the local quadratic fit giving the acceleration [samples]
    shaft_orders : shaft orders of a speed ripple locked to the shaft angle, whose
        acceleration is taken from θ, not from differences of sampled speed [-]
    stuck_turn : most the shaft angle may change before a breakaway, creep included [rad]
    smooth_viscosity : replace each running run's viscometer readings by a
        polynomial in time (:func:`smooth_viscosity`) where the readings are a
        slow curve plus white noise; False keeps every reading as read [-]
    viscosity_max_degree : highest degree of that polynomial [-]
    """

    rest_speed: float = 2e-3
    min_samples: int = 10
    min_steady: int = 3
    band_sigmas: float = 4.0
    rel_tol: float = 0.02
    speed_floor: float = 1e-3
    pressure_floor: float = 5e3
    accel_window: int = 9
    shaft_orders: tuple = (1, 2)
    stuck_turn: float = 0.2
    smooth_viscosity: bool = True
    viscosity_max_degree: int = 5


@dataclass
class Dataset:
    """The samples and events a fit uses, with what was left out and why.

    running : :class:`~motorid.model.Samples` of the steady-state samples of the
        running runs (direction = sign of the run's median speed; acceleration
        from a smoothed derivative of speed within the run; viscosity smoothed
        per run, :func:`smooth_viscosity`)
    measured : channel → array aligned with ``running``: "torque" [N·m], "q_a",
        "q_b", "q_case" [m³/s]; NaN where the sensor had no reading
    run_of_sample : index of each running sample's run into ``runs`` [-]
    frame_index : position (``iloc``) of each running sample's row in the frame given to :func:`extract`
    runs : one row per run: run, protocol, file, n_samples, n_steady,
        speed_median_rad_s, dp_median_Pa (P_A − P_B), psum_median_Pa (P_A + P_B),
        temp_median_C, direction (±1, 0 where none), onset_time_s (startability),
        excluded (why the run gives nothing, "" where it does), viscosity_degree
        (degree of the curve that replaced the viscometer's readings, −1 where
        they are used as read), viscosity_noise_Pa_s (the readings' scatter about it)
    events : :class:`~motorid.model.Samples` at the breakaway instants (θ, P_A,
        P_B, P_c, μ at the onset; speed 0; direction = the way the shaft broke away)
    held_torque : load torque held in the stuck phase of each event [N·m]
    event_runs : run key of each event; run_of_event : its index into ``runs``
    onset_time : breakaway instant of each event, run time [s]
    excluded : reason → count (samples or runs, as the reason says)
    notes : one line per run that gave less than it might, in words
    viscosity_error : the error the smoothed viscosity of each run still carries
        (:class:`ViscositySmoothing`), or None where every reading is used as read
    """

    running: Samples
    measured: dict
    run_of_sample: np.ndarray
    frame_index: np.ndarray
    runs: pd.DataFrame
    events: Samples
    held_torque: np.ndarray
    event_runs: list
    run_of_event: np.ndarray
    onset_time: np.ndarray
    excluded: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    viscosity_error: "ViscositySmoothing | None" = None

    @property
    def n_running(self) -> int:
        return int(np.asarray(self.running.theta).shape[0])

    @property
    def n_events(self) -> int:
        return len(self.event_runs)


# ----------------------------------------------------------------- small robust tools


def _odd(k: int) -> int:
    return k if k % 2 == 1 else k - 1


def _robust_poly(x: np.ndarray, y: np.ndarray, degree: int, k: float = 3.5, iterations: int = 6):
    """Polynomial fit of y(x), readings beyond k robust deviations dropped → (coef, σ of the rest)."""

    def outside(r, sel):
        centre = np.median(r[sel])
        sigma = _MAD * np.median(np.abs(r[sel] - centre))
        return np.abs(r - centre) > max(k * sigma, 1e-300), sigma

    far, _ = outside(y, np.ones(x.size, bool))
    keep = ~far
    for _ in range(iterations):
        if degree > 0 and keep.sum() > degree + 2 and np.ptp(x[keep]) > 0:
            coef = np.polyfit(x[keep], y[keep], degree)
        else:
            coef = np.array([np.median(y[keep])])
        far, sigma = outside(y - np.polyval(coef, x), keep)
        if (~far).sum() < degree + 3 or np.array_equal(~far, keep):
            break
        keep = ~far
    return coef, float(sigma)


def _sustained(x: np.ndarray, length: int) -> np.ndarray:
    """Forward running minimum min(x[i:i+length]): a level x stays above for ``length`` samples."""
    out = x.copy()
    for j in range(1, length):
        out[:-j] = np.minimum(out[:-j], x[j:])
    return out


def moving_median(x, window: int) -> np.ndarray:
    """Centred moving median over ``window`` (odd) samples, NaN skipped, windows cut
    short at the ends (as pandas' ``rolling(window, center=True, min_periods=1).median()``)."""
    x = np.asarray(x, dtype=float)
    n, h = x.size, window // 2
    if n == 0 or window <= 1:
        return x.copy()
    padded = np.concatenate([np.full(h, np.nan), x, np.full(h, np.nan)])
    return _window_median(np.lib.stride_tricks.sliding_window_view(padded, window))


def _window_median(windows: np.ndarray) -> np.ndarray:
    """Median of the finite values of each row (NaN where a row has none)."""
    out = np.full(windows.shape[0], np.nan)
    full = ~np.isnan(windows).any(axis=1)
    w = windows.shape[1]
    if full.any():  # rows without a gap: a partial sort is enough
        part = np.partition(windows[full], [(w - 1) // 2, w // 2], axis=1)
        out[full] = 0.5 * (part[:, (w - 1) // 2] + part[:, w // 2])
    if not full.all():
        ws = np.sort(windows[~full], axis=1)  # NaN last
        count = w - np.isnan(ws).sum(axis=1)
        rows = np.arange(ws.shape[0])
        lo, hi = ws[rows, np.maximum(count - 1, 0) // 2], ws[rows, np.maximum(count, 1) // 2]
        out[~full] = np.where(count > 0, 0.5 * (lo + hi), np.nan)
    return out


def input_spikes(x, k: float = 6.0, half: int = 3) -> np.ndarray:
    """Isolated readings of one run's input channel → boolean mask (a Hampel filter).

    The fit averages a cell's inputs (pressures, speed, viscosity) over all its
    samples, and each output channel over its own inliers; a spike in an input
    moves its cell's model by δ/N — N·m on cells whose noise is hundredths, and no
    residual test of an output shows it.  A reading is a spike where it stands
    more than ``k`` deviations from the median of the 2·``half`` + 1 readings
    around it; the deviation is the larger of the window's own MAD (ripple, steps
    and transients widen it) and the run's: the MAD of each reading against the
    median of its four neighbours (itself left out: against a median that holds it,
    a reading is so often the median itself that the MAD collapses to zero), or
    where that is zero (quantized readings on their neighbours' level) the smallest
    step.  Two spikes in a row are still found.  NaN readings are never spikes.
    """
    x = np.asarray(x, dtype=float)
    out = np.zeros(x.size, bool)
    ok = np.flatnonzero(np.isfinite(x))
    if ok.size < 2 * half + 4:
        return out
    v = x[ok]
    view = np.lib.stride_tricks.sliding_window_view
    # the median of the four neighbours: (sum − largest − smallest)/2 inside, sorted at the ends
    a, b, c, d = v[:-4], v[1:-3], v[3:-1], v[4:]
    near = np.empty(v.size)
    near[2:-2] = 0.5 * (a + b + c + d - np.maximum(np.maximum(a, b), np.maximum(c, d))
                        - np.minimum(np.minimum(a, b), np.minimum(c, d)))
    pad2 = np.concatenate([[np.nan] * 2, v[:4], [np.nan] * 2])
    near[:2] = _window_median(view(pad2, 5)[:2, [0, 1, 3, 4]])
    pad2 = np.concatenate([[np.nan] * 2, v[-4:], [np.nan] * 2])
    near[-2:] = _window_median(view(pad2, 5)[-2:, [0, 1, 3, 4]])
    r = np.abs(v - near)
    mad = _MAD * float(np.partition(r, r.size // 2)[r.size // 2])
    if not mad > 0:  # quantized readings that mostly sit on their neighbours' level: one step
        steps = r[r > 0]  # (unless only a few readings stand off a flat signal: those are spikes)
        mad = float(steps.min()) if steps.size >= max(3, 0.05 * r.size) else 0.0
    floor = max(mad, 1e-9 * float(np.max(np.abs(v))), 1e-300)
    # candidates: far from their neighbours' median (the window's median is within the
    # window's spread of it); for them the window's median and deviation
    i = np.flatnonzero(r > 0.5 * k * floor)
    if i.size:
        windows = view(np.concatenate([[np.nan] * half, v, [np.nan] * half]), 2 * half + 1)[i]
        med = _window_median(windows)
        local = _MAD * _window_median(np.abs(windows - med[:, None]))
        out[ok[i]] = np.abs(v[i] - med) > k * np.maximum(local, floor)
    return out


def _median3(x: np.ndarray) -> np.ndarray:
    """Running median of three: removes isolated spikes, leaves monotone runs and corners as they are."""
    if x.size < 3:
        return x.copy()
    out = x.copy()
    out[1:-1] = np.median(np.stack([x[:-2], x[1:-1], x[2:]]), axis=0)
    return out


def _circular_mean(theta: np.ndarray) -> float:
    return float(np.mod(np.angle(np.mean(np.exp(1j * theta))), 2.0 * np.pi))


# ----------------------------------------------------------------- steady state


def steady_state_mask(speed, dp, psum, settings: ExtractSettings = ExtractSettings(), smoothed=None):
    """Steady-state samples of one running run → (steady, start_transient) boolean masks.

    speed [rad/s], dp = P_A − P_B [Pa], psum = P_A + P_B [Pa], in time order (NaN
    allowed).  Each channel is smoothed by a short moving median (isolated spikes
    vanish); its settled level is the median of the smoothed second half of the
    run, and the band around it is ``band_sigmas`` robust deviations of that half
    (so shaft-angle ripple at low speed stays inside), at least ``rel_tol`` of the
    level and the floors.  The start transient ends where every channel has
    stayed in its band for a sustained stretch; later samples out of band are
    unsteady.  ``smoothed``: a dict to receive each channel's moving median (the
    caller reuses the speed's).
    """
    speed, dp, psum = (np.asarray(a, dtype=float) for a in (speed, dp, psum))
    n = speed.size
    window = max(1, _odd(min(int(np.clip(n // 100, 5, 21)), n)))
    in_band = np.ones(n, bool)
    for name, x, floor in (("speed", speed, settings.speed_floor), ("dp", dp, settings.pressure_floor),
                           ("psum", psum, settings.pressure_floor)):
        if not np.isfinite(x).any():
            continue
        smooth = moving_median(x, window)
        if smoothed is not None:
            smoothed[name] = smooth
        tail = smooth[n // 2:]
        if not np.isfinite(tail).any():
            continue
        level = np.nanmedian(tail)
        spread = _MAD * np.nanmedian(np.abs(tail - level))
        tol = max(settings.band_sigmas * spread, settings.rel_tol * abs(level), floor)
        in_band &= ~(np.abs(smooth - level) > tol)  # NaN counts as in band
    hold = int(np.clip(n // 20, 3, 50))
    bad = np.concatenate([[0], np.cumsum(~in_band)])
    k = np.arange(n)
    settled = bad[np.minimum(k + hold, n)] - bad[k] == 0
    start = int(np.argmax(settled)) if settled.any() else n
    transient = k < start
    return in_band & ~transient, transient


def smoothed_acceleration(time, speed, window: int = 9) -> np.ndarray:
    """dω/dt of one run by a local quadratic fit of speed against time [rad/s²].

    time [s], speed [rad/s] (NaN gaps are bridged).  Each sample's slope comes
    from a least-squares quadratic through the ``window`` samples around it (a
    Savitzky-Golay derivative when the sampling is even; uneven sampling is
    honoured).  Zero where the run is too short to tell.
    """
    t = np.asarray(time, dtype=float)
    w = np.asarray(speed, dtype=float)
    n = t.size
    ok = np.isfinite(w)
    if n < 5 or ok.sum() < 5:
        return np.zeros(n)
    if not ok.all():
        w = np.interp(t, t[ok], w[ok])
    k = _odd(min(max(window, 5), n))
    dt = np.diff(t)
    scale = float(np.median(dt))
    # (for even sampling this is the Savitzky-Golay derivative, edges as its "interp" mode)
    first = np.clip(np.arange(n) - k // 2, 0, n - k)  # windows shift inwards at the ends
    if np.all(np.abs(dt - scale) <= 1e-3 * scale) and n > k:
        # even sampling (time stamps rounded to a few digits count as even: a 0.1 % jitter
        # moves the slope by 0.1 % at most): one set of derivative weights for every interior sample
        x = np.arange(k) - k // 2
        powers = x[:, None] ** np.arange(3)[None, :]
        weights = np.linalg.solve(powers.T @ powers, powers.T)[1]
        out = np.empty(n)
        out[k // 2:n - k // 2] = np.correlate(w, weights, mode="valid")
        edge = np.r_[np.arange(k // 2), np.arange(n - k // 2, n)]
    else:
        out, edge = None, np.arange(n)
    idx = first[edge, None] + np.arange(k)[None, :]
    x = (t[idx] - t[edge, None]) / scale
    powers = x[:, :, None] ** np.arange(3)[None, None, :]  # (n, k, 3): 1, x, x²
    normal = np.einsum("nkp,nkq->npq", powers, powers)
    rhs = np.einsum("nkp,nk->np", powers, w[idx])
    slope = np.linalg.solve(normal, rhs[..., None])[:, 1, 0]
    if out is None:
        return slope / scale
    out[edge] = slope
    return out / scale


#: least F statistic of a shaft order of the speed ripple that running_acceleration keeps:
#: 2, Akaike's (an order's two coefficients must lower the misfit by more than two
#: residual variances each); a stricter test (30 before) left real ripples of fast
#: runs unresolved where the dynamometer's slow speed wander raised the residual
RIPPLE_F = 2.0


def aliased_cycles(time, speed, orders) -> dict:
    """Cycles that each shaft order of a steady run goes through as the samples see it
    (aliased) → {order: cycles over the run} [-].  Order k turns k·ω̄·Δt/2π cycles a
    sample; sampling folds that to its distance from the nearest whole number, 0 … ½.
    Near 0 the order is in step with the sampling: a speed ripple at it reads as a
    constant, and its acceleration, k·ω times its size, is invisible in the samples."""
    t = np.asarray(time, dtype=float)
    w = np.asarray(speed, dtype=float)
    ok = np.isfinite(t) & np.isfinite(w)
    if ok.sum() < 3:
        return {int(k): 0.0 for k in orders}
    dt = float(np.median(np.diff(np.sort(t[ok]))))
    turn = abs(float(np.mean(w[ok]))) * dt / (2 * np.pi)
    return {int(k): abs(k * turn - round(k * turn)) * int(ok.sum()) for k in orders}


def running_acceleration(time, speed, theta, steady, window: int = 9, orders=(1, 2)) -> np.ndarray:
    """dω/dt of a steady run with any speed ripple locked to the shaft angle resolved [rad/s²].

    A dynamometer's coupling or a shaft's eccentricity makes the speed wobble at
    shaft orders 1, 2, …; at high speed the samples alias that wobble, and a
    derivative of sampled speed (:func:`smoothed_acceleration`) turns it into a
    false slow acceleration, J·α of which lands in the torque.  Over the
    ``steady`` samples, speed = slow trend + Σₖ aₖ cos kθ + bₖ sin kθ is fitted
    by least squares (the trend a Chebyshev polynomial in time of degree about
    half the revolutions turned, 2 to 10: smooth over a revolution, so the two
    parts do not mix); the derivative of sampled speed is taken of the rest, and
    the ripple's own derivative, ω Σₖ k(bₖ cos kθ − aₖ sin kθ), is added back
    exactly.  Orders are taken lowest first, each kept where it lowers the misfit
    by F ≥ :data:`RIPPLE_F` and the sampling does not fold it onto an order
    already kept (an order fitted to noise adds that noise back k·ω times
    amplified; a real ripple left out adds itself); the plain derivative is
    returned where none is kept or the run turns less than two revolutions.
    """
    t = np.asarray(time, dtype=float)
    w = np.asarray(speed, dtype=float)
    th = np.asarray(theta, dtype=float)
    plain = smoothed_acceleration(t, w, window)
    sel = np.flatnonzero(np.asarray(steady, dtype=bool) & np.isfinite(w) & np.isfinite(th) & np.isfinite(t))
    orders = tuple(int(k) for k in orders)
    if not orders or sel.size < 50:
        return plain
    span = np.ptp(t[sel])
    if abs(float(np.mean(w[sel]))) * span / (2 * np.pi) < 2.0:
        return plain
    revolutions = abs(np.ptp(np.unwrap(th[sel]))) / (2 * np.pi)  # as sampled: order 1's aliased cycles
    u = 2.0 * (t[sel] - t[sel].min()) / max(span, 1e-300) - 1.0
    trend = np.polynomial.chebyshev.chebvander(u, int(np.clip(revolutions / 2, 2, 10)))
    m = trend.shape[1]
    X = np.column_stack([trend] + [np.column_stack([np.cos(k * th[sel]), np.sin(k * th[sel])]) for k in orders])
    y = w[sel] - np.mean(w[sel])  # (the trend holds the constant; centring keeps yᵀy − bᵀXᵀy exact)
    # every subset of orders from one Gram matrix (einsum: no threaded BLAS against XLA's threads)
    gram, xty, yy = np.einsum("ni,nj->ij", X, X), np.einsum("ni,n->i", X, y), float(y @ y)

    def fit(kept):
        cols = np.r_[np.arange(m), [m + 2 * orders.index(k) + j for k in kept for j in (0, 1)]].astype(int)
        g = gram[np.ix_(cols, cols)]
        lam = np.linalg.eigvalsh(g)
        cond = math.sqrt(lam[-1] / lam[0]) if lam[0] > 0 else math.inf  # of X: √ of its Gram's
        if not cond <= 1e8:
            return None, 0.0, 0, cond
        coef = np.linalg.solve(g, xty[cols])
        return coef, max(yy - float(coef @ xty[cols]), 0.0), sel.size - cols.size, cond

    # orders taken one at a time, lowest first: one that the sampling folds onto an order
    # already kept (at 1000 rpm and 50 Hz orders 1 and 2 alias to one frequency) is left
    # out, as is one that does not lower the misfit by F ≥ RIPPLE_F (an order fitted to
    # noise adds its noise back amplified k·ω times through the derivative; a real ripple
    # left out puts all of itself, k·ω times, into the acceleration)
    coef, rss_kept, _, _ = fit([])
    kept = []
    cycles = aliased_cycles(t[sel], w[sel], orders)
    for k in sorted(orders):
        # an order the sampling folds near 0 Hz is the trend's; near the Nyquist frequency its
        # cosine and sine read alike
        if not (cycles[k] >= m / 2 + 1 and 0.5 * sel.size - cycles[k] >= 1.0):
            continue
        c, rss, dof, cond = fit(kept + [k])
        if c is None or dof < 20 or cond > 1e6 or not rss > 0:
            continue
        if ((rss_kept - rss) / 2.0) / (rss / dof) >= RIPPLE_F:
            kept, coef, rss_kept = kept + [k], c, rss
    if not kept:
        return plain
    a, b = coef[trend.shape[1]::2], coef[trend.shape[1] + 1::2]
    k = np.asarray(kept, dtype=float)
    ok = np.isfinite(th)
    phase = np.outer(np.where(ok, th, 0.0), k)
    ripple = np.where(ok, np.cos(phase) @ a + np.sin(phase) @ b, np.nan)
    ripple_rate = np.where(ok, np.cos(phase) @ (k * b) - np.sin(phase) @ (k * a), 0.0)
    return smoothed_acceleration(t, w - ripple, window) + w * ripple_rate


# ----------------------------------------------------------------- viscosity

VISCOSITY_MODES = 6  # columns of ViscositySmoothing.factor: degree 5 at most


@dataclass(frozen=True)
class ViscositySmoothing:
    """What is left of the viscometer's error once each run's readings are smoothed.

    The viscosity of a steady run follows the oil temperature, which drifts
    slowly; the viscometer adds noise sample by sample (0.3 % is typical).  The
    leakage flows go as 1/μ and the viscous torque as μ, so a reading's noise
    multiplies them sample by sample, and the fit conditions on it (errors in
    variables: the leakage coefficients are biased low by ≈ 2σ_rel² and the
    harmonics of K_L(θ) scatter more).  :func:`smooth_viscosity` replaces the
    readings by a polynomial in time; its coefficients are still uncertain, and
    that error is common to the run: it does not average out over the run's
    samples.  It is kept here so that the fit can carry it into the parameters'
    covariance (:func:`motorid.identify.least_squares.fit_least_squares`).

    Per run (aligned with ``Dataset.runs``): ``center`` and ``half_span`` [s] map
    run time to u ∈ [−1, 1], the Chebyshev variable; ``factor`` (runs,
    VISCOSITY_MODES, VISCOSITY_MODES) [Pa·s] is L with L Lᵀ the covariance of the
    run's Chebyshev coefficients (zero for a run whose readings are used as read).
    The smoothed viscosity's error at a sample is then Σₖ modes[k]·zₖ with z
    standard normal per run (:meth:`modes`).
    """

    center: np.ndarray
    half_span: np.ndarray
    factor: np.ndarray

    def modes(self, run_of_sample, time) -> np.ndarray:
        """(n, VISCOSITY_MODES) error modes of the smoothed viscosity at the samples [Pa·s]."""
        r = np.asarray(run_of_sample, dtype=int)
        u = (np.asarray(time, dtype=float) - self.center[r]) / self.half_span[r]
        basis = np.polynomial.chebyshev.chebvander(u, VISCOSITY_MODES - 1)
        return np.einsum("nj,njk->nk", basis, self.factor[r])

    @property
    def any(self) -> bool:
        return bool(np.any(self.factor))


def smooth_viscosity(time, viscosity, max_degree: int = 5):
    """One steady run's viscometer readings as a slow curve → (smoothed, degree, σ, factor, center, half_span).

    time [s], viscosity [Pa·s] of the run's steady samples (finite).  The curve
    is a Chebyshev polynomial in time, fitted by least squares with readings
    beyond 4 robust deviations left out (spikes); its degree is the lowest
    after which one more degree no longer lowers the residual sum of squares
    by more than max(log n, 10) residual variances.  It replaces the readings
    only where what is left is white noise: the residuals' lag-one
    autocorrelation, in time order, must be below 3/√n (a change the curve
    cannot follow, such as a temperature step, leaves it near one).  Otherwise,
    where the run is shorter than 20 samples, or the readings do not scatter at
    all (a held viscosity), the readings are returned as read, with degree −1
    and a zero factor.  σ is the readings' deviation about the curve [Pa·s]; factor
    (VISCOSITY_MODES, VISCOSITY_MODES) is a square root L (L Lᵀ) of the curve's
    coefficient covariance σ²(XᵀX)⁻¹ (see :class:`ViscositySmoothing`).
    """
    t = np.asarray(time, dtype=float)
    mu = np.asarray(viscosity, dtype=float)
    n = t.size
    center = 0.5 * (t.min() + t.max()) if n else 0.0
    half = 0.5 * float(np.ptp(t)) if n else 0.0
    as_read = (mu.copy(), -1, math.nan, np.zeros((VISCOSITY_MODES, VISCOSITY_MODES)), center, max(half, 1.0))
    if n < 20 or half <= 0 or not np.all(np.isfinite(mu)) or not np.all(np.isfinite(t)):
        return as_read
    order = np.argsort(t, kind="stable")
    d = np.diff(mu[order])
    noise_diff = _MAD * float(np.median(np.abs(d - np.median(d)))) / math.sqrt(2.0)
    if not noise_diff > 0:
        return as_read
    u = (t - center) / half
    X_all = np.polynomial.chebyshev.chebvander(u, min(max_degree, VISCOSITY_MODES - 1))
    top = X_all.shape[1] - 1
    # spikes: readings beyond 4 robust deviations of the highest-degree curve (a spike is
    # one at any degree), found once
    keep = np.ones(n, bool)
    for _ in range(4):
        coef = np.linalg.lstsq(X_all[keep], mu[keep], rcond=None)[0]
        r = mu - X_all @ coef
        sigma = _MAD * float(np.median(np.abs(r[keep] - np.median(r[keep]))))
        new = np.abs(r) <= max(4.0 * sigma, 1e-300)
        if new.sum() < top + 10 or np.array_equal(new, keep):
            break
        keep = new
    # every degree from one QR of the kept rows: the first d + 1 columns of Q span degree d
    Q, R = np.linalg.qr(X_all[keep])
    qy = Q.T @ mu[keep]
    rss_all = float(mu[keep] @ mu[keep]) - np.cumsum(qy**2)  # residual sum of squares by degree
    m = int(keep.sum())
    penalty = max(math.log(n), 10.0)
    degree = 0
    while degree < top and m > degree + 12:
        var = max(rss_all[degree + 1], 0.0) / max(m - degree - 2, 1)
        if rss_all[degree] - rss_all[degree + 1] <= penalty * var:
            break
        degree += 1
    Rd = R[: degree + 1, : degree + 1]
    try:
        coef = np.linalg.solve(Rd, qy[: degree + 1])
    except np.linalg.LinAlgError:
        return as_read
    smooth = X_all[:, : degree + 1] @ coef
    # what is left must be white: lag-one autocorrelation of the (clipped) residuals in
    # time order within 3/√n of zero (a curve the polynomial misses leaves it positive)
    sigma = _MAD * float(np.median(np.abs((mu - smooth)[keep] - np.median((mu - smooth)[keep]))))
    rr = np.clip((mu - smooth)[order], -4.0 * sigma, 4.0 * sigma)
    power = float(rr @ rr)
    if not (power > 0 and float(rr[:-1] @ rr[1:]) / power <= 3.0 / math.sqrt(n)):
        return as_read
    sigma_ls = math.sqrt(max(rss_all[degree], 0.0) / max(m - degree - 1, 1))
    # covariance σ²(XᵀX)⁻¹ = σ² R⁻¹R⁻ᵀ: σR⁻¹ is a square root of it
    factor = np.zeros((VISCOSITY_MODES, VISCOSITY_MODES))
    factor[: degree + 1, : degree + 1] = sigma_ls * np.linalg.inv(Rd)
    return smooth, degree, sigma_ls, factor, center, half


# ----------------------------------------------------------------- breakaway


class NoBreakaway(ValueError):
    """No breakaway in a startability run; the message says why, in words."""


@dataclass(frozen=True)
class Breakaway:
    """Where the speed of a startability run leaves rest.

    onset_time [s]; direction ±1, the way the shaft breaks away; last_rest: index
    (into the arrays given) of the last sample still within the rest noise;
    rest_level [rad/s] and noise [rad/s]: the stuck speed's level and robust
    deviation (at least half a quantization step).  acceleration [rad/s²]: the
    growth rate of |speed| just after the onset, where the samples show it (NaN
    elsewhere).  limited: where the first moving sample had already met a speed
    limit W, (t₁ [s], Δθ₁/W [s], t₁ − t_rest [s], W [rad/s]): the time of that
    sample, the angle it had turned over the limit speed, the interval since the
    last sample at rest, and W; the onset then depends on the unseen time u_s the shaft took
    to reach the limit, t₀ = t₁ − Δθ₁/W − u_s/2 (:func:`place_limited_onset`), and
    ``onset_time`` takes the middle of the interval the angle allows.  None elsewhere.
    """

    onset_time: float
    direction: float
    last_rest: int
    rest_level: float
    noise: float
    acceleration: float = math.nan
    limited: tuple | None = None


def _rest_level(t, w, line: bool, floor: float):
    """Rest speed of the stuck samples → (baseline function, noise σ [rad/s]).

    σ is the largest of: the MAD of the residuals, the standard deviation of their
    central 80 % (scaled to a normal σ; it does not collapse to zero when most
    quantized readings sit on one level), half the quantization step between the
    levels the readings keep returning to (rare off-level readings are spikes),
    and ``floor``.
    """
    t_ref = t[-1]
    coef, sigma = _robust_poly(t - t_ref, w, 1 if line else 0)
    r = w - np.polyval(coef, t - t_ref)
    lo, hi = np.percentile(r, [10.0, 90.0])
    central = r[(r >= lo) & (r <= hi)]
    trimmed = 1.51 * float(central.std()) if central.size >= 5 else 0.0
    levels, counts = np.unique(w, return_counts=True)
    frequent = levels[counts >= max(3, 0.05 * w.size)]
    quantum = float(np.diff(frequent).min()) if frequent.size >= 2 else 0.0
    return (lambda tt: np.polyval(coef, tt - t_ref)), max(sigma, trimmed, 0.5 * quantum, floor)


def _hinge_costs(tt, yy, t0, quadratic: bool = True):
    """Least-squares cost of yy ≈ a·u + b·u², u = max(tt − t0, 0), a, b ≥ 0, for each t0.

    The two-column non-negative least squares in closed form, vectorized over
    ``t0``: the unconstrained solution where both coefficients come out ≥ 0,
    else the better of the one-column fits (the problem is convex, so the best
    feasible candidate is the optimum).  ``quadratic=False``: the linear hinge
    yy ≈ a·u alone (b = 0).
    """
    u = np.clip(tt[None, :] - np.asarray(t0, dtype=float)[:, None], 0.0, None)
    v = u * u
    uu, uv, vv = (u * u).sum(1), (u * v).sum(1), (v * v).sum(1)
    uy, vy, yy2 = u @ yy, v @ yy, float(yy @ yy)
    det = uu * vv - uv * uv
    with np.errstate(invalid="ignore", divide="ignore"):
        a2 = np.where(det > 0, (vv * uy - uv * vy) / det, -1.0)
        b2 = np.where(det > 0, (uu * vy - uv * uy) / det, -1.0)
        a1 = np.where(uu > 0, np.maximum(uy / uu, 0.0), 0.0)
        b1 = np.where(vv > 0, np.maximum(vy / vv, 0.0), 0.0)
    both = yy2 - (a2 * uy + b2 * vy)  # at the unconstrained optimum, SSE = yy − cᵀ(Xᵀy)
    only_a = yy2 - 2 * a1 * uy + a1 * a1 * uu
    if not quadratic:
        return np.maximum(only_a, 0.0)
    only_b = yy2 - 2 * b1 * vy + b1 * b1 * vv
    feasible = (a2 >= 0) & (b2 >= 0)
    return np.maximum(np.minimum(np.where(feasible, both, np.inf), np.minimum(only_a, only_b)), 0.0)


def _hinge_onset(t, dev, lo: int, last_rest: int, hi: int, noise: float = 0.0) -> float:
    """Onset t0 by fitting dev = a·u + b·u², u = max(t − t0, 0), a, b ≥ 0, over samples lo..hi.

    Rest before t0; after it, growth from zero at a rate that does not fall (the
    pressure keeps rising): linear when the static friction exceeds the kinetic
    one, quadratic when they are equal.  t0 is searched on a grid between
    sample ``lo`` and the first moving sample, then refined twice on finer grids
    around the best point (resolution 1/128 000 of that span).

    The linear hinge (b = 0) is fitted first; the quadratic term is taken only
    where it lowers the cost significantly (by more than a χ²₁ of p = 0.001 in
    units of the noise variance: ``noise``, the fit's own residual or 1e-4 of
    the largest deviation, whichever is largest) and three growth samples or
    more determine it.  With few growth samples the full model is not determined: two
    samples after the onset are fitted exactly by a line from any of a range of
    t0 with a matching b, and the grid would pick one of those at random.
    """
    tt, yy = t[lo:hi + 1], dev[lo:hi + 1]
    a, b = t[lo], t[last_rest + 1]

    def search(quadratic: bool):
        grid = np.linspace(a, b, 81)
        costs = _hinge_costs(tt, yy, grid, quadratic)
        k = int(np.argmin(costs))
        best, cost = float(grid[k]), float(costs[k])
        step = (b - a) / 80
        for _ in range(2):
            grid = np.linspace(max(best - step, a), min(best + step, b), 81)
            costs = _hinge_costs(tt, yy, grid, quadratic)
            k = int(np.argmin(costs))
            best, cost = float(grid[k]), float(costs[k])
            step = (grid[-1] - grid[0]) / 80
        return best, cost

    t_lin, c_lin = search(False)
    dof = tt.size - 3
    if dof < 1 or hi - last_rest < 3:  # b needs a third growth sample to be determined at all
        return t_lin
    t_quad, c_quad = search(True)
    # (the floor: the grid's own resolution and rounding leave a relative misfit of about 1e-5)
    var = max(noise * noise, c_quad / dof, (1e-4 * float(np.max(np.abs(yy)))) ** 2, 1e-300)
    return t_quad if c_lin - c_quad > 10.83 * var else t_lin


def _angle_onset(t, theta, dev, direction: float, last_rest: int, limit) -> tuple | None:
    """Onset from the angle turned by the first moving samples, where the speed alone cannot place it.

    The angle is the integral of the speed, so it carries the time since the
    onset that one speed sample does not.  The speed grows linearly from t0
    (static friction above kinetic: the acceleration jumps at breakaway), ω = a·u,
    u = t − t0, up to a speed limit W (``limit`` = (threshold, W): a sample at or
    above the threshold has met the limit W; None: none did), so
    θ − θ_rest = a u²/2 until u_s = W/a, W (u − u_s/2) after.

    - first moving sample below the limit (ω₁): with a = ω₁/u₁, the angles of that
      sample and, where it met the limit, of the next one are fitted for u₁
      (least squares on a fine grid; one angle alone gives u₁ = 2 Δθ₁/ω₁);
    - first moving sample on the limit: Δθ₁ = W (u₁ − u_s/2) with 0 < u_s ≤ u₁,
      so u₁ lies between Δθ₁/W and 2 Δθ₁/W, and the middle of that interval is taken.

    u₁ is kept within the interval between the last rest sample and the first
    moving one.  Returns (t₀, a, limited) — a = ω₁/u₁ where the first moving
    sample is below the limit (NaN on it), limited as :class:`Breakaway` has it —
    or None where the angle gives nothing (no readings, no movement).
    """
    if theta is None:
        return None
    grow = last_rest + 1
    t_lr, t1 = float(t[last_rest]), float(t[grow])
    span = t1 - t_lr
    level = _rest_angle(theta, last_rest)
    if level is None or not math.isfinite(theta[grow]) or not span > 0.0:
        return None
    turned = lambda k: direction * math.remainder(float(theta[k]) - level, 2 * math.pi)  # noqa: E731
    w1 = float(dev[grow])
    if not w1 > 0.0:
        return None
    threshold, limit = (math.inf, math.inf) if limit is None else limit
    if w1 >= threshold:  # already on the limit at the first moving sample
        d1 = turned(grow)
        if not d1 > 0.0:
            return None
        lo, hi = min(d1 / limit, span), min(2.0 * d1 / limit, span)
        return t1 - 0.5 * (lo + hi), math.nan, (t1, d1 / limit, span, limit)
    use = [grow]
    if grow + 1 < t.size and dev[grow + 1] >= threshold and math.isfinite(theta[grow + 1]):
        use.append(grow + 1)
    if len(use) == 1:
        u1 = min(max(2.0 * turned(grow), 0.0) / w1, span)
        return t1 - u1, (w1 / u1 if u1 > 0 else math.nan), None
    obs = np.array([turned(k) for k in use])
    lag = np.array([float(t[k]) - t1 for k in use])
    u1 = np.linspace(0.0, span, 2001)[1:]
    for _ in range(3):  # grid, then two finer grids around the best point
        a = w1 / u1[:, None]
        u = u1[:, None] + lag[None, :]
        u_s = limit / a
        pred = np.where(u <= u_s, 0.5 * a * u * u, limit * (u - 0.5 * u_s))
        best = int(np.argmin(((pred - obs[None, :]) ** 2).sum(1)))
        step = u1[1] - u1[0]
        u1 = np.linspace(max(u1[best] - step, 1e-3 * step), min(u1[best] + step, span), 201)
    return t1 - float(u1[100]), w1 / float(u1[100]), None


def place_limited_onset(limited: tuple, acceleration: float) -> float:
    """Onset of a breakaway whose first moving sample had already met the speed limit W,
    given the acceleration a [rad/s²] with which the shaft left rest [s].

    limited = (t₁, Δθ₁/W, span, W) of :class:`Breakaway`: the shaft reached W after
    u_s = W/a and had turned Δθ₁ = W (u₁ − u_s/2) by t₁, so t₀ = t₁ − Δθ₁/W − u_s/2.
    u_s is kept where the angle allows it (u_s ≤ u₁: at most 2 Δθ₁/W) and u₁
    within the interval since the last sample at rest.
    """
    t1, turned_time, span, w_limit = limited
    u_s = min(w_limit / acceleration, 2.0 * turned_time) if acceleration > 0 else turned_time
    return t1 - min(turned_time + 0.5 * u_s, span)


ANGLE_STEP = math.radians(0.01)  # shaft-angle reading step assumed where the readings do not show one [rad]


def _rest_angle(theta, last_rest: int) -> float | None:
    """Shaft angle at rest [rad]: the circular median of the last ten readings up to
    ``last_rest`` about the last of them; None where none was read."""
    rest = np.arange(max(0, last_rest - 9), last_rest + 1)
    rest = rest[np.isfinite(theta[rest])]
    if rest.size == 0:
        return None
    ref = float(theta[rest[-1]])
    return ref + float(np.median(np.remainder(theta[rest] - ref + np.pi, 2 * np.pi) - np.pi))


def _turned_since_rest(theta, direction: float, last_rest: int, idx) -> tuple | None:
    """Angle the shaft turned in the direction of motion since rest, at samples ``idx``
    after ``last_rest`` [rad] (rest: the median of the last ten readings at rest), and the
    angle's reading step [rad] → (turned, step); None where the readings give nothing."""
    if theta is None:
        return None
    idx = np.atleast_1d(np.asarray(idx, dtype=int))
    level = _rest_angle(theta, last_rest)
    if level is None or idx.size == 0 or not np.all(np.isfinite(theta[idx])):
        return None
    turned = direction * (np.unwrap(np.r_[level, theta[idx]])[1:] - level)
    # the reading step: at most the smallest gap between the distinct angles read in the run,
    # and taken as 0.01° (an encoder's or resolver's) where the readings do not show one
    gaps = np.diff(np.unique(np.mod(theta[np.isfinite(theta)], 2 * np.pi)))
    step = min(float(gaps.min()) if gaps.size else math.inf, ANGLE_STEP)
    return turned, step


def _angle_agrees(t, theta, dev, direction: float, last_rest: int, onset: float) -> bool:
    """Does an onset agree with the angle the first moving sample had turned?

    A speed that rose from 0 at t₀ to ω₁ at t₁ as u^p (p = 0: a jump, 1: linear, 2:
    quadratic) turned the shaft Δθ₁ = ω₁ u₁/(1 + p), u₁ = t₁ − t₀; growth between a
    jump and a quadratic puts u₁ between Δθ₁/ω₁ and 3 Δθ₁/ω₁ (a fifth and three
    reading steps of slack; the step is taken no larger than Δθ₁).  True where the
    angle cannot tell."""
    grow = last_rest + 1
    got = _turned_since_rest(theta, direction, last_rest, grow)
    w1 = float(dev[grow])
    if got is None or not w1 > 0:
        return True
    (d1,), step = got
    if not d1 > 0:
        return True
    step = min(step, d1)  # a nonzero reading has turned at least one step
    u1 = float(t[grow]) - onset
    return 0.8 * (d1 - 3 * step) / w1 <= u1 <= 1.2 * (3.0 * d1 + 3 * step) / w1


def _lag_onset(t, dev, theta, direction: float, last_rest: int, stop: int, noise: float) -> float | None:
    """Onset from the first moving samples' speed and angle, with a growth of any speed of response.

    After breakaway the shaft's speed follows a first-order lag and goes on rising
    with the load, ω = V (1 − e^(−u/τ)) + r u, u = t − t₀ (a load with damping; V = 0
    is the linear growth of an undamped one, small τ a jump), and the angle its
    integral, θ − θ_rest = V (u − τ (1 − e^(−u/τ))) + r u²/2.  The speed and angle of
    up to three moving samples (before ``stop``) are fitted for t₀ (between the last
    sample at rest and the first moving one), τ (a log grid) and V, r ≥ 0 (least
    squares), the speed weighted by its rest noise, the angle by its reading step.
    None where the angle gives nothing.
    """
    grow = last_rest + 1
    use = np.arange(grow, min(grow + 3, stop + 1, t.size))
    got = _turned_since_rest(theta, direction, last_rest, use) if use.size >= 2 else None
    if got is None:
        return None
    turned, step = got
    if not (turned[0] > 0 and np.all(np.diff(np.r_[0.0, turned]) < np.pi)):
        return None
    s_theta = max(min(step, turned[0]) / math.sqrt(12.0), 1e-9)
    s_speed = max(noise, 1e-12)
    t_lr, t1 = float(t[last_rest]), float(t[grow])
    t0 = np.linspace(t_lr, t1, 402)[:-1]
    u = np.maximum(t[use][None, :] - t0[:, None], 0.0)  # (t0, samples)
    span = t1 - t_lr
    y = np.r_[dev[use] / s_speed, turned / s_theta]
    ramp = np.concatenate([u / s_speed, 0.5 * u * u / s_theta], axis=1)  # a speed rising on with the load
    best, cost = None, math.inf
    for tau in span * np.logspace(-3.0, 3.0, 61):
        f = -np.expm1(-u / tau)
        lag = np.concatenate([f / s_speed, (u - tau * f) / s_theta], axis=1)  # (t0, 2 K)
        # least squares in (V, r) for every t0 at once: 2 × 2 normal equations
        a11, a12, a22 = (lag * lag).sum(1), (lag * ramp).sum(1), (ramp * ramp).sum(1)
        b1, b2 = lag @ y, ramp @ y
        det = a11 * a22 - a12 * a12
        with np.errstate(divide="ignore", invalid="ignore"):
            V = np.where(det > 0, (a22 * b1 - a12 * b2) / det, -1.0)
            r = np.where(det > 0, (a11 * b2 - a12 * b1) / det, -1.0)
            # V, r ≥ 0: where the pair is not, the better of each alone (the problem is convex)
            V_only, r_only = np.maximum(b1 / a11, 0.0), np.maximum(b2 / a22, 0.0)
        both = (V >= 0) & (r >= 0)
        c_both = ((y[None, :] - V[:, None] * lag - r[:, None] * ramp) ** 2).sum(1)
        c_V = ((y[None, :] - V_only[:, None] * lag) ** 2).sum(1)
        c_r = ((y[None, :] - r_only[:, None] * ramp) ** 2).sum(1)
        c = np.where(both, c_both, np.minimum(c_V, c_r))
        c = np.where(np.isfinite(c), c, np.inf)
        k = int(np.argmin(c))
        if c[k] < cost:
            best, cost = float(t0[k]), float(c[k])
    return best


def find_breakaway(time, speed, rest_speed: float = 2e-3, theta=None) -> Breakaway:
    """Find the instant a startability run's speed leaves rest.

    time [s], speed [rad/s] of one run (NaN speeds are skipped).  The rest level
    and noise come from the early stuck phase (robust median/MAD, then a robust
    line over the whole stuck phase, so slight creep is absorbed); the first
    departure sustained over three samples by more than max(10 σ, rest_speed)
    marks motion; walking back gives the last sample within 3 σ of rest, and the
    onset is refined by fitting the initial growth of speed, zero before t0 and
    a(t − t0) + b(t − t0)² after, over the rest samples and the first growth
    samples (b only where the samples ask for it, :func:`_hinge_onset`).  Samples
    that may have met a speed limit (within 2 % or 5 σ of the sustained peak, as a
    dynamometer's limiter holds it) are left out of that fit.  Where fewer than two
    growth samples remain (fast breakaway at a low sample rate), ``theta`` (shaft
    angle [rad], optional) places the onset by the angle turned by the first moving
    sample (:func:`_angle_onset`); without it the onset is the middle between the
    last sample at rest and the first moving one.  Where that first moving sample
    had already met the limit, the onset also depends on how long the shaft took
    to reach it: the result's ``limited`` keeps what :func:`place_limited_onset`
    needs once the acceleration is known (:func:`extract` takes it from the
    campaign's other events).  Raises :class:`NoBreakaway` with the reason when
    there is none.
    """
    t_all = np.asarray(time, dtype=float)
    w_all = np.asarray(speed, dtype=float)
    ok = np.flatnonzero(np.isfinite(t_all) & np.isfinite(w_all))
    t, w = t_all[ok], w_all[ok]
    n = t.size
    if n < 8:
        raise NoBreakaway(f"only {n} samples with a speed reading")
    floor = 1e-12 * (1.0 + np.abs(w).max())
    stuck_end, line, last = min(max(20, n // 10), n // 2), False, None
    for _ in range(5):
        base, noise = _rest_level(t[:stuck_end], w[:stuck_end], line, floor)
        r = w - base(t)
        moving = max(10.0 * noise, rest_speed)
        up, down = _sustained(r, 3), _sustained(-r, 3)
        if max(up.max(), down.max()) < moving:
            raise NoBreakaway(f"speed never left rest (largest sustained departure "
                              f"{max(up.max(), down.max()):.3g} rad/s, rest noise {noise:.3g} rad/s)")
        first = [int(np.argmax(x >= moving)) if x.max() >= moving else n for x in (up, down)]
        direction = 1.0 if first[0] <= first[1] else -1.0  # the first sustained departure
        lasting = up if direction > 0 else down
        dev = direction * r
        first_moving = min(first)
        # (one-sided: a reading against the direction of motion is noise, not motion)
        at_rest = np.flatnonzero(dev[:first_moving + 1] <= max(3.0 * noise, 0.1 * moving))
        if first_moving < 3 or at_rest.size == 0:
            raise NoBreakaway("the shaft is already turning at the start of the run")
        last_rest = int(at_rest[-1])
        if last_rest == last:
            break
        last = last_rest
        stuck_end = max(8, int(0.9 * (last_rest + 1)))
        line = stuck_end >= 20
    # the initial growth: up to 30 σ (at least 6 samples), never past half the peak
    peak = lasting.max()
    grow = last_rest + 1
    high = np.flatnonzero(dev[grow:] >= max(30.0 * noise, moving))
    end = max(grow + int(high[0]) if high.size else n - 1, grow + 5)
    half = np.flatnonzero(dev[grow:] >= 0.5 * peak)
    if half.size:
        end = min(end, grow + int(half[0]))
    end = min(end, grow + 20000, n - 1)
    # a speed limit clips the growth: samples near the sustained peak may have met it
    limit = peak - max(0.02 * abs(peak), 5.0 * noise)
    limited = np.flatnonzero(dev[grow:] >= limit)
    limit = (float(limit), float(np.median(dev[grow + limited]))) if limited.size else None
    if limited.size:
        end = min(end, grow + int(limited[0]) - 1)
    onset, accel, on_limit = None, math.nan, None
    th = None if theta is None else np.asarray(theta, dtype=float)[ok]
    if end - last_rest >= 2:
        lo = max(0, last_rest + 1 - max(5, end - last_rest))
        onset = _hinge_onset(t, _median3(dev), lo, last_rest, end, noise)
        u = t[grow:end + 1] - onset  # the growth rate: a line from the onset through the growth samples
        accel = float(u @ dev[grow:end + 1] / (u @ u)) if np.all(u > 0) else math.nan
        # a line through a concave growth (a damped load near its speed within a sample or
        # two) reaches back too far: past a sample that still read rest (the line would have
        # it moving by six rest deviations), or past what the angle turned allows.  Then the
        # speed and angle of the first moving samples, with a lag of any time constant
        at_last_rest = accel * max(float(t[last_rest]) - onset, 0.0) if math.isfinite(accel) else 0.0
        past_rest = at_last_rest > 6.0 * noise + (dev[last_rest] if dev[last_rest] > 0 else 0.0)
        if past_rest or not _angle_agrees(t, th, dev, direction, last_rest, onset):
            lagged = _lag_onset(t, dev, th, direction, last_rest, end, noise)
            if lagged is not None:
                onset, accel = lagged, math.nan
            elif past_rest:
                onset, accel = None, math.nan
    elif grow < n:  # fewer than two growth samples: the angle turned by the first moving one
        placed = _angle_onset(t, th, dev, direction, last_rest, limit)
        if placed is not None:
            onset, accel, on_limit = placed
            if on_limit is None and onset <= t[last_rest]:
                # a linear growth would need more time than the interval had: the speed rose
                # faster (a damped load near its speed at once); the lag model over the moving
                # samples that met no limit
                free_end = grow + int(limited[0]) - 1 if limited.size else n - 1
                lagged = _lag_onset(t, dev, th, direction, last_rest, free_end, noise)
                if lagged is not None:
                    onset, accel = lagged, math.nan
    if onset is None:  # the onset lies between the last sample at rest and the first moving one
        onset = 0.5 * float(t[last_rest] + t[min(grow, n - 1)])
    return Breakaway(onset, direction, int(ok[last_rest]), float(base(np.array([onset]))[0]), noise,
                     accel, on_limit)


ONSET_WINDOWS = (3, 4, 6, 8, 12, 16, 24, 32, 50)  # readings a line at the onset may go through


def value_at_onset(time, values, onset_time: float, count: int) -> float:
    """A slowly ramped channel at the onset: a line through its last readings before
    the onset, evaluated there [unit of values].

    How many readings (3 … ``count``): those whose line best predicts the reading
    that follows, over the last ten readings before the onset (one step ahead, as
    the onset is at most a step beyond the last reading).  A long line averages the
    sensor's noise; a short one follows a supply ripple that a long one would
    average out (the shaft breaks away where the ripple pushes the pressure up, so
    that averaging reads it low) and stays clear of the hold before the ramp.  The
    line of the chosen length is fitted robustly (readings beyond 3.5 deviations
    left out)."""
    t = np.asarray(time, dtype=float)
    x = np.asarray(values, dtype=float)
    sel = np.flatnonzero((t < onset_time) & np.isfinite(x))[-count:]
    if sel.size == 0:
        return math.nan
    if sel.size < 4:
        return float(x[sel[-1]])
    before = np.flatnonzero((t < onset_time) & np.isfinite(x))
    tests = 40
    keep = before[-(count + tests):]
    c, xx = t[keep] - t[keep[-1]], x[keep]
    # sliding sums for every window at once: a line through readings j−m … j−1, at reading j
    cum = [np.r_[0.0, np.cumsum(v)] for v in (np.ones_like(c), c, c * c, xx, c * xx)]
    best, best_err = min(count, sel.size), math.inf
    for m in [k for k in ONSET_WINDOWS if k < count] + [count]:
        j = np.arange(max(m, keep.size - tests), keep.size)
        if keep.size < m + 3 or j.size == 0:
            break
        n0, s1, s2, sx, scx = (v[j] - v[j - m] for v in cum)
        det = n0 * s2 - s1 * s1
        with np.errstate(invalid="ignore", divide="ignore"):
            slope = np.where(det > 0, (n0 * scx - s1 * sx) / det, 0.0)
        pred = (sx - slope * s1) / n0 + slope * c[j]
        err = float(np.mean((xx[j] - pred) ** 2))
        if err < best_err:
            best, best_err = m, err
    sel = sel[-best:]
    if sel.size < 4:
        u = t[sel] - onset_time
        return float(np.polyval(np.polyfit(u, x[sel], 1), 0.0)) if sel.size >= 2 and np.ptp(u) > 0 else float(x[sel[-1]])
    coef, _ = _robust_poly(t[sel] - onset_time, x[sel], 1)
    return float(np.polyval(coef, 0.0))


# ----------------------------------------------------------------- the extraction


def _check_frame(frame: pd.DataFrame) -> None:
    missing = [c for c in SI_COLUMNS if c not in frame.columns]
    if missing:
        raise InputError(f"log frame: missing column(s) {', '.join(missing)} (read logs with motorid.logs.read_logs)")


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


def _median(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.nanmedian(x)) if np.isfinite(x).any() else math.nan


def _running_run(key, cols, settings, excluded, notes):
    """Steady samples of one running run → (their positions in the run or None, direction, why not)."""
    n = cols["time_s"].size
    if n < settings.min_samples:
        excluded[SHORT_RUN] = excluded.get(SHORT_RUN, 0) + 1
        notes.append(f"run {key}: only {n} samples (at least {settings.min_samples} needed)")
        return None, 0.0, "too few samples"
    valid = np.all([np.isfinite(cols[c]) for c in _INPUTS], axis=0)
    excluded[MISSING_INPUT] = excluded.get(MISSING_INPUT, 0) + int((~valid).sum())
    speed = cols["speed_rad_s"]
    median_speed = _median(speed[valid])
    if not valid.any() or not abs(median_speed) >= settings.rest_speed:
        excluded[NO_STEADY_SPEED] = excluded.get(NO_STEADY_SPEED, 0) + int(valid.sum())
        notes.append(f"run {key}: no steady speed (median {median_speed:.3g} rad/s, "
                     f"below {settings.rest_speed:g} rad/s)")
        return None, 0.0, "no steady speed"
    direction = float(np.sign(median_speed))
    # a spike in an input reading: the sample is left out (and bridged in the speed's derivative)
    spikes = np.zeros(n, bool)
    for c in ("speed_rad_s", "p_a_Pa", "p_b_Pa", "p_case_Pa", "viscosity_Pa_s"):
        hit = input_spikes(cols[c]) & valid
        if hit.any():
            cols[c] = np.where(hit, np.nan, cols[c])
            spikes |= hit
    if spikes.any():
        excluded[INPUT_SPIKE] = excluded.get(INPUT_SPIKE, 0) + int(spikes.sum())
        valid &= ~spikes
    speed = cols["speed_rad_s"]
    p_a, p_b = cols["p_a_Pa"], cols["p_b_Pa"]
    idx = np.flatnonzero(valid)
    smoothed: dict = {}
    steady, transient = steady_state_mask(speed[idx], (p_a - p_b)[idx], (p_a + p_b)[idx], settings, smoothed)
    smooth = smoothed["speed"]  # the speed's moving median (valid samples have a finite speed)
    stopped = direction * smooth < min(settings.rest_speed, 0.5 * abs(median_speed))
    excluded[START_TRANSIENT] = excluded.get(START_TRANSIENT, 0) + int(transient.sum())
    excluded[NO_STEADY_SPEED] = excluded.get(NO_STEADY_SPEED, 0) + int((stopped & ~transient).sum())
    excluded[UNSTEADY] = excluded.get(UNSTEADY, 0) + int((~steady & ~transient & ~stopped).sum())
    steady &= ~stopped
    if steady.sum() < settings.min_steady:
        excluded[FEW_STEADY] = excluded.get(FEW_STEADY, 0) + 1
        notes.append(f"run {key}: only {int(steady.sum())} steady samples of {n}")
        return None, direction, "too few steady samples"
    return idx[steady], direction, ""


def _event_at(t, cols, onset: float, direction: float) -> dict:
    """A breakaway event of a startability run with its onset placed at ``onset`` [s]:
    the port and case pressures there (a line through the readings before it), the
    shaft angle, viscosity and temperature of the late stuck phase, and the held
    load torque (median over the last half of the stuck phase)."""
    stuck = np.flatnonzero(t < onset)
    count = int(np.clip(stuck.size // 4, 8, 50))
    window = stuck[-count:]
    event = {"onset": onset, "direction": direction}
    for c in ("p_a_Pa", "p_b_Pa", "p_case_Pa"):
        event[c] = value_at_onset(t, cols[c], onset, count)
    theta = cols["theta_rad"][window]
    theta = theta[np.isfinite(theta)]
    event["theta_rad"] = _circular_mean(theta) if theta.size else math.nan
    event["viscosity_Pa_s"] = _median(cols["viscosity_Pa_s"][window])
    event["oil_temp_C"] = _median(cols["oil_temp_C"][window])
    torque = cols["torque_Nm"]
    late = stuck[t[stuck] >= t[0] + 0.5 * (onset - t[0])]
    if np.isfinite(torque[late]).sum() < 3:
        late = stuck
    event["held"] = _median(torque[late])
    return event


def _place_limited_onsets(events: list, pending: list) -> int:
    """Onsets of the breakaways whose first moving sample had already met a speed limit → how many were placed.

    Such an onset depends on the time u_s the shaft took to reach the limit, which
    no sample saw (:func:`place_limited_onset`); the middle of what the angle allows
    is late by up to a quarter sample where u_s is short.  Just after breakaway the
    shaft accelerates at (static − kinetic friction)/(J_motor + J_load) =
    (D (P_A + P_B) K_FS + T_Fc K_s)/J: a line in P_A + P_B (MODEL.md).  The events
    whose growth the samples did show give |a| (:attr:`Breakaway.acceleration`);
    a robust line of |a| against P_A + P_B over them (a constant where they are
    fewer than five or at one pressure) gives each limited event its a, hence its
    u_s = W/a and onset.  Fewer than three such events: the middles are kept.
    ``pending``: (event, columns of its run) of the limited events, updated in place.
    """
    if not pending:
        return 0
    psum = np.array([e["p_a_Pa"] + e["p_b_Pa"] for e in events], dtype=float)
    accel = np.abs(np.array([e["acceleration"] for e in events], dtype=float))
    have = np.isfinite(psum) & np.isfinite(accel) & (accel > 0)
    if have.sum() < 3:
        return 0
    x, y = psum[have], accel[have]
    centre = float(np.median(x))
    x = x - centre
    if have.sum() >= 5 and np.ptp(x) > 0.1 * max(abs(centre), 1.0):
        # Theil-Sen (median of the pairwise slopes: the events sit at a few loads, so a
        # first cut on |a| alone would drop whole loads), then least squares on the events
        # within 3.5 robust deviations of it
        i, j = np.triu_indices(x.size, 1)
        apart = x[j] != x[i]
        slope = float(np.median((y[j] - y[i])[apart] / (x[j] - x[i])[apart]))
        coef = np.array([slope, float(np.median(y - slope * x))])
        r = y - np.polyval(coef, x)
        keep = np.abs(r - np.median(r)) <= max(3.5 * _MAD * np.median(np.abs(r - np.median(r))), 1e-300)
        if keep.sum() >= 3 and np.ptp(x[keep]) > 0:
            coef = np.polyfit(x[keep], y[keep], 1)
    else:
        coef, _ = _robust_poly(x, y, 0)
    placed = 0
    for event, cols in pending:
        b = event["breakaway"]
        a = float(np.polyval(coef, event["p_a_Pa"] + event["p_b_Pa"] - centre))
        if not (math.isfinite(a) and a > 0):
            continue
        onset = place_limited_onset(b.limited, a)
        event.update(_event_at(cols["time_s"], cols, onset, b.direction))
        placed += 1
    return placed


def _startability_run(key, cols, settings, excluded, notes):
    """Breakaway event of one startability run → (dict of the event or None, why not)."""
    t = cols["time_s"]
    if t.size < settings.min_samples:
        excluded[SHORT_RUN] = excluded.get(SHORT_RUN, 0) + 1
        notes.append(f"run {key}: only {t.size} samples (at least {settings.min_samples} needed)")
        return None, "too few samples"

    def turned(before: float) -> float:  # how far the shaft angle moved before a time [rad]
        theta = cols["theta_rad"][t < before]
        theta = np.unwrap(theta[np.isfinite(theta)])
        return float(np.ptp(theta)) if theta.size else 0.0

    try:
        try:
            b = find_breakaway(t, cols["speed_rad_s"], settings.rest_speed, cols["theta_rad"])
        except NoBreakaway:
            if turned(t[-1] + 1.0) <= settings.stuck_turn:
                raise
            b = None
        if b is None or turned(b.onset_time) > settings.stuck_turn:
            end = t[-1] + 1.0 if b is None else b.onset_time
            raise NoBreakaway(f"the shaft is already turning at the start of the run (the shaft angle moved "
                              f"{turned(end):.3g} rad while the speed seemed at rest)")
    except NoBreakaway as exc:
        excluded[NO_BREAKAWAY] = excluded.get(NO_BREAKAWAY, 0) + 1
        notes.append(f"run {key}: no breakaway found, {exc}")
        return None, "no breakaway found"
    event = _event_at(t, cols, b.onset_time, b.direction)
    event["acceleration"], event["breakaway"] = b.acceleration, b
    if not math.isfinite(event["held"]):
        excluded[NO_HELD_TORQUE] = excluded.get(NO_HELD_TORQUE, 0) + 1
        notes.append(f"run {key}: breakaway at t = {b.onset_time:.4g} s but no torque reading while stuck")
    dp = event["p_a_Pa"] - event["p_b_Pa"]
    if math.isfinite(dp) and dp * b.direction < 0:
        notes.append(f"run {key}: the shaft broke away against P_A − P_B ({dp:.4g} Pa)")
    missing = [c for c in ("theta_rad", "p_a_Pa", "p_b_Pa", "p_case_Pa", "viscosity_Pa_s")
               if not math.isfinite(event[c])]
    if missing:
        excluded[NO_BREAKAWAY] = excluded.get(NO_BREAKAWAY, 0) + 1
        notes.append(f"run {key}: breakaway at t = {b.onset_time:.4g} s but no reading of "
                     f"{', '.join(missing)} before it")
        return None, "no input readings at the breakaway"
    return event, ""


def extract(frame: pd.DataFrame, spec: MotorSpec, settings: ExtractSettings | None = None) -> Dataset:
    """Steady-state running samples and breakaway events of a campaign.

    frame : canonical SI frame of :func:`motorid.logs.read_logs` (its ``run``
        column, else ``run_id``, names the runs); spec : the motor (pistons for
        S(θ)); settings : tolerances, :class:`ExtractSettings` by default.
    """
    settings = settings or ExtractSettings()
    _check_frame(frame)
    _check_spec(spec)
    # text columns by their codes (categoricals from read_logs, or plain text): no string per row
    codes, uniques = pd.factorize(frame["run"] if "run" in frame.columns else frame["run_id"])
    uniques = [str(u) for u in uniques]
    order = np.lexsort((frame["time_s"].to_numpy(dtype=float), codes))
    bounds = np.searchsorted(codes[order], np.arange(len(uniques) + 1))
    numeric = {c: frame[c].to_numpy(dtype=float) for c in FRAME_NUMERIC}
    protocol_codes, protocol_names = pd.factorize(frame["protocol"])
    file_codes, file_names = (pd.factorize(frame["file"]) if "file" in frame.columns
                              else (np.zeros(len(frame), int), [""]))
    all_temp = _median(numeric["oil_temp_C"])

    excluded: dict = {}
    notes: list = []
    rows, picks, accel, run_of_sample, directions, events = [], [], [], [], [], []
    visc, pending = [], []
    n_runs = len(uniques)
    visc_center, visc_half = np.zeros(n_runs), np.ones(n_runs)
    visc_factor = np.zeros((n_runs, VISCOSITY_MODES, VISCOSITY_MODES))
    for r, key in enumerate(uniques):
        pos = order[bounds[r]:bounds[r + 1]]
        cols = {c: v[pos] for c, v in numeric.items()}
        protocol = str(protocol_names[protocol_codes[pos[0]]])
        row = {"run": key, "protocol": protocol, "file": str(file_names[file_codes[pos[0]]]), "n_samples": pos.size, "n_steady": 0,
               "direction": 0.0, "onset_time_s": math.nan, "excluded": "", "viscosity_degree": -1,
               "viscosity_noise_Pa_s": math.nan}
        used = np.arange(pos.size)
        if protocol == STARTABILITY:
            event, why = _startability_run(key, cols, settings, excluded, notes)
            row["excluded"] = why
            if event is not None:
                event["run"], event["run_index"] = key, r
                events.append(event)
                row.update(direction=event["direction"])
                if event["breakaway"].limited is not None:
                    pending.append((event, cols))
        elif protocol in RUNNING_PROTOCOLS:
            chosen, direction, why = _running_run(key, cols, settings, excluded, notes)
            row.update(direction=direction, excluded=why)
            if chosen is not None:
                used = chosen
                steady = np.zeros(pos.size, bool)
                steady[chosen] = True
                acc = running_acceleration(cols["time_s"], cols["speed_rad_s"], cols["theta_rad"], steady,
                                           settings.accel_window, settings.shaft_orders)
                cycles = aliased_cycles(cols["time_s"][chosen], cols["speed_rad_s"][chosen], settings.shaft_orders)
                in_step = [k for k, c in cycles.items() if c < 1.0]
                if in_step and np.ptp(cols["time_s"][chosen]) * abs(_median(cols["speed_rad_s"][chosen])) > 4 * np.pi:
                    notes.append(f"run {key}: sampled in step with shaft order {', '.join(map(str, in_step))} "
                                 f"(it folds to under one cycle over the run): a speed ripple locked to the "
                                 f"shaft at that order would read as a constant, and its acceleration would "
                                 f"bias this run's torque; a sample rate not in step with the speed avoids it")
                picks.append(pos[chosen])
                accel.append(acc[chosen])
                mu = cols["viscosity_Pa_s"][chosen]
                if settings.smooth_viscosity:
                    mu, degree, noise, factor, visc_center[r], visc_half[r] = smooth_viscosity(
                        cols["time_s"][chosen], mu, settings.viscosity_max_degree)
                    visc_factor[r] = factor
                    row.update(viscosity_degree=degree, viscosity_noise_Pa_s=noise)
                visc.append(mu)
                run_of_sample.append(np.full(chosen.size, r))
                directions.append(np.full(chosen.size, direction))
                row["n_steady"] = int(chosen.size)
        else:
            raise InputError(f"run {key}: unknown protocol '{protocol}'")
        p_a, p_b = cols["p_a_Pa"][used], cols["p_b_Pa"][used]
        row.update(speed_median_rad_s=_median(cols["speed_rad_s"][used]), dp_median_Pa=_median(p_a - p_b),
                   psum_median_Pa=_median(p_a + p_b), temp_median_C=_median(cols["oil_temp_C"][used]))
        rows.append(row)

    _place_limited_onsets(events, pending)
    for e in events:
        rows[e["run_index"]]["onset_time_s"] = e["onset"]
    runs = pd.DataFrame(rows, columns=["run", "protocol", "file", "n_samples", "n_steady",
                                       "speed_median_rad_s", "dp_median_Pa", "psum_median_Pa",
                                       "temp_median_C", "direction", "onset_time_s", "excluded",
                                       "viscosity_degree", "viscosity_noise_Pa_s"])
    join = lambda parts, dtype=float: (np.concatenate(parts).astype(dtype) if parts  # noqa: E731
                                       else np.zeros(0, dtype=dtype))
    index = join(picks, int)
    run_of_sample_arr = join(run_of_sample, int)
    temperature = numeric["oil_temp_C"][index]
    run_temp = runs["temp_median_C"].to_numpy(dtype=float)[run_of_sample_arr]
    temperature = np.where(np.isfinite(temperature), temperature,
                           np.where(np.isfinite(run_temp), run_temp, all_temp if math.isfinite(all_temp) else 40.0))
    running = make_samples(spec, numeric["theta_rad"][index], numeric["speed_rad_s"][index],
                           numeric["p_a_Pa"][index], numeric["p_b_Pa"][index], numeric["p_case_Pa"][index],
                           join(visc), acceleration=join(accel),
                           direction=join(directions), temperature=temperature, time=numeric["time_s"][index])
    measured = {name: numeric[col][index] for name, col in MEASURED_CHANNELS.items()}

    ev = lambda c: np.array([e[c] for e in events], dtype=float)  # noqa: E731
    ev_temp = ev("oil_temp_C")
    event_samples = make_samples(spec, ev("theta_rad"), np.zeros(len(events)), ev("p_a_Pa"), ev("p_b_Pa"),
                                 ev("p_case_Pa"), ev("viscosity_Pa_s"), acceleration=np.zeros(len(events)),
                                 direction=ev("direction"),
                                 temperature=np.where(np.isfinite(ev_temp), ev_temp, 40.0), time=ev("onset"))
    return Dataset(
        running=running, measured=measured, run_of_sample=run_of_sample_arr, frame_index=index, runs=runs,
        events=event_samples, held_torque=ev("held"), event_runs=[e["run"] for e in events],
        run_of_event=np.array([e["run_index"] for e in events], dtype=int), onset_time=ev("onset"),
        excluded={k: v for k, v in excluded.items() if v}, notes=notes,
        viscosity_error=(ViscositySmoothing(visc_center, visc_half, visc_factor) if np.any(visc_factor) else None))

