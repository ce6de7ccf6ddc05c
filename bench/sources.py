"""Measured steps from a run directory or a UFF58 file of time records (contract 2).

    load_source(path) -> Source(path, kind "run" | "uff58", steps, rejected)

Every step is analysed from its time records, the same way for both kinds
(:func:`sim.records.analyse_records`): harmonics up to Nyquist (at most 200) over the
largest whole number of periods, the noise from the scatter of the periods, the
one-period averaged records (for loop plots), and a periodicity score.

- Run directory (``bench run``): the step results and raw blocks are read through
  :mod:`bench.storage`; the frequency is the generator's, the level the plan's.
- UFF58 file (the convention of docs/uff58-input.md): function type 1, one load case per
  step, three records per step with ordinate specific data types 13 (force, N),
  12 (acceleration, m/s^2) and 8 (displacement, m), abscissa increment 1/fs.  No tags
  needed: the frequency is estimated from the force record and the level is the measured
  force amplitude.  ``bench export`` tags (``bench step=... f=...``) are used when present.

Before the harmonics, :func:`sim.artefacts.assess_step` looks at the time records for
measurement artefacts: interference lines (fitted and removed), offset drift (removed),
unsettled transients (the first periods dropped, or the step rejected with the settle
cycles it needs), clipping and drop-outs (rejected); then, over the steps in the order they
were measured, :func:`sim.artefacts.attribute_lines` names a line that no steady source
explains (mains, or one frequency in several steps) the rig's own unsettled free vibration.
Its :class:`~sim.artefacts.StepQuality`
(usable / flagged / rejected, reasons naming the channel) is the one notion of step
quality: ``bench analyze`` and the run report both show it (``Source.quality``).

A run directory's step of format version 2 (decision record 0047) holds that analysis,
made once when its block was measured (:func:`sim.step_record.measure_block`): it is
read, not made again; the raw block is assessed here only for a version-1 step and for a
UFF58 file.

A step whose records are missing, inconsistent (lengths, sample rates), non-finite, too
short, spoiled by an artefact, or not periodic enough after cleaning (harmonics or offset
changing between the two halves of the record by more than DRIFT_LIMIT standard errors)
is rejected with a reason, never silently dropped; so is a step with a record pyuff cannot
read (the rest of the file is used).  A file that is not a universal file raises
ValueError naming it.  Nothing is written: the user's files are left as they are.
"""

from __future__ import annotations

import logging
import math
import re
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

import numpy as np

from procedures.kind import QUANTITIES
from sim.artefacts import StepQuality, assess_step, attribute_lines
from sim.errors import ConfigurationError, RunDirectoryError
from sim.identify import StepHarmonics
from sim.records import PeriodicRecords
from sim.step_record import quality_of, records_of

from .storage import RunStore
from .words import terminal_data as words

log = logging.getLogger(__name__)

SDT = {13: "force", 12: "accel", 8: "disp"}      # UFF58 record 8 ordinate specific data type
FUNC_TIME = 1
TAG = "bench"


