"""Run directory: crash-safe storage of a stepped-sine test, step by step.

    <run>/run.json          metadata: plan, rig, identities, versions, start/end, status
    <run>/events.jsonl      start, resume, interruption, abort, end (append-only)
    <run>/steps/<key>.json  one step's results   } written to a temporary name, fsynced,
    <run>/steps/<key>.npz   one step's raw block }   then renamed: all or nothing
    <run>/bench.log         the application's log

A step counts as done when its .json exists; the .npz is written first, so a .json never
points at a missing block.  A kill -9 at any moment leaves every completed step readable;
a torn last line of events.jsonl is skipped on reading.

Damage from outside (a full disk, an interrupted copy, a flipped bit, a file deleted by
hand) is found by checksums: each step's .json carries ``integrity`` = the SHA-256 of its
own content (canonical JSON of everything else in it) and the SHA-256 and size of its
.npz.  Every reader goes through :meth:`RunStore.results` / :meth:`RunStore.raw`, which
skip a damaged or half-missing step with a warning naming the file and why, and carry on;
:meth:`RunStore.check` lists every problem; :meth:`RunStore.set_aside_damaged` moves a
damaged step's files to ``<run>/damaged/<time>/`` (never deleting) so that resume measures
it again.  Steps written before checksums existed are read with the structural checks only.

run.json and every step file carry a ``format_version`` (docs/run-format.md); files without
one are version 1, and a version newer than this code reads is refused with a message
naming the file, never taken for damage.

Links and modes: nothing a run writes goes through a symbolic link inside the run
directory (``steps/``, ``damaged/``, ``events.jsonl``, ``bench.log``, ...): a link there
raises :class:`RunDirError` naming it, and appends open with ``O_NOFOLLOW``.  Every file
a run writes gets the mode ``0o666 & ~umask`` and every directory ``0o777 & ~umask``,
what ``touch`` and ``mkdir`` give (the temporary files of atomic writes are widened to
it: ``mkstemp`` alone makes them 0o600).  See docs/decisions/0028-hardening.md.

Here: :class:`RunStore`.  The crash-safe writing is in :mod:`bench.durable`, a step's two
files read and checked in :mod:`bench.step_files`, the steps counted against the plan in
:mod:`bench.accounting` (issue 35: one job each).
"""

from __future__ import annotations

import enum
import io
import json
import logging
import os
import stat
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from procedures.plan import StepSpec
from sim.errors import RunDirectoryError, StorageError
from sim.step_result import STEP_FORMAT_VERSION, StepResult

from .accounting import Accounting, _sweeps, stored_plan
from .accounting import planned_count as planned_count
from .durable import (
    _canonical,
    _fsync_dir,
    _json_default,
    _sha256,
    _writing,
    atomic_write,
    now_iso,
    open_append,
    real_dir,
    write_json,
)
from .durable import file_mode as file_mode
from .files import UnreadableFile, file_kind, read_file
from .runlock import LOCK_NAME
from .step_files import DamagedStep, Problem, StepProblem, _check_npz, _json_fields, _read_step_json, _utf8
from .step_files import _json_cut as _json_cut
from .step_files import shown as shown
from .words import say, terminal_run
from .words.terminal import refused

log = logging.getLogger(__name__)


class StoreLine(enum.StrEnum):
    """What reading a run directory logs and fills in (:data:`bench.words.terminal_run.STORE`)."""

    EVENTS_UNREADABLE = "events_unreadable"             # error
    EVENT_LINE_DAMAGED = "event_line_damaged"           # path, line
    EVENT_LINE_NOT_OBJECT = "event_line_not_object"     # path, line
    HISTORY_UNREADABLE = "history_unreadable"           # error (identification.jsonl's)
    SKIPPING_STEP = "skipping_step"                     # key, error
    DAMAGED_MOVED = "damaged_moved"                     # key, problem, dest
    NO_REASON = "no_reason"                             # a step skipped at run time without one


