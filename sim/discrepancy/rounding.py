"""Figures rounded to what their interval supports.

A value with a 95 % interval is written with its last digit where the interval's
half-width has its second significant digit when that half-width starts with 1 or 2, its
first otherwise (the Particle Data Group's rule, which keeps the rounding of the
uncertainty below about 5 % of it); the bounds are written to the same place.  So
159.1549 Hz with 158.9 to 159.4 Hz is "159.2 Hz (95 %: 158.9 to 159.4 Hz)": the
hundredths were noise.  A value without a usable interval keeps three significant digits.
"""

from __future__ import annotations

import math


def last_digit(low: float, high: float) -> int | None:
    """Decimal exponent of the last digit the interval [low, high] supports (None: no
    usable interval, i.e. not finite or of zero width)."""
    half = abs(high - low) / 2
    if not math.isfinite(half) or half == 0:
        return None
    e = math.floor(math.log10(half))
    lead = int(half / 10 ** e + 1e-9)
    return e - 1 if lead <= 2 else e


def _fmt(x: float, q: int | None, signed: bool) -> str:
    sign = "+" if signed else ""
    if not math.isfinite(x):
        return "n/a" if math.isnan(x) else ("+inf" if x > 0 else "-inf")
    if q is None:
        return f"{x:{sign}.3g}"
    mag = math.floor(math.log10(abs(x))) if x != 0 else q
    if -4 <= mag < 7 and q >= -9:                      # plain decimals
        return f"{round(x, -q):{sign}.{max(0, -q)}f}"
    sig = max(1, mag - q + 1)                          # scientific, with the supported digits
    return f"{x:{sign}.{sig - 1}e}"


def round_to_interval(value: float, low: float, high: float, signed: bool = False) -> tuple[str, str, str]:
    """(value, low, high) as text, each to the last digit the interval supports."""
    q = last_digit(low, high)
    return _fmt(value, q, signed), _fmt(low, q, signed), _fmt(high, q, signed)


def value_text(value: float, low: float, high: float, unit: str = "", signed: bool = False) -> str:
    """Only the value, rounded to its interval: '159.2 Hz'."""
    return round_to_interval(value, low, high, signed)[0] + unit


def interval_text(value: float, low: float, high: float, unit: str = "", signed: bool = False) -> str:
    """'41 N s/m (95 %: 37 to 45 N s/m)', each figure to the digit the interval supports."""
    v, lo, hi = round_to_interval(value, low, high, signed)
    if last_digit(low, high) is None:
        return f"{v}{unit}"
    return f"{v}{unit} (95 %: {lo} to {hi}{unit})"


def percent_text(fraction: float, digits: int = 2) -> str:
    """'12.30 %', or 'not computed' for a NaN (a candidate that failed the BIC gate is
    never scored on held-out data), as the analysis page says it."""
    return "not computed" if math.isnan(fraction) else f"{100 * fraction:.{digits}f} %"
