"""``motorid export --format simscape``: loss tables for Simscape Fluids' Fixed-Displacement Motor (TL).

The block's tabulated-losses parameterization ("Tabulated data - volumetric
and mechanical losses") takes a volumetric loss and a mechanical (torque)
loss over breakpoint vectors of the pressure drop Δp = p_A − p_B and the shaft
speed ω = ω_R − ω_C, at one temperature.  The tables here are the motor
model's values averaged over the shaft angle θ (the block has no angle):

    torque_loss(Δp, ω) = D Δp / 2π − ⟨torque⟩_θ                      [N·m]
    volumetric_loss(Δp, ω) = sgn(Δp) · (⟨q_in⟩_θ − |swept flow into that port|)  [m³/s]

where q_in is the flow into the high-pressure port (A for Δp ≥ 0, B for
Δp < 0): the block's inlet flow is D ω/2π + volumetric loss, its shaft torque
D Δp/2π − torque loss.  Friction and viscous losses oppose motion, so the
torque loss has the sign of ω (plus its pressure part); leakage runs from the
high- to the low-pressure side, so the volumetric loss has the sign of Δp.
The block has no case drain: the motor's case-drain flow is tabulated beside
them (``case_flow``) for a user who models the drain line.

Breakpoints are refined until linear interpolation between them reproduces
the model within a tolerance; the bound written in README.txt and the .mat
is the largest error found at 3×3 interior points of every cell, times 1.5.
Within ±ω_min of zero speed the model's Coulomb friction jumps (sgn ω) and the
tables interpolate linearly through zero friction: those two cells are left
out of the bound, as the README says.
"""

from __future__ import annotations

import io
import math
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motorid.errors import InputError
from motorid.export.motor import IdentifiedMotor

BAR = 1e5
RPM = 2.0 * math.pi / 60.0
#: Gauss-Legendre nodes per piston half-pitch of the θ-average (see theta_nodes)
GAUSS_NODES = 8
#: operating points per call of the generated function (memory of its intermediates)
CHUNK = 1 << 16
SAFETY = 1.5


@dataclass
class LossTables:
    """The tables and how they were made (SI)."""

    pressure_drop: np.ndarray  # Δp = p_A − p_B breakpoints [Pa]
    speed: np.ndarray  # ω breakpoints [rad/s]
    torque_loss: np.ndarray  # [len(Δp), len(ω)] [N·m]
    volumetric_loss: np.ndarray  # [m³/s]
    case_flow: np.ndarray  # case-drain flow [m³/s]
    temperature: float  # [K]
    p_low: float  # low-side port pressure [Pa gauge]
    p_case: float  # case pressure [Pa gauge]
    speed_min: float  # |ω| below which the bound does not hold [rad/s]
    torque_error_bound: float  # [N·m]
    volumetric_error_bound: float  # [m³/s]
    case_error_bound: float  # [m³/s]
    theta_average_error: float  # bound on the θ-average's quadrature error of the torque [N·m]


def _evaluator(motor: IdentifiedMotor):
    from motorid.export.python import load_evaluator

    return load_evaluator(motor)


def theta_nodes(pistons: int):
    """Nodes θ [rad] and weights (summing to 1) of the average over one revolution.

    The port sum S(θ) has kinks where a piston crosses the valve-plate bridge,
    cos θᵢ = 0, all at θ = π/2 + jπ/n; between them the model is smooth (cosines,
    and the mechanisms' smooth functions of θ).  Gauss-Legendre quadrature of
    :data:`GAUSS_NODES` nodes on each of those 2n intervals is then exact to
    rounding for the pressure torque and swept flow (checked against the exact
    mean of S, n/π, in :func:`theta_quadrature_error`), where uniform samples
    would converge only as 1/N².
    """
    x, wts = np.polynomial.legendre.leggauss(GAUSS_NODES)
    width = np.pi / pistons
    starts = np.pi / 2 + width * np.arange(2 * pistons)
    theta = (starts[:, None] + width * (x[None, :] + 1.0) / 2.0).ravel()
    weights = np.tile(wts / 2.0, 2 * pistons) / (2 * pistons)
    return theta, weights


