"""The question the 1992 model was written for: what do the motors' friction, stick-slip
and torque ripple do to an antenna axis tracking a star?

    python examples/antenna_servo.py [--result RESULT_DIR] [--out examples/antenna_servo.png]

One axis of a large antenna (in the manner of the NASA DSN 70-m antennas, Bartos 1992)
is driven by eight identical hydraulic motors through a gear train: four drive, and four
give counter-torque so that every pinion stays loaded against its own flank (a bias
torque that takes the backlash out).  A PI speed loop closes around the motor speed and
commands the pressure difference.  The axis tracks a slow ramp, at the sidereal rate
and 10 and 100 times slower, each simulated twice: with the identified motor (the one model of
motorid: Coulomb and viscous friction, static friction at breakaway — stick-slip —,
and the kinematic torque ripple of the pistons, plus any accepted mechanism), and with
an ideal motor (torque = D·ΔP/2π, no friction, no ripple).  The plot shows the axis
tracking error of each.

Assumptions (all of them are choices of this example, not data of a real antenna):
- motor: the demo campaign's fitted motor (80 cm³/rev, 9 pistons); without --result,
  ``motorid fit`` is run on synthetic_data/demo first (about 10-20 s);
- gear ratio N = 20 000 motor revolutions per axis revolution; axis inertia
  J_axis = 5·10⁶ kg·m² (reflected to the motor shaft: J_axis/N²), plus the eight rotors;
  rigid gearing, backlash fully taken out by the bias, no gear friction, no wind or
  gravity torque;
- servo-valves are ideal pressure sources: each motor gets exactly the commanded
  ΔP (no valve dynamics, no oil compressibility, no line losses); low-side port at
  5 bar, case at 1 bar, oil at 40 °C;
- bias: drive motors at ΔP_bias + u, counter motors at −ΔP_bias + u, ΔP_bias = 40 bar;
- speed loop: u = K_p (ω_ref − ω) + K_i ∫(ω_ref − ω) dt with K_p = 6.5·10⁴ Pa·s/rad and
  K_i = 2.0·10⁶ Pa/rad (a 20 Hz loop on the total inertia); the integral of the speed
  error is the motor-angle error, so with no friction the axis tracks a ramp exactly;
- each motor's shaft angle is the common angle plus a fixed random piston phase;
- stick-slip by Karnopp's method: below |ω| < 10⁻³ rad/s the shaft stays stuck while
  the net pressure torque is within the sum of the motors' breakaway torques
  (``torque_breakaway`` of the export), and breaks away with the running friction above;
- explicit time steps of 0.2 ms.
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
ARCSEC = math.pi / 180.0 / 3600.0  # [rad]
SIDEREAL = 0.0042 * math.pi / 180.0  # axis rate [rad/s] (about 15 arcsec/s)
RATES = (SIDEREAL, SIDEREAL / 10, SIDEREAL / 100)  # the ramps tracked [rad/s at the axis]


@dataclass(frozen=True)
class Axis:
    """The axis, gearing, hydraulics and loop of the example (SI)."""

    gear_ratio: float = 20_000.0
    axis_inertia: float = 5.0e6  # [kg m²]
    motors_per_group: int = 4
    bias: float = 40e5  # ΔP_bias [Pa]
    p_low: float = 5e5  # low-side port [Pa gauge]
    p_case: float = 1e5  # [Pa gauge]
    T_oil: float = 313.15  # [K]
    kp: float = 6.5e4  # [Pa per rad/s]
    ki: float = 2.0e6  # [Pa per rad]
    stick_speed: float = 1e-3  # Karnopp band [rad/s]
    dt: float = 2e-4  # [s]
    seed: int = 1


def identified_motor(result_dir: Path | None):
    """The exported motor of a fit's folder; the demo campaign fitted first where none is given."""
    from motorid.export.source import load_identified

    if result_dir is None:
        tmp = Path(tempfile.mkdtemp(prefix="antenna-fit-"))
        logs = sorted(str(p) for p in (ROOT / "synthetic_data" / "demo").glob("*.csv.gz"))
        cmd = [sys.executable, "-m", "motorid", "fit", *logs, "--motor",
               str(ROOT / "synthetic_data" / "demo" / "motor.toml"), "--out", str(tmp)]
        print("fitting the demo campaign: motorid fit ... --out", tmp, flush=True)
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        result_dir = tmp
    return load_identified(result_dir)


