"""One formatter for every number the bench prints about a fit (decision 0042): a value
that is missing, not finite or absurd (an overflowed fit: 5e-211 N, a 200-digit
percentage) is never printed as a number, but named."""

from __future__ import annotations

import math

ABSURD = 1e30        # |v| above this, or nonzero below 1 / ABSURD, is not a measurement


def as_number(v) -> float:
    """``v`` as a float; NaN when it is not a number."""
    if isinstance(v, bool):
        return math.nan
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def sane(v) -> bool:
    """Whether ``v`` is a finite number of a size a measurement can have (0 included)."""
    x = as_number(v)
    return math.isfinite(x) and (x == 0 or 1 / ABSURD < abs(x) < ABSURD)


def number(v, scale: float = 1.0, fmt: str = ".4g", *, missing: str = "n/a", unbounded: str = "unbounded") -> str:
    """``v * scale`` with ``fmt``; 'n/a' when missing, ``unbounded`` when it overflowed
    upwards (an interval end of an undetermined parameter), 'not a number' or
    'absurd (fit failed)' otherwise.  The test is on ``v`` itself, in SI units."""
    x = as_number(v)
    if v is None or (isinstance(v, str) and not v):
        return missing
    if math.isnan(x):
        return missing if not isinstance(v, (int, float)) else "not a number"
    if math.isinf(x) or abs(x) >= ABSURD:
        return unbounded if x > 0 else "absurd (fit failed)"
    if x != 0 and abs(x) <= 1 / ABSURD:
        return "absurd (fit failed)"
    return format(x * scale, fmt)


def percent(x, fmt: str = "+.2f") -> str:
    """A relative value (0.05) as '+5.00 %'; absurd ones (above 1e6 %) named, not printed."""
    v = as_number(x)
    if not math.isfinite(v):
        return "n/a"
    if abs(v) > 1e4:
        return "absurd (fit failed)"
    return f"{format(100 * v, fmt)} %"


def insane(values: dict) -> list[str]:
    """The names of the values in ``values`` that are not :func:`sane`."""
    return [k for k, v in values.items() if not sane(v)]
