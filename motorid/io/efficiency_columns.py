"""Efficiency and loss columns of an operating-point table: a data sheet's η_v, η_hm, η, or a loss
table's T_loss and Q_loss → torque and flow (loss columns: :func:`outputs_from_losses`).

Makers publish loss maps as efficiencies more often than as torque and flow.  With
the theoretical flow Q_th = D|ω|/2π and torque T_th = D|ΔP|/2π they give back the
shaft torque and the flow into the high-pressure port exactly (the inverse of
:func:`motorid.physics.efficiency.efficiencies`, ISO 4409 definitions, mode from
the sign of ΔP·ω):

motor mode (ΔP·ω > 0)    T = η_hm·T_th·sgn ω        Q_hp = Q_th/η_v
pump mode  (ΔP·ω < 0)    T = −T_th·sgn ω/η_hm       Q_hp = −η_v·Q_th

where the table gives the overall η with one of the two, the other is η over it.
Q_hp is the flow into port A where ΔP ≥ 0, into port B where ΔP < 0; the other
port's flow and the case drain are not in an efficiency.  Headers:
``volumetric_efficiency``, ``hydromechanical_efficiency``, ``overall_efficiency``
(fractions, as ``motorid predict`` writes them), the same with ``_pct`` (per
cent), or ``eta_v``, ``eta_hm``, ``eta`` (``eta_t``) with or without ``_pct``.
"""

from __future__ import annotations

import numpy as np

#: header (normalized) → (efficiency, factor to a fraction)
HEADERS = {}
for _key, _names in (("v", ("volumetric_efficiency", "eta_v", "eff_v", "vol_eff")),
                     ("hm", ("hydromechanical_efficiency", "mechanical_efficiency", "eta_hm", "eta_m", "eff_hm",
                             "hm_eff")),
                     ("t", ("overall_efficiency", "total_efficiency", "eta", "eta_t", "eff_t", "overall_eff"))):
    for _name in _names:
        HEADERS[_name] = (_key, 1.0)
        HEADERS[_name + "_pct"] = (_key, 0.01)
        HEADERS[_name + "_percent"] = (_key, 0.01)
        HEADERS[_name + "_%"] = (_key, 0.01)

WORDS = {"v": "volumetric", "hm": "hydromechanical", "t": "overall"}


def loss_headers(torque_units: dict, flow_units: dict) -> dict:
    """Loss columns (normalized header → (loss, factor to SI)): ``torque_loss_<torque unit>`` and
    ``q_loss_`` / ``volumetric_loss_`` / ``flow_loss_<flow unit>`` (the units of the log reader)."""
    out = {f"torque_loss_{u}": ("torque", f) for u, f in torque_units.items()}
    for base in ("q_loss", "volumetric_loss", "flow_loss"):
        out.update({f"{base}_{u}": ("q", f) for u, f in flow_units.items()})
    return out


def outputs_from_losses(loss: dict, speed, p_a, p_b, displacement) -> tuple[dict, list]:
    """Loss columns → ({"torque", "q_a", "q_b"} [SI, NaN where not given], words for the table's notes).

    The convention of Simscape's tabulated-loss motor blocks (and of ``motorid export --format
    simscape``), in every quadrant, with no mode switch:

        T   = D ΔP / 2π − T_loss          (shaft torque delivered; T_loss has the sign of ω, plus
                                           its pressure part)
        Q_hp = ±(D ω / 2π + Q_loss)       (flow into the high-pressure port, + for A where ΔP ≥ 0,
                                           − for B where ΔP < 0; Q_loss, the leakage, signed like ΔP)

    The block has no case drain, so its inlet and outlet flows are one; a motor's are not, and the
    loss is read, as ``motorid export --format simscape`` writes it, at the high-pressure port.
    loss : "torque" [N·m] and/or "q" [m³/s] per point (NaN where empty); speed [rad/s], pressures
    [Pa], displacement [m³/rev] per point → {"torque", "q_a", "q_b"}."""
    dp = np.asarray(p_a, float) - np.asarray(p_b, float)
    w = np.asarray(speed, float)
    d = np.asarray(displacement, float)
    out, parts = {}, []
    if "torque" in loss:
        out["torque"] = d * dp / (2 * np.pi) - np.asarray(loss["torque"], float)
        parts.append("the torque as T = DΔP/2π − T_loss")
    if "q" in loss:
        inlet = d * w / (2 * np.pi) + np.asarray(loss["q"], float)
        out["q_a"] = np.where(dp >= 0, inlet, np.nan)
        out["q_b"] = np.where(dp < 0, -inlet, np.nan)
        parts.append("the flow into the high-pressure port as ±(Dω/2π + Q_loss) (Q_loss signed like ΔP: into A "
                     "where ΔP ≥ 0, into B where ΔP < 0)")
    notes = [f"{' and '.join(parts)} from the loss columns (Simscape's tabulated-loss convention); the "
             "other port and the case drain are not in a loss column"]
    return out, notes


def outputs_from_efficiencies(eff: dict, speed, p_a, p_b, displacement) -> tuple[dict, list]:
    """Efficiencies (key "v", "hm", "t" → fractions per point, NaN where empty) → ({"torque", "q_a",
    "q_b"} [SI, NaN where not given], words for the table's notes).  speed [rad/s], pressures [Pa],
    displacement [m³/rev] per point."""
    n = np.asarray(speed).size
    nan = np.full(n, np.nan)
    v, hm, t = (np.asarray(eff.get(k, nan), dtype=float) for k in ("v", "hm", "t"))
    with np.errstate(invalid="ignore", divide="ignore"):
        hm = np.where(np.isfinite(hm), hm, t / v)
        v = np.where(np.isfinite(v), v, t / hm)
    dp = np.asarray(p_a, float) - np.asarray(p_b, float)
    w = np.asarray(speed, float)
    power = dp * w
    motor, pump = power > 0, power < 0
    q_th = displacement * np.abs(w) / (2 * np.pi)
    t_th = displacement * np.abs(dp) / (2 * np.pi)
    sgn = np.sign(w)
    ok_hm = np.isfinite(hm) & (hm > 0)
    ok_v = np.isfinite(v) & (v > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        torque = np.where(motor & ok_hm, hm * t_th * sgn, np.where(pump & ok_hm, -t_th * sgn / hm, np.nan))
        q_hp = np.where(motor & ok_v, q_th / v, np.where(pump & ok_v, -v * q_th, np.nan))
    q_a = np.where(dp >= 0, q_hp, np.nan)
    q_b = np.where(dp < 0, q_hp, np.nan)
    given = ", ".join(WORDS[k] for k in ("v", "hm", "t") if k in eff)
    notes = [f"torque and the high-pressure port's flow derived from the {given} efficiency (ISO 4409: "
             f"T = η_hm·DΔP/2π, Q = Dω/2π/η_v in motor mode; T = DΔP/2π/η_hm, Q = η_v·Dω/2π in pump "
             f"mode); the other port and the case drain are not in an efficiency"]
    return {"torque": torque, "q_a": q_a, "q_b": q_b}, notes
