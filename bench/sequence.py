"""Sequences: a list of (plan, rig, labels) entries run one after the other, resumable as a
whole, with one report (issue 34; decision record 0055).

    # SEQ.toml
    [sequence]
    name = "oils A and B, overnight"
    [[sequence.entry]]
    name = "oil-a"                      # the entry's run directory: OUT/oil-a/
    plan = "plans/sweep.toml"           # paths relative to this file
    rig = "rigs/oil_a.toml"
    labels = { lubricant = "ISO VG 32" }
    [[sequence.entry]]
    name = "oil-a-backbone"
    plan = "plans/backbone.toml"
    rig = "rigs/oil_a.toml"

``bench sequence SEQ.toml --out OUT`` checks every entry first (each plan and rig file, each
plan against its rig's limits) and refuses the whole sequence, naming every problem, before
anything is switched on.  It copies the entries (their plan and rig as parsed) into
``OUT/sequence.json``, then runs them in order into ``OUT/<name>/``; ``OUT/report.md`` lists
every entry's status with a link to its report, rewritten after each entry.  An entry that
does not complete (a limit, an instrument error, Ctrl-C) stops the sequence there: an
unattended rig does not go on to the next test after a fault.  ``bench resume OUT`` goes on
at the entry and the step where it stopped (completed entries are left alone).
"""

from __future__ import annotations

import json
import logging
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

from procedures.plan import Plan, Rig
from sim.errors import BenchError, ConfigurationError, RunDirectoryError

from .words import Said
from .words.terminal import refused
from .words.terminal_config import sequence_line

log = logging.getLogger(__name__)

SEQUENCE_FILE = "sequence.json"
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
KEYS = ("name", "entry")                        # [sequence]
ENTRY_KEYS = ("name", "plan", "rig", "labels")  # each [[sequence.entry]]
TABLES = ("sequence",)


class SequenceProblem(StrEnum):
    """A sequence file's or directory's problem (its words: bench.words.terminal_config.SEQUENCE);
    fields path (the file) and, for an entry's, entry (its number from 1)."""

    NOT_FOUND = "sequence_not_found"
    NOT_TOML = "sequence_not_toml"                  # detail (the reader's or the TOML parser's words)
    NO_TABLE = "sequence_no_table"
    UNKNOWN_KEY = "sequence_unknown_key"            # key, known
    UNKNOWN_TABLE = "sequence_unknown_table"        # table, known
    NO_ENTRY = "sequence_no_entry"
    ENTRY_NOT_TABLE = "entry_not_table"
    ENTRY_UNKNOWN_KEY = "entry_unknown_key"         # key, known
    ENTRY_BAD_NAME = "entry_bad_name"               # name (what the file gives)
    ENTRY_NAME_USED = "entry_name_used"             # name
    ENTRY_BAD_LABELS = "entry_bad_labels"
    ENTRY_NO_FILE = "entry_no_file"                 # key (plan or rig)
    ENTRY_FILE = "entry_file"                       # key, detail (the plan's or rig's ConfigError, its words)
    ENTRY_ENVELOPE = "entry_envelope"               # detail (the envelope's refusal, its words)
    SEVERAL = "sequence_several"                    # problems: each a Said, in order
    NOT_A_SEQUENCE_DIR = "not_a_sequence_dir"       # out, file, detail (the reader's words)
    OUT_NOT_EMPTY = "sequence_out_not_empty"        # out


class EntryStatus(StrEnum):
    """An entry's status besides its run's (bench.storage.RunStatus, run.json's ``status``)."""

    NOT_STARTED = "not started"     # its directory holds no run yet (never stored)


class SequenceLine(StrEnum):
    """What a sequence logs (its words: bench.words.terminal_config.SEQUENCE)."""

    ENTRY = "sequence_entry"        # sequence, entry (from 1), entries, name, resumed


@dataclass(frozen=True)
class Entry:
    name: str
    plan: Plan
    rig: Rig
    labels: dict[str, str] = field(default_factory=dict)
    plan_file: str = ""
    rig_file: str = ""


