"""An independent ISO 4392 bench-log generator ("another lab's bench") for motorid.

    python benchmarks/foreign_bench.py list
    python benchmarks/foreign_bench.py make SCENARIO OUTDIR [--quick]

It writes bench logs in the format of ``../shared/BENCH_LOG_FORMAT.md`` from
the physics of ``../shared/MODEL.md``, re-derived here from those pages alone:
numpy, scipy and pandas only, nothing imported from ``motorid``.  On purpose
its shapes differ from motorid's own simulator (``motorid/bench``), the way
another maker's bench would:

- motors of 7, 8, 11, 12 pistons and 10-250 cm³/rev, parameters scaled with D;
- constant-speed runs on a stiff speed-controlled dynamometer whose speed
  carries its own ripple: a few sinusoids at unrelated frequencies (one of them
  often above the logger's Nyquist frequency) and a ripple locked to the shaft
  angle (orders 1, 2, optionally 3); ω, θ and α are analytic;
- constant-pressure runs where the load is a fan-law brake T = T₀(ω/ω₀)² with
  its own inertia: the speed is *not* imposed, it spins up from 70 % and
  settles, integrated by RK4 (the motor's own torque ripple then shakes the
  shaft at order n);
- startability runs (ISO 4392-2) in three shapes: a torque-mode dynamometer
  with damping (T = T_h + c ω) and the ramp going on after breakaway; a dead
  weight on a drum (constant T_h, large inertia) with the supply valve closed
  shortly after breakaway; and a flow-fed volume (constant small supply flow
  into a compressible line), whose pressure drops as soon as the motor turns:
  stick-slip.  The start pressure is drawn anywhere inside the static band, so
  the pressure torque may start well below the held load.
- sensors: Gaussian + relative noise per channel, quantization in the written
  unit, optional small zero offsets and gain errors, isolated spikes, runs or
  cells with a sensor missing; a shaft encoder of 2¹⁴ counts/rev reporting the
  centre of its count (``encoder_floor``: the count itself, i.e. an angle
  offset of half a count); speed from a tachometer, or (option) from encoder
  counts over the sample interval;
- logs: sample rates 10 Hz … 2 kHz, time stamps that start anywhere and carry
  jitter, columns in any order, extra columns, header units of several
  flavours (bar/psi/kPa/MPa/Pa, L/min/gpm/m³/s, °C/°F/K, …), one file per run
  or many runs per file, .csv or .csv.gz, with or without ``viscosity_mPas``.

Conventions (read from MODEL.md and BENCH_LOG_FORMAT.md):

- S(θ) = Σ_{cos θᵢ>0} cos θᵢ, θᵢ = θ + 2π(i−1)/n; T_p = D ΔP S/(2n) (mean D ΔP/2π,
  D in m³ per revolution); swept flow into A: Q_A = D ω S/(2n), Q_B = −Q_A.
- running: T_L = T_p − J α − K_v D μ ω − [D (P_A+P_B) K_F + T_Fc] sgn ω, the
  torque the transducer reads (load side of the motor: motor torque less the
  motor's own J α).  Positive speed is the direction flow into port A drives,
  so for negative speed port B is the inlet (P_B > P_A, ΔP < 0, T_p < 0).
- stuck: the transducer reads the held load; the shaft breaks away in
  direction d when d (T_p − T_held) exceeds
  T_break = D (P_A+P_B)(K_F+K_FS) + T_Fc (1+K_s); after that the friction is
  the kinetic one and (J + J_load) α = T_p − T_v − T_F,kin − T_load(ω).
- K_LA(θ) = K_L0 [1 + a₁ cos nθ + b₁ sin nθ], K_LB(θ) = K_LA(θ − φ), φ = π/n
  unless the spec sets ``leak_phase_deg``; Q_LA = K_LA (P_A − P_c)/μ,
  Q_LB = K_LB (P_B − P_c)/μ, Q_AB = K_AB (P_A − P_B)/μ;
  Q_AN = Q_A + Q_LA + Q_AB, Q_BN = −Q_A + Q_LB − Q_AB, Q_CN = Q_LA + Q_LB.
- oil: kinematic viscosity by Walther / ASTM D341,
  log10 log10(ν[cSt] + 0.7) = A − B log10 T[K], through ν40 and ν100; density
  ρ(T) = ρ15 (1 − β (T − 15 °C)) with β = 6.5e-4 /K (the linear law, written to
  the spec as ``expansion_per_K``; motorid's reader uses ρ15 / (1 + β (T − 15)),
  which differs by ≈ β²(T−15)², 2.6e-4 at 40 °C, 1.1e-3 at 65 °C: where a log
  has no viscosity column, the reader's μ differs from this generator's truth by
  that much.  ``Oil(density_law="reciprocal")`` uses motorid's law).  μ = ρ ν.

Every campaign folder gets ``motor.toml`` (the spec, BENCH_LOG_FORMAT.md),
``truth.toml`` ([parameters] in SI with MODEL.md names, plus [motor] and
[generator] notes), ``manifest.json`` and the logs under ``logs/``.
"""

from __future__ import annotations

import argparse
import gzip
import io
import json
import math
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

TWO_PI = 2.0 * math.pi
KELVIN = 273.15
PSI = 6894.757293168361  # Pa
US_GALLON = 3.785411784e-3  # m³
LBF_FT = 1.3558179483314004  # N·m


# ============================================================================ physics

@dataclass(frozen=True)
class Oil:
    name: str = "ISO VG 46 mineral oil"
    nu40: float = 46.0  # cSt
    nu100: float = 6.8  # cSt
    rho15: float = 875.0  # kg/m³
    beta: float = 6.5e-4  # 1/K, thermal expansion of density
    density_law: str = "linear"  # linear: ρ15 (1 − β ΔT); reciprocal: ρ15 / (1 + β ΔT) (motorid's reader)

    def walther(self):
        t1, t2 = math.log10(40.0 + KELVIN), math.log10(100.0 + KELVIN)
        z1 = math.log10(math.log10(self.nu40 + 0.7))
        z2 = math.log10(math.log10(self.nu100 + 0.7))
        b = (z1 - z2) / (t2 - t1)
        return z1 + b * t1, b

    def nu(self, temp_C):
        """Kinematic viscosity [m²/s] (Walther, ASTM D341)."""
        a, b = self.walther()
        z = a - b * np.log10(np.asarray(temp_C, dtype=float) + KELVIN)
        return (10.0 ** (10.0 ** z) - 0.7) * 1e-6

    def rho(self, temp_C):
        dT = np.asarray(temp_C, dtype=float) - 15.0
        if self.density_law == "reciprocal":
            return self.rho15 / (1.0 + self.beta * dT)
        return self.rho15 * (1.0 - self.beta * dT)

    def mu(self, temp_C):
        """Dynamic viscosity [Pa·s]."""
        return self.rho(temp_C) * self.nu(temp_C)

    def mu_scalar(self, temp_C: float) -> float:
        a, b = self.walther()
        nu = 10.0 ** (10.0 ** (a - b * math.log10(temp_C + KELVIN))) - 0.7
        return float(self.rho(temp_C)) * nu * 1e-6


@dataclass(frozen=True)
class Motor:
    name: str
    n: int
    D: float  # m³/rev
    J: float  # kg·m²
    oil: Oil
    leak_phase: float | None = None  # rad; None → π/n

    @property
    def phi(self) -> float:
        return math.pi / self.n if self.leak_phase is None else self.leak_phase


def port_sum(theta, n: int):
    """S(θ) = Σ_{cos θᵢ > 0} cos θᵢ, θᵢ = θ + 2π(i−1)/n (vectorized)."""
    th = np.asarray(theta, dtype=float)
    c = np.cos(th[..., None] + TWO_PI * np.arange(n) / n)
    return np.where(c > 0.0, c, 0.0).sum(axis=-1)


