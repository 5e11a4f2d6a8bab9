"""Numbers and units for people: engineering-friendly text for the HTML report.

Every function returns HTML-safe text (``×10<sup>−14</sup>`` for powers of ten,
a true minus sign).  Values keep 4 significant digits, standard errors 2.
"""

from __future__ import annotations

import html
import math

from motorid.units import LPM_PER_M3S

MINUS = "\u2212"
# symbols of the parameters as MODEL.md writes them
SYMBOLS = {
    "Kv": "K<sub>v</sub>", "KF": "K<sub>F</sub>", "KFS": "K<sub>FS</sub>", "TFc": "T<sub>Fc</sub>",
    "Ks": "K<sub>s</sub>", "KL0": "K<sub>L0</sub>", "KAB": "K<sub>AB</sub>",
}


def symbol(name: str) -> str:
    """HTML symbol of a parameter (``KL_a1`` → a<sub>1</sub>)."""
    if name in SYMBOLS:
        return SYMBOLS[name]
    if name.startswith("KL_") and name[3:4] in ("a", "b") and name[4:].isdigit():
        return f"{name[3]}<sub>{name[4:]}</sub>"
    return html.escape(name)


def number(x, digits: int = 4) -> str:
    """``x`` with ``digits`` significant digits: plain between 10⁻³ and 10⁵, else a×10ⁿ."""
    if x is None:
        return "—"
    x = float(x)
    if not math.isfinite(x):
        return "—"
    if x == 0.0:
        return "0"
    if 1e-3 <= abs(x) < 1e5:
        text = f"{x:#.{digits}g}"
        if "e" in text:  # rounding pushed it over a decade boundary
            text = f"{x:.{digits}g}"
        text = text.rstrip(".")
        return text.replace("-", MINUS)
    exp = int(math.floor(math.log10(abs(x))))
    mant = x / 10.0**exp
    if round(abs(mant), digits - 1) >= 10.0:
        exp += 1
        mant = x / 10.0**exp
    return f"{mant:.{digits - 1}f}".replace("-", MINUS) + f"×10<sup>{str(exp).replace('-', MINUS)}</sup>"


def unit_suffix(unit: str | None) -> str:
    """`` N·m`` for a unit, nothing for a dimensionless one."""
    if not unit or unit in ("-", "–", "1"):
        return ""
    return " " + html.escape(unit)


def quantity(x, unit: str | None = None, digits: int = 4) -> str:
    """A value with its unit, e.g. ``3.001 N·m``."""
    if x is None:
        return "—"
    return number(x, digits) + unit_suffix(unit)


def interval(pair, unit: str | None = None, digits: int = 4) -> str:
    """``[low, high] unit``, with at least ``digits`` significant digits and enough more (up to 8)
    that the two ends differ in print."""
    if not pair or pair[0] is None or pair[1] is None:
        return "—"
    lo, hi = float(pair[0]), float(pair[1])
    width, size = abs(hi - lo), max(abs(lo), abs(hi))
    if width > 0 and size > 0:
        digits = int(min(max(digits, 1 + math.ceil(math.log10(size / width))), 8))
    return f"[{number(lo, digits)}, {number(hi, digits)}]{unit_suffix(unit)}"


def count(n) -> str:
    """An integer with thousands separators (2,000)."""
    return f"{int(round(float(n))):,}"


def attr(x) -> str:
    """Full-precision value for a ``data-value`` attribute (machine readable)."""
    return "" if x is None else repr(float(x))


# channel → (display name, practical unit, factor from SI)
CHANNELS = {
    "torque": ("running torque", "N·m", 1.0),
    "q_a": ("port A flow", "L/min", LPM_PER_M3S),
    "q_b": ("port B flow", "L/min", LPM_PER_M3S),
    "q_case": ("case-drain flow", "L/min", LPM_PER_M3S),
    "breakaway": ("breakaway (held) torque", "N·m", 1.0),
}


def channel_noise(channel: str, sigma_si) -> str:
    """Noise level of a channel in its practical unit."""
    if sigma_si is None:
        return "—"
    _, unit, factor = CHANNELS.get(channel, (channel, "", 1.0))
    return quantity(float(sigma_si) * factor, unit, 3)
