#!/usr/bin/env python3
"""compare.py CASE_DIR RESULT_DIR [--points]  -> z of every parameter; optionally the
points motorid extracted vs the theta-averaged truth at their own (mean) conditions."""
import json, sys, csv, math
import numpy as np
sys.path.insert(0, __import__("os").path.dirname(__file__))
from gen import mean_model, mu_of_T, BAR, LPM, RPM

case, res = sys.argv[1], sys.argv[2]
T = json.load(open(f"{case}/truth.json"))
R = json.load(open(f"{res}/result.json"))
P = T["parameters"]
m = dict(n=T["motor"]["n"], D=T["motor"]["D_m3"], J=T["motor"]["J"])
worst = (0, None)
print(f"{'param':6s} {'truth':>12s} {'value':>12s} {'std':>10s} {'z':>7s}")
zs = {}
for k, v in R["parameters"].items():
    if k not in P:
        continue
    if not v.get("identifiable") or v.get("value") is None:
        print(f"{k:6s} {P[k]:12.5g} {'-':>12s}  not identifiable")
        continue
    z = (v["value"] - P[k]) / v["std"] if v["std"] else float("inf")
    zs[k] = z
    print(f"{k:6s} {P[k]:12.5g} {v['value']:12.5g} {v['std']:10.3g} {z:7.2f}")
    if abs(z) > abs(worst[0]):
        worst = (z, k)
print("WORST", worst)
json.dump(zs, open(f"{res}/z.json", "w"))
if "--points" in sys.argv:
    rows = list(csv.DictReader(open(f"{res}/points_from_logs.csv")))
    print(f"{'pt':5s} {'rpm':>8s} {'dp':>7s} {'cov':>6s} {'dT':>8s} {'Tstd/sqrtN':>8s} {'zT':>6s} {'zQc':>6s} {'zQa':>6s}")
    for r in rows:
        f = lambda c: float(r[c]) if r.get(c) not in (None, "") else float("nan")
        mu = float(mu_of_T(f("oil_temp_C")))
        tq, qa, qb, qc = mean_model(f("speed_rpm") * RPM, f("p_a_bar") * BAR, f("p_b_bar") * BAR, f("p_case_bar") * BAR, mu, P, m)
        N = f("n_samples")
        se = f("torque_std_Nm") / math.sqrt(N)
        zT = (f("torque_Nm") - tq) / se
        zQc = (f("q_case_lpm") - qc / LPM) / (f("q_case_std_lpm") / math.sqrt(N))
        zQa = (f("q_a_lpm") - qa / LPM) / (f("q_a_std_lpm") / math.sqrt(N))
        print(f"{r['point_id'][:5]:5s} {f('speed_rpm'):8.1f} {f('p_a_bar')-f('p_b_bar'):7.1f} {f('ripple_coverage'):6.3f} "
              f"{f('torque_Nm')-tq:8.3f} {se:8.3f} {zT:6.1f} {zQc:6.1f} {zQa:6.1f}")