def port_sum_scalar(theta: float, n: int) -> float:
    """S(θ) in closed form: the pistons with cos θᵢ > 0 are a run of consecutive indices
    i_lo..i_hi, and a sum of cosines over an arithmetic progression is
    sin(mδ/2)/sin(δ/2)·cos(θ + (i_lo + i_hi)δ/2), δ = 2π/n (tested against the plain sum)."""
    step = TWO_PI / n
    x = theta % TWO_PI
    i_lo = math.ceil((-0.5 * math.pi - x) / step)
    i_hi = math.floor((0.5 * math.pi - x) / step)
    m = i_hi - i_lo + 1
    if m <= 0:
        return 0.0
    return math.sin(0.5 * m * step) / math.sin(0.5 * step) * math.cos(x + 0.5 * (i_lo + i_hi) * step)


def leak_coeff(theta, p: dict, n: int):
    """K_L(θ) = K_L0 [1 + Σ a_m cos(m n θ) + b_m sin(m n θ)] [m³]."""
    th = np.asarray(theta, dtype=float)
    shape = np.ones_like(th)
    m = 1
    while f"KL_a{m}" in p:
        shape = shape + p[f"KL_a{m}"] * np.cos(m * n * th) + p[f"KL_b{m}"] * np.sin(m * n * th)
        m += 1
    return p["KL0"] * shape


def leak_coeff_scalar(theta: float, p: dict, n: int) -> float:
    shape, m = 1.0, 1
    while f"KL_a{m}" in p:
        shape += p[f"KL_a{m}"] * math.cos(m * n * theta) + p[f"KL_b{m}"] * math.sin(m * n * theta)
        m += 1
    return p["KL0"] * shape


def flows(motor: Motor, p: dict, theta, omega, pa, pb, pc, mu):
    """(Q_AN, Q_BN, Q_CN) [m³/s] of MODEL.md Eq. 59-61."""
    n = motor.n
    qa_swept = motor.D * omega * port_sum(theta, n) / (2.0 * n)
    q_la = leak_coeff(theta, p, n) * (pa - pc) / mu
    q_lb = leak_coeff(np.asarray(theta) - motor.phi, p, n) * (pb - pc) / mu
    q_ab = p["KAB"] * (pa - pb) / mu
    return qa_swept + q_la + q_ab, -qa_swept + q_lb - q_ab, q_la + q_lb


def internal_torque(motor: Motor, p: dict, theta, omega, pa, pb, mu, sgn):
    """T_p + T_v + T_F (kinetic) — the motor's torque before its own inertia [N·m]."""
    n, D = motor.n, motor.D
    tp = D * (pa - pb) * port_sum(theta, n) / (2.0 * n)
    return tp - p["Kv"] * D * mu * omega - (D * (pa + pb) * p["KF"] + p["TFc"]) * sgn


def breakaway_limit(motor: Motor, p: dict, pa, pb):
    return motor.D * (pa + pb) * (p["KF"] + p["KFS"]) + p["TFc"] * (1.0 + p["Ks"])


# ============================================================================ smooth random signals

class Wobble:
    """A smooth zero-mean signal: a sum of sinusoids (analytic value, derivative, integral)."""

    def __init__(self, amps, freqs, phases):
        self.a = np.asarray(amps, dtype=float)
        self.w = TWO_PI * np.asarray(freqs, dtype=float)
        self.p = np.asarray(phases, dtype=float)

    @classmethod
    def random(cls, rng, rms: float, f_lo: float, f_hi: float, k: int = 4):
        if rms <= 0 or k == 0:
            return cls([], [], [])
        f = np.exp(rng.uniform(math.log(f_lo), math.log(f_hi), k))
        a = rng.uniform(0.3, 1.0, k)
        a *= rms * math.sqrt(2.0) / math.sqrt(np.sum(a**2))
        return cls(a, f, rng.uniform(0, TWO_PI, k))

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        return np.sin(t[..., None] * self.w + self.p) @ self.a if self.a.size else np.zeros_like(t)

    def deriv(self, t):
        t = np.asarray(t, dtype=float)
        return np.cos(t[..., None] * self.w + self.p) @ (self.a * self.w) if self.a.size else np.zeros_like(t)

    def integral(self, t):
        """∫₀ᵗ."""
        t = np.asarray(t, dtype=float)
        if not self.a.size:
            return np.zeros_like(t)
        return (np.cos(self.p) - np.cos(t[..., None] * self.w + self.p)) @ (self.a / self.w)

    def scalar(self, t: float) -> float:
        terms = getattr(self, "_terms", None)
        if terms is None:
            terms = self._terms = [(float(a), float(w), float(p)) for a, w, p in zip(self.a, self.w, self.p)]
        out = 0.0
        sin = math.sin
        for a, w, p in terms:
            out += a * sin(w * t + p)
        return out


# ============================================================================ scenario description

@dataclass
class Bench:
    """How the bench behaves (all optional shapes of one scenario)."""

    back_bar: float = 6.0  # outlet (return) port pressure
    case_bar: float = 0.6  # case pressure at zero drain flow
    drain_bar_per_lpm: float = 0.08  # case drain line resistance
    dyno_ripple: float = 1e-3  # relative RMS of the speed controller's unlocked ripple
    dyno_ripple_hz: tuple = (0.3, 40.0)
    dyno_locked: tuple = (8e-4, 4e-4, 0.0)  # relative amplitude of shaft orders 1, 2, 3
    dyno_abs_rpm: float = 2e-3  # absolute ripple floor [rpm RMS] (a slow run's controller)
    supply_ripple: float = 3e-4  # relative RMS of the pressure-difference ripple
    supply_ripple_hz: tuple = (0.5, 8.0)
    temp_drift_K_min: float = 0.4
    temp_cycle_K: float = 0.15  # thermostat cycle amplitude
    temp_cycle_s: float = 90.0
    load_inertia: float = 0.3  # kg·m² at 80 cm³ (scaled with D^(5/3))
    startability: str = "damped"  # damped | weight | flowfed
    start_after_s: tuple = (0.8, 1.6)  # how long the log goes on after breakaway
    speed_from_encoder: bool = False  # speed = Δθ/Δt of the encoder over each sample interval


@dataclass
class Sensors:
    scale: float = 1.0  # multiplies every noise level
    offsets: bool = False  # small zero offsets on every channel
    gains: bool = False  # small calibration gain errors
    spike_rate: float = 0.0  # fraction of readings per channel replaced by a spike
    spike_channels: tuple = ("torque", "pa", "pb", "pc", "qa", "qb", "qc", "omega")
    missing: tuple = ()  # (channel, protocol or "*", fraction of runs) → whole-run empty cells
    missing_cells: float = 0.0  # fraction of random empty cells in the flow/torque channels
    encoder_counts: int = 16384
    encoder_floor: bool = False  # report the count (floor: a half-count angle offset) instead of its centre


@dataclass
class Plan:
    cs_speeds_rpm: tuple = (0.3, 3.0, 30.0, 300.0, 1500.0)
    cs_dp_bar: tuple = (60.0, 160.0, 280.0)
    cs_temps_C: tuple = (45.0,)
    cs_rate: object = "auto"  # "auto" (by speed), a number, or a tuple per speed
    cs_min_s: float = 2.0
    cs_revs: float = 1.1
    cp_dp_bar: tuple = (120.0, 260.0)
    cp_speeds_rpm: tuple = (200.0, 1200.0)
    cp_temps_C: tuple = (45.0, 65.0)
    cp_rate: float = 200.0
    cp_s: float = 1.5
    st_angles: int = 7  # shaft angles over one piston pitch (plus a bit)
    st_loads: tuple = (0.1, 0.35, 0.7)  # held load as a fraction of D·300 bar/2π
    st_ramp_bar_s: tuple = (2.0,)
    st_rate: float = 100.0
    st_temp_C: float = 45.0
    directions: tuple = (1, -1)