class SourceProblem(StrEnum):
    """What is wrong with a source (a refusal) or with one of its steps (the step's rejection
    reason), the reader's log lines and a step's level in words; words:
    :data:`bench.words.terminal_data.SOURCE`."""

    NO_SUCH_SOURCE = "no_such_source"       # path
    RUN_UNREADABLE = "run_unreadable"       # path, detail: the reader's error
    DAMAGED = "damaged"                     # detail: the run directory's problem in words
    RAW_UNREADABLE = "raw_unreadable"       # error (its type), detail
    RAW_LACKS = "raw_lacks"                 # missing: the raw block's keys
    NOT_UFF = "not_uff"                     # path, error (its type), detail
    NOT_A_DATASET = "not_a_dataset"         # found: the type pyuff returned
    RECORD_UNREADABLE = "record_unreadable"  # record (1-based), error (its type), detail
    NO_DATASET_58 = "no_dataset_58"         # path, types: the file's dataset types
    NOT_A_QUANTITY = "not_a_quantity"       # record, sdt: its ordinate data type
    TWO_RECORDS = "two_records"             # sdt, first, second: the file's records
    MISSING_RECORDS = "missing_records"     # sdts: the data types missing
    UNEVEN_SPACING = "uneven_spacing"       # record
    COMPLEX_RECORD = "complex_record"       # channel
    LENGTHS_DIFFER = "lengths_differ"       # sizes: channel -> samples
    NO_SAMPLE_RATE = "no_sample_rate"
    RATES_DIFFER = "rates_differ"           # rates: channel -> S/s
    NOT_FINITE = "not_finite"               # channel
    NO_STEPS_TO_IDENTIFY = "no_steps_to_identify"   # path (bench identify, an identification batch)
    NOT_TIME_RECORDS = "not_time_records"   # path, count (a log line)
    STEP_REJECTED = "step_rejected"         # path, step, reason (a log line)
    LEVEL_HELD = "level_held"               # level, unit, force_N: a step's level in words (not a problem)
    LEVEL_FORCE = "level_force"             # force_N


@dataclass
class MeasuredStep:
    key: str
    level_N: float              # force amplitude: the plan's, or measured when untagged
    freq_Hz: float
    harmonics: StepHarmonics
    fs_Hz: float
    force_N: np.ndarray         # one period, averaged over the record's periods
    accel_m_s2: np.ndarray
    disp_m: np.ndarray
    direction: str = ""         # "up", "down", or "" when unknown
    periods: int = 0
    drift_sigma: float = 0.0
    quality: StepQuality = field(default_factory=StepQuality)
    held: tuple[float, str] | None = None   # a response-controlled step: (its level, the level's unit, "m" or "m/s^2")

    def level_text(self) -> str:
        """The step's level in words: the force, and the response it held if it held one."""
        return (words.said(SourceProblem.LEVEL_HELD, level=self.held[0], unit=self.held[1], force_N=self.level_N)
                if self.held else words.said(SourceProblem.LEVEL_FORCE, force_N=self.level_N))


@dataclass
class Rejected:
    step: str
    reason: str
    quality: StepQuality | None = None      # None when the records could not be read at all


class StepRejected(ValueError):
    """A step's records are readable but not usable; ``quality`` says why."""

    def __init__(self, quality: StepQuality):
        super().__init__(quality.reason)
        self.quality = quality


@dataclass
class Source:
    path: Path
    kind: str                   # "run" | "uff58"
    steps: list[MeasuredStep] = field(default_factory=list)
    rejected: list[Rejected] = field(default_factory=list)
    metadata: dict = field(default_factory=dict)   # run.json for a run

    def quality(self) -> list[tuple[str, StepQuality]]:
        """(step key, quality) of every step whose records could be read, kept or rejected,
        in the source's order of kept steps then rejected ones."""
        return ([(s.key, s.quality) for s in self.steps]
                + [(r.step, r.quality) for r in self.rejected if r.quality is not None])

    def attention(self) -> list[tuple[str, str, str]]:
        """(step, "rejected" | "flagged", reason) of every step that is not simply usable:
        what ``bench analyze`` writes as steps_rejected / steps_flagged and the report lists."""
        out = [(r.step, "rejected", r.reason) for r in self.rejected]
        out += [(s.key, "flagged", s.quality.text) for s in self.steps if s.quality.status == "flagged"]
        return out


def load_source(path: Path) -> Source:
    """Steps of a run directory or of a UFF58 file of time records."""
    path = Path(path)
    if path.is_dir():
        return _load_run(path)
    if not path.is_file():
        raise words.refused(ConfigurationError, SourceProblem.NO_SUCH_SOURCE, path=path)
    return _load_uff(path)


