"""The online identification of a run as stored by procedures.online_id: the history
(identification.jsonl), the final fit (run.json), the truth of a simulated rig, and the
identifiability warnings judged before the run.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class IdParam:
    key: str            # as in the estimate's dicts (SI)
    label: str
    unit: str           # display unit
    scale: float        # SI -> display unit
    log_y: bool


ID_PARAMS = (IdParam("F_s_N", "F_s", "N", 1.0, True), IdParam("x_s_m", "x_s", "um", 1e6, True),
             IdParam("n", "n", "", 1.0, False), IdParam("mass_kg", "m", "kg", 1.0, True))


@dataclass
class IdentificationData:
    """The online identification of a run: what procedures.online_id stored."""

    history: list[dict]            # identification.jsonl: one estimate per completed step
    final: dict | None             # run.json "identification": the full fit at the end
    truth: dict | None             # simulated rig: the RigModel's parameters (SI)
    identifiability: list[str]     # run.json "identifiability_warnings" (judged before the run)
    unknown: object = None         # a run.json "identification" entry that is not an estimate

    @property
    def latest(self) -> dict | None:
        """The estimate to report: the final fit, else the last online one."""
        return self.final if self.final is not None else (self.history[-1] if self.history else None)


def _is_estimate(d) -> bool:
    return isinstance(d, dict) and isinstance(d.get("values"), dict)


def identification_data(run_dir: Path, meta: dict) -> IdentificationData:
    from ..storage import RunStore
    final = meta.get("identification")
    truth = None
    rig = meta.get("rig") or {}
    if rig.get("simulated") and rig.get("model"):
        from sim.rig import RigModel
        try:
            model = RigModel.from_dict(rig["model"])
            truth = {p.key: float(getattr(model, p.key)) for p in ID_PARAMS}
        except Exception as e:          # the report must come out even with a bad model entry
            log.warning("rig model unreadable: %s", e)
    return IdentificationData([h for h in RunStore(Path(run_dir)).identification_history() if _is_estimate(h)],
                              final if _is_estimate(final) else None, truth,
                              list(meta.get("identifiability_warnings") or []),
                              None if final is None or _is_estimate(final) else final)


def finite(v) -> float:
    try:
        v = float(v)
    except (TypeError, ValueError):
        return math.nan
    return v if math.isfinite(v) else math.nan


def steps_of(history: list[dict]) -> np.ndarray:
    return np.array([h.get("steps_used", i + 1) for i, h in enumerate(history)], dtype=float)


def determined_from(history: list[dict]) -> int | None:
    """Steps completed from which on no estimate carried a warning (every relative
    standard error below 10 %); None if the last one still does."""
    if not history or history[-1].get("warnings"):
        return None
    i = len(history) - 1
    while i > 0 and not history[i - 1].get("warnings"):
        i -= 1
    return int(steps_of(history)[i])