@dataclass
class Flavour:
    units: str = "standard"  # standard | us | si | metric
    layout: str = "per_run"  # per_run | per_protocol | single | chunks
    gzip: bool = False
    viscosity: bool = True  # write a viscosity column
    shuffle_columns: bool = False
    extras: bool = False
    time_offset: str = "small"  # zero | small | day
    jitter: float = 0.002  # timestamp jitter, fraction of the sample interval (RMS)
    run_ids_restart: bool = False  # run ids restart in each file ("R1", "R2", …)
    protocol_case: str = "lower"  # lower | title (e.g. "Constant-Speed")


@dataclass
class Scenario:
    name: str
    seed: int
    pistons: int
    disp_cm3: float
    what: str = ""
    oil: Oil = field(default_factory=Oil)
    leak_phase_deg: float | None = None
    bench: Bench = field(default_factory=Bench)
    sensors: Sensors = field(default_factory=Sensors)
    plan: Plan = field(default_factory=Plan)
    flavour: Flavour = field(default_factory=Flavour)
    truth_jitter: bool = True


def make_truth(rng, D_cm3: float, jitter: bool = True) -> dict:
    """Parameters of realistic size for a motor of D_cm3 (the demo's sizes at 80 cm³)."""
    s = D_cm3 / 80.0
    u = (lambda lo, hi: rng.uniform(lo, hi)) if jitter else (lambda lo, hi: 1.0 if lo > 0 else 0.0)
    p = {
        "Kv": 5000.0 * s ** -0.15 * u(0.7, 1.4),
        "KF": 0.003 * u(0.6, 1.5),
        "KFS": 0.015 * u(0.6, 1.5),
        "TFc": 3.0 * s ** 0.9 * u(0.6, 1.5),
        "Ks": 1.0 * u(0.5, 1.5),
        "KL0": 5e-14 * s ** 0.7 * u(0.6, 1.6),
        "KL_a1": 0.15 * u(0.5, 1.5) * (1 if not jitter else rng.choice([-1, 1])),
        "KL_b1": 0.08 * u(0.5, 1.5) * (1 if not jitter else rng.choice([-1, 1])),
        "KAB": 2e-14 * s ** 0.7 * u(0.6, 1.6),
    }
    return {k: float(v) for k, v in p.items()}


# ============================================================================ runs (true signals, SI)

def _sample_times(rng, rate: float, duration: float, jitter_true: float = 0.01):
    """Sample instants of a logger at ``rate`` (its clock wanders by ``jitter_true`` of a step)."""
    k = max(int(round(duration * rate)), 12)
    dt = 1.0 / rate
    t = np.arange(k) * dt + rng.normal(0.0, jitter_true * dt, k)
    t[0] = 0.0
    return np.maximum.accumulate(t + np.arange(k) * 1e-9)


def _temperature(rng, bench: Bench, T_set: float, t):
    drift = bench.temp_drift_K_min / 60.0 * rng.uniform(-1, 1)
    ph = rng.uniform(0, TWO_PI)
    return (T_set + rng.uniform(-0.3, 0.3) + drift * t
            + bench.temp_cycle_K * np.sin(TWO_PI * t / bench.temp_cycle_s + ph))


def _case_pressure(bench: Bench, qc):
    return (bench.case_bar + bench.drain_bar_per_lpm * np.asarray(qc) * 6e4) * 1e5


def _ports(direction: int, p_in, p_out):
    return (p_in, p_out) if direction > 0 else (p_out, p_in)


def _finish_flows(motor, truth, bench, d, t, theta, omega, pa, pb, mu):
    """Flows and case pressure (the case pressure depends on the drain flow: two passes)."""
    pc = np.full_like(t, bench.case_bar * 1e5)
    for _ in range(3):
        qa, qb, qc = flows(motor, truth, theta, omega, pa, pb, pc, mu)
        pc = _case_pressure(bench, qc)
    return qa, qb, qc, pc


def run_constant_speed(rng, motor: Motor, truth: dict, bench: Bench, rpm: float, dp_bar: float,
                       T_set: float, rate: float, duration: float) -> dict:
    """Stiff speed-controlled dynamometer with its own ripple; ω, θ, α analytic."""
    t = _sample_times(rng, rate, duration)
    w0 = rpm * TWO_PI / 60.0
    d = 1 if w0 > 0 else -1
    rel = Wobble.random(rng, bench.dyno_ripple, *bench.dyno_ripple_hz, k=4)
    ab = Wobble.random(rng, bench.dyno_abs_rpm * TWO_PI / 60.0, 0.05, 2.0, k=3)
    th0 = rng.uniform(0, TWO_PI)
    locked = [(c * rng.uniform(0.5, 1.5), rng.uniform(0, TWO_PI)) for c in bench.dyno_locked]
    # nominal angle φ(t) = θ0 + ω0 t; locked ripple ω0 c_k sin(k φ + ψ_k) integrates to −(c_k/k) cos(k φ + ψ_k)
    phi = th0 + w0 * t
    omega = w0 * (1.0 + rel(t)) + ab(t)
    alpha = w0 * rel.deriv(t) + ab.deriv(t)
    theta = phi + w0 * rel.integral(t) + ab.integral(t)
    for k, (c, psi) in enumerate(locked, start=1):
        if c == 0:
            continue
        omega = omega + w0 * c * np.sin(k * phi + psi)
        alpha = alpha + w0 * w0 * c * k * np.cos(k * phi + psi)
        theta = theta - (c / k) * (np.cos(k * phi + psi) - math.cos(k * th0 + psi))
    temp = _temperature(rng, bench, T_set, t)
    mu = motor.oil.mu(temp)
    sup = Wobble.random(rng, bench.supply_ripple, *bench.supply_ripple_hz, k=3)
    p_in = (bench.back_bar + dp_bar) * 1e5 + dp_bar * 1e5 * sup(t)
    p_out = bench.back_bar * 1e5 * (1.0 + 0.01 * np.sin(TWO_PI * 1.3 * t + rng.uniform(0, 6)))
    pa, pb = _ports(d, p_in, p_out)
    torque = internal_torque(motor, truth, theta, omega, pa, pb, mu, d) - motor.J * alpha
    qa, qb, qc, pc = _finish_flows(motor, truth, bench, d, t, theta, omega, pa, pb, mu)
    return dict(t=t, theta=theta, omega=omega, torque=torque, pa=pa, pb=pb, pc=pc, qa=qa, qb=qb, qc=qc,
                temp=temp, mu=mu, alpha=alpha)


def _rk4_to(f, y, t0, t1, h_max):
    """RK4 from t0 to t1 in equal substeps of at most h_max."""
    m = max(1, int(math.ceil((t1 - t0) / h_max)))
    h = (t1 - t0) / m
    t = t0
    for _ in range(m):
        k1 = f(t, y)
        k2 = f(t + 0.5 * h, [a + 0.5 * h * b for a, b in zip(y, k1)])
        k3 = f(t + 0.5 * h, [a + 0.5 * h * b for a, b in zip(y, k2)])
        k4 = f(t + h, [a + h * b for a, b in zip(y, k3)])
        y = [a + h / 6.0 * (b + 2 * c + 2 * e + g) for a, b, c, e, g in zip(y, k1, k2, k3, k4)]
        t += h
    return y


