"""A resonance that is not a point (decision record 0056): where a mode is damped so much
that its peak is a plateau (the seed's feed mode at high force, "the resonance peak
disappeared"), a single-mode shape fitted to a skewed, flat nonlinear peak gives a
confident frequency its misfit has shifted.  Then the status says so ("overdamped/flat")
and the interval is the whole plateau: from the measured point below the first to the one
above the last contiguous point within PLATEAU of the measured maximum (for a curve that
rises to one maximum and falls, the maximum lies inside whatever the fit says), the
estimate kept inside it.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from .modal import ModeEstimate

FLAT_ZETA = 0.3          # a fitted damping ratio at or above this: the peak is a plateau
PLATEAU = 0.05           # points within 5 % of the measured maximum belong to it
OVERDAMPED = "overdamped/flat"


def plateau_Hz(f_Hz: ArrayLike, curve: ArrayLike, near_Hz: float) -> tuple[float, float]:
    """(low, high): the measured points either side of the contiguous run of points within
    PLATEAU of the largest value of ``curve``, the run taken about the maximum nearest to
    ``near_Hz``; the data's edge where the run reaches it."""
    f, c = np.asarray(f_Hz, float), np.asarray(curve, float)
    o = np.argsort(f)
    f, c = f[o], c[o]
    top = int(np.argmax(np.where(np.abs(np.log(f / near_Hz)) < 0.5, c, -np.inf)))
    level = (1 - PLATEAU) * c[top]
    lo = hi = top
    while lo > 0 and c[lo - 1] >= level:
        lo -= 1
    while hi < f.size - 1 and c[hi + 1] >= level:
        hi += 1
    return float(f[max(lo - 1, 0)]), float(f[min(hi + 1, f.size - 1)])


def mark_overdamped(e: ModeEstimate, f_Hz: ArrayLike, curve: ArrayLike) -> ModeEstimate:
    """``e`` (in place) with status OVERDAMPED and the plateau's interval when its fitted
    damping ratio is at least FLAT_ZETA."""
    if not (e.ok and math.isfinite(e.damping_ratio) and e.damping_ratio >= FLAT_ZETA):
        return e
    lo, hi = plateau_Hz(f_Hz, curve, e.resonance_Hz)
    e.status = OVERDAMPED
    e.resonance_low_Hz, e.resonance_high_Hz = min(lo, e.resonance_low_Hz), max(hi, e.resonance_high_Hz)
    e.resonance_Hz = min(max(e.resonance_Hz, lo), hi)
    e.note = (f"damped {100 * e.damping_ratio:.0f} % (fit): the peak is a plateau, its resonance not a point; "
              f"the interval holds the plateau (the points within {100 * PLATEAU:g} % of the measured maximum)"
              + (f"; {e.note}" if e.note else ""))
    return e
