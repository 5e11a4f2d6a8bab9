#!/usr/bin/env python3
"""Independent bench-log generator for a bent-axis piston motor (MODEL.md), written
from the shared notes only (no motorid code).  Simulates the shaft angle internally,
then drops it from the CSV.  numpy only.

usage: python gen.py            -> writes cases/<name>/{log*.csv, motor.toml, truth.json, heldout.csv, heldout_truth.csv}
"""
import json, os, math
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
KELVIN = 273.15
BAR = 1e5
LPM = 1e-3 / 60.0
RPM = 2 * math.pi / 60.0

OIL = dict(name="ISO VG 46 mineral oil", nu40_cSt=46.0, nu100_cSt=6.8, density15_kg_m3=875.0)


# ---------------------------------------------------------------- oil (ASTM D341 Walther)
def mu_of_T(T_C, oil=OIL, beta=6.5e-4):
    t1, t2 = math.log10(40 + KELVIN), math.log10(100 + KELVIN)
    z1 = math.log10(math.log10(oil["nu40_cSt"] + 0.7))
    z2 = math.log10(math.log10(oil["nu100_cSt"] + 0.7))
    b = (z1 - z2) / (t2 - t1)
    a = z1 + b * t1
    z = a - b * np.log10(np.asarray(T_C) + KELVIN)
    nu = (10.0 ** (10.0 ** z) - 0.7) * 1e-6
    rho = oil["density15_kg_m3"] / (1 + beta * (np.asarray(T_C) - 15.0))
    return rho * nu


# ---------------------------------------------------------------- exact model (MODEL.md)
def port_sum(theta, n):
    """sum over pistons with cos(theta_i) > 0 of cos(theta_i)"""
    th = theta[..., None] + 2 * np.pi * np.arange(n) / n
    c = np.cos(th)
    return np.where(c > 0, c, 0.0).sum(-1)


def motor(theta, omega, alpha, pa, pb, pc, mu, P, m):
    n, D, J = m["n"], m["D"], m["J"]
    phi = m.get("phi", np.pi / n)
    S = port_sum(theta, n)
    dp = pa - pb
    Tp = D / (2 * n) * dp * S
    sg = np.sign(omega)
    T = (Tp - J * alpha - P["Kv"] * D * mu * omega
         - D * (pa + pb) * P["KF"] * sg - P["TFc"] * sg)
    KLA = P["KL0"] * (1 + P["KL_a1"] * np.cos(n * theta) + P["KL_b1"] * np.sin(n * theta))
    KLB = P["KL0"] * (1 + P["KL_a1"] * np.cos(n * (theta - phi)) + P["KL_b1"] * np.sin(n * (theta - phi)))
    QA = D * omega / (2 * n) * S
    QLA = KLA * (pa - pc) / mu
    QLB = KLB * (pb - pc) / mu
    QAB = P["KAB"] * dp / mu
    return T, QA + QLA + QAB, -QA + QLB - QAB, QLA + QLB


def mean_model(omega, pa, pb, pc, mu, P, m):
    """theta-averaged running point (for held-out truth)"""
    D = m["D"]
    dp = pa - pb
    sg = np.sign(omega)
    T = D * dp / (2 * np.pi) - P["Kv"] * D * mu * omega - D * (pa + pb) * P["KF"] * sg - P["TFc"] * sg
    QLA = P["KL0"] * (pa - pc) / mu
    QLB = P["KL0"] * (pb - pc) / mu
    QAB = P["KAB"] * dp / mu
    Qs = D * omega / (2 * np.pi)
    return T, Qs + QLA + QAB, -Qs + QLB - QAB, QLA + QLB


