"""Compliance maps G(beta, gamma0) of the Masing model (seed Eq. 9), for one or more n.

A task is one row of a map: one (n, gamma0) and the whole beta grid, swept up and down
with the shooting engine's continuation (:func:`sim.shooting.frf_shooting`; points
outside its assumptions are computed with RK4), or with the seed's RK4 sweeps, each point
warm-started from the previous one (``engine="rk4"``: slow, the reference for jumps,
since shooting also finds unstable orbits; a continuation cannot pass a fold, though, so
it does leave a branch where the branch ends).  Per beta the row
gives the compliance of both sweeps, whether they disagree (two coexisting responses: a
jump region) and whether the beta is the harmonic or a superharmonic resonance of the up
sweep (:func:`sim.frf.find_peaks`): the ridges of the map.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from sim.errors import ConfigurationError

from ..words import terminal_data as words
from .engine import Engine, Outcome, Study

log = logging.getLogger(__name__)


class MapRefusal(StrEnum):
    """A map's bad inputs, and a case with no peaks (words: :data:`bench.words.terminal_data.STUDIES`)."""

    NO_N_OR_GAMMA0 = "no_n_or_gamma0"
    BAD_N = "bad_n"                         # n
    BAD_GAMMA0 = "bad_gamma0"               # gamma0
    BAD_BETA_RANGE = "bad_beta_range"       # low, high
    BAD_BETA_POINTS = "bad_beta_points"     # points
    BAD_ENGINE = "bad_engine"               # engine
    NO_PEAKS = "no_peaks"                   # n, gamma0, detail (a log line)

JUMP_RTOL = 0.02      # sweeps differing by more than this (relative) mark a jump region


@dataclass(frozen=True)
class MapSpec:
    """The grid of a compliance map study."""

    n: tuple[float, ...]
    gamma0: tuple[float, ...]
    beta_min: float = 0.2
    beta_max: float = 3.0
    beta_points: int = 200
    engine: str = "shooting"

    def __post_init__(self):
        if not self.n or not self.gamma0:
            raise words.refused(ConfigurationError, MapRefusal.NO_N_OR_GAMMA0)
        for n in self.n:
            if not (n > 0 and abs(n - 1) > 1e-9):
                raise words.refused(ConfigurationError, MapRefusal.BAD_N, n=n)
        for g in self.gamma0:
            if not (0 < g < 1):
                raise words.refused(ConfigurationError, MapRefusal.BAD_GAMMA0, gamma0=g)
        if not (0 < self.beta_min < self.beta_max):
            raise words.refused(ConfigurationError, MapRefusal.BAD_BETA_RANGE, low=self.beta_min, high=self.beta_max)
        if self.beta_points < 3:
            raise words.refused(ConfigurationError, MapRefusal.BAD_BETA_POINTS, points=self.beta_points)
        if self.engine not in ("shooting", "rk4"):
            raise words.refused(ConfigurationError, MapRefusal.BAD_ENGINE, engine=self.engine)

    def betas(self) -> np.ndarray:
        return np.geomspace(self.beta_min, self.beta_max, self.beta_points)

    def tasks(self) -> list[dict]:
        return [dict(n=float(n), gamma0=float(g), beta_min=self.beta_min, beta_max=self.beta_max,
                     beta_points=self.beta_points, engine=self.engine)
                for n in self.n for g in self.gamma0]

    def to_dict(self) -> dict:
        return dict(n=list(self.n), gamma0=list(self.gamma0), beta_min=self.beta_min,
                    beta_max=self.beta_max, beta_points=self.beta_points, engine=self.engine)


def map_row(inputs: dict, seed: int = 0) -> list[dict]:
    """One row of the map (a task): rows of the table, one per beta."""
    from sim.frf import find_peaks, sweep_up_down
    from sim.shooting import frf_shooting

    betas = np.geomspace(inputs["beta_min"], inputs["beta_max"], int(inputs["beta_points"]))
    n, g = inputs["n"], inputs["gamma0"]
    if inputs.get("engine", "shooting") == "rk4":
        # the seed's method: RK4 sweeps, each point warm-started from the previous one
        # (the reference for jumps: shooting finds orbits whatever their stability)
        up, down, _ = sweep_up_down(betas, g, n)
        fb_up = fb_down = np.ones(betas.size, bool)
    else:
        up, fb_up = frf_shooting(betas, g, n, direction="up")
        down, fb_down = frf_shooting(betas, g, n, direction="down")
    differ = np.abs(up.G - down.G) > JUMP_RTOL * np.maximum(up.G, down.G)
    peak = np.full(betas.size, "", dtype=object)
    try:
        for p in find_peaks(up):
            peak[int(np.argmin(np.abs(np.log(betas / p.beta))))] = p.kind
    except ValueError as e:
        log.warning("%s", words.said(MapRefusal.NO_PEAKS, n=n, gamma0=g, detail=e))
    return [dict(n=float(n), gamma0=float(g), beta=float(b), G_up=float(up.G[i]), G_down=float(down.G[i]),
                 jump_region=bool(differ[i]), peak=str(peak[i]),
                 converged=bool(up.converged[i] and down.converged[i]),
                 rk4_fallback=bool(fb_up[i] or fb_down[i]))
            for i, b in enumerate(betas)]


def compliance_map(spec: MapSpec, study_dir, *, scheduler: str | None = None, workers: int | None = None,
                   engine: Engine | None = None, progress=None, figure: bool = True) -> Outcome:
    """Run (or resume) a map study; writes results.parquet and, with ``figure``, map.png."""
    study = Study(study_dir, "compliance-map", spec.to_dict(), spec.tasks())
    out = study.run_on(map_row, engine, scheduler, workers, progress=progress)
    if figure and out.table_path.exists():
        from .figures import plot_compliance_map
        plot_compliance_map(out.table(), study.dir / "map.png")
    return out
