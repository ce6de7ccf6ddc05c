"""One formatter for every number the bench prints about a fit (decision 0042; moved here
from bench/numbers.py, which decides what is a measurement): a value that is missing, not
finite or absurd is never printed as a number, but named (:data:`bench.words.terminal_config.NUMBER`)."""

from __future__ import annotations

import math

from ..numbers import ABSURD, Shown, as_number
from .terminal_config import shown


def number(v, scale: float = 1.0, fmt: str = ".4g", *, missing: str = "n/a", unbounded: str = "unbounded") -> str:
    """``v * scale`` with ``fmt``; 'n/a' when missing, ``unbounded`` when it overflowed
    upwards (an interval end of an undetermined parameter), 'not a number' or
    'absurd (fit failed)' otherwise.  The test is on ``v`` itself, in SI units."""
    x = as_number(v)
    if v is None or (isinstance(v, str) and not v):
        return missing
    if math.isnan(x):
        return missing if not isinstance(v, (int, float)) else shown(Shown.NAN)
    if math.isinf(x) or abs(x) >= ABSURD:
        return unbounded if x > 0 else shown(Shown.ABSURD)
    if x != 0 and abs(x) <= 1 / ABSURD:
        return shown(Shown.ABSURD)
    return format(x * scale, fmt)


def percent(x, fmt: str = "+.2f") -> str:
    """A relative value (0.05) as '+5.00 %'; absurd ones (above 1e6 %) named, not printed."""
    v = as_number(x)
    if not math.isfinite(v):
        return "n/a"
    if abs(v) > 1e4:
        return shown(Shown.ABSURD)
    return f"{format(100 * v, fmt)} %"