def run_constant_pressure(rng, motor: Motor, truth: dict, bench: Bench, rpm: float, dp_bar: float,
                          T_set: float, rate: float, duration: float) -> dict:
    """Supply holds ΔP; a fan-law brake with inertia sets the speed; the shaft spins up from
    70 % of the speed and settles (RK4, 40 steps per piston pitch at least)."""
    t = _sample_times(rng, rate, duration)
    w_set = rpm * TWO_PI / 60.0
    d = 1 if w_set > 0 else -1
    n, D = motor.n, motor.D
    JL = bench.load_inertia * (D / 80e-6) ** (5.0 / 3.0)
    Jt = motor.J + JL
    temp0 = T_set + rng.uniform(-0.3, 0.3)
    drift = bench.temp_drift_K_min / 60.0 * rng.uniform(-1, 1)
    temp_of = lambda tt: temp0 + drift * tt  # noqa: E731
    sup = Wobble.random(rng, bench.supply_ripple, *bench.supply_ripple_hz, k=3)
    dyn = Wobble.random(rng, 2e-3, 0.5, 15.0, k=3)  # brake torque ripple, relative
    p_back = bench.back_bar * 1e5
    mu_mid = float(motor.oil.mu(T_set))
    # brake sized so that the mean motor torque at w_set balances it there
    t_int = (D * dp_bar * 1e5 / TWO_PI - truth["Kv"] * D * mu_mid * abs(w_set)
             - (D * (2 * p_back + dp_bar * 1e5) * truth["KF"] + truth["TFc"]))
    T0 = max(t_int, 1.0)

    def pressures(tt):
        p_in = p_back + dp_bar * 1e5 * (1.0 + sup.scalar(tt))
        return (p_in, p_back) if d > 0 else (p_back, p_in)

    def rhs(tt, y):
        th, w = y
        pa, pb = pressures(tt)
        mu = mu_a + mu_b * tt  # (μ(T(t)) is a line over a run to 1e-6; the logged torque uses the exact μ)
        tp = D * (pa - pb) * port_sum_scalar(th, n) / (2 * n)
        tint = tp - truth["Kv"] * D * mu * w - (D * (pa + pb) * truth["KF"] + truth["TFc"]) * d
        tload = d * T0 * (w / w_set) ** 2 * (1.0 + dyn.scalar(tt))
        return [w, (tint - tload) / Jt]

    mu_a = motor.oil.mu_scalar(temp_of(0.0))
    mu_b = (motor.oil.mu_scalar(temp_of(duration)) - mu_a) / duration
    h_max = min(1e-3, (TWO_PI / n) / abs(w_set) / 40.0, 0.25 / rate)
    y = [rng.uniform(0, TWO_PI), 0.7 * w_set]
    th, om = np.empty(t.size), np.empty(t.size)
    tprev = 0.0
    for i, ti in enumerate(t):
        if ti > tprev:
            y = _rk4_to(rhs, y, tprev, ti, h_max)
        tprev = ti
        th[i], om[i] = y
    temp = temp_of(t)
    mu = motor.oil.mu(temp)
    p_in = p_back + dp_bar * 1e5 * (1.0 + sup(t))
    pa, pb = _ports(d, p_in, np.full_like(t, p_back))
    tint = internal_torque(motor, truth, th, om, pa, pb, mu, d)
    tload = d * T0 * (om / w_set) ** 2 * (1.0 + dyn(t))
    alpha = (tint - tload) / Jt
    torque = tint - motor.J * alpha
    qa, qb, qc, pc = _finish_flows(motor, truth, bench, d, t, th, om, pa, pb, mu)
    return dict(t=t, theta=th, omega=om, torque=torque, pa=pa, pb=pb, pc=pc, qa=qa, qb=qb, qc=qc,
                temp=temp, mu=mu, alpha=alpha)