# ---------------------------------------------------------------- bench
class Bench:
    def __init__(self, m, P, noise, rng, T0=40.0, drift_K_per_s=0.004, ar=0.0):
        self.m, self.P, self.noise, self.rng = m, P, noise, rng
        self.Tglob = T0
        self.drift = drift_K_per_s
        self.theta = rng.uniform(0, 2 * np.pi)
        self.ar = ar  # AR(1) coefficient of sensor noise (band-limited noise), 0 = white

    def _noise(self, sig, N):
        e = self.rng.normal(0, sig, N)
        if self.ar > 0:
            out = np.empty(N)
            acc = 0.0
            s = math.sqrt(1 - self.ar ** 2)
            for i in range(N):
                acc = self.ar * acc + s * e[i]
                out[i] = acc
            return out
        return e

    def run(self, rate, dur, omega_fn, pa_fn, pb_fn, pc, T_level=None, alpha_fn=None):
        N = int(round(rate * dur))
        t = np.arange(N) / rate
        # fine internal integration of theta (exact for constant speed)
        om = omega_fn(t)
        al = alpha_fn(t) if alpha_fn else np.zeros(N)
        # theta(t) = theta0 + integral omega dt; integrate with sub-steps
        sub = 20
        tf = np.arange(N * sub) / (rate * sub)
        omf = omega_fn(tf)
        thf = self.theta + np.concatenate([[0], np.cumsum(0.5 * (omf[1:] + omf[:-1]) / (rate * sub))])
        th = thf[::sub]
        self.theta = float(thf[-1] + omf[-1] / (rate * sub))
        if T_level is not None:
            self.Tglob = T_level + (self.Tglob - T_level) * 0.0
        T_C = self.Tglob + self.drift * t
        self.Tglob = float(T_C[-1] + self.drift / rate)
        pa, pb = pa_fn(t), pb_fn(t)
        pcv = np.full(N, pc)
        mu = mu_of_T(T_C)
        T, qa, qb, qc = motor(th, om, al, pa * BAR, pb * BAR, pcv * BAR, mu, self.P, self.m)
        nz = self.noise
        out = dict(
            time_s=t,
            speed_rpm=om / RPM + self._noise(nz["rpm"], N),
            torque_Nm=T + self._noise(nz["T"], N),
            p_a_bar=pa + self._noise(nz["p"], N),
            p_b_bar=pb + self._noise(nz["p"], N),
            p_case_bar=pcv + self._noise(nz["p"] * 0.2, N),
            q_a_lpm=qa / LPM + self._noise(nz["q"], N),
            q_b_lpm=qb / LPM + self._noise(nz["q"], N),
            q_case_lpm=qc / LPM + self._noise(nz["q"] * 0.5, N),
            oil_temp_C=T_C + self.rng.normal(0, 0.05, N),
        )
        truth = dict(theta=th, T=T, mu=mu)
        return out, truth


COLS = ["time_s", "run_id", "protocol", "speed_rpm", "torque_Nm", "p_a_bar", "p_b_bar",
        "p_case_bar", "q_a_lpm", "q_b_lpm", "q_case_lpm", "oil_temp_C"]
FMT = {"time_s": "%.6f", "speed_rpm": "%.3f", "torque_Nm": "%.3f", "p_a_bar": "%.3f", "p_b_bar": "%.3f",
       "p_case_bar": "%.3f", "q_a_lpm": "%.4f", "q_b_lpm": "%.4f", "q_case_lpm": "%.4f", "oil_temp_C": "%.3f"}


def write_csv(path, rows, with_run_id=True):
    cols = [c for c in COLS if with_run_id or c != "run_id"]
    with open(path, "w") as f:
        f.write(",".join(cols) + "\n")
        for r in rows:
            N = len(r["time_s"])
            arrs = []
            for c in cols:
                if c in ("run_id", "protocol"):
                    arrs.append(np.full(N, r[c], dtype=object))
                else:
                    arrs.append(np.char.mod(FMT[c], r[c]))
            for i in range(N):
                f.write(",".join(str(a[i]) for a in arrs) + "\n")


def write_motor(path, m, name, leak_phase=None):
    with open(path, "w") as f:
        f.write(f'[motor]\nname = "{name}"\npistons = {m["n"]}\ndisplacement_cm3 = {m["D"]*1e6:.4g}\n'
                f'inertia_kg_m2 = {m["J"]}\n')
        f.write(f'\n[oil]\nname = "{OIL["name"]}"\nnu40_cSt = {OIL["nu40_cSt"]}\nnu100_cSt = {OIL["nu100_cSt"]}\n'
                f'density15_kg_m3 = {OIL["density15_kg_m3"]}\n')


def params_for(D_cc, rng):
    s = D_cc / 80.0
    return dict(Kv=5000.0 * rng.uniform(0.7, 1.4), KF=0.003 * rng.uniform(0.7, 1.4), TFc=3.0 * s * rng.uniform(0.7, 1.4),
                KL0=5e-14 * s ** (2 / 3) * rng.uniform(0.7, 1.4), KL_a1=0.15, KL_b1=0.08,
                KAB=2e-14 * s ** (2 / 3) * rng.uniform(0.7, 1.4), KFS=0.015, Ks=1.0)