def measured_step(key: str, force, accel, disp, fs_Hz: float, freq_Hz: float | None = None,
                  level_N: float | None = None, direction: str = "") -> MeasuredStep:
    """One step from its three records, cleaned of the artefacts that can be removed;
    ValueError names what is wrong with them (:class:`StepRejected` with the step's quality
    when an artefact or the periodicity gate rejects it)."""
    a = assess_step(force, accel, disp, fs_Hz, freq_Hz)
    if a.records is None:
        raise StepRejected(a.quality)
    return _step(key, a.records, a.quality, level_N, direction)


def recorded_step(key: str, result: dict) -> MeasuredStep | None:
    """One step from the analysis its step result keeps (format version 2), not made again;
    None for a version-1 step (no analysis kept).  :class:`StepRejected` when its quality
    check rejected it."""
    rec, quality = records_of(result), quality_of(result)
    if rec is None or quality is None:
        return None
    if quality.status == "rejected":
        raise StepRejected(quality)
    return _step(key, rec, quality, result.get("target_force_N"), result.get("direction", ""))


def _held_level(result: dict) -> tuple[float, str] | None:
    """(level, unit) a response-controlled step held (its ``response_control`` record), else None."""
    rc = result.get("response_control")
    if not isinstance(rc, dict) or rc.get("quantity") not in QUANTITIES:
        return None
    return float(rc["target"]), QUANTITIES[rc["quantity"]].unit


def _step(key: str, rec: PeriodicRecords, quality: StepQuality, level_N: float | None, direction: str) -> MeasuredStep:
    h = StepHarmonics.from_records(rec)
    c = rec.channels
    level = float(abs(h.force[0])) if level_N is None or not math.isfinite(level_N) else float(level_N)
    return MeasuredStep(key=key, level_N=level, freq_Hz=rec.freq_Hz, harmonics=h, fs_Hz=rec.fs_Hz,
                        force_N=c["force"].mean_period, accel_m_s2=c["accel"].mean_period,
                        disp_m=c["disp"].mean_period, direction=direction, periods=rec.periods,
                        drift_sigma=rec.drift_sigma, quality=quality)


# ---------------------------------------------------------------------------- run directories


def _load_run(path: Path) -> Source:
    store = RunStore.open(path)
    try:
        src = Source(path=path, kind="run", metadata=store.metadata)
        results = store.results()
    except (OSError, ValueError) as e:         # json.JSONDecodeError is a ValueError
        raise words.refused(RunDirectoryError, SourceProblem.RUN_UNREADABLE, path=path, detail=str(e)) from e
    src.rejected += [Rejected(p.key or p.path.name, words.said(SourceProblem.DAMAGED, detail=str(p)))
                     for p in store.problems]
    order = []
    for r in results:
        key = str(r.get("key", "?"))
        order.append(key)
        try:
            kept = recorded_step(key, dict(r))
        except (StepRejected, ValueError, KeyError, TypeError) as e:
            src.rejected.append(Rejected(key, str(e), getattr(e, "quality", None)))
            continue
        if kept is not None:
            kept.held = _held_level(r)
            src.steps.append(kept)
            continue
        try:
            raw = store.raw(key)
        except Exception as e:  # noqa: BLE001 - a damaged block rejects its step, not the run
            src.rejected.append(Rejected(key, words.said(SourceProblem.RAW_UNREADABLE, error=type(e).__name__,
                                                         detail=str(e))))
            continue
        missing = [k for k in ("force_N", "accel_m_s2", "disp_m", "fs_Hz") if k not in raw]
        if missing:
            src.rejected.append(Rejected(key, words.said(SourceProblem.RAW_LACKS, missing=missing)))
            continue
        try:
            src.steps.append(measured_step(key, raw["force_N"], raw["accel_m_s2"], raw["disp_m"],
                                           float(raw["fs_Hz"]), float(r["freq_Hz"]),
                                           r.get("target_force_N"), r.get("direction", "")))
            src.steps[-1].held = _held_level(r)
        except (ValueError, KeyError, TypeError) as e:
            src.rejected.append(Rejected(key, str(e), getattr(e, "quality", None)))
    _attribute_lines(src, order)
    _log_rejections(src)
    return src


