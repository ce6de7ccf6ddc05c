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

from ..numbers import insane

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
    analysis: dict | None = None   # analysis.json's parameters as an estimate (bench analyze ran)
    status: str = ""               # the run's status (run.json)

    @property
    def failed(self) -> str | None:
        """Why the final fit failed, when run.json records a failure (or absurd numbers)."""
        if isinstance(self.unknown, dict) and self.unknown.get("error"):
            return str(self.unknown["error"])
        if self.final is not None:
            bad = insane(self.final.get("values") or {})
            if bad:
                return f"{', '.join(bad)} came out not finite or absurd (an overflow in the fit)"
        return None

    @property
    def latest(self) -> dict | None:
        """The one parameter set to report: the analysis' once `bench analyze` has run, else
        the final fit (unless it failed), else the last online estimate."""
        if self.analysis is not None:
            return self.analysis
        if self.final is not None and self.failed is None:
            return self.final
        return self.history[-1] if self.history else None

    def source_of(self, est: dict) -> str:
        """Where ``est`` came from, in words."""
        if est is self.analysis:
            return est.get("source", "analysis")
        if est is self.final:
            return f"{est.get('source') or 'final fit'} over {est.get('steps_used', '?')} steps (run.json)"
        why = (f"the final fit failed: {self.failed}" if self.failed else
               "there is no final fit (the run did not complete)" if self.status != "completed" else
               "there is no final fit in run.json")
        return (f"last online estimate, after step {est.get('step', '?')} ({est.get('steps_used', '?')} steps); "
                f"{why}")


def analysis_estimate(analysis: dict | None) -> dict | None:
    """analysis.json's final-model parameters in the estimate layout (None when absent or unusable)."""
    if not isinstance(analysis, dict) or not isinstance(analysis.get("parameters"), dict):
        return None
    from sim.discrepancy.analysis import stored_analysis
    analysis = stored_analysis(analysis)
    values, low, high, rel = {}, {}, {}, {}
    for k in ("F_s_N", "x_s_m", "n", "mass_kg"):
        p = analysis["parameters"].get(k)
        if not isinstance(p, dict):
            return None
        values[k], low[k], high[k] = (finite(p.get(x)) for x in ("value", "low", "high"))
        half = (high[k] - low[k]) / (2 * 1.959964) if k == "n" else math.log(max(high[k], 1e-300) / max(low[k], 1e-300)) / (2 * 1.959964)
        rel[k] = half / abs(values[k]) if k == "n" and values[k] else half
    final = analysis.get("final") or {}
    causes = [c.get("id") for c in analysis.get("causes") or [] if isinstance(c, dict) and c.get("kind") != "artefact"]
    chi2 = finite(final.get("reduced_chi2"))
    from sim.identify import misfit_text
    mis = misfit_text(chi2, 10 ** 6) if math.isfinite(chi2) else ""
    warn = [mis] if mis else []
    if analysis.get("unexplained"):
        warn.append("the analysis found structure its model does not explain (see the analysis section)")
    return dict(values=values, low=low, high=high, rel_std=rel, reduced_chi2=chi2, warnings=warn, misfit=bool(mis),
                steps_used=len(analysis.get("steps_used") or []),
                model=dict(effects=list(final.get("effects") or []), parameters={}),
                source=("the analysis (bench analyze, analysis/analysis.json): Masing friction and the moving mass"
                        + (f" with {', '.join(causes)}" if causes else "") + ", fitted with its named causes"))


def _is_estimate(d) -> bool:
    return isinstance(d, dict) and isinstance(d.get("values"), dict)


def identification_data(run_dir: Path, meta: dict, analysis: dict | None = None) -> IdentificationData:
    from ..storage import RunStore
    final = meta.get("identification")
    truth = None
    rig = meta.get("rig") or {}
    from procedures.plan import stored_model
    try:
        model = stored_model(rig)
        if model is not None:
            truth = {p.key: float(getattr(model, p.key)) for p in ID_PARAMS}
    except Exception as e:          # the report must come out even with a bad model entry
        log.warning("rig model unreadable: %s", e)
    return IdentificationData([h for h in RunStore(Path(run_dir)).identification_history() if _is_estimate(h)],
                              final if _is_estimate(final) else None, truth,
                              list(meta.get("identifiability_warnings") or []),
                              None if final is None or _is_estimate(final) else final,
                              analysis_estimate(analysis), str(meta.get("status", "")))


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


def truth_misses(ident: IdentificationData, est: dict | None) -> list[tuple[str, float]]:
    """(label, standard errors out) of each parameter whose 95 % interval excludes the
    simulated rig's truth (the report's "truth in interval: no"); [] for a real rig."""
    if not ident.truth or not est:
        return []
    out = []
    for p in ID_PARAMS:
        t = ident.truth.get(p.key)
        v, lo, hi = (finite((est.get(k) or {}).get(p.key)) for k in ("values", "low", "high"))
        if t is None or not all(math.isfinite(x) for x in (v, lo, hi)) or lo <= t <= hi:
            continue
        if p.log_y and min(t, v, lo, hi) > 0:
            out.append((p.label, abs(math.log(t / v)) / (math.log(hi / lo) / (2 * 1.959964)) if hi > lo else math.inf))
        else:
            out.append((p.label, abs(t - v) / ((hi - lo) / (2 * 1.959964)) if hi > lo else math.inf))
    return out