def steady_case(name, n, D_cc, rates, speeds, dps, backs, temps, dur, noise, seed,
                pump=False, with_run_id=True, gap=None, ar=0.0, heldout=None, protocol="constant_speed",
                phase_reset=False):
    """rates: one rate, or dict speed->rate"""
    rng = np.random.default_rng(seed)
    m = dict(n=n, D=D_cc * 1e-6, J=0.0002 * D_cc / 10)
    P = params_for(D_cc, rng)
    bench = Bench(m, P, noise, rng, ar=ar)
    rows = []
    k = 0
    tglob = 0.0
    for T_level in temps:
        bench.Tglob = T_level
        for direction in (+1, -1):
            for sp in speeds:
                for dp in dps:
                    for pbk in backs:
                        modes = [+1, -1] if pump else [+1]
                        for mode in modes:
                            k += 1
                            rate = rates[sp] if isinstance(rates, dict) else rates
                            om = direction * sp * RPM
                            # motor mode: high pressure on the side that drives direction
                            hp_on_A = (direction > 0) == (mode > 0)
                            pa = pbk + dp if hp_on_A else pbk
                            pb = pbk if hp_on_A else pbk + dp
                            d = dur if not callable(dur) else dur(sp)
                            if phase_reset:  # shaft stopped/accelerated between set points: random start angle
                                bench.theta = rng.uniform(0, 2 * np.pi)
                            out, tr = bench.run(rate, d, lambda t, om=om: np.full_like(t, om),
                                                lambda t, pa=pa: np.full_like(t, pa),
                                                lambda t, pb=pb: np.full_like(t, pb),
                                                pc=rng.uniform(0.5, 2.0))
                            out["run_id"] = f"r{k:03d}"
                            out["protocol"] = protocol
                            if gap is not None:
                                out["time_s"] = out["time_s"] + tglob
                                tglob = out["time_s"][-1] + gap
                            rows.append(out)
    d = os.path.join(HERE, "cases", name)
    os.makedirs(d, exist_ok=True)
    write_csv(os.path.join(d, "log.csv"), rows, with_run_id=with_run_id)
    write_motor(os.path.join(d, "motor.toml"), m, name)
    json.dump(dict(parameters=P, motor=dict(n=n, D_m3=m["D"], J=m["J"]), noise=noise, seed=seed, ar=ar,
                   runs=k, rows=int(sum(len(r["time_s"]) for r in rows))),
              open(os.path.join(d, "truth.json"), "w"), indent=1)
    if heldout:
        write_heldout(d, heldout, P, m)
    return d


def write_heldout(d, pts, P, m):
    with open(os.path.join(d, "heldout.csv"), "w") as f1, open(os.path.join(d, "heldout_truth.csv"), "w") as f2:
        f1.write("point_id,speed_rpm,p_a_bar,p_b_bar,p_case_bar,oil_temp_C\n")
        f2.write("point_id,speed_rpm,p_a_bar,p_b_bar,p_case_bar,oil_temp_C,torque_Nm,q_a_lpm,q_b_lpm,q_case_lpm\n")
        for i, (sp, pa, pb, pc, T) in enumerate(pts):
            mu = float(mu_of_T(T))
            tq, qa, qb, qc = mean_model(sp * RPM, pa * BAR, pb * BAR, pc * BAR, mu, P, m)
            f1.write(f"h{i:02d},{sp},{pa},{pb},{pc},{T}\n")
            f2.write(f"h{i:02d},{sp},{pa},{pb},{pc},{T},{tq:.6f},{qa/LPM:.6f},{qb/LPM:.6f},{qc/LPM:.6f}\n")


def sine_case(name, n, D_cc, rate, period, dur, noise, seed, heldout=None):
    rng = np.random.default_rng(seed)
    m = dict(n=n, D=D_cc * 1e-6, J=0.0002 * D_cc / 10)
    P = params_for(D_cc, rng)
    bench = Bench(m, P, noise, rng, T0=45.0, drift_K_per_s=0.005)
    w0 = 600 * RPM
    om_fn = lambda t: w0 * np.sin(2 * np.pi * t / period)
    al_fn = lambda t: w0 * 2 * np.pi / period * np.cos(2 * np.pi * t / period)
    mag = lambda t: 40 + 160 * np.abs(np.sin(2 * np.pi * t / 37.3 + 0.4))
    back = 10.0
    pa_fn = lambda t: back + np.where(om_fn(t) >= 0, mag(t), 0.0)
    pb_fn = lambda t: back + np.where(om_fn(t) < 0, mag(t), 0.0)
    out, tr = bench.run(rate, dur, om_fn, pa_fn, pb_fn, pc=1.0, alpha_fn=al_fn)
    out["run_id"] = "sine1"
    out["protocol"] = "constant_flow"
    d = os.path.join(HERE, "cases", name)
    os.makedirs(d, exist_ok=True)
    write_csv(os.path.join(d, "log.csv"), [out])
    write_motor(os.path.join(d, "motor.toml"), m, name)
    json.dump(dict(parameters=P, motor=dict(n=n, D_m3=m["D"], J=m["J"]), noise=noise, seed=seed,
                   rows=len(out["time_s"])), open(os.path.join(d, "truth.json"), "w"), indent=1)
    if heldout:
        write_heldout(d, heldout, P, m)