def resonances_Hz(steps: list[MeasuredStep], group: float = 1.15) -> tuple[float, ...]:
    """The frequency of the most compliant step (|X1/P1|) of each force level (levels within
    15 % are one), where it lies inside that level's frequencies (not at an end)."""
    levels: list[float] = []
    for lv in sorted(s.level_N for s in steps if s.level_N > 0):
        if not levels or lv > group * levels[-1]:
            levels.append(lv)
    out = []
    for lv in levels:
        g = sorted((s for s in steps if s.level_N > 0 and max(x for x in levels if x <= s.level_N * (1 + 1e-9)) == lv),
                   key=lambda s: s.freq_Hz)
        mag = [abs(s.harmonics.disp[0] / s.harmonics.force[0]) if abs(s.harmonics.force[0]) > 0 else 0.0 for s in g]
        k = int(np.argmax(mag)) if mag else -1
        if 0 < k < len(g) - 1:
            out.append(float(g[k].freq_Hz))
    return tuple(out)


def _attribute_lines(src: Source, order: list[str]) -> None:
    """Each step's lines attributed over the source's steps in measured ``order``
    (:func:`sim.artefacts.attribute_lines`): a step's quality is replaced where a line
    turned out to be the rig's own free vibration."""
    by = dict(src.quality())
    new = dict(attribute_lines([(k, by[k]) for k in order if k in by], resonances_Hz(src.steps)))
    for s in src.steps:
        s.quality = new.get(s.key, s.quality)
    for r in src.rejected:
        if r.quality is not None:
            r.quality = new.get(r.step, r.quality)


# ---------------------------------------------------------------------------- UFF58


def _tags(ds: dict) -> dict[str, str]:
    out = {}
    for line in (ds.get("id4", ""), ds.get("id5", "")):
        words = str(line or "").split()
        if words and words[0] == TAG:
            out.update(w.split("=", 1) for w in words[1:] if "=" in w)
    return out


def _read_uff(path: Path) -> list[dict]:
    import pyuff

    try:
        uff = pyuff.UFF(str(path))
        types = [int(t) for t in uff.get_set_types()]
    except Exception as e:  # noqa: BLE001 - pyuff raises many kinds
        raise words.refused(ConfigurationError, SourceProblem.NOT_UFF, path=path, error=type(e).__name__,
                            detail=str(e)) from e
    out = []
    for i, t in enumerate(types):
        if t != 58:
            continue
        try:
            ds = uff.read_sets(i)
            if not isinstance(ds, dict):
                raise words.refused(ValueError, SourceProblem.NOT_A_DATASET, found=type(ds).__name__)
        except Exception as e:  # noqa: BLE001 - a damaged record costs its step only
            reason = words.said(SourceProblem.RECORD_UNREADABLE, record=i + 1, error=type(e).__name__, detail=str(e))
            log.warning("%s: %s", path, reason)
            ds = dict(_record_header(uff, path, i), _error=reason)
        ds["_record"] = i + 1
        out.append(ds)
    if not out:
        raise words.refused(ConfigurationError, SourceProblem.NO_DATASET_58, path=path, types=sorted(set(types)))
    return out


def _record_header(uff, path: Path, i: int) -> dict:
    """Function type, load case and ordinate data type of ASCII record ``i`` whose data
    pyuff could not read (records 6 and 9 of the dataset's header), so that the damaged
    record is grouped with its step and costs that step only; {} when the header cannot be
    read either (the record then stands alone)."""
    try:
        start, end = (int(v) for v in uff._block_ind[i])      # pyuff's index of the file's blocks
        if uff._set_formats[i] != 0:                           # binary 58b: no text header to read
            return {}
        with open(path, "rb") as fh:
            fh.seek(start)
            lines = fh.read(min(end - start, 2000)).decode("ascii", "replace").splitlines()
        rec6, rec9 = lines[7].split(), lines[10].split()
        return dict(func_type=int(rec6[0]), load_case_id=int(rec6[3]), ordinate_spec_data_type=int(rec9[0]))
    except Exception:  # noqa: BLE001 - best effort: the record is rejected on its own then
        return {}


