"""Unit factors and the table of measured channels: the one place they are written.

SI inside, units only at the edges.  Every factor is named ``<TO>_PER_<FROM>``,
so a name reads one way only: a speed in rpm times :data:`RAD_S_PER_RPM` is a
speed in rad/s; a speed in rad/s times :data:`RPM_PER_RAD_S` is one in rpm.
The two directions are two names, each the exact literal the code used before
(so conversions give the same floating-point numbers, bit for bit).

:data:`FORMAT_COLUMNS` is the bench-log format's channel table
(BENCH_LOG_FORMAT.md): canonical SI column → (file column, factor to SI).
"""

from __future__ import annotations

import math

# --------------------------------------------------------------- speed, angle

#: [rad/s] per [rpm]
RAD_S_PER_RPM = 2.0 * math.pi / 60.0
#: [rpm] per [rad/s]
RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
#: [rad] per [°]
RAD_PER_DEG = math.pi / 180.0

# --------------------------------------------------------------- pressure

#: [Pa] per [bar]
PA_PER_BAR = 1e5
#: [Pa] per [lbf/in²] (psi)
PA_PER_PSI = 6894.757293168361

# --------------------------------------------------------------- flow, volume

#: [m³/s] per [L/min]
M3S_PER_LPM = 1e-3 / 60.0
#: [L/min] per [m³/s]
LPM_PER_M3S = 6e4
#: [m³] per [cm³]
M3_PER_CM3 = 1e-6
#: [m³] per US gallon
M3_PER_US_GALLON = 3.785411784e-3

# --------------------------------------------------------------- torque, viscosity

#: [N·m] per [lbf·ft]
NM_PER_LBF_FT = 1.3558179483314004
#: [Pa·s] per [mPa·s] (cP)
PA_S_PER_MPAS = 1e-3

# --------------------------------------------------------------- the measured channels

#: canonical SI column ← (column of the bench-log format in its own units, factor to SI)
FORMAT_COLUMNS = {
    "time_s": ("time_s", 1.0),
    "theta_rad": ("shaft_angle_deg", RAD_PER_DEG),
    "speed_rad_s": ("speed_rpm", RAD_S_PER_RPM),
    "torque_Nm": ("torque_Nm", 1.0),
    "p_a_Pa": ("p_a_bar", PA_PER_BAR),
    "p_b_Pa": ("p_b_bar", PA_PER_BAR),
    "p_case_Pa": ("p_case_bar", PA_PER_BAR),
    "q_a_m3_s": ("q_a_lpm", M3S_PER_LPM),
    "q_b_m3_s": ("q_b_lpm", M3S_PER_LPM),
    "q_case_m3_s": ("q_case_lpm", M3S_PER_LPM),
    "oil_temp_C": ("oil_temp_C", 1.0),
    "viscosity_Pa_s": ("viscosity_mPas", PA_S_PER_MPAS),
}
#: the columns of a bench-log frame in SI, in order
SI_COLUMNS = ["run_id", "protocol", *FORMAT_COLUMNS]
#: the model's running channels (motorid.model.Channels), SI: torque [N·m], flows [m³/s]
RUNNING_CHANNELS = ("torque", "q_a", "q_b", "q_case")
#: each fitted channel in words (fit warnings, diagnose's located structure)
CHANNEL_WORDS = {"torque": "running torque", "q_a": "port A flow", "q_b": "port B flow",
                 "q_case": "case-drain flow", "breakaway": "breakaway (held) torque"}
#: every fitted channel: the running ones and the held torque at breakaway [N·m]
CHANNELS = (*RUNNING_CHANNELS, "breakaway")