def load_sequence(path: Path) -> tuple[str, list[Entry]]:
    """The sequence file's name and entries; every problem of every entry named in one
    `ConfigurationError` (one line each)."""
    import tomllib

    from .config import load_plan, load_rig
    from .session import check_envelope
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise refused(ConfigurationError, SequenceProblem.NOT_FOUND, path=path) from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise refused(ConfigurationError, SequenceProblem.NOT_TOML, path=path, detail=str(e)) from None
    problems: list[Said] = []

    def bad(code: SequenceProblem, **fields) -> None:
        problems.append(Said(code, {"path": path, **fields}))
    seq = data.get("sequence")
    if not isinstance(seq, dict):
        raise refused(ConfigurationError, SequenceProblem.NO_TABLE, path=path)
    for k in seq:
        if k not in KEYS:
            bad(SequenceProblem.UNKNOWN_KEY, key=k, known=KEYS)
    for k in data:
        if k not in TABLES:
            bad(SequenceProblem.UNKNOWN_TABLE, table=k, known=TABLES)
    raw = seq.get("entry")
    if not isinstance(raw, list) or not raw:
        bad(SequenceProblem.NO_ENTRY)
        raw = []
    entries, names = [], set()
    for i, e in enumerate(raw, 1):
        if not isinstance(e, dict):
            bad(SequenceProblem.ENTRY_NOT_TABLE, entry=i)
            continue
        for k in e:
            if k not in ENTRY_KEYS:
                bad(SequenceProblem.ENTRY_UNKNOWN_KEY, entry=i, key=k, known=ENTRY_KEYS)
        name = e.get("name")
        if not isinstance(name, str) or not NAME.fullmatch(name):
            bad(SequenceProblem.ENTRY_BAD_NAME, entry=i, name=name)
        elif name in names:
            bad(SequenceProblem.ENTRY_NAME_USED, entry=i, name=name)
        names.add(name if isinstance(name, str) else "")
        labels = e.get("labels", {})
        if not isinstance(labels, dict) or not all(isinstance(v, str | int | float) for v in labels.values()):
            bad(SequenceProblem.ENTRY_BAD_LABELS, entry=i)
            labels = {}
        files = {}
        for key, loader in (("plan", load_plan), ("rig", load_rig)):
            rel = e.get(key)
            if not isinstance(rel, str) or not rel:
                bad(SequenceProblem.ENTRY_NO_FILE, entry=i, key=key)
                continue
            try:
                files[key] = (rel, loader((path.parent / rel).resolve()))
            except ConfigurationError as err:
                bad(SequenceProblem.ENTRY_FILE, entry=i, key=key, detail=str(err))
        if len(files) == 2:
            try:          # the rig's limits hold the plan: refused now, not at 3 a.m. before entry 4
                check_envelope(files["plan"][1], files["rig"][1])
            except BenchError as err:
                bad(SequenceProblem.ENTRY_ENVELOPE, entry=i, detail=str(err))
        if len(files) == 2:
            entries.append(Entry(str(name), files["plan"][1], files["rig"][1], {str(k): str(v) for k, v in labels.items()},
                                 files["plan"][0], files["rig"][0]))
    if problems:
        raise refused(ConfigurationError, SequenceProblem.SEVERAL, problems=problems)
    return str(seq.get("name") or path.stem), entries


@dataclass
class SequenceResult:
    path: Path
    name: str
    entries: list[dict]          # name, status, steps_done, steps_total, report

    @property
    def completed(self) -> bool:
        return all(e["status"] == "completed" for e in self.entries)


def _stored(out: Path) -> tuple[str, list[Entry]]:
    from .config import parse_rig, parse_stored_plan, rig_toml
    try:
        data = json.loads((out / SEQUENCE_FILE).read_text())
    except (OSError, ValueError) as e:
        raise refused(RunDirectoryError, SequenceProblem.NOT_A_SEQUENCE_DIR, out=out, file=SEQUENCE_FILE,
                      detail=str(e)) from None
    entries = [Entry(e["name"], parse_stored_plan(e["plan"], f"{out}/{SEQUENCE_FILE}"),
                     parse_rig({"rig": rig_toml(e["rig"])}, f"{out}/{SEQUENCE_FILE}"), e.get("labels") or {},
                     e.get("plan_file", ""), e.get("rig_file", "")) for e in data["entries"]]
    return data["name"], entries


