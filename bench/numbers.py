"""Whether a number the bench prints about a fit is a measurement (decision 0042): a value
that is missing, not finite or absurd (an overflowed fit: 5e-211 N, a 200-digit
percentage) is never printed as a number, but named; the formatter that names it is
:mod:`bench.words.numbers` (its words, a renderer's)."""

from __future__ import annotations

import math
from enum import StrEnum

ABSURD = 1e30        # |v| above this, or nonzero below 1 / ABSURD, is not a measurement


class Shown(StrEnum):
    """A number that is not a measurement, named (its words: bench.words.terminal_config.NUMBER)."""

    NAN = "nan"                 # not a number
    ABSURD = "absurd"           # an overflowed fit


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


def insane(values: dict) -> list[str]:
    """The names of the values in ``values`` that are not :func:`sane`."""
    return [k for k, v in values.items() if not sane(v)]
