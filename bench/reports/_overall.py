"""The report's overall verdict (went well / with notes / needs attention) and why, as
values (decision 0067): a :class:`Verdict`, the reasons for attention and the notes each a
:class:`~bench.words.Said` of a :class:`Concern` code (or the procedure's
:class:`~bench.verdict.Short`) and its fields; the words are made by
:func:`bench.words.report.overall`."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from ..storage import shown
from ..verdict import Promise, promise
from ..words import Said
from ._identification import truth_misses
from ._run import RunData


class Verdict(StrEnum):
    NO_PLAN = "no_plan"                       # run.json holds no plan this version reads
    NEEDS_ATTENTION = "needs_attention"       # why, notes
    WENT_WELL_WITH_NOTES = "went_well_with_notes"
    WENT_WELL = "went_well"


class Concern(StrEnum):
    """A reason for attention, or a note of a run that went well."""

    RUN_STATUS = "run_status"                 # status: the run did not complete
    MISSING = "missing"                       # steps
    DAMAGED = "damaged"                       # steps
    REJECTED = "rejected"                     # steps rejected by the step-quality check
    QUALITY_UNKNOWN = "quality_unknown"       # error: the step quality could not be computed
    LIMIT_TRIP = "limit_trip"                 # reasons (the events')
    ERRORS = "errors"                         # count of instrument or run errors
    ORPHANS = "orphans"                       # count, names (the first five files)
    INTERRUPTED = "interrupted"               # times, reasons, unrecorded, resumes
    IDENT_FAILED = "ident_failed"             # error
    MISFIT = "misfit"                         # reduced_chi2, analyzed
    FLAGGED = "flagged"                       # steps, reasons: [(reason, steps)]
    TRUTH_MISSED = "truth_missed"             # misses: [(parameter, standard errors out)]
    BELOW_RESOLUTION = "below_resolution"     # steps, rms_m, source


@dataclass(frozen=True)
class Overall:
    """The verdict, its reasons (``why``) and notes, what the procedure kept, and the went
    well line's fields: ``skipped`` (steps skipped as the plan allows), ``quantity`` (the
    level's name), ``fits`` (a stepped sine's identified model fits)."""

    verdict: Verdict
    why: tuple[Said, ...] = ()
    notes: tuple[Said, ...] = ()
    kept: Promise | None = None
    skipped: int = 0
    quantity: str = ""
    fits: bool = False


def overall(run: RunData, rejected: int, flagged: list[tuple[str, int]]) -> Overall:
    """The run's verdict: ``rejected`` steps the step-quality check rejected, ``flagged``
    (reason, steps) of those it flagged."""
    from procedures.kind import ProcedureKind
    acc = run.accounting
    if acc is None or acc.planned is None:
        return Overall(Verdict.NO_PLAN)
    why: list[Said] = []
    status = run.meta.get("status", "?")
    if status != "completed":
        why.append(Said(Concern.RUN_STATUS, {"status": status}))
    if acc.missing:
        why.append(Said(Concern.MISSING, {"steps": acc.missing_count}))
    if acc.damaged:
        why.append(Said(Concern.DAMAGED, {"steps": len(acc.damaged)}))
    if rejected:
        why.append(Said(Concern.REJECTED, {"steps": rejected}))
    if run.attention_error:
        why.append(Said(Concern.QUALITY_UNKNOWN, {"error": run.attention_error}))
    trips = [e for e in run.events if e.get("event") == "abort"]
    if trips:
        why.append(Said(Concern.LIMIT_TRIP, {"reasons": [str(e.get("reason", "?")) for e in trips]}))
    errors = [e for e in run.events if e.get("event") in ("instrument_error", "error")]
    if errors:
        why.append(Said(Concern.ERRORS, {"count": len(errors)}))
    kept = promise(run.plan, run.results, run.rig, completed=status == "completed")
    why += kept.short
    if acc.orphan:
        why.append(Said(Concern.ORPHANS, {"count": len(acc.orphan), "names": [shown(p.path.name)
                                                                               for p in acc.orphan[:5]]}))
    notes: list[Said] = []
    stops = [e for e in run.events if e.get("event") == "interrupted"]
    resumes = [e for e in run.events if e.get("event") == "resume"]
    if stops or resumes:
        (notes if status == "completed" else why).append(Said(Concern.INTERRUPTED, {
            "times": max(len(stops), len(resumes)), "reasons": sorted({str(e.get("reason") or "?") for e in stops}),
            "unrecorded": len(resumes) > len(stops), "resumes": len(resumes)}))
    ident = run.ident
    if ident.failed:
        why.append(Said(Concern.IDENT_FAILED, {"error": ident.failed}))
    est = ident.latest
    if est is not None and est.get("misfit"):
        why.append(Said(Concern.MISFIT, {"reduced_chi2": est.get("reduced_chi2"), "analyzed": run.analysis is not None}))
    if flagged:
        total = sum(1 for _, status, _ in run.attention if status == "flagged")
        notes.append(Said(Concern.FLAGGED, {"steps": total, "reasons": flagged}))
    misses = truth_misses(ident, est)
    if misses:
        notes.append(Said(Concern.TRUTH_MISSED, {"misses": misses}))
    below = run.below_resolution
    if below and run.probe:
        notes.append(Said(Concern.BELOW_RESOLUTION, {"steps": len(below), "rms_m": run.probe.rms_m,
                                                      "source": run.probe.source}))
    verdict = Verdict.NEEDS_ATTENTION if why else Verdict.WENT_WELL_WITH_NOTES if notes else Verdict.WENT_WELL
    return Overall(verdict, tuple(why), tuple(notes), kept, len(acc.skipped), run.level_quantity.name,
                   kept.kind is ProcedureKind.STEPPED_SINE and est is not None)
