"""Features of a steady cycle that the seed names (section 3, Figs. 7-11).

- VOAD, variation of acceleration direction: the acceleration changes sign more often
  than the two times per period of a sinusoidal motion.
- VRAR, velocity reduction and recovery: between two reversals the speed falls to a
  local minimum and rises again without the motion reversing.
- Displacement spike (quadrant glitch): the displacement turns sharply at a reversal.
  Measured by the largest jerk |u'''| within 5 % of a period of a reversal, relative to
  the amplitude (a sinusoid gives sin(0.1 pi) = 0.31); with n < 1 the initial stiffness of a new branch is infinite and
  the acceleration jumps, so the index grows with the sampling resolution.
- Circularity: the spread of the normalised phase-plane radius (0 for a sinusoid).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .dynamics import TimeHistory


@dataclass(frozen=True)
class CycleFeatures:
    acceleration_sign_changes: int
    voad: bool
    vrar_count: int
    vrar: bool
    spike_index: float
    circularity: float        # (max - min) of the normalised phase-plane radius
    amplitude: float
    offset: float             # loop centre (steady loops may sit off-centre)


def _sign_changes(x: np.ndarray) -> int:
    s = np.sign(x)
    s = s[s != 0]
    return int(np.count_nonzero(s[1:] != s[:-1]))


def cycle_features(h: TimeHistory, speed_floor: float = 0.02) -> CycleFeatures:
    """Features of one recorded steady period (first and last sample one period apart)."""
    u, v, a = h.u[:-1], h.du[:-1], h.ddu[:-1]
    amp = 0.5 * (u.max() - u.min())
    centre = 0.5 * (u.max() + u.min())
    n_acc = _sign_changes(a)
    speed = np.abs(v)
    vmax = speed.max()
    # Local minima of the speed that are not reversals (speed clearly above zero).
    prev, nxt = np.roll(speed, 1), np.roll(speed, -1)
    dips = (speed < prev) & (speed <= nxt) & (speed > speed_floor * vmax)
    vrar = int(np.count_nonzero(dips))
    dtau = h.tau[1] - h.tau[0]
    jerk = np.abs(np.diff(a, append=a[0])) / dtau
    rev = np.flatnonzero(np.sign(v) != np.sign(np.roll(v, -1)))
    win = max(1, int(0.05 * len(u)))
    near = np.zeros(len(u), dtype=bool)
    for i in rev:
        near[np.arange(i - win, i + win + 1) % len(u)] = True
    spike = float(jerk[near].max() / max(amp, 1e-300)) if rev.size else 0.0
    radius = np.hypot((u - centre) / max(amp, 1e-300), v / max(vmax, 1e-300))
    return CycleFeatures(
        acceleration_sign_changes=n_acc, voad=n_acc > 2, vrar_count=vrar, vrar=vrar > 0,
        spike_index=spike, circularity=float(radius.max() - radius.min()),
        amplitude=float(amp), offset=float(centre))
