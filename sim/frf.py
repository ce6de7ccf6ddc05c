"""Frequency responses G(beta) (seed Eq. 9): grids, up/down sweeps, jumps and peaks.

Two engines compute a point:

- ``"rk4"``: :func:`sim.dynamics.steady_state`, the seed's method (reference);
- ``"shooting"``: :mod:`sim.shooting`, half-period shooting with continuation, which
  falls back to RK4 at points where its assumptions fail.

Independent points start from rest and run on all cores (the RK4 kernel releases the
GIL, so threads suffice).  Up and down sweeps warm-start each point from the previous
one, like a stepped-sine test on the rig; they expose jumps.
"""

from __future__ import annotations

import logging
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from .dynamics import FrictionState, Integrator, SteadyState, steady_state
from .errors import ConfigurationError

log = logging.getLogger(__name__)

SWEEPS = ("independent", "up", "down")


@dataclass(frozen=True)
class FrequencyResponse:
    gamma0: float
    n: float
    beta: np.ndarray
    G: np.ndarray
    converged: np.ndarray
    gross_rolling: np.ndarray
    reversals_per_cycle: np.ndarray
    cycles: np.ndarray
    sweep: str
    method: str
    max_depth: int

    @classmethod
    def from_points(cls, points: list[SteadyState], sweep: str, method: str) -> FrequencyResponse:
        return cls(
            gamma0=points[0].gamma0, n=points[0].n,
            beta=np.array([p.beta for p in points]), G=np.array([p.G for p in points]),
            converged=np.array([p.converged for p in points]),
            gross_rolling=np.array([p.gross_rolling for p in points]),
            reversals_per_cycle=np.array([p.reversals_per_cycle for p in points]),
            cycles=np.array([p.cycles for p in points]),
            sweep=sweep, method=method, max_depth=max(p.max_depth for p in points))


@dataclass(frozen=True)
class Peak:
    beta: float
    G: float
    kind: str          # "harmonic" or "superharmonic"
    ratio: float       # beta_harmonic / beta: about 2, 3, ... for superharmonics


@dataclass(frozen=True)
class Jump:
    beta_low: float    # grid points either side of the jump
    beta_high: float
    G_up: float        # compliance on the up sweep at beta_high
    G_down: float      # compliance on the down sweep at beta_high


def _workers(workers: int | None) -> int:
    return max(1, workers or os.cpu_count() or 1)


def beta_grid(betas) -> np.ndarray:
    b = np.asarray(betas, dtype=np.float64).ravel()
    if b.size == 0:
        raise ConfigurationError("beta grid is empty")
    if not np.all(np.isfinite(b)) or np.any(b <= 0):
        raise ConfigurationError("beta grid must hold finite values > 0")
    return b


def frf_rk4(betas, gamma0: float, n: float = 1.5, *, sweep: str = "independent",
            workers: int | None = None, integrator: Integrator | None = None,
            progress=None, **steady_kw) -> FrequencyResponse:
    """G(beta) with the RK4 engine.

    ``sweep="independent"`` starts every point from rest, in parallel; ``"up"``/``"down"``
    step through the grid in ascending/descending order, each point starting from the
    previous one's final state.  ``progress(done, total)`` is called after each point.
    """
    if sweep not in SWEEPS:
        raise ConfigurationError(f"sweep must be one of {SWEEPS}, got {sweep!r}")
    b = beta_grid(betas)
    it = integrator or Integrator(n=n)
    total = b.size
    if sweep == "independent":
        def one(beta):
            return steady_state(gamma0, beta, it.n, integrator=it, **steady_kw)
        with ThreadPoolExecutor(_workers(workers)) as ex:
            points = []
            for p in ex.map(one, b):
                points.append(p)
                if progress:
                    progress(len(points), total)
    else:
        order = np.sort(b) if sweep == "up" else np.sort(b)[::-1]
        state = FrictionState()
        points = []
        for beta in order:
            points.append(steady_state(gamma0, beta, it.n, integrator=it, state=state, **steady_kw))
            if progress:
                progress(len(points), total)
    return FrequencyResponse.from_points(points, sweep, "rk4")


def sweep_up_down(betas, gamma0: float, n: float = 1.5, *, rtol_jump: float = 0.02,
                  integrator: Integrator | None = None, **steady_kw):
    """Up and down sweeps (run in parallel) and the jumps between them.

    Returns (up, down, jumps); both responses are ordered by ascending beta.  A jump is
    reported where the sweeps disagree by more than ``rtol_jump`` and the disagreement
    ends, i.e. at each edge of a band where two steady responses coexist.
    """
    it = integrator or Integrator(n=n)
    with ThreadPoolExecutor(2) as ex:
        fu = ex.submit(frf_rk4, betas, gamma0, it.n, sweep="up", integrator=it, **steady_kw)
        fd = ex.submit(frf_rk4, betas, gamma0, it.n, sweep="down", integrator=it, **steady_kw)
        up, down = fu.result(), fd.result()
    down = _ascending(down)
    differ = np.abs(up.G - down.G) > rtol_jump * np.maximum(up.G, down.G)
    jumps = []
    for i in range(1, up.beta.size):
        if differ[i] != differ[i - 1]:
            j = i if differ[i] else i - 1
            jumps.append(Jump(float(up.beta[i - 1]), float(up.beta[i]), float(up.G[j]), float(down.G[j])))
    return up, down, jumps


def _ascending(fr: FrequencyResponse) -> FrequencyResponse:
    idx = np.argsort(fr.beta)
    return replace(fr, beta=fr.beta[idx], G=fr.G[idx], converged=fr.converged[idx],
                   gross_rolling=fr.gross_rolling[idx], reversals_per_cycle=fr.reversals_per_cycle[idx],
                   cycles=fr.cycles[idx])


def find_peaks(fr: FrequencyResponse, min_prominence: float = 0.005) -> list[Peak]:
    """Harmonic resonance (largest G) and superharmonic resonances (local maxima below it).

    Peak positions are refined by a parabola through the three grid points around each
    maximum.  ``min_prominence`` (relative to the harmonic peak) drops numerical ripple.
    """
    fr = _ascending(fr)
    b, G = fr.beta, fr.G
    if b.size < 3:
        raise ValueError("need at least 3 frequencies to locate peaks")
    ih = int(np.argmax(G))
    bh, Gh = _refine(b, G, ih)
    peaks = [Peak(bh, Gh, "harmonic", 1.0)]
    for i in range(ih - 1, 0, -1):
        if G[i] > G[i - 1] and G[i] >= G[i + 1]:
            # prominence: drop to the higher of the minima on either side
            if G[i] - max(G[: i + 1].min(), G[i:ih + 1].min()) >= min_prominence * Gh:
                bp, Gp = _refine(b, G, i)
                peaks.append(Peak(bp, Gp, "superharmonic", bh / bp))
    return peaks


def _refine(b: np.ndarray, G: np.ndarray, i: int) -> tuple[float, float]:
    if i == 0 or i == b.size - 1:
        return float(b[i]), float(G[i])
    x0, x1, x2 = b[i - 1], b[i], b[i + 1]
    y0, y1, y2 = G[i - 1], G[i], G[i + 1]
    denom = (x0 - x1) * (x0 - x2) * (x1 - x2)
    A = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / denom
    B = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / denom
    if A >= 0:
        return float(x1), float(y1)
    xv = -B / (2 * A)
    if not (x0 <= xv <= x2):
        return float(x1), float(y1)
    C = y0 - A * x0 * x0 - B * x0
    return float(xv), float(A * xv * xv + B * xv + C)
