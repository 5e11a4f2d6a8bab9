"""The peer baseline: the fit an engineer would write by hand.

pandas to read, a numpy re-implementation of the Bartos model (per-piston sums
evaluated in every call), scipy.optimize.least_squares with finite-difference
Jacobians, noise levels from a first pass.  Used by `make bench` only, side by
side with motorid on the same campaign; it is not part of the package.

    python benchmarks/baseline.py LOG... --motor SPEC.toml --out result.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import tomllib

import numpy as np
import pandas as pd
from scipy.optimize import least_squares

NAMES = ["Kv", "KF", "KFS", "TFc", "Ks", "KL0", "KL_a1", "KL_b1", "KAB"]
X0 = np.array([1e3, 1e-3, 1e-2, 1.0, 1.0, 1e-13, 0.0, 0.0, 1e-13])


def walther(temp_c, nu40, nu100, rho15):
    t1, t2 = np.log10(313.15), np.log10(373.15)
    z1, z2 = np.log10(np.log10(nu40 + 0.7)), np.log10(np.log10(nu100 + 0.7))
    b = (z1 - z2) / (t2 - t1)
    a = z1 + b * t1
    nu = 10 ** (10 ** (a - b * np.log10(temp_c + 273.15))) - 0.7
    return rho15 / (1 + 6.5e-4 * (temp_c - 15)) * nu * 1e-6


def load(paths, spec):
    df = pd.concat([pd.read_csv(p) for p in paths], ignore_index=True)
    df["theta"] = np.radians(df["shaft_angle_deg"])
    df["w"] = df["speed_rpm"] * 2 * np.pi / 60
    for c in ("p_a", "p_b", "p_case"):
        df[c] = df[f"{c}_bar"] * 1e5
    for c in ("q_a", "q_b", "q_case"):
        df[c] = df[f"{c}_lpm"] / 6e4
    oil = spec["oil"]
    df["mu"] = (df["viscosity_mPas"] * 1e-3 if "viscosity_mPas" in df
                else walther(df["oil_temp_C"], oil["nu40_cSt"], oil["nu100_cSt"], oil["density15_kg_m3"]))
    run = df[df.protocol != "startability"].copy()
    # steady state: drop the first 20 % of every run
    run["k"] = run.groupby("run_id").cumcount() / run.groupby("run_id")["time_s"].transform("size")
    run = run[run.k > 0.2]
    run["dir"] = np.sign(run.groupby("run_id")["w"].transform("median"))
    ev = []
    for rid, g in df[df.protocol == "startability"].groupby("run_id"):
        moving = np.abs(g["w"].to_numpy()) > 0.01
        if not moving.any():
            continue
        i = int(np.argmax(moving))
        ev.append(dict(theta=g["theta"].iloc[i], p_a=g["p_a"].iloc[i], p_b=g["p_b"].iloc[i],
                       held=np.median(g["torque_Nm"].iloc[: max(i - 5, 1)]), dir=np.sign(g["w"].iloc[i])))
    return run, pd.DataFrame(ev)


def port_sum(theta, n):
    c = np.cos(theta[:, None] + 2 * np.pi * np.arange(n) / n)
    return np.where(c > 0, c, 0).sum(axis=1)


def model(x, run, ev, D, n, phase):
    Kv, KF, KFS, TFc, Ks, KL0, a1, b1, KAB = x
    th, w, pa, pb, pc, mu, d = (run[c].to_numpy() for c in ("theta", "w", "p_a", "p_b", "p_case", "mu", "dir"))
    S = port_sum(th, n)
    T = D * (pa - pb) / (2 * n) * S - Kv * D * mu * w - D * (pa + pb) * KF * d - TFc * d
    kla = KL0 * (1 + a1 * np.cos(n * th) + b1 * np.sin(n * th))
    klb = KL0 * (1 + a1 * np.cos(n * (th - phase)) + b1 * np.sin(n * (th - phase)))
    qla, qlb, qab = kla * (pa - pc) / mu, klb * (pb - pc) / mu, KAB * (pa - pb) / mu
    qs = D * w / (2 * n) * S
    out = [T, qs + qla + qab, -qs + qlb - qab, qla + qlb]
    if len(ev):
        Se = port_sum(ev["theta"].to_numpy(), n)
        tp = D * (ev.p_a - ev.p_b).to_numpy() / (2 * n) * Se
        brk = D * (ev.p_a + ev.p_b).to_numpy() * (KF + KFS) + TFc * (1 + Ks)
        out.append(tp - ev["dir"].to_numpy() * brk)
    return out


def fit(paths, spec_path):
    spec = tomllib.load(open(spec_path, "rb"))
    D, n = spec["motor"]["displacement_cm3"] * 1e-6, spec["motor"]["pistons"]
    phase = np.radians(spec["motor"].get("leak_phase_deg", 180.0 / n))
    run, ev = load(paths, spec)
    t0 = time.time()
    meas = [run["torque_Nm"].to_numpy(), run["q_a"].to_numpy(), run["q_b"].to_numpy(), run["q_case"].to_numpy()]
    if len(ev):
        meas.append(ev["held"].to_numpy())
    sig = [np.nanstd(np.diff(m)) / np.sqrt(2) or 1.0 for m in meas]

    def resid(x):
        pred = model(x * X_SCALE, run, ev, D, n, phase)
        return np.concatenate([np.nan_to_num((m - p) / s) for m, p, s in zip(meas, pred, sig)])

    res = least_squares(resid, np.ones(len(NAMES)), method="trf", x_scale="jac")
    for _ in range(2):  # noise from the residuals, then refit
        pred = model(res.x * X_SCALE, run, ev, D, n, phase)
        sig = [np.nanstd(m - p) or 1.0 for m, p in zip(meas, pred)]
        res = least_squares(resid, res.x, method="trf", x_scale="jac")
    J = res.jac
    cov = np.linalg.pinv(J.T @ J)
    values = res.x * X_SCALE
    std = np.sqrt(np.diag(cov)) * np.abs(X_SCALE)
    return {k: {"value": float(v), "std": float(s)} for k, v, s in zip(NAMES, values, std)}, time.time() - t0


X_SCALE = np.array([5e3, 3e-3, 1.5e-2, 3.0, 1.0, 5e-14, 0.1, 0.1, 2e-14])


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("logs", nargs="+")
    ap.add_argument("--motor", required=True)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    result, seconds = fit(a.logs, a.motor)
    json.dump({"parameters": result, "fit_seconds": seconds}, open(a.out, "w"), indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
