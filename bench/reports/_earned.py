"""A mode the rig does not have is never reported (decision record 0056).

- A rig whose model has no pitching mode (``pitch_inertia_kg_m2`` 0) gets no pitch rows:
  a second accelerance maximum there is the feed mode's shoulder, a harmonic or noise.
- On a rig without a model, a second accelerance maximum is called the pitching mode only
  when it earns it: the phase of A1/F1 turns across the peak's points (a resonance turns
  it by 90 degrees across its half-power band; at least MIN_TURN_DEG is asked) and the
  other sensor, the displacement probe, sees the same mode (X1/F1's phase turns there by at
  least MIN_TURN_OTHER_DEG: the pitching mode moves the feed direction through the
  coupling m e).  A maximum that fails is dropped, with the reason in the log.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

import numpy as np

from sim.modal import LevelData, ModeEstimate

log = logging.getLogger(__name__)

MIN_TURN_DEG = 30.0
MIN_TURN_OTHER_DEG = 10.0


def _turn_deg(H: np.ndarray) -> float:
    """The largest minus the smallest unwrapped phase, in degrees."""
    ph = np.unwrap(np.angle(H))
    return float(np.degrees(ph.max() - ph.min())) if ph.size else 0.0


def phase_turns(d: LevelData, lo_Hz: float, hi_Hz: float) -> tuple[float, float]:
    """(turn of A1/F1, turn of X1/F1) in degrees over the points in [lo_Hz, hi_Hz]."""
    sel = (d.f_Hz >= lo_Hz) & (d.f_Hz <= hi_Hz)
    return _turn_deg(d.accelerance[sel]), _turn_deg(d.compliance[sel])


def earned_pitch(modes: Sequence[ModeEstimate], data: Sequence[LevelData]) -> list[ModeEstimate]:
    """``modes`` without the pitch estimates whose peak does not earn its place (module doc)."""
    by_level = {d.level_N: d for d in data}
    out = []
    for e in modes:
        d = by_level.get(e.level_N)
        if e.mode == "pitch" and math.isfinite(e.resonance_Hz) and d is not None \
                and all(map(math.isfinite, e.window_Hz)):
            a, x = phase_turns(d, *e.window_Hz)
            if a < MIN_TURN_DEG or x < MIN_TURN_OTHER_DEG:
                log.info("%g N: the accelerance maximum at %.4g Hz is not called the pitching mode: its phase "
                         "turns %.0f deg (at least %.0f asked), the displacement's %.0f deg (at least %.0f)",
                         e.level_N, e.resonance_Hz, a, MIN_TURN_DEG, x, MIN_TURN_OTHER_DEG)
                continue
            e.extra["phase_turn_deg"] = (a, x)
        out.append(e)
    return out
