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
from pathlib import Path

from procedures.plan import Plan, Rig
from sim.errors import BenchError, ConfigurationError, RunDirectoryError

log = logging.getLogger(__name__)

SEQUENCE_FILE = "sequence.json"
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")


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
        raise ConfigurationError(f"{path}: no such sequence file") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise ConfigurationError(f"{path}: not a readable TOML file ({e})") from None
    problems: list[str] = []
    seq = data.get("sequence")
    if not isinstance(seq, dict):
        raise ConfigurationError(f"{path}: no [sequence] table")
    problems += [f"{path}: [sequence] {k}: unknown key (known: name, entry)" for k in seq if k not in ("name", "entry")]
    problems += [f"{path}: {k}: unknown table (known: sequence)" for k in data if k != "sequence"]
    raw = seq.get("entry")
    if not isinstance(raw, list) or not raw:
        problems.append(f"{path}: [[sequence.entry]]: at least one entry is needed")
        raw = []
    entries, names = [], set()
    for i, e in enumerate(raw):
        where = f"{path}: [[sequence.entry]] {i + 1}"
        if not isinstance(e, dict):
            problems.append(f"{where}: not a table")
            continue
        problems += [f"{where}: {k}: unknown key (known: name, plan, rig, labels)" for k in e
                     if k not in ("name", "plan", "rig", "labels")]
        name = e.get("name")
        if not isinstance(name, str) or not NAME.fullmatch(name):
            problems.append(f"{where}: name: expected a directory name (letters, digits, '.', '_', '-'), got {name!r}")
        elif name in names:
            problems.append(f"{where}: name: {name!r} is used by an earlier entry")
        names.add(name if isinstance(name, str) else "")
        labels = e.get("labels", {})
        if not isinstance(labels, dict) or not all(isinstance(v, str | int | float) for v in labels.values()):
            problems.append(f"{where}: labels: expected a table of strings, e.g. {{ lubricant = \"ISO VG 32\" }}")
            labels = {}
        files = {}
        for key, loader in (("plan", load_plan), ("rig", load_rig)):
            rel = e.get(key)
            if not isinstance(rel, str) or not rel:
                problems.append(f"{where}: {key}: the path of a {key} file is needed")
                continue
            try:
                files[key] = (rel, loader((path.parent / rel).resolve()))
            except ConfigurationError as err:
                problems.append(f"{where}: {key}: {err}")
        if len(files) == 2:
            try:          # the rig's limits hold the plan: refused now, not at 3 a.m. before entry 4
                check_envelope(files["plan"][1], files["rig"][1])
            except BenchError as err:
                problems.append(f"{where}: {err}")
        if len(files) == 2:
            entries.append(Entry(str(name), files["plan"][1], files["rig"][1], {str(k): str(v) for k, v in labels.items()},
                                 files["plan"][0], files["rig"][0]))
    if problems:
        raise ConfigurationError("\n".join(problems))
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
        raise RunDirectoryError(f"{out}: not a sequence directory ({SEQUENCE_FILE}: {e})") from None
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
        raise ConfigurationError(f"{out}: exists and is not empty (a sequence starts in a new directory; "
                                 f"bench resume {out} goes on with one)")
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
        return "not started"


def _go(out: Path, name: str, entries: list[Entry], *, progress, report: bool) -> SequenceResult:
    from dataclasses import replace

    from .api import execute
    try:
        for i, e in enumerate(entries):
            d = out / e.name
            status = _status(d)
            if status == "completed":
                continue
            log.warning("sequence %s: entry %d/%d %s (%s)", name, i + 1, len(entries), e.name,
                        "resumed" if status != "not started" else "started")
            cb = progress(e.name) if progress else None
            if status == "not started":
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
        if row["status"] != "not started":
            meta = RunStore.open(d).metadata
            row["steps_done"], row["steps_total"] = meta.get("steps_done", 0) or 0, meta.get("steps_total", 0) or 0
        rows.append(row)
    return rows


def _write_report(out: Path, name: str, entries: list[Entry]) -> Path:
    from .storage import atomic_write
    rows = _rows(out, entries)
    done = sum(r["status"] == "completed" for r in rows)
    lines = [f"# Sequence: {name}", "",
             f"{done} of {len(rows)} entries completed"
             + ("." if done == len(rows) else f"; `bench resume {out}` goes on at the first that did not."), "",
             "| # | entry | plan | rig | labels | status | steps | report |", "|---|---|---|---|---|---|---|---|"]
    for i, r in enumerate(rows, 1):
        labels = ", ".join(f"{k}={v}" for k, v in r["labels"].items())
        link = f"[report]({r['report']})" if r["report"] else ""
        steps = f"{r['steps_done']}/{r['steps_total']}" if r["status"] != "not started" else ""
        lines.append(f"| {i} | {r['name']} | {r['plan_file']} | {r['rig_file']} | {labels} | {r['status']} | {steps} "
                     f"| {link} |")
    path = out / "report.md"
    text = ("\n".join(lines) + "\n").encode()
    atomic_write(path, lambda fh: fh.write(text))
    return path