if __name__ == "__main__":
    import sys
    which = sys.argv[1:] or ["A", "A2", "B", "B2", "C", "C2", "D", "E", "F"]
    lowN = dict(rpm=0.05, T=0.05, p=0.1, q=0.01)
    # A: baseline 9 pistons, 80 cc, 100 Hz, one file with run ids, two temperature levels
    if "A" in which:
        steady_case("A_n9_D80_100Hz", 9, 80, 100.0, [30, 100, 300, 1000, 2000], [50, 150, 250], [5, 20], [40, 60],
                    dur=3.0, noise=dict(rpm=0.3, T=0.8, p=0.3, q=0.05), seed=1,
                    heldout=[(500, 200, 10, 1, 50), (1500, 110, 15, 1, 45), (-700, 10, 180, 1, 55),
                             (50, 230, 5, 1, 42), (-2000, 5, 60, 1.5, 58)])
    # A2: as A, but every run starts at a random shaft angle (no phase continuity between runs)
    if "A2" in which:
        steady_case("A2_n9_D80_100Hz_randphase", 9, 80, 100.0, [30, 100, 300, 1000, 2000], [50, 150, 250], [5, 20], [40, 60],
                    dur=3.0, noise=dict(rpm=0.3, T=0.8, p=0.3, q=0.05), seed=11, phase_reset=True)
    # B2: as B, random start angle per run
    if "B2" in which:
        steady_case("B2_n5_D10_1kHz_instep_randphase", 5, 10, 1000.0, [120, 600, 1200, 2400, 3000], [40, 120, 200], [5, 15], [45],
                    dur=2.0, noise=dict(rpm=0.5, T=0.03, p=0.2, q=0.005), seed=12, phase_reset=True)
    # B: 5 pistons, 10 cc, 1 kHz, round speeds in step with the pitch frequency
    if "B" in which:
        steady_case("B_n5_D10_1kHz_instep", 5, 10, 1000.0, [120, 600, 1200, 2400, 3000], [40, 120, 200], [5, 15], [45],
                    dur=2.0, noise=dict(rpm=0.5, T=0.03, p=0.2, q=0.005), seed=2,
                    heldout=[(900, 150, 10, 1, 46), (-1800, 8, 100, 1, 46), (2000, 60, 5, 1, 47)])
    # C: 10 pistons, 125 cc, 20 Hz, 30 s runs, pump-mode points, in-step at 60/120 rpm
    if "C" in which:
        steady_case("C_n10_D125_20Hz_pump", 10, 125, 20.0, [60, 120, 250, 700], [60, 180], [5, 25], [50],
                    dur=30.0, noise=dict(rpm=0.3, T=1.0, p=0.3, q=0.08), seed=3, pump=True,
                    heldout=[(400, 120, 10, 1, 52), (-400, 120, 10, 1, 52), (200, 15, 150, 1, 52)])
    # C2: as C, random start angle per run
    if "C2" in which:
        steady_case("C2_n10_D125_20Hz_pump_randphase", 10, 125, 20.0, [60, 120, 250, 700], [60, 180], [5, 25], [50],
                    dur=30.0, noise=dict(rpm=0.3, T=1.0, p=0.3, q=0.08), seed=13, pump=True, phase_reset=True)
    # D: 7 pistons, 250 cc, 5 kHz, 2 s runs, no run_id, runs separated by a time gap, higher noise
    if "D" in which:
        steady_case("D_n7_D250_5kHz_norunid", 7, 250, 5000.0, [50, 300, 1000], [80, 240], [10], [55],
                    dur=2.0, noise=dict(rpm=1.0, T=4.0, p=0.8, q=0.3), seed=4, with_run_id=False, gap=5.0,
                    heldout=[(600, 160, 10, 1, 56), (-150, 10, 200, 1, 56)])
    # E: 9 pistons, 45 cc, continuous sinusoidal motion (constant_flow), 100 Hz
    if "E" in which:
        sine_case("E_n9_D45_sine", 9, 45, 100.0, period=150.0, dur=600.0,
                  noise=dict(rpm=0.3, T=0.3, p=0.3, q=0.03), seed=5,
                  heldout=[(300, 10 + 100, 10, 1, 47), (-450, 10, 160, 1, 47)])
    # F: 7 pistons, 160 cc, mixed 20 Hz / 5 kHz, band-limited (AR1) sensor noise, constant_pressure
    if "F" in which:
        steady_case("F_n7_D160_mixed_AR", 7, 160, {20: 20.0, 100: 20.0, 400: 5000.0, 1500: 5000.0},
                    [20, 100, 400, 1500], [70, 210], [8, 30], [40, 48],
                    dur=lambda sp: 20.0 if sp <= 100 else 2.0, noise=dict(rpm=0.5, T=1.5, p=0.4, q=0.08),
                    seed=6, ar=0.9, protocol="constant_pressure",
                    heldout=[(800, 140, 10, 1, 44), (-60, 8, 150, 1, 44)])
