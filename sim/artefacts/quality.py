"""What the artefact check says of one step: each :class:`Artefact`, the step's
:class:`StepQuality` and the :class:`Assessment` (:mod:`sim.artefacts`)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from enum import StrEnum
from typing import Any

from ..records import PeriodicRecords
from . import sentences
from .sentences import UNIT

KINDS = ("line_interference", "unsettled_transient", "clipping", "dropout", "offset_drift")
RAW_FAULT_KINDS = ("clipping", "dropout")     # found in the raw samples: the step is rejected before cleaning


class Rejection(StrEnum):
    """Which check rejected a step (:attr:`StepQuality.rejected_by`)."""

    RAW_FAULT = "raw_fault"          # clipping or drop-outs in the raw samples
    NOT_PERIODIC = "not_periodic"    # the periodicity gate on the cleaned records (settling longer can cure it)


@dataclass(frozen=True)
class Artefact:
    """One artefact on one channel of one step.  ``size`` is in the channel's SI unit:
    a line's or a transient's amplitude (at the record start), a drift's change over the
    record, the clipping level, a drop-out's held value."""

    kind: str                        # one of KINDS
    channel: str                     # force | accel | disp
    size: float
    action: str                      # "removed" | "trimmed" | "rejected"
    freq_Hz: float = math.nan        # line / transient frequency
    time_s: float = math.nan         # clipping / drop-out: first sample, from the record start
    duration_s: float = math.nan     # drop-out length; clipping: time spent at the limit
    decay_per_s: float = math.nan    # transient: amplitude decay rate sigma (A = A_0 exp(-sigma t))
    settle_cycles: int = 0           # transient: drive cycles from the record start until harmless
    evidence: str = ""
    snr: float = math.nan            # line: amplitude over one standard error of a harmonic of the record
    decay_bound_per_s: float = math.nan   # line: upper bound of its decay rate (fit + 2 standard errors)
    settle_at_least: bool = False    # settle_cycles is a least number (from that bound)
    part_of_Hz: float = math.nan     # line: a component of this stronger line of the step (leakage, sideband)

    @property
    def unit(self) -> str:
        return UNIT[self.channel]

    def describe(self) -> str:
        """The artefact in words (:func:`sim.artefacts.sentences.artefact`)."""
        return sentences.artefact(self)

    def as_dict(self) -> dict:
        f = lambda v: None if not math.isfinite(v) else float(v)      # noqa: E731
        return dict(kind=self.kind, channel=self.channel, size=float(self.size), unit=self.unit,
                    action=self.action, freq_Hz=f(self.freq_Hz), time_s=f(self.time_s),
                    duration_s=f(self.duration_s), decay_per_s=f(self.decay_per_s),
                    settle_cycles=int(self.settle_cycles), evidence=self.evidence, text=self.describe())


@dataclass
class StepQuality:
    """What a step is worth: ``usable``, ``flagged`` (used, ``notes`` say why) or
    ``rejected`` (``reason`` says why, naming the channel)."""

    status: str = "usable"
    artefacts: list[Artefact] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    reason: str = ""
    freq_Hz: float = math.nan
    level_N: float = math.nan        # force fundamental amplitude, when it could be measured
    record_s: float = math.nan       # length of the record

    @property
    def rejected_by(self) -> Rejection | None:
        """Which check rejected the step (None: not rejected): a raw-sample fault when the
        step holds one (:func:`~sim.artefacts.assess_step` stops there), else the
        periodicity gate.  From the artefacts, so a stored quality says it too."""
        if self.status != "rejected":
            return None
        if any(a.kind in RAW_FAULT_KINDS for a in self.artefacts):
            return Rejection.RAW_FAULT
        return Rejection.NOT_PERIODIC

    @property
    def text(self) -> str:
        return self.reason if self.status == "rejected" else "; ".join(self.notes)

    def as_dict(self) -> dict:
        return dict(status=self.status, reason=self.reason, notes=list(self.notes),
                    artefacts=[a.as_dict() for a in self.artefacts])

    def to_record(self) -> dict:
        """Everything of the quality, for a step file (NaN as null); :meth:`from_record` reads it back."""
        f = lambda v: None if isinstance(v, float) and not math.isfinite(v) else v      # noqa: E731
        return dict(status=self.status, reason=self.reason, notes=list(self.notes), freq_Hz=f(self.freq_Hz),
                    level_N=f(self.level_N), record_s=f(self.record_s),
                    artefacts=[{k: f(v) for k, v in asdict(a).items()} for a in self.artefacts])

    @classmethod
    def from_record(cls, d: dict) -> StepQuality:
        def g(v: Any) -> Any:
            return math.nan if v is None else v
        return cls(status=d["status"], reason=d["reason"], notes=list(d["notes"]), freq_Hz=g(d["freq_Hz"]),
                   level_N=g(d["level_N"]), record_s=g(d["record_s"]),
                   artefacts=[Artefact(**{k: g(v) for k, v in a.items()}) for a in d["artefacts"]])


@dataclass
class Assessment:
    quality: StepQuality
    records: PeriodicRecords | None      # of the cleaned (and possibly trimmed) records; None if rejected
    cleaned: dict | None = None          # channel -> cleaned samples
    start: int = 0                       # first sample kept
    # the harmonics of the cleaned records also when the periodicity gate rejected them (the
    # step's record keeps them, decision 0047); None when a raw-sample fault stopped the check first
    analysed: PeriodicRecords | None = None
