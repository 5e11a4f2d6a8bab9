#!/usr/bin/env python3
"""cmp_pred.py PRED.csv HELDOUT_TRUTH.csv -> z of each prediction against the theta-averaged truth, using the 95% confidence band"""
import csv, sys
P = {r["point_id"]: r for r in csv.DictReader(open(sys.argv[1]))}
T = {r["point_id"]: r for r in csv.DictReader(open(sys.argv[2]))}
for pid, t in T.items():
    p = P.get(pid)
    if p is None:
        print(pid, "missing in prediction"); continue
    out = [pid, f"rpm={t['speed_rpm']}", f"dp={float(t['p_a_bar'])-float(t['p_b_bar']):.0f}", f"mode={p.get('mode')}"]
    for c in ("torque_Nm", "q_a_lpm", "q_b_lpm", "q_case_lpm"):
        if p.get(c) in (None, ""):
            out.append(f"{c}=empty"); continue
        v, lo, hi, tv = float(p[c]), float(p[c + "_lo95"]), float(p[c + "_hi95"]), float(t[c])
        sd = (hi - lo) / 3.92
        out.append(f"{c}: {v:.4g} vs {tv:.4g} z={(v-tv)/sd if sd>0 else float('inf'):.1f}")
    out.append(p.get("note", "")[:120])
    print("  ".join(out))
