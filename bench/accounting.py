"""A run's steps counted against its stored plan (moved from :mod:`bench.storage`):
:class:`Accounting` (intact, missing, damaged, orphan, skipped, owed) and the plan's sweeps."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

from procedures.plan import Plan
from sim.errors import ConfigurationError
from sim.errors import RunDirectoryError as RunDirError

from .config import parse_stored_plan
from .step_files import Problem, StepProblem, shown
from .words import say, terminal_run

log = logging.getLogger(__name__)


class AccountLine(StrEnum):
    """A run's account (:data:`bench.words.terminal_run.ACCOUNT`); its fields: planned,
    missing [(key, steps a sweep lacks or None)], damaged [(key, kind)], owed [(key, a
    dwell?)], skipped [key], and those of each code."""

    RESUME = "resume"                       # measures, retry (the skipped ones)
    SUMMARY = "summary"                     # intact, orphan [file name]


class AccountRefusal(StrEnum):
    """Why nothing is counted (:data:`bench.words.terminal_run.REFUSAL`)."""

    STORED_PLAN = "stored_plan"             # error: the stored plan's


def stored_plan(meta: dict, source: Path | str = "run.json") -> Plan:
    """The run's stored plan, checked by the validator of a plan file
    (:func:`bench.config.parse_stored_plan`: ranges, the size bounds, the format); a
    :class:`RunDirError` names ``source`` (its run.json) and the key."""
    try:
        return parse_stored_plan(meta.get("plan"), str(source))
    except ConfigurationError as e:
        raise terminal_run.refused(RunDirError, AccountRefusal.STORED_PLAN, error=e) from None


def planned_keys(meta: dict, source: Path | str) -> set[str]:
    """Keys of every step of the run's stored plan (:class:`RunDirError` if it is not valid)."""
    return {s.key for s in stored_plan(meta, source).schedule()}


@dataclass
class Accounting:
    """A run's steps counted against its plan (:meth:`RunStore.account`).

    ``missing``: planned steps without a complete file pair (nothing, or only one of the
    two files); in an adaptive plan, the steps a sweep still lacks of the number it
    measures (their keys are chosen online, so the sweep is named).  ``damaged``: planned
    steps whose files are both there but fail a check.  ``orphan``: files no planned step
    owns.  ``skipped``: planned steps without files that the run skipped because their
    force was unreachable within the drive limit, as the plan allows (``infeasible =
    "skip"``; a ``step_skipped`` event names the reason): accounted for, neither missing
    nor damaged (decision record 0033).  ``planned`` is None when run.json holds no plan
    this version can rebuild."""

    planned: int | None
    intact: list[str]
    missing: list[StepProblem]
    damaged: list[StepProblem]
    orphan: list[StepProblem]
    skipped: list[StepProblem] = field(default_factory=list)
    owed: list[StepProblem] = field(default_factory=list)     # a refined run's unended refinements, dwells

    @property
    def complete(self) -> bool:
        """Every planned step is there and intact, or was skipped at run time as the plan
        allows (nothing a resume would measure unless asked to retry the skipped ones), and
        a refined run owes nothing (every refinement ended, every dwell it owes measured)."""
        return self.planned is not None and not self.missing and not self.damaged and not self.owed

    @property
    def missing_count(self) -> int:
        return sum(p.count for p in self.missing)

    def _fields(self) -> dict:
        return dict(planned=self.planned,
                    missing=[(p.key, p.count if p.code is Problem.SWEEP_SHORT else None) for p in self.missing],
                    damaged=[(p.key, p.kind) for p in self.damaged],
                    owed=[(p.key, p.code is Problem.DWELL_OWED) for p in self.owed],
                    skipped=[p.key for p in self.skipped])

    def resume_text(self, retry_skipped: bool = False) -> str:
        """'measures again 3 of 30 planned steps; missing: K1, K2; damaged: K3 (truncated);
        skipped at run time, not retried (--retry-skipped retries them): K4'."""
        n = self.missing_count + len(self.damaged) + (len(self.skipped) if retry_skipped else 0)
        return say(terminal_run.ACCOUNT, AccountLine.RESUME, dict(self._fields(), measures=n, retry=retry_skipped))

    def summary(self) -> str:
        """'28 intact / 30 planned; skipped at run time: K4; missing: K1; damaged: K2
        (truncated); orphan: none' (the skipped part only when there is one)."""
        return say(terminal_run.ACCOUNT, AccountLine.SUMMARY,
                   dict(self._fields(), intact=len(self.intact), orphan=[shown(p.path.name) for p in self.orphan]))


def _sweeps(plan) -> dict[tuple[int, str], list[str]]:
    out: dict[tuple[int, str], list[str]] = {}
    for s in plan.schedule():
        out.setdefault((s.level_index, s.direction), []).append(s.key)
    return out


def planned_count(plan) -> int:
    """Steps the plan measures: its schedule, or in adaptive mode the chosen number per sweep."""
    k = plan.adaptive_per_sweep
    return sum(min(len(keys), k) if k else len(keys) for keys in _sweeps(plan).values())