def _said(code: StoreLine, **fields) -> str:
    return say(terminal_run.STORE, code, fields)


# run.json's ``format_version`` (docs/run-format.md; absent = 1, the layout before the
# field existed).  Step files carry their own: sim.step_result.STEP_FORMAT_VERSION.
RUN_FORMAT_VERSION = 1


class RunStatus(enum.StrEnum):
    """``status`` in run.json (stored as these strings)."""

    RUNNING = "running"
    COMPLETED = "completed"
    ABORTED = "aborted"                    # stopped by a safety limit
    INTERRUPTED = "interrupted"            # Ctrl-C, SIGTERM, a stop request
    INSTRUMENT_ERROR = "instrument error"
    FAILED = "failed"                      # any other error




RunDirError = RunDirectoryError    # not a readable run directory (missing, or run.json damaged)


class RunDirRefusal(enum.StrEnum):
    """Why a run directory was refused (the error's ``code``; its words: :mod:`bench.words.terminal`)."""

    NOT_EMPTY = "run_dir_not_empty"                 # path (a new run's --out)
    NO_DIR = "run_dir_missing"                      # path
    NO_RUN_JSON = "run_dir_no_run_json"             # path
    LINK = "run_dir_link"                           # path, kind ("directory" | "file")
    NOT_REGULAR = "run_dir_not_regular"             # path, kind, found (bench.files.file_kind)
    RUN_JSON_MISSING = "run_json_missing"           # path
    RUN_JSON_UNREADABLE = "run_json_unreadable"     # detail: the file reader's words
    RUN_JSON_NOT_JSON = "run_json_not_json"         # path, json (Problem.NOT_JSON's fields)
    RUN_JSON_NOT_UTF8 = "run_json_not_utf8"         # path, byte
    RUN_JSON_TOO_DEEP = "run_json_too_deep"         # path
    RUN_JSON_NOT_OBJECT = "run_json_not_object"     # path, found
    NEWER_FORMAT = "run_json_newer"                 # path, version, reads (the newest this version reads)
    STEPS_GONE = "steps_gone"                       # path: steps/ deleted while the run used it


class NewerFormat(RunDirectoryError):
    """run.json was written by a newer guideway-bench: refused by name, never taken for damage."""


PROBLEM_KINDS = ("missing", "truncated", "corrupt", "checksum", "unknown", "skipped", "owed")


# what a run writes inside its directory: none of them may be a symbolic link
WRITTEN = ("steps", "damaged", "events.jsonl", "bench.log", "identification.jsonl", "stop.request", LOCK_NAME)