def run_startability(rng, motor: Motor, truth: dict, bench: Bench, theta0: float, load: float,
                     direction: int, ramp_bar_s: float, T_set: float, rate: float) -> dict:
    """ISO 4392-2: shaft held at theta0 by a constant load torque, inlet pressure raised until
    breakaway, logged on past it.  ``load`` is the held torque's magnitude [N·m]."""
    n, D, p = motor.n, motor.D, truth
    d = direction
    JL = bench.load_inertia * (D / 80e-6) ** (5.0 / 3.0)
    mode = bench.startability
    if mode == "weight":
        JL *= 4.0
    Jt = motor.J + JL
    p_out = bench.back_bar * 1e5
    pc_rest = bench.case_bar * 1e5  # no motion: the drain flow is the leakage only (small)
    S0 = port_sum_scalar(theta0, n)
    kst = p["KF"] + p["KFS"]
    # g(p_in) = d (T_p − T_h) − T_break, linear in p_in (the held load T_h = d·load)
    slope = D * S0 / (2 * n) - D * kst
    const = -D * p_out * S0 / (2 * n) - load - D * p_out * kst - p["TFc"] * (1 + p["Ks"])
    p_break_static = -const / slope
    t_brk0 = breakaway_limit(motor, p, p_break_static, p_out)
    frac = rng.uniform(0.5, 1.5)  # where inside the static band the ramp starts
    p_start = max(p_break_static - frac * t_brk0 / slope, p_out + 2e5)
    hold = rng.uniform(0.5, 1.5)
    r = ramp_bar_s * 1e5
    temp0 = T_set + rng.uniform(-0.3, 0.3)
    mu0 = float(motor.oil.mu(temp0))
    sup = Wobble.random(rng, bench.supply_ripple, *bench.supply_ripple_hz, k=3)

    def ports(p_in):
        return (p_in, p_out) if d > 0 else (p_out, p_in)

    def g_of(p_in, th=theta0):
        pa, pb = ports(p_in)
        tp = D * (pa - pb) * port_sum_scalar(th, n) / (2 * n)
        return d * (tp - d * load) - breakaway_limit(motor, p, pa, pb)

    if mode == "flowfed":
        # constant supply flow into a compressible line: dP/dt = (Q_s − Q_in)/C.  Q_s exceeds the
        # leakage at the breakaway pressure by the swept flow of 1-3 rpm (slow driving: stick-slip),
        # and C makes the ramp r there.
        def q_in(th, w, p_in):
            pa, pb = ports(p_in)
            kla = leak_coeff_scalar(th, p, n)
            klb = leak_coeff_scalar(th - motor.phi, p, n)
            sw = D * w * port_sum_scalar(th, n) / (2 * n)
            if d > 0:
                return sw + kla * (pa - pc_rest) / mu0 + p["KAB"] * (pa - pb) / mu0
            return -sw + klb * (pb - pc_rest) / mu0 - p["KAB"] * (pa - pb) / mu0

        q_leak_b = q_in(theta0, 0.0, p_break_static)
        q_s = q_leak_b + D * rng.uniform(1.0, 3.0) / 60.0
        C = (q_s - q_leak_b) / r
    else:
        stop_after = rng.uniform(0.05, 0.3) if mode == "weight" else math.inf

        def p_in_ramp(tt, t_b=math.inf):
            te = min(tt, t_b + stop_after)
            return p_start + r * max(te - hold, 0.0) + (p_start - p_out) * sup.scalar(tt)

    # ---- stuck phase and the breakaway instant
    if mode == "flowfed":
        # stuck: dP/dt = (Q_s − c0 − c1 P)/C, linear in P → P(t) analytic; g is linear in P
        c0 = q_in(theta0, 0.0, 0.0)
        c1 = q_in(theta0, 0.0, 1e7) / 1e7 - c0 / 1e7
        p_inf = (q_s - c0) / c1

        def p_stuck(tt, t_from=hold, p_from=p_start):
            return p_from if tt <= t_from else p_inf + (p_from - p_inf) * math.exp(-c1 * (tt - t_from) / C)

        P_b = p_break_static
        if not p_start < P_b < p_inf:
            raise RuntimeError("flow-fed line never reaches the breakaway pressure")
        t_b = hold - C / c1 * math.log((P_b - p_inf) / (p_start - p_inf))
    else:
        t_guess = hold + (p_break_static - p_start) / r
        grid = np.arange(0.0, 2.0 * t_guess + 10.0, 1e-3)
        # (vectorized g on the grid, then a root by bisection)
        p_grid = p_start + r * np.maximum(grid - hold, 0.0) + (p_start - p_out) * sup(grid)
        pa_g, pb_g = ports(p_grid)
        g = d * (D * (pa_g - pb_g) * S0 / (2 * n) - d * load) - breakaway_limit(motor, p, pa_g, pb_g)
        k = int(np.argmax(g >= 0.0))
        if g[k] < 0:
            raise RuntimeError("no breakaway found")
        lo, hi = grid[k - 1], grid[k]
        for _ in range(50):
            mid = 0.5 * (lo + hi)
            (lo, hi) = (mid, hi) if g_of(p_in_ramp(mid)) < 0 else (lo, mid)
        t_b = hi
        P_b = p_in_ramp(t_b)
    t_end = t_b + rng.uniform(*bench.start_after_s)
    t = _sample_times(rng, rate, t_end)
    # ---- motion after breakaway: (J + J_L) α = T_int − T_load(ω), Karnopp re-sticking
    c_damp = 0.0
    if mode == "damped":
        w_term = rng.uniform(5.0, 30.0) * TWO_PI / 60.0  # terminal speed for the static-kinetic excess
        pa_b, pb_b = ports(P_b)
        c_damp = (D * (pa_b + pb_b) * p["KFS"] + p["TFc"] * p["Ks"]) / w_term

    def load_torque(w):
        return d * load + c_damp * w

    def rhs(tt, y):
        th, w = y[0], y[1]
        if mode == "flowfed":
            p_in = y[2]
        else:
            p_in = p_in_ramp(tt, t_b)
        pa, pb = ports(p_in)
        mu = mu0
        tp = D * (pa - pb) * port_sum_scalar(th, n) / (2 * n)
        sgn = brk_dir[0] if w == 0.0 else math.copysign(1.0, w)
        tint = tp - p["Kv"] * D * mu * w - (D * (pa + pb) * p["KF"] + p["TFc"]) * sgn
        acc = (tint - load_torque(w)) / Jt
        out = [w, acc]
        if mode == "flowfed":
            out.append((q_s - q_in(th, w, p_in)) / C)
        return out

    state = [theta0, 0.0] + ([P_b] if mode == "flowfed" else [])
    stuck = False
    brk_dir = [d]  # the way the shaft last broke away
    h_max = 1e-3
    omega = np.zeros(t.size)
    theta = np.full(t.size, theta0)
    p_in_arr = np.empty(t.size)
    stuck_flag = np.ones(t.size, bool)
    tcur = t_b
    for i, ti in enumerate(t):
        if ti <= t_b:
            if mode == "flowfed":
                p_in_arr[i] = p_stuck(ti)
            else:
                p_in_arr[i] = p_in_ramp(ti)
            continue
        # integrate to ti in small steps, watching for the speed to return to zero
        while tcur < ti - 1e-12:
            hstep = min(h_max, ti - tcur, (TWO_PI / n) / max(abs(state[1]), 1e-9) / 40.0)
            if stuck:
                p_in = state[2] if mode == "flowfed" else p_in_ramp(tcur, t_b)
                pa, pb = ports(p_in)
                tp = D * (pa - pb) * port_sum_scalar(state[0], n) / (2 * n)
                excess = tp - load_torque(0.0)
                if abs(excess) > breakaway_limit(motor, p, pa, pb):
                    stuck = False  # breaks away again (Karnopp), friction kinetic from now on
                    brk_dir[0] = 1 if excess > 0 else -1
                else:
                    if mode == "flowfed":  # the line fills at the stuck angle (linear ODE, exact)
                        k0 = q_in(state[0], 0.0, 0.0)
                        k1 = q_in(state[0], 0.0, 1e7) / 1e7 - k0 / 1e7
                        pinf = (q_s - k0) / k1
                        state[2] = pinf + (state[2] - pinf) * math.exp(-k1 * hstep / C)
                    tcur += hstep
                    continue
            w_before = state[1]
            new = _rk4_to(rhs, state, tcur, tcur + hstep, hstep)
            if w_before != 0.0 and new[1] * w_before < 0.0:
                new[1] = 0.0
                stuck = True
            elif w_before == 0.0 and new[1] * brk_dir[0] < 0.0 and tcur > t_b + 1e-9:
                new[1] = 0.0
                stuck = True
            state = new
            tcur += hstep
        theta[i] = state[0]
        omega[i] = state[1]
        stuck_flag[i] = stuck
        p_in_arr[i] = state[2] if mode == "flowfed" else p_in_ramp(ti, t_b)
    temp = np.full(t.size, temp0)  # (the viscosity of the whole run is mu0: a ramp lasts seconds)
    mu = np.full(t.size, mu0)
    pa, pb = ports(p_in_arr)
    pa, pb = np.asarray(pa, float) * np.ones(t.size), np.asarray(pb, float) * np.ones(t.size)
    moving = (t > t_b) & ~stuck_flag
    sgn = np.where(omega != 0, np.sign(omega), d)
    tint = internal_torque(motor, p, theta, omega, pa, pb, mu, sgn)
    alpha = np.where(moving, (tint - (d * load + c_damp * omega)) / Jt, 0.0)
    torque = np.where(moving, tint - motor.J * alpha, d * load)  # stuck: the transducer reads the held load
    qa, qb, qc, pc = _finish_flows(motor, p, bench, d, t, theta, omega, pa, pb, mu)
    return dict(t=t, theta=theta, omega=omega, torque=torque, pa=pa, pb=pb, pc=pc, qa=qa, qb=qb, qc=qc,
                temp=temp, mu=mu, alpha=alpha,
                breakaway=dict(t=t_b, p_in=P_b, theta=theta0, direction=d, held=d * load,
                               p_a=ports(P_b)[0], p_b=ports(P_b)[1], mode=mode, hold_s=hold,
                               p_start=p_start, ramp_Pa_s=r))


# ============================================================================ sensors

# channel → (absolute σ, relative σ) in SI; scaled per motor size where marked
def sensor_levels(motor: Motor, s: Sensors) -> dict:
    k = motor.D / 80e-6
    fs_torque = 1.2 * motor.D * 400e5 / TWO_PI
    lv = {
        "torque": (1.2e-4 * fs_torque, 2e-4),
        "pa": (0.03e5, 1e-4), "pb": (0.03e5, 1e-4), "pc": (0.004e5, 2e-3),
        "qa": (0.02 / 6e4 * k, 1e-3), "qb": (0.02 / 6e4 * k, 1e-3),
        "qc": (0.003 / 6e4 * k ** 0.7, 3e-3),
        "omega": (0.003 * TWO_PI / 60, 2e-4),
        "temp": (0.05, 0.0),
        "mu": (0.0, 3e-3),
    }
    return {c: (a * s.scale, r * s.scale) for c, (a, r) in lv.items()}


def apply_sensors(rng, motor: Motor, sens: Sensors, sig: dict, cal: dict) -> dict:
    """True SI signals of one run → readings (noise, offsets, gains, spikes; not yet quantized)."""
    lv = sensor_levels(motor, sens)
    out = {"t": sig["t"]}
    # encoder: counts of the true angle; speed from a tachometer or from the encoder counts
    out["theta"] = np.mod(encoder_angle(sig["theta"], sens), TWO_PI)
    for c in ("torque", "pa", "pb", "pc", "qa", "qb", "qc", "omega", "temp", "mu"):
        x = np.asarray(sig[c], dtype=float)
        a, r = lv[c]
        noise = rng.normal(0.0, 1.0, x.size) * np.sqrt(a * a + (r * x) ** 2)
        y = x * cal["gain"].get(c, 1.0) + cal["offset"].get(c, 0.0) + noise
        if sens.spike_rate > 0 and c in sens.spike_channels:
            k = rng.binomial(x.size, sens.spike_rate)
            if k:
                idx = rng.choice(x.size, k, replace=False)
                size = 30.0 * np.sqrt(a * a + (r * np.abs(x[idx])) ** 2) + 0.05 * np.abs(x[idx])
                y[idx] += rng.choice([-1, 1], k) * size * rng.uniform(1, 3, k)
        out[c] = y
    return out