def theta_averaged(motor: IdentifiedMotor, evaluate, dp, w, temperature, p_low, p_case):
    """(torque_loss, volumetric_loss, case_flow) at the grid dp × w, θ-averaged [SI]."""
    dp = np.asarray(dp, dtype=np.float64)[:, None, None]
    w = np.asarray(w, dtype=np.float64)[None, :, None]
    theta, weights = theta_nodes(motor.spec.pistons)
    p_a = p_low + np.maximum(dp, 0.0)
    p_b = p_low + np.maximum(-dp, 0.0)
    rows = max(1, CHUNK // (w.size * theta.size))  # the generated code keeps its intermediates: bound their size
    parts = [evaluate(p_a[i:i + rows], p_b[i:i + rows], p_case, w, theta[None, None, :], temperature)
             for i in range(0, dp.shape[0], rows)]
    mean = {k: np.concatenate([part[k] for part in parts]) @ weights for k in parts[0]}
    D = motor.spec.displacement
    dp2, w2 = dp[..., 0], w[..., 0]
    swept = D * w2 / (2.0 * np.pi)
    torque_loss = D * dp2 / (2.0 * np.pi) - mean["torque"]
    inlet_excess = np.where(dp2 >= 0.0, mean["q_A"] - swept, -(mean["q_B"] + swept))
    return torque_loss, inlet_excess, mean["q_case"]


def _interp_error(motor, evaluate, dp, w, tables, temperature, p_low, p_case, skip_w):
    """Largest |model − bilinear interpolation| at 3×3 interior points of every cell, per table."""
    from scipy.interpolate import RegularGridInterpolator

    fr = np.array([0.25, 0.5, 0.75])
    dp_pts = (dp[:-1, None] + np.diff(dp)[:, None] * fr).ravel()
    w_cells = [(a, b) for a, b in zip(w[:-1], w[1:]) if not (skip_w and min(abs(a), abs(b)) == 0.0)]
    w_pts = np.array([a + (b - a) * f for a, b in w_cells for f in fr])
    model = theta_averaged(motor, evaluate, dp_pts, w_pts, temperature, p_low, p_case)
    grid = np.stack(np.meshgrid(dp_pts, w_pts, indexing="ij"), axis=-1)
    errs = []
    for table, exact in zip(tables, model):
        approx = RegularGridInterpolator((dp, w), table, method="linear")(grid)
        errs.append(float(np.max(np.abs(approx - exact))))
    return errs


def _refine(motor, evaluate, dp, w, temperature, p_low, p_case, rel_tol, max_points):
    """Insert midpoints where linear interpolation misses the model by more than rel_tol of the table's range."""
    for _ in range(12):
        tables = theta_averaged(motor, evaluate, dp, w, temperature, p_low, p_case)
        scales = [max(float(np.max(np.abs(t))), 1e-300) for t in tables]
        dp_mid = 0.5 * (dp[:-1] + dp[1:])
        w_mid = 0.5 * (w[:-1] + w[1:])
        at_dp = theta_averaged(motor, evaluate, dp_mid, w, temperature, p_low, p_case)
        at_w = theta_averaged(motor, evaluate, dp, w_mid, temperature, p_low, p_case)
        bad_dp = np.zeros(len(dp_mid), bool)
        bad_w = np.zeros(len(w_mid), bool)
        for t, a, b, s in zip(tables, at_dp, at_w, scales):
            bad_dp |= np.max(np.abs(a - 0.5 * (t[:-1] + t[1:])), axis=1) > rel_tol * s
            bad_w |= np.max(np.abs(b - 0.5 * (t[:, :-1] + t[:, 1:])), axis=0) > rel_tol * s
        straddle = (w[:-1] == 0.0) | (w[1:] == 0.0)  # the Coulomb jump at ω = 0: not refinable
        bad_w &= ~straddle
        if len(dp) + bad_dp.sum() > max_points:
            bad_dp[:] = False
        if len(w) + bad_w.sum() > max_points:
            bad_w[:] = False
        if not bad_dp.any() and not bad_w.any():
            break
        dp = np.sort(np.concatenate([dp, dp_mid[bad_dp]]))
        w = np.sort(np.concatenate([w, w_mid[bad_w]]))
    return dp, w


def loss_tables(motor: IdentifiedMotor, *, max_pressure: float = 350 * BAR, max_speed: float = 3000 * RPM,
                speed_min: float = 0.1 * RPM, temperature: float = 313.15, p_low: float = 0.0,
                p_case: float = 0.0, rel_tol: float = 2e-3, max_points: int = 65) -> LossTables:
    """The θ-averaged loss tables of ``motor`` (see the module docstring).

    max_pressure : largest |Δp| [Pa]; max_speed : largest |ω| [rad/s];
    speed_min : smallest nonzero |ω| breakpoint [rad/s]; temperature : oil [K];
    p_low : pressure of the low-side port [Pa gauge]; p_case : case pressure [Pa gauge];
    rel_tol : refinement tolerance, relative to each table's largest magnitude;
    max_points : most breakpoints per axis.
    """
    if not (max_pressure > 0 and max_speed > speed_min > 0):
        raise InputError("simscape tables need max pressure > 0 and max speed > min speed > 0")
    evaluate = _evaluator(motor)
    dp = np.linspace(-max_pressure, max_pressure, 9)
    half = np.geomspace(speed_min, max_speed, 9)
    w = np.concatenate([-half[::-1], [0.0], half])
    dp, w = _refine(motor, evaluate, dp, w, temperature, p_low, p_case, rel_tol, max_points)
    tables = theta_averaged(motor, evaluate, dp, w, temperature, p_low, p_case)
    errs = _interp_error(motor, evaluate, dp, w, tables, temperature, p_low, p_case, skip_w=True)
    s_error = theta_quadrature_error(motor.spec.pistons)
    return LossTables(dp, w, *tables, temperature=temperature, p_low=p_low, p_case=p_case, speed_min=speed_min,
                      torque_error_bound=SAFETY * errs[0], volumetric_error_bound=SAFETY * errs[1],
                      case_error_bound=SAFETY * errs[2],
                      theta_average_error=s_error * motor.spec.displacement * max_pressure / (2 * np.pi))


def theta_quadrature_error(pistons: int) -> float:
    """Relative error of the θ-average of the port sum S(θ) (exact mean n/π) on :func:`theta_nodes`."""
    from motorid.physics.kinematics import port_a_sum

    theta, weights = theta_nodes(pistons)
    return abs(float(np.asarray(port_a_sum(theta, pistons)) @ weights) / (pistons / np.pi) - 1.0)


def readme_text(motor: IdentifiedMotor, t: LossTables) -> str:
    spec = motor.spec
    mechs = ", ".join(m.id for m in motor.mechanisms) or "none"
    return f"""Loss tables of motor '{spec.name}' for Simscape Fluids' Fixed-Displacement Motor (TL) block
(Simscape > Fluids > Thermal Liquid > Pumps & Motors), made by motorid from {motor.source}.
Mechanisms beyond the 1992 model: {mechs}.

Block settings
  Displacement                                 {spec.displacement:.9g} m^3/rev  ({spec.displacement * 1e6:.6g} cm^3/rev)
  Leakage and friction parameterization        Tabulated data - volumetric and mechanical losses
  Pressure drop vector for losses, dp          pressure_drop_Pa        ({len(t.pressure_drop)} values, Pa)
  Shaft angular velocity vector for losses, w  shaft_speed_rad_s       ({len(t.speed)} values, rad/s)
  Volumetric loss table, q_loss(dp,w)          volumetric_loss_m3_s    ({len(t.pressure_drop)} x {len(t.speed)}, m^3/s)
  Mechanical loss table, torque_loss(dp,w)     torque_loss_Nm          ({len(t.pressure_drop)} x {len(t.speed)}, N*m)
  (rows follow dp, columns follow w; load with  S = load('simscape_losses.mat')  and enter S.pressure_drop_Pa, ...)

Conditions of the tables
  oil temperature      {t.temperature:.2f} K ({t.temperature - 273.15:.1f} degC), oil: {spec.oil.name}
  low-side port        {t.p_low / BAR:.4g} bar gauge (the high side is this plus |dp|), case {t.p_case / BAR:.4g} bar gauge
  shaft angle          values averaged over one revolution (the block has no shaft angle)

Sign conventions (the block's: dp = p_A - p_B, w = w_R - w_C, forward motor = dp > 0 and w > 0)
  torque_loss = D*dp/(2*pi) - shaft torque:  the block's shaft torque is D*dp/(2*pi) - torque_loss.
                Friction opposes motion, so torque_loss has the sign of w (positive in forward motoring).
  volumetric_loss = flow into the high-pressure port - swept flow into it, signed like dp:
                the block's inlet flow is D*w/(2*pi) + volumetric_loss; leakage runs from high to low pressure.
  case_flow_m3_s (not a block parameter): the motor's case-drain flow; the block has no case drain and
                returns the inlet flow at the outlet, so the outlet flow it computes is this much too high.

Interpolation error (linear interpolation between breakpoints, as the block does, against the model)
  torque_loss      <= {t.torque_error_bound:.3g} N*m
  volumetric_loss  <= {t.volumetric_error_bound:.3g} m^3/s
  case_flow        <= {t.case_error_bound:.3g} m^3/s
  for |w| >= {t.speed_min:.4g} rad/s: the largest error at 3 x 3 interior points of every cell, times {SAFETY}.
  Between -{t.speed_min:.4g} and +{t.speed_min:.4g} rad/s the table ramps linearly through zero Coulomb friction
  (the model's friction jumps with sgn w there); for stick-slip use the FMU, which has the breakaway torque.
  The shaft-angle average (Gauss-Legendre between the valve-plate crossings) is exact to
  {t.theta_average_error:.2g} N*m in the pressure torque.

Files: simscape_losses.mat (all arrays, SI), torque_loss.csv, volumetric_loss.csv, case_flow.csv
(first row: w in rad/s; first column: dp in Pa).

Notes
{chr(10).join("  " + n for n in motor.notes)}
"""


def _csv(dp, w, table) -> str:
    buf = io.StringIO()
    np.savetxt(buf, np.column_stack([dp, table]), delimiter=",", fmt="%.17g",
               header="dp_Pa\\w_rad_s," + ",".join(f"{x:.17g}" for x in w), comments="")
    return buf.getvalue()


def write_simscape(motor: IdentifiedMotor, out, **options) -> Path:
    """Write the folder ``out`` (README.txt, .mat, CSV) whole or not at all."""
    from scipy.io import savemat

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a folder (the simscape export writes a folder)")
    t = loss_tables(motor, **options)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        savemat(tmp / "simscape_losses.mat", {
            "pressure_drop_Pa": t.pressure_drop[None, :], "shaft_speed_rad_s": t.speed[None, :],
            "torque_loss_Nm": t.torque_loss, "volumetric_loss_m3_s": t.volumetric_loss,
            "case_flow_m3_s": t.case_flow, "temperature_K": t.temperature,
            "displacement_m3_rev": motor.spec.displacement, "low_side_pressure_Pa": t.p_low,
            "case_pressure_Pa": t.p_case, "speed_min_rad_s": t.speed_min,
            "torque_loss_error_bound_Nm": t.torque_error_bound,
            "volumetric_loss_error_bound_m3_s": t.volumetric_error_bound,
            "case_flow_error_bound_m3_s": t.case_error_bound,
        }, do_compression=True)
        (tmp / "torque_loss.csv").write_text(_csv(t.pressure_drop, t.speed, t.torque_loss))
        (tmp / "volumetric_loss.csv").write_text(_csv(t.pressure_drop, t.speed, t.volumetric_loss))
        (tmp / "case_flow.csv").write_text(_csv(t.pressure_drop, t.speed, t.case_flow))
        (tmp / "README.txt").write_text(readme_text(motor, t))
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
