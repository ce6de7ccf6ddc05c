"""A refinement that did not converge is never hidden (decision record 0056): how each
level's resonance search ended, from the stored steps (procedures.resonance.
refinement_outcomes), becomes the mode's status "not converged" in modes.csv and the
report, with the interval widened to the bracket of the measured maximum (the peak lies
between its measured neighbours whatever the fit says), and a sentence in the report (its
words, and the note's, made by bench.words.report, decision 0067)."""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

from procedures.resonance import refinement_outcomes
from sim.modal import LevelData, ModeEstimate, find_feed, find_pitch

from ..words import report as words

log = logging.getLogger(__name__)

NOT_CONVERGED = "not converged"
# how a refinement ended without converging (procedures.resonance.refinement_outcomes)
_OPEN = ("budget_spent", "no_progress", "not finished")


def mark_refinement(modes: Sequence[ModeEstimate], meta: dict, results: list[dict], data: Sequence[LevelData],
                    levels_N: Sequence[float], pitch_band_Hz: tuple[float, float] | None) -> dict:
    """Set the status of every estimate whose level's refinement did not converge (in
    place); returns {(level_N, mode): outcome} for every refined mode and level."""
    from ..storage import stored_plan
    plan_d = meta.get("plan") or {}
    if not (plan_d.get("resonance") or {}).get("refine") and not plan_d.get("refine"):
        return {}
    try:
        plan = stored_plan(meta)
    except Exception as e:  # noqa: BLE001 - an unreadable plan: the modes come out without the outcome
        log.warning("refinement outcome unknown (stored plan: %s)", e)
        return {}
    rig = meta.get("rig") or {}
    no_pitch = bool(rig.get("simulated") and rig.get("model")) and pitch_band_Hz is None
    outcomes = {(float(plan.levels_N[li]), mode): why
                for (li, mode), why in refinement_outcomes(plan, results, pitch_band_Hz, no_pitch).items()}
    by_level = {d.level_N: d for d in data}
    for e in modes:
        why = outcomes.get((e.level_N, e.mode))
        if why not in _OPEN or e.status not in ("ok", "coarse"):
            continue
        e.status = NOT_CONVERGED
        e.note = words.refinement_note(why, e.note)
        d = by_level.get(e.level_N)
        if d is not None and math.isfinite(e.resonance_Hz):
            lo, hi = _bracket(d, e)
            e.resonance_low_Hz = min(v for v in (e.resonance_low_Hz, lo) if math.isfinite(v))
            e.resonance_high_Hz = max(v for v in (e.resonance_high_Hz, hi) if math.isfinite(v))
    return outcomes


def _bracket(d: LevelData, e: ModeEstimate) -> tuple[float, float]:
    """The frequencies either side of the mode's measured maximum."""
    i = find_feed(d, e.resonance_Hz) if e.mode == "feed" else find_pitch(d, e.resonance_Hz, None, None)
    if i is None:
        return math.nan, math.nan
    f = d.f_Hz
    return float(f[max(i - 1, 0)]), float(f[min(i + 1, f.size - 1)])


def refinement_lines(outcomes: dict) -> list[str]:
    """The report's lines for the refinements that did not converge."""
    bad = sorted((lv, mode, why) for (lv, mode), why in outcomes.items() if why in _OPEN)
    return [words.refinement_line(why, mode, lv) for lv, mode, why in bad]