def encoder_angle(theta, sens: Sensors):
    """The encoder's reading of the true angle: its count × the count angle, plus half a count
    (the centre of the count interval) unless ``encoder_floor``."""
    q = TWO_PI / sens.encoder_counts
    return (np.floor(np.asarray(theta) / q) + (0.0 if sens.encoder_floor else 0.5)) * q


def encoder_speed(t, theta_counts_rad, true_omega0: float):
    """Speed from the unwrapped encoder angle over each sample interval (first sample: the true speed)."""
    un = np.unwrap(theta_counts_rad)
    w = np.empty_like(un)
    w[1:] = np.diff(un) / np.diff(t)
    w[0] = true_omega0
    return w


def calibration(rng, sens: Sensors, motor: Motor) -> dict:
    off, gain = {}, {}
    if sens.offsets:
        k = motor.D / 80e-6
        off = {"torque": rng.normal(0, 0.03) * k, "pa": rng.normal(0, 0.02e5), "pb": rng.normal(0, 0.02e5),
               "pc": rng.normal(0, 0.005e5), "qa": rng.normal(0, 0.01 / 6e4) * k, "qb": rng.normal(0, 0.01 / 6e4) * k,
               "qc": rng.normal(0, 0.002 / 6e4) * k ** 0.7, "omega": rng.normal(0, 0.0005) * TWO_PI / 60,
               "temp": rng.normal(0, 0.1)}
    if sens.gains:
        gain = {c: 1.0 + rng.normal(0, 5e-4) for c in ("torque", "pa", "pb", "qa", "qb", "qc", "omega")}
    return {"offset": off, "gain": gain}


# ============================================================================ campaign

def _auto_rate(rpm: float, n: int) -> float:
    a = abs(rpm)
    if a < 1:
        return 10.0
    if a < 10:
        return 25.0
    if a < 100:
        return 100.0
    if a < 1000:
        return 500.0
    return 2000.0


def build_motor(sc: Scenario):
    rng = np.random.default_rng(sc.seed)
    D = sc.disp_cm3 * 1e-6
    J = 0.005 * (sc.disp_cm3 / 80.0) ** (5.0 / 3.0)
    motor = Motor(f"foreign-{sc.name}", sc.pistons, D, J, sc.oil,
                  None if sc.leak_phase_deg is None else math.radians(sc.leak_phase_deg))
    truth = make_truth(rng, sc.disp_cm3, sc.truth_jitter)
    return motor, truth, rng