def simulate(motor, axis: Axis, rate: float, seconds: float, ideal: bool) -> dict:
    """Track the ramp φ_ref = rate·t [rad at the axis] for ``seconds``.

    ideal : the motor as an ideal torque source D·ΔP/2π (no friction, ripple, stick).
    returns time [s], tracking error [arcsec at the axis], motor speed [rad/s], stuck [bool].
    """
    from motorid.export.motor import motor_outputs

    n = 2 * axis.motors_per_group
    sign = jnp.array([1.0] * axis.motors_per_group + [-1.0] * axis.motors_per_group)  # drive, counter
    phase = jnp.asarray(np.random.default_rng(axis.seed).uniform(0, 2 * np.pi, n))
    D = motor.spec.displacement
    J = axis.axis_inertia / axis.gear_ratio**2 + n * motor.spec.inertia
    w_ref = rate * axis.gear_ratio  # motor speed [rad/s]

    def motor_torques(dp, omega, theta):
        """(Σ torque, Σ breakaway torque) of the eight motors at ΔP_i, ω, θ_i."""
        if ideal:
            return jnp.sum(D * dp / (2 * jnp.pi)), 0.0
        p_a = axis.p_low + jnp.maximum(dp, 0.0)
        p_b = axis.p_low + jnp.maximum(-dp, 0.0)
        out = motor_outputs(motor, p_a, p_b, axis.p_case + 0 * dp, omega + 0 * dp, theta, axis.T_oil + 0 * dp)
        return jnp.sum(out[0]), jnp.sum(out[4])

    def step(state, t):
        angle, omega, integral = state  # motor angle error integral = ∫(ω_ref − ω)
        u = axis.kp * (w_ref - omega) + axis.ki * integral
        dp = sign * axis.bias + u
        theta = angle + phase
        t_rest, t_break = motor_torques(dp, 0.0 * omega, theta)
        t_run, _ = motor_torques(dp, omega, theta)
        near_rest = jnp.abs(omega) < axis.stick_speed
        holds = near_rest & (jnp.abs(t_rest) <= t_break)
        # breaking away: the running friction in the direction the net torque drives
        t_away, _ = motor_torques(dp, jnp.sign(t_rest) * axis.stick_speed, theta)
        torque = jnp.where(near_rest, t_away, t_run)
        omega_next = jnp.where(holds, 0.0, omega + torque / J * axis.dt)
        crossed = (~near_rest) & (omega * omega_next < 0.0)  # friction cannot reverse the motion: stop
        omega_next = jnp.where(crossed, 0.0, omega_next)
        angle_next = angle + omega_next * axis.dt
        integral_next = integral + (w_ref - omega_next) * axis.dt
        return (angle_next, omega_next, integral_next), (integral_next, omega_next, holds)

    steps = int(round(seconds / axis.dt))
    run = jax.jit(lambda: jax.lax.scan(step, (0.0, 0.0, 0.0), jnp.arange(steps) * axis.dt)[1])
    err, omega, stuck = (np.asarray(a) for a in run())
    t = (np.arange(steps) + 1) * axis.dt
    return {"time": t, "error_arcsec": err / axis.gear_ratio / ARCSEC, "speed": omega, "stuck": stuck}


def plot(runs: dict, out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rates = sorted({k[0] for k in runs}, reverse=True)
    fig, axes = plt.subplots(len(rates), 1, figsize=(8, 3.2 * len(rates)), squeeze=False)
    for ax, rate in zip(axes[:, 0], rates):
        for ideal, style, label in ((False, "C3", "identified motor (friction, stick-slip, ripple)"),
                                    (True, "C0", "ideal motor (no friction, no ripple)")):
            r = runs[(rate, ideal)]
            ax.plot(r["time"], r["error_arcsec"], style, lw=0.8, label=label)
        ax.set_title(f"ramp at {rate / SIDEREAL:.3g} × sidereal ({rate / ARCSEC:.3g} arcsec/s at the axis)")
        ax.set_ylabel("tracking error [arcsec]")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    fig.suptitle("Antenna axis: 4 drive + 4 counter-torque motors, PI speed loop", fontsize=11)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def summary(runs: dict, settle: float) -> list[str]:
    lines = []
    for (rate, ideal), r in sorted(runs.items(), key=lambda kv: (-kv[0][0], kv[0][1])):
        late = r["time"] >= settle
        rms = float(np.sqrt(np.mean(r["error_arcsec"][late] ** 2)))
        peak = float(np.max(np.abs(r["error_arcsec"][late])))
        stuck = float(np.mean(r["stuck"][late]))
        lines.append(f"{rate / SIDEREAL:6.3g}× sidereal  {'ideal     ' if ideal else 'identified'}  "
                     f"RMS error {rms:9.4g} arcsec  peak {peak:9.4g} arcsec  shaft stuck {100 * stuck:5.1f} % "
                     f"of the time (after {settle:g} s)")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--result", type=Path, help="folder of a motorid fit (default: fit the demo campaign)")
    ap.add_argument("--out", type=Path, default=ROOT / "examples" / "antenna_servo.png")
    ap.add_argument("--seconds", type=float, default=60.0, help="simulated time of each run [s]")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    motor = identified_motor(args.result)
    axis = Axis()
    runs = {(rate, ideal): simulate(motor, axis, rate, args.seconds, ideal)
            for rate in RATES for ideal in (False, True)}
    path = plot(runs, args.out)
    print("\n".join(summary(runs, settle=args.seconds / 4)))
    print(f"wrote {path} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