def _group(records: list[dict]) -> list[tuple[str, list[dict]]]:
    """Records of one step: by load case when the file numbers them, else by our step
    tag, else consecutive runs of force/acceleration/displacement."""
    cases = {int(ds.get("load_case_id", 0) or 0) for ds in records}
    groups: dict[str, list[dict]] = {}
    if len(cases) > 1:
        for ds in records:
            groups.setdefault(f"LC{int(ds.get('load_case_id', 0) or 0):04d}", []).append(ds)
        return list(groups.items())
    out: list[tuple[str, list[dict]]] = []
    for ds in records:
        tag = _tags(ds).get("step")
        sdt = int(ds.get("ordinate_spec_data_type", -1))
        last = out[-1] if out else None
        new = (last is None or (tag is not None and last[0] != tag)
               or any(int(d.get("ordinate_spec_data_type", -1)) == sdt for d in last[1]))
        if new:
            out.append((tag or f"uff-{len(out):05d}", []))
        out[-1][1].append(ds)
    return out


def _fs(ds: dict, tags: dict) -> float:
    if "fs" in tags:
        return float(tags["fs"])
    inc = ds.get("abscissa_inc")
    if not inc:
        x = np.asarray(ds.get("x", []), float)
        inc = x[1] - x[0] if x.size > 1 else 0.0
    return 1.0 / float(inc) if inc and float(inc) > 0 else math.nan


def _uff_step(key: str, recs: list[dict]) -> MeasuredStep:
    damaged = [ds["_error"] for ds in recs if "_error" in ds]
    if damaged:
        raise ValueError("; ".join(damaged))
    by = {}
    for ds in recs:
        sdt = int(ds.get("ordinate_spec_data_type", -1))
        if sdt not in SDT:
            raise words.refused(ValueError, SourceProblem.NOT_A_QUANTITY, record=ds["_record"], sdt=sdt)
        if sdt in by:
            raise words.refused(ValueError, SourceProblem.TWO_RECORDS, sdt=sdt, first=by[sdt]["_record"],
                                second=ds["_record"])
        by[sdt] = ds
    missing = [t for t in SDT if t not in by]
    if missing:
        raise words.refused(ValueError, SourceProblem.MISSING_RECORDS, sdts=missing)
    for ds in by.values():
        if int(ds.get("abscissa_spacing", 1)) != 1:
            raise words.refused(ValueError, SourceProblem.UNEVEN_SPACING, record=ds["_record"])
    tags = {}
    for ds in by.values():
        tags.update(_tags(ds))
    data = {SDT[t]: np.asarray(by[t]["data"]) for t in SDT}
    for name, x in data.items():
        if np.iscomplexobj(x):
            raise words.refused(ValueError, SourceProblem.COMPLEX_RECORD, channel=name)
    sizes = {name: x.size for name, x in data.items()}
    if len(set(sizes.values())) != 1:
        raise words.refused(ValueError, SourceProblem.LENGTHS_DIFFER, sizes=sizes)
    rates = {SDT[t]: _fs(by[t], tags) for t in SDT}
    fs = rates["force"]
    if not (math.isfinite(fs) and fs > 0):
        raise words.refused(ValueError, SourceProblem.NO_SAMPLE_RATE)
    if any(not (abs(r / fs - 1) < 1e-6) for r in rates.values()):
        raise words.refused(ValueError, SourceProblem.RATES_DIFFER, rates=rates)
    for name, x in data.items():
        if not np.all(np.isfinite(x)):
            raise words.refused(ValueError, SourceProblem.NOT_FINITE, channel=name)
    freq = float(tags["f"]) if "f" in tags else None
    level = float(tags["level"]) if "level" in tags else None
    direction = tags.get("dir", "")
    if not direction:
        m = re.search(r"-(up|down)$", key)
        direction = m.group(1) if m else ""
    return measured_step(key, data["force"].astype(float), data["accel"].astype(float),
                         data["disp"].astype(float), fs, freq, level, direction)


