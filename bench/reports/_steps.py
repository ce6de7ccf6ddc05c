"""Steps and sweeps of a run: grouping, flags and the small conversions every figure and table uses."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.artefacts import NOISY_RESIDUAL as UNSETTLED_RESIDUAL  # noqa: F401 - re-exported: flagged above (residual / fundamental)


@dataclass
class Series:
    """One force level's sweep in one direction, sorted by frequency."""

    level_index: int
    level_N: float
    direction: str
    steps: list[dict]

    def col(self, getter) -> np.ndarray:
        return np.array([getter(s) for s in self.steps], dtype=float)

    @property
    def freq_Hz(self) -> np.ndarray:
        return self.col(lambda s: s["freq_Hz"])


def series_of(results: list[dict], levels_N) -> list[Series]:
    groups: dict[tuple[int, str], list[dict]] = {}
    for r in results:
        groups.setdefault((r["level_index"], r["direction"]), []).append(r)
    out = []
    for (li, d), steps in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1] != "up")):
        level = levels_N[li] if li < len(levels_N) else steps[0]["target_force_N"]
        out.append(Series(li, float(level), d, sorted(steps, key=lambda s: s["freq_Hz"])))
    return out


def legacy_pp(results: list[dict]) -> bool:
    """True for runs stored before compliance_pp came from the harmonic fit: their steps
    have no ``disp.raw_peak_to_peak`` and their compliance_pp is the raw record's."""
    return any("raw_peak_to_peak" not in r.get("disp", {}) for r in results)


def pp_source(results: list[dict]) -> str:
    """Where the stored compliance_pp of this run comes from, for the texts."""
    if legacy_pp(results):
        return ("the raw record (this run predates compliance_pp from the harmonic fit: it is biased high "
                "by noise and non-periodic motion, most at the flagged steps)")
    return "the periodic displacement of the harmonic fit"


def residual_ratio(step: dict) -> float:
    """Displacement residual rms (noise plus anything not periodic) / fundamental amplitude."""
    a1 = step["disp"]["amplitude"][0]
    return step["disp"]["noise_rms"] / a1 if a1 > 0 else math.inf


def phase_deg(phase_rad: np.ndarray) -> np.ndarray:
    """Compliance phase in degrees in (-270, 90]: a mass-spring-like lag runs 0 -> -180
    without wrapping at -180."""
    return (np.degrees(phase_rad) - 90.0) % 360.0 - 270.0


def control_error(step: dict) -> float:
    """The control error of the quantity the step's level holds: the response's (a
    ``response_control`` record, decision 0044) or the force's, relative."""
    rc = step.get("response_control")
    return float(rc["error"]) if isinstance(rc, dict) and "error" in rc else float(step["force_error"])