def simulate(sc: Scenario, quick: bool = False):
    """Scenario → (motor, truth, list of runs (dict: protocol, run_id, true, read, meta))."""
    motor, truth, rng = build_motor(sc)
    pl, bench = sc.plan, sc.bench
    cal = calibration(rng, sc.sensors, motor)
    runs = []
    k = 0

    def add(protocol, sig, meta):
        nonlocal k
        k += 1
        read = apply_sensors(rng, motor, sc.sensors, sig, cal)
        if bench.speed_from_encoder:
            read["omega"] = encoder_speed(sig["t"], encoder_angle(sig["theta"], sc.sensors), float(sig["omega"][0]))
        runs.append(dict(protocol=protocol, run_id=f"{protocol[:2].upper()}{k:03d}", true=sig, read=read, meta=meta))

    speeds = pl.cs_speeds_rpm[::2] if quick else pl.cs_speeds_rpm
    for T in pl.cs_temps_C:
        for i, rpm in enumerate(speeds):
            for dp in pl.cs_dp_bar:
                for d in pl.directions:
                    if pl.cs_rate == "auto":
                        rate = _auto_rate(rpm, motor.n)
                    elif isinstance(pl.cs_rate, (tuple, list)):
                        rate = float(pl.cs_rate[pl.cs_speeds_rpm.index(rpm)])
                    else:
                        rate = float(pl.cs_rate)
                    dur = max(pl.cs_min_s, pl.cs_revs * 60.0 / rpm)
                    if rpm < 1.0:  # one pitch and a bit suffices at creep speed (ISO 4392-1 low speed)
                        dur = max(pl.cs_min_s, 1.3 * (60.0 / rpm) / motor.n)
                    sig = run_constant_speed(rng, motor, truth, bench, d * rpm, dp, T, rate, dur)
                    add("constant_speed", sig, dict(rpm=d * rpm, dp_bar=dp, temp_C=T, rate=rate))
    for T in pl.cp_temps_C:
        for rpm in pl.cp_speeds_rpm:
            for dp in pl.cp_dp_bar:
                for d in pl.directions:
                    sig = run_constant_pressure(rng, motor, truth, bench, d * rpm, dp, T, pl.cp_rate, pl.cp_s)
                    add("constant_pressure", sig, dict(rpm=d * rpm, dp_bar=dp, temp_C=T, rate=pl.cp_rate))
    pitch = TWO_PI / motor.n
    n_ang = max(3, pl.st_angles // (2 if quick else 1))
    angles = rng.uniform(0, TWO_PI) + np.linspace(0.0, 1.1 * pitch, n_ang) + rng.uniform(0, 0.02, n_ang)
    t_ref = motor.D * 300e5 / TWO_PI
    j = 0
    for load in pl.st_loads:
        for th0 in angles:
            for d in pl.directions:
                ramp = pl.st_ramp_bar_s[j % len(pl.st_ramp_bar_s)]
                j += 1
                sig = run_startability(rng, motor, truth, bench, float(np.mod(th0, TWO_PI)), load * t_ref, d,
                                       ramp, pl.st_temp_C, pl.st_rate)
                add("startability", sig, dict(load_Nm=d * load * t_ref, theta0=float(np.mod(th0, TWO_PI)),
                                              ramp_bar_s=ramp, rate=pl.st_rate, breakaway=sig["breakaway"]))
    # missing sensors: whole runs without a channel's readings
    for ch, proto, frac in sc.sensors.missing:
        cands = [r for r in runs if proto in ("*", r["protocol"])]
        if not cands:
            continue
        for idx in rng.choice(len(cands), max(1, int(round(frac * len(cands)))), replace=False):
            cands[idx]["read"][ch] = np.full(cands[idx]["read"][ch].size, np.nan)
            cands[idx]["meta"].setdefault("missing", []).append(ch)
    if sc.sensors.missing_cells > 0:
        for r in runs:
            for ch in ("torque", "qa", "qb", "qc", "mu"):
                m = rng.random(r["read"][ch].size) < sc.sensors.missing_cells
                r["read"][ch] = np.where(m, np.nan, r["read"][ch])
    return motor, truth, runs, cal


# ============================================================================ writing

# canonical channel → (header, SI → file unit, decimals or ("sig", digits))
UNITS = {
    "standard": {
        "t": ("time_s", lambda x: x, 6), "theta": ("shaft_angle_deg", np.degrees, 4),
        "omega": ("speed_rpm", lambda x: x * 60 / TWO_PI, 4), "torque": ("torque_Nm", lambda x: x, 3),
        "pa": ("p_a_bar", lambda x: x / 1e5, 3), "pb": ("p_b_bar", lambda x: x / 1e5, 3),
        "pc": ("p_case_bar", lambda x: x / 1e5, 4), "qa": ("q_a_lpm", lambda x: x * 6e4, 4),
        "qb": ("q_b_lpm", lambda x: x * 6e4, 4), "qc": ("q_case_lpm", lambda x: x * 6e4, 4),
        "temp": ("oil_temp_C", lambda x: x, 2), "mu": ("viscosity_mPas", lambda x: x * 1e3, 3),
    },
    "us": {
        "t": ("time_s", lambda x: x, 6), "theta": ("shaft_angle_deg", np.degrees, 3),
        "omega": ("speed_rpm", lambda x: x * 60 / TWO_PI, 4), "torque": ("torque_lbf_ft", lambda x: x / LBF_FT, 3),
        "pa": ("p_a_psi", lambda x: x / PSI, 2), "pb": ("p_b_psi", lambda x: x / PSI, 2),
        "pc": ("p_case_psi", lambda x: x / PSI, 3), "qa": ("q_a_gpm", lambda x: x * 60 / US_GALLON, 4),
        "qb": ("q_b_gpm", lambda x: x * 60 / US_GALLON, 4), "qc": ("q_case_gpm", lambda x: x * 60 / US_GALLON, 5),
        "temp": ("oil_temp_F", lambda x: x * 9 / 5 + 32, 2), "mu": ("viscosity_cP", lambda x: x * 1e3, 3),
    },
    "si": {
        "t": ("time_s", lambda x: x, 6), "theta": ("shaft_angle_rad", lambda x: x, 6),
        "omega": ("speed_rad_s", lambda x: x, ("sig", 7)), "torque": ("torque_Nm", lambda x: x, 3),
        "pa": ("p_a_Pa", lambda x: x, 0), "pb": ("p_b_Pa", lambda x: x, 0), "pc": ("p_case_Pa", lambda x: x, 0),
        "qa": ("q_a_m3_s", lambda x: x, ("sig", 6)), "qb": ("q_b_m3_s", lambda x: x, ("sig", 6)),
        "qc": ("q_case_m3_s", lambda x: x, ("sig", 5)), "temp": ("oil_temp_K", lambda x: x + KELVIN, 3),
        "mu": ("viscosity_Pa_s", lambda x: x, ("sig", 5)),
    },
    "metric": {
        "t": ("time_ms", lambda x: x * 1e3, 3), "theta": ("shaft_angle_deg", np.degrees, 4),
        "omega": ("speed_rpm", lambda x: x * 60 / TWO_PI, 4), "torque": ("torque_Nm", lambda x: x, 3),
        "pa": ("p_a_kPa", lambda x: x / 1e3, 1), "pb": ("p_b_MPa", lambda x: x / 1e6, 5),
        "pc": ("p_case_kPa", lambda x: x / 1e3, 2), "qa": ("q_a_l_min", lambda x: x * 6e4, 4),
        "qb": ("q_b_lpm", lambda x: x * 6e4, 4), "qc": ("q_case_ml_min", lambda x: x * 6e7, 1),
        "temp": ("oil_temp_degC", lambda x: x, 2), "mu": ("viscosity_mPa_s", lambda x: x * 1e3, 3),
    },
}
CHANNELS = ("t", "theta", "omega", "torque", "pa", "pb", "pc", "qa", "qb", "qc", "temp", "mu")


def _fmt(values: np.ndarray, spec) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    if isinstance(spec, tuple):
        s = np.char.mod(f"%.{spec[1]}g", np.where(np.isfinite(v), v, 0.0))
    else:
        s = np.char.mod(f"%.{spec}f", np.where(np.isfinite(v), v, 0.0))
    return np.where(np.isfinite(v), s, "")


def run_table(run: dict, fl: Flavour, rng, t_offset: float) -> pd.DataFrame:
    units = UNITS[fl.units]
    rd = run["read"]
    t = rd["t"]
    dt = np.median(np.diff(t)) if t.size > 1 else 1.0
    stamp = t + t_offset + rng.normal(0.0, fl.jitter * dt, t.size)  # the logger's clock stamps, not the sample
    stamp = np.maximum.accumulate(stamp)
    stamp = stamp + np.arange(t.size) * 1e-6  # strictly increasing after rounding to µs
    cols = {}
    proto = run["protocol"]
    if fl.protocol_case == "title":
        proto = proto.replace("_", "-").title()
    for c in CHANNELS:
        if c == "mu" and not fl.viscosity:
            continue
        head, conv, dec = units[c]
        x = stamp if c == "t" else rd[c]
        cols[head] = _fmt(conv(x), dec)
    df = pd.DataFrame(cols)
    df.insert(1, "run_id", run["run_id"])
    df.insert(2, "protocol", proto)
    if fl.extras:
        df["p_supply_bar"] = _fmt(np.nanmax(np.vstack([rd["pa"], rd["pb"]]), axis=0) / 1e5 + 3.0, 2)
        df["dyno_mode"] = "speed" if run["protocol"] == "constant_speed" else "torque"
        df["operator"] = "lab B"
        df["case_temp_C"] = _fmt(rd["temp"] + 2.0, 1)
        df["setpoint_rpm"] = f"{run['meta'].get('rpm', 0.0):g}"
    return df


def write_campaign(sc: Scenario, motor: Motor, truth: dict, runs: list, cal: dict, out: Path) -> dict:
    rng = np.random.default_rng(sc.seed + 1000)
    fl = sc.flavour
    out = Path(out)
    (out / "logs").mkdir(parents=True, exist_ok=True)
    offsets = {"zero": lambda: 0.0, "small": lambda: float(rng.uniform(0.5, 30.0)),
               "day": lambda: float(rng.uniform(30000.0, 80000.0))}[fl.time_offset]
    tables = [(r, run_table(r, fl, rng, offsets())) for r in runs]
    if fl.layout == "per_run":
        groups = [[i] for i in range(len(tables))]
    elif fl.layout == "per_protocol":
        protos = sorted({r["protocol"] for r in runs})
        groups = [[i for i, r in enumerate(runs) if r["protocol"] == p] for p in protos]
    elif fl.layout == "single":
        groups = [list(range(len(tables)))]
    else:  # chunks of about 8 runs, protocols mixed
        order = rng.permutation(len(tables))
        groups = [list(order[i:i + 8]) for i in range(0, len(order), 8)]
    ext = ".csv.gz" if fl.gzip else ".csv"
    files = []
    cols_order = None
    for gi, g in enumerate(groups):
        parts = []
        for j, i in enumerate(g):
            df = tables[i][1]
            if fl.run_ids_restart:
                df = df.assign(run_id=f"R{j + 1}")
                runs[i]["file_run_id"] = f"R{j + 1}"
            parts.append(df)
        df = pd.concat(parts, ignore_index=True)
        if fl.shuffle_columns:
            if cols_order is None or set(cols_order) != set(df.columns):
                cols_order = list(rng.permutation(df.columns))
            df = df[cols_order]
        name = f"lab_b_{gi + 1:03d}{ext}"
        buf = io.StringIO()
        df.to_csv(buf, index=False, lineterminator="\n")
        data = buf.getvalue().encode()
        if fl.gzip:
            data = gzip.compress(data, mtime=0)
        (out / "logs" / name).write_bytes(data)
        files.append(str(out / "logs" / name))
        for i in g:
            runs[i]["file"] = name
    # spec and truth
    spec = ["[motor]", f'name = "{motor.name}"', f"pistons = {motor.n}",
            f"displacement_cm3 = {motor.D * 1e6!r}", f"inertia_kg_m2 = {motor.J!r}"]
    if motor.leak_phase is not None:
        spec.append(f"leak_phase_deg = {math.degrees(motor.leak_phase)!r}")
    o = motor.oil
    spec += ["", "[oil]", f'name = "{o.name}"', f"nu40_cSt = {o.nu40!r}", f"nu100_cSt = {o.nu100!r}",
             f"density15_kg_m3 = {o.rho15!r}", f"expansion_per_K = {o.beta!r}", ""]
    (out / "motor.toml").write_text("\n".join(spec))
    tr = ["# Truth of a foreign_bench.py campaign (SI, MODEL.md names)", "[parameters]"]
    tr += [f"{k} = {float(v)!r}" for k, v in truth.items()]
    tr += ["", "[motor]", f"pistons = {motor.n}", f"displacement_m3 = {motor.D!r}", f"inertia_kg_m2 = {motor.J!r}",
           f"leak_phase_rad = {motor.phi!r}", "", "[generator]", f'scenario = "{sc.name}"', f"seed = {sc.seed}",
           f'density_law = "{o.density_law}"', f"beta_per_K = {o.beta!r}", ""]
    (out / "truth.toml").write_text("\n".join(tr))
    manifest = {
        "scenario": sc.name, "what": sc.what, "seed": sc.seed, "files": [Path(f).name for f in files],
        "rows": int(sum(len(t[1]) for t in tables)),
        "calibration": {k: {c: float(v) for c, v in d.items()} for k, d in cal.items()},
        "runs": [{"run_id": r["run_id"], "file": r.get("file"), "file_run_id": r.get("file_run_id", r["run_id"]),
                  "protocol": r["protocol"], "rows": int(r["true"]["t"].size),
                  **{k: v for k, v in r["meta"].items()}} for r in runs],
    }
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1, default=float))
    return {"logs": files, "motor": str(out / "motor.toml"), "truth": str(out / "truth.toml"),
            "rows": manifest["rows"], "truth_values": dict(truth)}