def is_sequence_dir(path: Path) -> bool:
    return (Path(path) / SEQUENCE_FILE).is_file()


def run_sequence(seq_file: Path, out: Path, *, progress: Callable[[str], Callable | None] | None = None,
                 report: bool = True) -> SequenceResult:
    """Check every entry of ``seq_file``, then run them in order into ``out/<name>/``."""
    from .storage import write_json
    name, entries = load_sequence(seq_file)
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        raise refused(ConfigurationError, SequenceProblem.OUT_NOT_EMPTY, out=out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / SEQUENCE_FILE, {"name": name, "source": str(Path(seq_file).resolve()), "entries": [
        {"name": e.name, "plan": e.plan.to_dict(), "rig": e.rig.to_dict(), "labels": e.labels,
         "plan_file": e.plan_file, "rig_file": e.rig_file} for e in entries]})
    return _go(out, name, entries, progress=progress, report=report)


def resume_sequence(out: Path, *, progress=None, report: bool = True) -> SequenceResult:
    """Go on with the sequence in ``out`` at the entry and the step where it stopped."""
    name, entries = _stored(Path(out))
    return _go(Path(out), name, entries, progress=progress, report=report)


def _status(run_dir: Path) -> str:
    from .storage import RunStore
    try:
        return str(RunStore.open(run_dir).metadata.get("status", "unknown"))
    except RunDirectoryError:
        return EntryStatus.NOT_STARTED


def _go(out: Path, name: str, entries: list[Entry], *, progress, report: bool) -> SequenceResult:
    from dataclasses import replace

    from .api import execute
    try:
        for i, e in enumerate(entries):
            d = out / e.name
            status = _status(d)
            if status == "completed":
                continue
            log.warning(sequence_line(SequenceLine.ENTRY, sequence=name, entry=i + 1, entries=len(entries),
                                      name=e.name, resumed=status != EntryStatus.NOT_STARTED))
            cb = progress(e.name) if progress else None
            if status == EntryStatus.NOT_STARTED:
                execute(e.plan, e.rig, d, progress=cb, labels={**e.labels, "sequence": name, "entry": e.name})
            else:
                execute(replace(e.plan, skip=()), e.rig, d, resume=True, progress=cb)
            if _status(d) == "completed" and report:
                from .reports import write_report
                write_report(d)
            _write_report(out, name, entries)
            if _status(d) != "completed":
                break                 # a fault stops the sequence: the next entry waits for a person
    finally:
        _write_report(out, name, entries)
    return SequenceResult(out, name, _rows(out, entries))


def _rows(out: Path, entries: list[Entry]) -> list[dict]:
    from .storage import RunStore
    rows = []
    for e in entries:
        d = out / e.name
        row = {"name": e.name, "status": _status(d), "steps_done": 0, "steps_total": 0,
               "report": f"{e.name}/report/report.md" if (d / "report" / "report.md").is_file() else "",
               "plan_file": e.plan_file, "rig_file": e.rig_file, "labels": e.labels}
        if row["status"] != EntryStatus.NOT_STARTED:
            meta = RunStore.open(d).metadata
            row["steps_done"], row["steps_total"] = meta.get("steps_done", 0) or 0, meta.get("steps_total", 0) or 0
        rows.append(row)
    return rows


def _write_report(out: Path, name: str, entries: list[Entry]) -> Path:
    from .reports import sequence_md
    from .storage import atomic_write
    path = out / "report.md"
    text = sequence_md(out, name, _rows(out, entries), EntryStatus.NOT_STARTED).encode()
    atomic_write(path, lambda fh: fh.write(text))
    return path