class RunStore:
    def __init__(self, path: Path):
        self.path = Path(path)
        self.steps_dir = self.path / "steps"
        self.problems: list[StepProblem] = []     # damaged steps met by the last results()
        self._npz_ok: dict[str, tuple] = {}        # key -> stamp of a block already verified
        self._json_ok: dict[str, bytes] = {}       # key -> SHA-256 of a JSON file already verified

    # ------------------------------------------------------------------ life cycle
    @staticmethod
    def check_new(path: Path) -> None:
        """Raise ``FileExistsError`` unless ``path`` can become a new run directory (absent,
        or empty but for the session lock the new session holds: bench.runlock)."""
        path = Path(path)
        if path.exists() and any(p.name != LOCK_NAME for p in path.iterdir()):
            raise refused(FileExistsError, RunDirRefusal.NOT_EMPTY, path=path)

    @classmethod
    def create(cls, path: Path, metadata: dict) -> RunStore:
        path = Path(path)
        cls.check_new(path)
        path.mkdir(parents=True, exist_ok=True)
        real_dir(path / "steps", create=True)
        store = cls(path)
        write_json(path / "run.json", dict(metadata, format_version=RUN_FORMAT_VERSION, status=RunStatus.RUNNING,
                                           started=now_iso()))
        store.event("start")
        return store

    @classmethod
    def open(cls, path: Path) -> RunStore:
        store = cls(path)
        if not store.path.exists():
            raise refused(RunDirError, RunDirRefusal.NO_DIR, path=path)
        if not (store.path / "run.json").is_file():
            raise refused(RunDirError, RunDirRefusal.NO_RUN_JSON, path=path)
        _ = store.metadata          # a damaged run.json or a newer format is named now, not deep inside a reader
        store.refuse_links()
        return store

    def refuse_links(self, *, writing: bool = False) -> None:
        """Raise :class:`RunDirError` if anything the run writes is a symbolic link, before
        anything is written (a link could lead the writes out of the run directory); with
        ``writing`` (a session about to write) also if one is not a regular file or
        directory (a FIFO would hold the session; the readers skip it)."""
        for name in WRITTEN:
            kind = "directory" if name in ("steps", "damaged") else "file"
            if (self.path / name).is_symlink():
                raise refused(RunDirError, RunDirRefusal.LINK, path=self.path / name, kind=kind)
            if not writing:
                continue
            try:
                mode = os.lstat(self.path / name).st_mode
            except FileNotFoundError:
                continue
            if not (stat.S_ISDIR(mode) if kind == "directory" else stat.S_ISREG(mode)):
                raise refused(RunDirError, RunDirRefusal.NOT_REGULAR, path=self.path / name, kind=kind,
                              found=file_kind(mode))

    @property
    def metadata(self) -> dict:
        """run.json's content; :class:`RunDirError` names it when it is missing, not a regular
        file, too large, damaged, or :class:`NewerFormat` when a newer version wrote it."""
        p = self.path / "run.json"
        try:
            meta = json.loads(read_file(p))
        except FileNotFoundError:
            raise refused(RunDirError, RunDirRefusal.RUN_JSON_MISSING, path=p) from None
        except UnreadableFile as e:
            raise refused(RunDirError, RunDirRefusal.RUN_JSON_UNREADABLE, detail=str(e)) from None
        except json.JSONDecodeError as e:
            raise refused(RunDirError, RunDirRefusal.RUN_JSON_NOT_JSON, path=p, json=_json_fields(e)) from None
        except UnicodeDecodeError as e:
            raise refused(RunDirError, RunDirRefusal.RUN_JSON_NOT_UTF8, path=p, byte=e.start) from None
        except RecursionError:
            raise refused(RunDirError, RunDirRefusal.RUN_JSON_TOO_DEEP, path=p) from None
        if not isinstance(meta, dict):
            raise refused(RunDirError, RunDirRefusal.RUN_JSON_NOT_OBJECT, path=p, found=type(meta).__name__)
        version = meta.get("format_version", 1)
        if not isinstance(version, int) or isinstance(version, bool) or version > RUN_FORMAT_VERSION:
            raise refused(NewerFormat, RunDirRefusal.NEWER_FORMAT, path=p, version=version, reads=RUN_FORMAT_VERSION)
        return meta

    def update(self, **fields) -> None:
        with _writing(self.path / "run.json"):
            write_json(self.path / "run.json", dict(self.metadata, **fields))

    def finish(self, status: RunStatus, **fields) -> None:
        self.update(status=status, ended=now_iso(), **fields)
        self.event("end", status=status)

    # ------------------------------------------------------------------ events
    def event(self, kind: str, **fields) -> None:
        line = json.dumps(dict(time=now_iso(), event=kind, **fields), default=_json_default)
        with _writing(self.path / "events.jsonl"), open_append(self.path / "events.jsonl") as fh:
            fh.write(line + "\n")
            fh.flush()
            os.fsync(fh.fileno())

    def events(self) -> list[dict]:
        out = []
        p = self.path / "events.jsonl"
        try:
            data = read_file(p)
        except FileNotFoundError:
            return out
        except UnreadableFile as e:
            log.warning(_said(StoreLine.EVENTS_UNREADABLE, error=e))
            return out
        for n, line in enumerate(data.decode(errors="replace").splitlines(), 1):
            try:
                e = json.loads(line)
            except (json.JSONDecodeError, RecursionError):
                log.warning(_said(StoreLine.EVENT_LINE_DAMAGED, path=p, line=n))
                continue
            if isinstance(e, dict):
                out.append(e)
            else:
                log.warning(_said(StoreLine.EVENT_LINE_NOT_OBJECT, path=p, line=n))
        return out

    def identification_history(self) -> list[dict]:
        """identification.jsonl's estimates, one a step (a damaged line is skipped)."""
        p = self.path / "identification.jsonl"
        try:
            data = read_file(p)
        except FileNotFoundError:
            return []
        except UnreadableFile as e:
            log.warning(_said(StoreLine.HISTORY_UNREADABLE, error=e))
            return []
        out = []
        for line in data.decode(errors="replace").splitlines():
            try:
                out.append(json.loads(line))
            except (json.JSONDecodeError, RecursionError):
                pass
        return out

    # ------------------------------------------------------------------ steps: writing
    def write_step(self, key: str, result: StepResult, raw: dict[str, np.ndarray]) -> None:
        """Store one step (raises :class:`StorageError` naming the file when it cannot)."""
        buf = io.BytesIO()
        np.savez(buf, **raw)
        npz = buf.getvalue()
        self._steps_dir_there()
        with _writing(self.steps_dir / f"{key}.npz"):
            atomic_write(self.steps_dir / f"{key}.npz", lambda fh: fh.write(npz))
        plain = json.loads(json.dumps(result, default=_json_default))    # what a reader will see
        plain.pop("integrity", None)
        plain["format_version"] = STEP_FORMAT_VERSION
        plain["integrity"] = {"json_sha256": _sha256(_canonical(plain)), "npz_sha256": _sha256(npz),
                              "npz_bytes": len(npz)}
        with _writing(self.steps_dir / f"{key}.json"):
            write_json(self.steps_dir / f"{key}.json", plain)
        st = (self.steps_dir / f"{key}.npz").stat()
        self._npz_ok[key] = (st.st_mtime_ns, st.st_size, plain["integrity"]["npz_sha256"])   # just written

    def _steps_dir_there(self) -> None:
        if not self.steps_dir.exists() and not self.steps_dir.is_symlink():
            raise refused(StorageError, RunDirRefusal.STEPS_GONE, path=self.steps_dir)

    def check_writable(self) -> None:
        """Create, write, fsync and remove a probe file in ``steps/``: a run checks that it
        can store a step before the output goes on (:class:`StorageError` naming why not)."""
        self._steps_dir_there()
        real_dir(self.steps_dir)
        probe = self.steps_dir / f".probe-{os.getpid()}.tmp"
        with _writing(probe):
            fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
            try:
                os.write(fd, b"\0" * 65536)      # about one step's block
                os.fsync(fd)
            finally:
                os.close(fd)
                probe.unlink(missing_ok=True)

    # ------------------------------------------------------------------ steps: reading
    def step_files(self) -> list[Path]:
        """The steps' JSON files present (intact or not), in key order."""
        return sorted(p for p in self.steps_dir.glob("*.json") if _utf8(p.name)) if self._steps_here() else []

    def _steps_here(self) -> bool:
        """``steps/`` is a directory inside the run directory (not a link leading out of it)."""
        return self.steps_dir.is_dir() and not self.steps_dir.is_symlink()

    def verify_step(self, key: str) -> StepResult:
        """The step's result after checking both its files (JSON content, the .npz's size
        and checksum); raises :class:`DamagedStep` naming the file and why."""
        jp, zp = self.steps_dir / f"{key}.json", self.steps_dir / f"{key}.npz"
        result, integrity = _read_step_json(jp, key, self._json_ok)
        try:
            st = os.lstat(zp)          # a link put in its place later is not the block verified
            stamp = (st.st_mtime_ns, st.st_size, (integrity or {}).get("npz_sha256"))
        except FileNotFoundError:
            stamp = None
        if stamp is None or self._npz_ok.get(key) != stamp:   # hash each block once per store
            _check_npz(zp, key, integrity)
            self._npz_ok[key] = stamp
        return result

    def done_keys(self) -> set[str]:
        """Keys of the completed steps whose files are intact (a damaged step is not done)."""
        return {r["key"] for r in self.results(warn=False)}

    def results(self, *, warn: bool = True) -> list[StepResult]:
        """Completed steps' results, in schedule order; a damaged or half-missing step is
        skipped with a warning naming the file and why (and listed in ``self.problems``)."""
        out, self.problems = [], []
        for p in self.step_files():
            try:
                out.append(self.verify_step(p.stem))
            except DamagedStep as e:
                self.problems.append(e.problem)
                if warn:
                    log.warning(_said(StoreLine.SKIPPING_STEP, key=p.stem, error=e))
        return out

    def raw(self, key: str) -> dict[str, np.ndarray]:
        """The step's raw block; raises :class:`DamagedStep` if its files are damaged."""
        self.verify_step(key)
        zp = self.steps_dir / f"{key}.npz"
        try:
            with np.load(io.BytesIO(read_file(zp)), allow_pickle=False) as z:
                return {k: z[k] for k in z.files}
        except UnreadableFile as e:
            raise DamagedStep(StepProblem(key, zp, "corrupt", Problem.UNREADABLE,
                                          dict(detail=str(e).split(": ", 1)[-1]))) from None
        except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as e:
            raise DamagedStep(StepProblem(key, zp, "corrupt", Problem.NPZ_UNREADABLE,
                                          dict(error=type(e).__name__, detail=str(e)))) from None

    def with_raw(self, results: list[dict]):
        """(result, raw block) of each given step whose block reads; damaged ones are
        skipped with a warning naming the file."""
        for r in results:
            try:
                yield r, self.raw(r["key"])
            except DamagedStep as e:
                log.warning(_said(StoreLine.SKIPPING_STEP, key=r["key"], error=e))

    # ------------------------------------------------------------------ checking and repair
    def check(self) -> list[StepProblem]:
        """Every problem of the run directory: damaged run.json or steps (missing, truncated,
        corrupt, checksum mismatch) and step files the plan does not know."""
        problems: list[StepProblem] = []
        known, plan = None, None
        try:
            plan = stored_plan(self.metadata, self.path / "run.json")
            known = {s.key for s in plan.schedule()}
        except NewerFormat:
            raise                                # not damage: refused by name
        except RunDirError as e:
            problems.append(StepProblem("", self.path / "run.json", "corrupt", Problem.RUN_JSON,
                                        dict(detail=str(e).split(": ", 1)[-1])))
        if plan is not None and plan.refine:                   # refinement steps (decision 0043)
            known = (known or set()) | {p.stem for p in self.step_files() if plan.refined_key_ok(p.stem)}
            known |= {p.stem for p in self.steps_dir.glob("*.npz") if plan.refined_key_ok(p.stem)}
        if self.steps_dir.is_symlink():
            problems.append(StepProblem("", self.steps_dir, "corrupt", Problem.STEPS_LINK))
            return problems
        if not self.steps_dir.is_dir():
            problems.append(StepProblem("", self.steps_dir, "missing", Problem.NO_STEPS_DIR))
            return problems
        jsons = {p.stem for p in self.step_files()}
        for key in sorted(jsons):
            try:
                raw = self.raw(key)                 # verifies both files first
                if not {"force_N", "accel_m_s2", "disp_m"} <= set(raw):
                    problems.append(StepProblem(key, self.steps_dir / f"{key}.npz", "corrupt", Problem.RAW_LACKS,
                                                dict(channels={"force_N", "accel_m_s2", "disp_m"} - set(raw))))
            except DamagedStep as e:
                problems.append(e.problem)
            if known is not None and key not in known:
                problems.append(StepProblem(key, self.steps_dir / f"{key}.json", "unknown", Problem.NOT_IN_PLAN))
        for p in sorted(self.steps_dir.iterdir()):
            if p.name.startswith(".") and p.name.endswith(".tmp"):
                continue       # a write cut short by a kill: harmless, replaced on resume
            if not _utf8(p.name):
                problems.append(StepProblem("", p, "unknown", Problem.NAME_NOT_UTF8))
                continue
            if p.suffix == ".npz" and p.stem in jsons:
                continue
            if p.suffix == ".json":
                continue
            if p.suffix == ".npz":
                if known is not None and p.stem not in known:
                    problems.append(StepProblem(p.stem, p, "unknown", Problem.NOT_IN_PLAN))
                # else: a block whose result was never written (kill -9): resume measures it
                continue
            problems.append(StepProblem("", p, "unknown", Problem.NOT_A_STEP_FILE))
        return problems

    def skipped_at_run_time(self) -> dict[str, str]:
        """Steps the run skipped because their force was unreachable (``step_skipped``
        events, written only when the plan says ``infeasible = "skip"``): key -> reason, the
        latest reason when a step was retried and skipped again.  A step retried later and
        measured has files and is counted as such by :meth:`account`."""
        out: dict[str, str] = {}
        for e in self.events():
            if e.get("event") == "step_skipped" and isinstance(e.get("key"), str):
                out[e["key"]] = str(e.get("reason") or _said(StoreLine.NO_REASON))
        return out

    def account(self) -> Accounting:
        """The run's steps counted against its stored plan: intact, missing (no files, or
        only one of the pair), damaged and orphan files, each named (see :class:`Accounting`)."""
        plan = stored_plan(self.metadata, self.path / "run.json")     # RunDirError naming the key
        problems = self.check()
        orphan = [p for p in problems if p.kind == "unknown" or not p.key]
        bad = {p.key: p for p in problems if p.key and p.kind != "unknown"}
        have_json = {p.stem for p in self.step_files()}
        have_npz = {p.stem for p in self.steps_dir.glob("*.npz")} if self._steps_here() else set()
        sweeps = _sweeps(plan)
        k = plan.adaptive_per_sweep
        # a run-time skip counts only where the plan allows it (the procedure writes the event
        # only then; a plan edited to "refuse" afterwards makes those steps missing again)
        allowed = self.skipped_at_run_time() if plan.infeasible == "skip" else {}
        intact, missing, damaged, skipped, n_planned = [], [], [], [], 0

        def present_step(key: str) -> None:      # a step with at least one of its files
            if key not in have_json:
                missing.append(StepProblem(key, self.steps_dir / f"{key}.json", "missing", Problem.MISSING_PAIR,
                                           dict(files=(".json",)), files=(".json",)))
            elif bad.get(key) and bad[key].kind == "missing":
                missing.append(StepProblem(key, self.steps_dir / f"{key}.npz", "missing", Problem.MISSING_PAIR,
                                           dict(files=(".npz",)), files=(".npz",)))
            elif key in bad:
                damaged.append(bad[key])
            else:
                intact.append(key)

        for (li, direction), keys in sweeps.items():
            n_sweep = min(len(keys), k) if k else len(keys)
            n_planned += n_sweep
            present = 0
            for key in keys:
                jp = self.steps_dir / f"{key}.json"
                if key not in have_json and key not in have_npz:
                    if key in allowed:
                        present += 1
                        skipped.append(StepProblem(key, jp, "skipped", Problem.SKIPPED, dict(why=allowed[key])))
                    elif not k:
                        missing.append(StepProblem(key, jp, "missing", Problem.MISSING_PAIR,
                                                   dict(files=(".json", ".npz")), files=(".json", ".npz")))
                    continue
                present += 1
                present_step(key)
            if k and present < n_sweep:
                label = f"L{li:02d}-{direction}"
                missing.append(StepProblem(label, self.steps_dir, "missing", Problem.SWEEP_SHORT,
                                           dict(short=n_sweep - present, planned=n_sweep), count=n_sweep - present))
        if plan.refine:       # refinement steps: chosen online, counted as measured (decision 0043)
            for key in sorted(k for k in have_json | have_npz if plan.refined_key_ok(k)):
                n_planned += 1
                present_step(key)
        order = {key: i for i, key in enumerate(s.key for s in plan.schedule())}
        missing.sort(key=lambda p: order.get(p.key, -1))
        owed = self._refinement_owed(plan, set(intact), set(allowed), {p.key for p in missing}) if plan.refine else []
        return Accounting(n_planned, intact, missing, damaged, orphan, skipped, owed)

    def _refinement_owed(self, plan, intact: set[str], skipped: set[str], missing: set[str]) -> list[StepProblem]:
        """What a refined run still owes (decision record 0050), one problem per level and
        mode: a refinement whose end no ``refinement_end`` event records (a run that
        completed ended them all: the procedure goes on only once the refiner says so; runs
        of earlier versions have no such events), and a dwell that the recorded end owes and
        that is neither stored intact nor skipped at run time as the plan allows."""
        from procedures.resonance import END_REASONS
        completed = self.metadata.get("status") == RunStatus.COMPLETED
        ends: dict[tuple[int, str], dict] = {}
        for e in self.events():
            if e.get("event") == "refinement_end" and e.get("reason") in END_REASONS:
                ends[(e.get("level_index"), e.get("mode"))] = e
        last: dict[int, StepSpec] = {}
        for step in plan.schedule():
            last[step.level_index] = step
        sweeps = _sweeps(plan)
        out = []
        for li, step in sorted(last.items()):
            swept = not any(k in missing for k in sweeps.get((li, step.direction), []))
            for mode in plan.refine_modes:
                label = f"L{li:02d}-{mode}"
                end = ends.get((li, mode))
                if end is None and not completed:
                    done = len([k for k in intact if k.startswith(f"{step.index:05d}-L{li:02d}-R{mode[0].upper()}")])
                    out.append(StepProblem(label, self.steps_dir, "owed", Problem.REFINEMENT_OPEN,
                                           dict(mode=mode, force_N=step.force_N, done=done, most=plan.refine_steps,
                                                swept=swept, dwell=bool(plan.dwell_cycles))))
                elif end is not None and end.get("dwell_owed"):
                    dwell = replace(step, freq_index=-1, refined=0, refined_mode=mode,
                                    dwell_cycles=plan.dwell_cycles).key
                    if dwell not in intact and dwell not in skipped:
                        out.append(StepProblem(label, self.steps_dir / f"{dwell}.json", "owed", Problem.DWELL_OWED,
                                               dict(cycles=plan.dwell_cycles, mode=mode, force_N=step.force_N,
                                                    dwell=dwell, end=end["reason"])))
        return out

    def set_aside_damaged(self) -> list[StepProblem]:
        """Move the files of every damaged step to ``<run>/damaged/<time>/`` (so that resume
        measures those steps again) and record it; returns the problems found."""
        damaged = [pr for pr in self.check() if pr.key and pr.kind != "unknown"]
        if not damaged:
            return []
        real_dir(self.steps_dir)
        dest = real_dir(real_dir(self.path / "damaged", create=True) / now_iso().replace(":", "-"), create=True)
        for pr in damaged:
            for p in (self.steps_dir / f"{pr.key}.json", self.steps_dir / f"{pr.key}.npz"):
                if p.exists():
                    os.replace(p, dest / p.name)
            self._npz_ok.pop(pr.key, None)
            self._json_ok.pop(pr.key, None)
            log.warning(_said(StoreLine.DAMAGED_MOVED, key=pr.key, problem=pr, dest=dest))
            self.event("damaged_step", step=pr.key, problem=pr.kind, reason=str(pr), moved_to=str(dest))
        _fsync_dir(self.steps_dir)
        return damaged