def _load_uff(path: Path) -> Source:
    records = _read_uff(path)
    times = [ds for ds in records if int(ds.get("func_type", -1)) == FUNC_TIME
             or ("_error" in ds and "func_type" not in ds)]    # damaged beyond its header: rejected, not dropped
    if len(times) < len(records):
        log.info("%s", words.said(SourceProblem.NOT_TIME_RECORDS, path=path, count=len(records) - len(times)))
    src = Source(path=path, kind="uff58")
    groups = _group(times)
    for key, recs in groups:
        try:
            src.steps.append(_uff_step(key, recs))
        except ValueError as e:
            src.rejected.append(Rejected(key, str(e), getattr(e, "quality", None)))
    _attribute_lines(src, [k for k, _ in groups])
    _log_rejections(src)
    return src


def _log_rejections(src: Source) -> None:
    for r in src.rejected:
        log.warning("%s", words.said(SourceProblem.STEP_REJECTED, path=src.path, step=r.step, reason=r.reason))


# ---------------------------------------------------------------------------- UFF58 FRF records

FUNC_FRF, FUNC_SPECTRUM, FUNC_AUTO = 4, 12, 2   # record 6: frequency response function, (linear) spectrum, auto spectrum


@dataclass(frozen=True)
class FrfRecord:
    """One dataset-58 record of a frequency-domain function as the file holds it (function
    type 4, an FRF, 12, a spectrum, or 2, an auto spectrum): read here, judged by :mod:`bench.frf_import`."""

    record: int                 # 1-based, in the file's order of datasets 58
    func_type: int
    sdt: int                    # ordinate specific data type (record 9): 8 disp, 11 vel, 12 accel, 13 force
    denominator: int            # record 10's (13: per newton)
    f_Hz: np.ndarray
    data: np.ndarray            # complex
    ids: tuple[str, ...]        # id1..id5
    load_case: int
    rsp: tuple[int, int]        # response node, direction
    ref: tuple[int, int]        # reference node, direction
    unit: str                   # the ordinate's units label ("" when NONE)
    tags: dict = field(default_factory=dict)    # our ``bench k=v`` tags (bench export)
    error: str = ""             # a record pyuff could not read: why


def read_frf_records(path: Path) -> list[FrfRecord]:
    """Every dataset-58 record of function type 4 (FRF), 12 (spectrum) or 2 (auto spectrum) in ``path``
    (:class:`ConfigurationError` naming the file when it is not a universal file or holds
    no dataset 58); the judging of what they hold is the importer's."""
    out = []
    for ds in _read_uff(Path(path)):
        ft = int(ds.get("func_type", -1))
        if "_error" in ds:
            out.append(FrfRecord(ds["_record"], ft, -1, -1, np.zeros(0), np.zeros(0, complex), (), 0, (0, 0), (0, 0),
                                 "", {}, ds["_error"]))
            continue
        if ft not in (FUNC_FRF, FUNC_SPECTRUM, FUNC_AUTO):
            continue
        unit = str(ds.get("ordinate_axis_units_lab", "") or "").strip()
        out.append(FrfRecord(
            ds["_record"], ft, int(ds.get("ordinate_spec_data_type", -1)), int(ds.get("orddenom_spec_data_type", 0) or 0),
            np.asarray(ds.get("x", []), float), np.asarray(ds.get("data", []), complex),
            tuple(str(ds.get(f"id{i}", "") or "") for i in range(1, 6)), int(ds.get("load_case_id", 0) or 0),
            (int(ds.get("rsp_node", 0) or 0), int(ds.get("rsp_dir", 0) or 0)),
            (int(ds.get("ref_node", 0) or 0), int(ds.get("ref_dir", 0) or 0)),
            "" if unit.upper() == "NONE" else unit, _tags(ds)))
    return out
