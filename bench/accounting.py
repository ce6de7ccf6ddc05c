"""A run's steps counted against its stored plan (moved from :mod:`bench.storage`):
:class:`Accounting` (intact, missing, damaged, orphan, skipped, owed) and the plan's sweeps."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

from procedures.plan import Plan
from sim.errors import ConfigurationError
from sim.errors import RunDirectoryError as RunDirError

from .config import parse_stored_plan
from .step_files import Problem, StepProblem, shown

log = logging.getLogger(__name__)


def stored_plan(meta: dict, source: Path | str = "run.json") -> Plan:
    """The run's stored plan, checked by the validator of a plan file
    (:func:`bench.config.parse_stored_plan`: ranges, the size bounds, the format); a
    :class:`RunDirError` names ``source`` (its run.json) and the key."""
    try:
        return parse_stored_plan(meta.get("plan"), str(source))
    except ConfigurationError as e:
        raise RunDirError(f"{e} (the plan stored in run.json; nothing is counted against it)") from None


def planned_keys(meta: dict, source: Path | str) -> set[str]:
    """Keys of every step of the run's stored plan (:class:`RunDirError` if it is not valid)."""
    return {s.key for s in stored_plan(meta, source).schedule()}


def _keys_text(keys: list[str], limit: int = 8) -> str:
    return ", ".join(keys[:limit]) + (f" and {len(keys) - limit} more" if len(keys) > limit else "")


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

    def resume_text(self, retry_skipped: bool = False) -> str:
        """'measures again 3 of 30 planned steps; missing: K1, K2; damaged: K3 (truncated);
        skipped at run time, not retried (--retry-skipped retries them): K4'."""
        n = self.missing_count + len(self.damaged) + (len(self.skipped) if retry_skipped else 0)
        parts = [f"measures again {n} of {'?' if self.planned is None else self.planned} planned "
                 f"step{'s' * (self.planned != 1)}"]
        if self.missing:
            parts.append("missing: " + _keys_text([_missing_label(p) for p in self.missing], 12))
        if self.damaged:
            parts.append("damaged: " + _keys_text([f"{p.key} ({p.kind})" for p in self.damaged], 12))
        if self.owed:
            parts.append("owed: " + _keys_text([_owed_label(p) for p in self.owed], 12))
        if self.skipped:
            parts.append(("skipped at run time, retried: " if retry_skipped else
                          "skipped at run time, not retried (--retry-skipped retries them): ")
                         + _keys_text([p.key for p in self.skipped], 12))
        return "; ".join(parts)

    def summary(self) -> str:
        """'28 intact / 30 planned; skipped at run time: K4; missing: K1; damaged: K2
        (truncated); orphan: none' (the skipped part only when there is one)."""
        missing = [_missing_label(p) for p in self.missing]
        skipped = f"skipped at run time: {_keys_text([p.key for p in self.skipped])}; " if self.skipped else ""
        return (f"{len(self.intact)} intact / {'?' if self.planned is None else self.planned} planned; {skipped}"
                f"missing: {_keys_text(missing) or 'none'}; "
                f"damaged: {_keys_text([f'{p.key} ({p.kind})' for p in self.damaged]) or 'none'}; "
                f"orphan: {_keys_text([shown(p.path.name) for p in self.orphan]) or 'none'}"
                + (f"; owed: {_keys_text([_owed_label(p) for p in self.owed])}" if self.owed else ""))


def _owed_label(p: StepProblem) -> str:
    """'L00-feed dwell' or 'L01-pitch refinement'."""
    return f"{p.key} {'dwell' if p.code is Problem.DWELL_OWED else 'refinement'}"


def _missing_label(p: StepProblem) -> str:
    """A step's key, or an adaptive sweep with the number of steps it lacks: 'L01-up (2)'."""
    return f"{p.key} ({p.count})" if p.code is Problem.SWEEP_SHORT else p.key


def _sweeps(plan) -> dict[tuple[int, str], list[str]]:
    out: dict[tuple[int, str], list[str]] = {}
    for s in plan.schedule():
        out.setdefault((s.level_index, s.direction), []).append(s.key)
    return out


def planned_count(plan) -> int:
    """Steps the plan measures: its schedule, or in adaptive mode the chosen number per sweep."""
    k = plan.adaptive_per_sweep
    return sum(min(len(keys), k) if k else len(keys) for keys in _sweeps(plan).values())
