"""The types that flow between the stages of an identification, and their vocabularies.

extract (:class:`ExtractSettings` → :class:`Dataset`, with :class:`ViscositySmoothing`
and :class:`Breakaway`) → least squares (:class:`FitOptions` → :class:`FitResult`)
→ Bayes (:class:`BayesResult`) → results.  SI units throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from motorid.model import Samples

if TYPE_CHECKING:  # pragma: no cover
    from motorid.identify.problem import Problem


RUNNING_PROTOCOLS = ("constant_speed", "constant_pressure", "constant_flow", "constant_torque")
STARTABILITY = "startability"
MEASURED_CHANNELS = {"torque": "torque_Nm", "q_a": "q_a_m3_s", "q_b": "q_b_m3_s", "q_case": "q_case_m3_s"}
INPUT_CHANNELS = ("theta_rad", "speed_rad_s", "p_a_Pa", "p_b_Pa", "p_case_Pa", "viscosity_Pa_s")

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

# the fitted channels
RUNNING_CHANNELS = ("torque", "q_a", "q_b", "q_case")
CHANNELS = RUNNING_CHANNELS + ("breakaway",)
CHANNEL_UNITS = {"torque": "N·m", "q_a": "m³/s", "q_b": "m³/s", "q_case": "m³/s", "breakaway": "N·m"}
BREAKAWAY_ONLY = ("KFS", "Ks")  # parameters only the breakaway events determine


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
    piston_order_ripple : resolve the piston order n too, where the sampling and the
        misfit test allow: the motor's own pressure-torque ripple shakes the shaft at it
        through the coupling's compliance, and J·α of that ripple is in the torque [-]
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
    piston_order_ripple: bool = True
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
    cells : None where each running row is one sample; for a campaign reduced as it
        was read (:func:`motorid.identify.extract.extract_cells`) each running row is
        one shaft-angle cell of one run (its inputs the cell means, viscosity their
        harmonic mean, its measured channels the means of their inliers) and
        :class:`CellStatistics` holds its counts, scatter and the noise levels
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
    cells: "CellStatistics | None" = None

    @property
    def n_running(self) -> int:
        return int(np.asarray(self.running.theta).shape[0])

    @property
    def n_events(self) -> int:
        return len(self.event_runs)


VISCOSITY_MODES = 6  # columns of ViscositySmoothing.factor: degree 5 at most


@dataclass
class CellStatistics:
    """Sufficient statistics of the running rows of a :class:`Dataset` reduced to cells.

    n : steady samples in each row (cell) [-]; counts : channel → the inlier samples
    of that channel in the row [-] (spikes and missing readings left out); within :
    channel → Σ (x − row mean)² over those samples [SI²]; noise : channel → σ of one
    sample per run, estimated model-free when the run was reduced (within-cell scatter
    and first differences, the smaller) and held by the fit [SI]; viscosity_basis :
    (rows, VISCOSITY_MODES) the row means of the Chebyshev basis Tₖ(u) of the run's
    viscosity curve (:class:`ViscositySmoothing`) [-]; outliers : channel → samples
    left out as spikes [-]; rows : rows read [-]; viscosity_from_oil : steady samples
    whose viscosity came from the oil model, not a viscometer [-].
    """

    n: np.ndarray
    counts: dict
    within: dict
    noise: dict
    viscosity_basis: np.ndarray
    outliers: dict
    rows: int = 0
    viscosity_from_oil: int = 0


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
    covariance (:func:`motorid.identify.covariance.viscosity_covariance`).

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


@dataclass
class FitOptions:
    """Settings of the least-squares fit (what to change when a fit fails)."""

    harmonics: int | None = None  # order M of K_L(θ); default: the spec's
    outlier_sigma: float = 5.0  # reject residuals beyond this many σ
    rounds: int = 2  # noise/outlier re-estimation rounds (robust start, then settled)
    rtol: float = 1e-9
    atol: float = 1e-9
    max_steps: int = 200
    null_space_tol: float = 1e-7  # relative singular value below which a direction is unidentified
    fixed: dict = field(default_factory=dict)  # parameters held at given values
    bins_per_pitch: int = 192  # shaft-angle cells per piston pitch (data reduction)
    compress: bool = True  # exact compression where the model is quadratic in the parameters
    # hold the noise levels (channel -> σ per run; "breakaway" -> σ) and the
    # inlier masks (channel -> bool per sample) of an earlier fit: to compare
    # models on equal terms, or to hold runs out of a fit
    fixed_noise: dict | None = None
    fixed_inliers: dict | None = None
    # carry the smoothed viscosity's run-level error (Dataset.viscosity_error) into the covariance
    viscosity_error: bool = True
    # standard errors at all (a candidate screened by diagnose needs only its χ²)
    uncertainty: bool = True
    # "levenberg-marquardt": the fit; "gauss-newton" (with fixed_noise and fixed_inliers): only the
    # Gauss-Newton steps from ``initial`` that lower χ², a polish of a model fitted elsewhere
    # (diagnose's screening cells) on every sample
    solve: str = "levenberg-marquardt"
    # residuals (channel → per sample, every sample) of a fit of the same model to the same data
    # near its optimum (diagnose's last finalist, its noise held at the base fit's): the noise
    # rounds start from them, as from the first round's, so that round (its Gauss-Newton start
    # and its solve) is not redone
    start_residuals: dict | None = None


@dataclass
class FitResult:
    """What a least-squares fit found; SI units throughout."""

    names: list  # every parameter of the model (fitted or not)
    free: list  # the fitted ones
    values: dict  # name -> value (None where not identifiable)
    std: dict  # name -> standard error (None where not identifiable)
    covariance: np.ndarray  # over `free`
    correlation: np.ndarray
    identifiable: dict  # name -> bool
    reasons: dict  # name -> words, for the not identifiable ones
    noise: dict  # channel -> pooled σ [SI]
    noise_by_run: dict  # channel -> array over runs (NaN where no data)
    outliers: dict  # channel -> count of rejected samples
    used: dict  # channel -> count of residuals used
    chi2: float
    dof: int
    steps: int
    converged: bool
    warnings: list
    residuals: dict  # channel -> array (measured − model; NaN where missing), aligned with the data
    sigma: dict  # channel -> per-sample σ used in the final round
    inliers: dict  # channel -> bool mask of samples used
    params_all: dict  # every parameter incl. held ones (for predictions)
    mechanisms: tuple = ()
    problem: Problem | None = None  # the reduced problem (cells, noise, inliers) for the sampler
    # the share of `covariance` that the smoothed viscosity's run-level error carries
    # (over `free`; None where every viscosity reading was used as read)
    covariance_viscosity: np.ndarray | None = None
    # channel -> per run, the variance the same error adds to the run's mean residual [SI²]
    viscosity_run_variance: dict = field(default_factory=dict)
    # γ of the breakaway events' variance model σ_i² = σ₀²(1 + γ x_i²/median x²) (0: one level)
    breakaway_noise_shape: float = 0.0
    # the share of `covariance` added where the breakaway events scatter more than their
    # variance model says (:func:`breakaway_sandwich`; over `free`, None where nothing was added)
    covariance_breakaway: np.ndarray | None = None
    # channel -> integrated autocorrelation time of its residuals [samples], where above
    # noise.correlation_threshold and the covariance was widened by it
    noise_correlation: dict = field(default_factory=dict)
    # how the smoothed viscosity's run-level error moves each run's score of each free parameter
    # (runs × modes × free; :func:`viscosity_covariance`), None where it was not counted
    viscosity_shifts: np.ndarray | None = None
    # parameter -> the factor its standard error was widened by where its runs disagree
    # (:mod:`motorid.identify.run_scatter`; the Bayesian fit spreads its draws by the same)
    run_scatter: dict = field(default_factory=dict)

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / max(self.dof, 1)


@dataclass
class BayesResult:
    names: list
    chain: np.ndarray  # (steps, walkers, ndim) in natural units
    log_prob: np.ndarray  # (steps, walkers)
    median: dict
    ci95: dict
    std: dict
    tau: dict
    ess: dict
    converged: bool
    acceptance: float
    steps: int
    walkers: int
    burn: int
    thin: int
    seconds: float
    warnings: list
    expansion_gap: float | None = None  # largest |Δ log p| of the expansion against the full model
    breakaway_noise: str = "fixed"  # "marginalized" where σ_brk was integrated out (p(σ) ∝ 1/σ)

    def samples(self) -> np.ndarray:
        """Flat posterior draws after burn-in and thinning, (draws, ndim)."""
        return self.chain[self.burn :: self.thin].reshape(-1, len(self.names))