def generate(sc: Scenario, out, quick: bool = False) -> dict:
    motor, truth, runs, cal = simulate(sc, quick)
    return write_campaign(sc, motor, truth, runs, cal, Path(out))


# ============================================================================ scenarios

def scenarios() -> list:
    """The study's scenarios: each a different combination of motor, bench, sensors and log flavour."""
    return [
        Scenario("n7_small_fast", 11, 7, 12.0, "7 pistons, 12 cm³; rates to 2 kHz; standard headers; one file per run; "
                 "damped torque-mode dyno at breakaway",
                 plan=Plan(cs_speeds_rpm=(0.4, 4.0, 40.0, 400.0, 3000.0), cp_speeds_rpm=(300.0, 2000.0))),
        Scenario("n8_us_units_noviscosity", 12, 8, 45.0, "8 pistons, 45 cm³; psi/gpm/°F/lbf·ft headers; many runs per "
                 "file, .csv.gz; no viscosity column (μ from the oil)",
                 flavour=Flavour(units="us", layout="per_protocol", gzip=True, viscosity=False)),
        Scenario("n11_large_SI_lowrate", 13, 11, 180.0, "11 pistons, 180 cm³; SI headers (Pa, rad/s, m³/s, rad, K); "
                 "10-100 Hz; dead-weight load at breakaway; run ids restart per file",
                 bench=Bench(startability="weight"),
                 plan=Plan(cs_speeds_rpm=(0.3, 3.0, 30.0, 300.0, 1200.0), cs_rate=(10.0, 10.0, 25.0, 100.0, 100.0),
                           cp_rate=50.0, st_rate=20.0, st_ramp_bar_s=(1.0, 4.0)),
                 flavour=Flavour(units="si", layout="chunks", run_ids_restart=True)),
        Scenario("n12_250cc_stickslip", 14, 12, 250.0, "12 pistons, 250 cm³; flow-fed startability (stick-slip); "
                 "kPa/MPa/ml/min headers; shuffled columns, extra columns",
                 bench=Bench(startability="flowfed"),
                 plan=Plan(st_rate=200.0, st_ramp_bar_s=(3.0,)),
                 flavour=Flavour(units="metric", layout="per_protocol", shuffle_columns=True, extras=True,
                                 protocol_case="title")),
        Scenario("n7_10Hz_dayclock", 15, 7, 30.0, "7 pistons, 30 cm³; every run logged at 10-20 Hz; time of day "
                 "stamps with 5 % jitter; fast ramps",
                 plan=Plan(cs_speeds_rpm=(0.5, 5.0, 50.0, 500.0, 2500.0), cs_rate=(10.0, 10.0, 10.0, 20.0, 20.0),
                           cs_min_s=5.0, cp_rate=20.0, cp_s=4.0, st_rate=10.0, st_ramp_bar_s=(5.0, 10.0)),
                 flavour=Flavour(time_offset="day", jitter=0.05, layout="single")),
        Scenario("n8_spikes_missing", 16, 8, 80.0, "8 pistons, 80 cm³; spikes in every channel; runs with no torque, "
                 "no port flows, no case flow; random empty cells",
                 sensors=Sensors(spike_rate=2e-3, missing=(("torque", "constant_speed", 0.1), ("qa", "*", 0.15),
                                                           ("qb", "*", 0.15), ("qc", "constant_speed", 0.2)),
                                 missing_cells=0.01),
                 flavour=Flavour(layout="chunks", gzip=True)),
        Scenario("n11_ripple_thermal", 17, 11, 60.0, "11 pistons, 60 cm³; strong dyno ripple (orders 1-3 and "
                 "unlocked to 150 Hz), supply ripple, thermostat cycling",
                 bench=Bench(dyno_ripple=4e-3, dyno_ripple_hz=(0.5, 150.0), dyno_locked=(3e-3, 2e-3, 1e-3),
                             supply_ripple=1.5e-3, supply_ripple_hz=(1.0, 20.0), temp_cycle_K=0.8, temp_cycle_s=40.0,
                             temp_drift_K_min=1.5),
                 flavour=Flavour(layout="per_protocol")),
        Scenario("n12_offsets_gains", 18, 12, 100.0, "12 pistons, 100 cm³; small sensor zero offsets and 0.05 % gain "
                 "errors (what no model term absorbs)",
                 sensors=Sensors(offsets=True, gains=True, encoder_floor=True)),
        Scenario("n8_leakphase_cp_heavy", 19, 8, 120.0, "8 pistons, 120 cm³; spec sets leak_phase_deg = 15; "
                 "constant-pressure heavy, three temperatures",
                 leak_phase_deg=15.0,
                 plan=Plan(cs_speeds_rpm=(0.3, 10.0, 300.0), cs_dp_bar=(80.0, 200.0, 320.0),
                           cp_speeds_rpm=(150.0, 600.0, 1800.0), cp_temps_C=(40.0, 55.0, 70.0), cp_rate=250.0,
                           cp_s=1.2)),
        Scenario("n8_50Hz_synchronous", 22, 8, 45.0, "8 pistons, 45 cm³; constant-speed runs logged at 50 Hz with "
                 "set points 750/1500/3000 rpm (shaft orders alias to 0 Hz); dyno ripple not shaft-locked "
                 "(a shaft order in step with the sampling is left to the trend)",
                 bench=Bench(dyno_locked=(0.0, 0.0, 0.0)),
                 plan=Plan(cs_speeds_rpm=(0.3, 30.0, 750.0, 1500.0, 3000.0), cs_rate=50.0, cp_rate=50.0, st_rate=25.0),
                 flavour=Flavour(layout="per_protocol", gzip=True)),
        Scenario("n7_encoder_speed", 20, 7, 60.0, "7 pistons, 60 cm³; speed from encoder counts over each sample "
                 "interval (no tachometer); 50 Hz startability",
                 bench=Bench(speed_from_encoder=True),
                 plan=Plan(st_rate=50.0, st_ramp_bar_s=(2.0, 6.0))),
    ]


def scenario(name: str) -> Scenario:
    for s in scenarios():
        if s.name == name:
            return s
    raise KeyError(name)


def clean(sc: Scenario) -> Scenario:
    """The same scenario with noise-free sensors, no ripple, no spikes, no missing data."""
    return replace(sc, sensors=Sensors(scale=0.0, encoder_counts=2**40, encoder_floor=True),
                   bench=replace(sc.bench, dyno_ripple=0.0, dyno_locked=(0.0, 0.0, 0.0), dyno_abs_rpm=0.0,
                                 supply_ripple=0.0))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    sub.add_parser("list")
    mk = sub.add_parser("make")
    mk.add_argument("scenario")
    mk.add_argument("out")
    mk.add_argument("--quick", action="store_true")
    mk.add_argument("--clean", action="store_true", help="noise-free sensors, no ripple")
    a = ap.parse_args(argv)
    if a.cmd == "list":
        for s in scenarios():
            print(f"{s.name:28s} {s.what}")
        return 0
    sc = scenario(a.scenario)
    if a.clean:
        sc = clean(sc)
    info = generate(sc, a.out, quick=a.quick)
    print(json.dumps({k: v for k, v in info.items() if k != "truth_values"}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
