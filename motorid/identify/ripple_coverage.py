"""What a steady run's sampling leaves of the shaft-angle ripple in its mean, without the angle.

A log without a shaft angle is fitted from the means of its steady runs (identify/log_points.py);
the mean is the mean over the angle only where the samples see every phase of the ripple.  These
functions tell, per multiple of the piston-pitch order, how far a run's sampling is from that
(:func:`ripple_coverages`), and what error it leaves in each output's mean (:func:`ripple_bias`).
"""

from __future__ import annotations

import math

import numpy as np

#: the multiples k of the piston-pitch order n (shaft orders k·n) whose ripple a steady run's sampling
#: may leave in its mean: the port sum, a rectified cosine, has them at every multiple of 2n (odd n) or
#: n (even n), falling as 1/k²
RIPPLE_MULTIPLES = 32
#: the pitch frequency is taken as uncertain by this share (a speed sensor's gain error)
RIPPLE_FREQUENCY_SPAN = 0.003
#: where the leakage's own ripple (K_L(θ)'s harmonics) must be bounded without data: this share of it
LEAK_RIPPLE_SHARE = 0.5


def ripple_coverages(t, speed, pistons: int) -> np.ndarray:
    """How far the samples of a steady run are from seeing every phase of the shaft-angle ripple, per
    pitch multiple k = 1 … :data:`RIPPLE_MULTIPLES`: |mean exp(i·2π·f_k·t)| over the samples, f_k =
    k·n·ω̄/2π at the run's mean speed, its largest for f_k within ±:data:`RIPPLE_FREQUENCY_SPAN`
    (a speed reading a little off) (0: that order's ripple averages out of the mean; 1: every sample
    at one of its phases, it reads as a constant).  For a steady rate 1/Δt this is the Dirichlet
    kernel |sin(Nπx)/(N sin πx)| of x, the distance of f_k·Δt to the nearest whole number: 1 where
    the rate is in step with that multiple of the pitch frequency.  The mean speed, not ∫ω dt, sets
    the phase: the speed's noise, integrated, would blur the phase at the high multiples and hide a
    lock the shaft itself keeps."""
    t, speed = np.asarray(t, float), np.asarray(speed, float)
    good = np.isfinite(t) & np.isfinite(speed)
    if pistons <= 0 or good.sum() < 2:
        return np.ones(RIPPLE_MULTIPLES)
    t, speed = t[good], speed[good]
    n = t.size
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        return np.ones(RIPPLE_MULTIPLES)
    k = np.arange(1, RIPPLE_MULTIPLES + 1)
    x0 = k * pistons * abs(float(np.mean(speed))) / (2 * np.pi) * dt
    frac = np.abs(x0 - np.round(x0))
    x = np.maximum(frac - x0 * RIPPLE_FREQUENCY_SPAN, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.abs(np.sin(n * np.pi * x) / (n * np.sin(np.pi * x)))
    return np.where(x > 0, np.minimum(d, 1.0), 1.0)


def ripple_coverage(t, speed, pistons: int) -> float:
    """The largest of :func:`ripple_coverages` over the pitch multiples."""
    return float(np.max(ripple_coverages(t, speed, pistons)))


def port_sum_harmonics(pistons: int) -> np.ndarray:
    """Amplitude of the port sum S(θ) (physics/kinematics.port_a_sum) at shaft orders k·n, k = 1 …
    :data:`RIPPLE_MULTIPLES`, over its mean n/π [-]."""
    from motorid.physics.kinematics import port_a_sum

    m = 4096
    theta = 2 * np.pi / max(pistons, 1) * np.arange(m) / m  # one pitch
    c = np.fft.rfft(np.asarray(port_a_sum(theta, pistons))) / m
    return 2 * np.abs(c[1:RIPPLE_MULTIPLES + 1]) / (pistons / np.pi)


#: a pitch multiple whose coverage exceeds this is sampled in step: every sample at nearly one phase
LOCKED_COVERAGE = 0.9


def ripple_bias(row: dict, spreads: dict, coverages, spec) -> tuple[dict, dict]:
    """The standard error a steady run's mean carries from the ripple its sampling leaves in it, per
    output [the output's unit] → (all of it, the part of the model's ripple at the multiples sampled
    in step, coverage > :data:`LOCKED_COVERAGE`: an error runs at one clock-locked phase share).

    The model's part: Σ_k D_k·A_k/√2 over the pitch multiples, D_k the :func:`ripple_coverages` and
    A_k the ripple's amplitude there: the pressure torque's D·|ΔP|/2π and the swept flow's
    D·|ω|/2π times the port sum's harmonic (:func:`port_sum_harmonics`), and
    :data:`LEAK_RIPPLE_SHARE` of the case flow at the K_L(θ) harmonics' orders.  Where the samples
    see the ripple (every D_k ≤ 0.5), at least max D_k × √2 × the output's spread / √2 (a ripple
    the model does not hold shows in the spread)."""
    coverages = np.asarray(coverages, dtype=float)
    s_k = port_sum_harmonics(int(spec.pistons))
    leak_orders = np.arange(1, RIPPLE_MULTIPLES + 1) <= int(getattr(spec, "leak_harmonics", 1) or 0)
    disp = float(spec.displacement)
    dp = abs(row["p_a_bar"] - row["p_b_bar"]) * 1e5
    w = abs(row["speed_rpm"]) * math.pi / 30.0
    leak = abs(row.get("q_case_lpm", math.nan))
    leak = 0.0 if not np.isfinite(leak) else leak
    leak_k = LEAK_RIPPLE_SHARE * leak * leak_orders
    amplitude = {"torque_Nm": disp * dp / (2 * math.pi) * s_k,
                 "q_a_lpm": disp * w / (2 * math.pi) * s_k * 6e4 + leak_k,
                 "q_b_lpm": disp * w / (2 * math.pi) * s_k * 6e4 + leak_k,
                 "q_case_lpm": leak_k}
    total, locked = {}, {}
    worst = float(coverages.max()) if coverages.size else 1.0
    lock = coverages > LOCKED_COVERAGE
    for name, spread in spreads.items():
        modelled = float(np.sum(coverages * amplitude.get(name, 0.0))) / math.sqrt(2.0)
        locked[name] = float(np.sum((coverages * amplitude.get(name, 0.0))[lock])) / math.sqrt(2.0)
        seen = worst * spread if (worst <= 0.5 and np.isfinite(spread)) else 0.0
        total[name] = max(modelled, seen)
    return total, locked


