"""Simulated operating-point tables (steady loss maps) from the one model.

A map point is the θ-average of :func:`motorid.model.predict`
(:func:`motorid.identify.tables.point_channels`) at a steady (ΔP, speed), plus
Gaussian noise on each output: what an ISO 4409 efficiency test writes.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

BAR, RPM, LPM = 1e5, 2 * np.pi / 60, 1e-3 / 60


def map_grid(speeds_rpm, dps_bar, quadrants: int = 4, p_low_bar: float = 0.0):
    """Grid points (speed [rpm], P_A [bar], P_B [bar]) over ``speeds_rpm`` × ``dps_bar``.

    quadrants : 1 (motor mode, ω > 0, ΔP > 0), 2 (both signs of ΔP at ω > 0: motor and
    pump mode) or 4 (both signs of both).  The low-pressure port sits at ``p_low_bar``.
    """
    rows = []
    s_signs = (1, -1) if quadrants == 4 else (1,)
    p_signs = (1, -1) if quadrants >= 2 else (1,)
    for ss in s_signs:
        for ps in p_signs:
            for n in speeds_rpm:
                for dp in dps_bar:
                    pa, pb = (p_low_bar + dp, p_low_bar) if ps > 0 else (p_low_bar, p_low_bar + dp)
                    rows.append((ss * n, pa, pb))
    return np.array(rows, dtype=float)


def simulate_map(spec, params: dict, grid, temp_C: float = 50.0, mechanisms=(), noise: dict | None = None,
                 rng=None, displacement_cm3=None, p_case_bar: float = 0.0) -> pd.DataFrame:
    """A table in the format's units (BENCH_LOG_FORMAT.md) at ``grid`` (from :func:`map_grid`).

    noise : channel → σ in the table's units ("torque_Nm", "q_a_lpm", "q_b_lpm",
    "q_case_lpm"); displacement_cm3 : per-point displacement (a variable unit), or None.
    """
    from motorid.identify.tables import angle_samples, point_channels
    from motorid.io.tables import PointTable

    rng = np.random.default_rng(0) if rng is None else rng
    grid = np.asarray(grid, dtype=float)
    n = len(grid)
    mu = float(spec.oil.viscosity(temp_C))
    disp = np.full(n, spec.displacement) if displacement_cm3 is None else np.asarray(displacement_cm3) * 1e-6
    nan = np.full(n, np.nan)
    t = PointTable(np.array([f"P{i:03d}" for i in range(n)], dtype=object), grid[:, 0] * RPM, grid[:, 1] * BAR,
                   grid[:, 2] * BAR, np.full(n, p_case_bar * BAR), np.full(n, temp_C), np.full(n, mu), disp,
                   {c: nan for c in ("torque", "q_a", "q_b", "q_case")},
                   {c: np.ones(n) for c in ("torque", "q_a", "q_b", "q_case")}, np.array(["sim"] * n, dtype=object),
                   np.arange(n), True, {}, displacement_cm3 is not None)
    ch = point_channels(params, spec, angle_samples(spec, t, mechanisms, params),
                        disp if displacement_cm3 is not None else None, mechanisms)
    out = pd.DataFrame({"point_id": t.point_id, "speed_rpm": grid[:, 0], "p_a_bar": grid[:, 1],
                        "p_b_bar": grid[:, 2], "p_case_bar": p_case_bar, "oil_temp_C": temp_C})
    if displacement_cm3 is not None:
        out["displacement_cm3"] = np.asarray(displacement_cm3, dtype=float)
    noise = noise or {}
    for col, v, unit in (("torque_Nm", ch.torque, 1.0), ("q_a_lpm", ch.q_a, LPM), ("q_b_lpm", ch.q_b, LPM),
                         ("q_case_lpm", ch.q_case, LPM)):
        out[col] = np.asarray(v) / unit + noise.get(col, 0.0) * rng.standard_normal(n)
    return out
