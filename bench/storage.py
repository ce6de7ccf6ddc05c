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
"""

from __future__ import annotations

import enum
import hashlib
import io
import json
import logging
import os
import tempfile
import zipfile
from dataclasses import dataclass, fields
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from sim.errors import RunDirectoryError
from sim.step_result import STEP_FORMAT_VERSION, StepResult, check_step_version

log = logging.getLogger(__name__)


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


def now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def atomic_write(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        _fsync_dir(path.parent)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, complex):
        return {"re": o.real, "im": o.imag}
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def write_json(path: Path, obj) -> None:
    data = json.dumps(obj, indent=1, default=_json_default).encode()
    atomic_write(path, lambda fh: fh.write(data))


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _canonical(obj) -> bytes:
    """The bytes a step's ``json_sha256`` covers: key order and spacing do not matter
    (Python's float repr survives a JSON round trip exactly)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=_json_default).encode()


RunDirError = RunDirectoryError    # not a readable run directory (missing, or run.json damaged)


class DamagedStep(RunDirectoryError):
    """A completed step's files are missing, truncated or fail their checksum."""

    def __init__(self, problem: StepProblem):
        super().__init__(str(problem))
        self.problem = problem


@dataclass(frozen=True)
class StepProblem:
    """One problem of a run directory, found by :meth:`RunStore.check` or a reader."""

    key: str          # the step key ("" for a file that is not a step)
    path: Path        # the file concerned
    kind: str         # one of PROBLEM_KINDS
    reason: str       # plain language
    count: int = 1    # steps concerned (more than one: an adaptive sweep's shortfall)

    def __str__(self) -> str:
        return f"{self.path}: {self.reason}"


PROBLEM_KINDS = ("missing", "truncated", "corrupt", "checksum", "unknown")


class RunStore:
    def __init__(self, path: Path):
        self.path = Path(path)
        self.steps_dir = self.path / "steps"
        self.problems: list[StepProblem] = []     # damaged steps met by the last results()
        self._npz_ok: dict[str, tuple] = {}        # key -> stamp of a block already verified

    # ------------------------------------------------------------------ life cycle
    @classmethod
    def create(cls, path: Path, metadata: dict) -> RunStore:
        path = Path(path)
        if path.exists() and any(path.iterdir()):
            raise FileExistsError(f"run directory {path} exists and is not empty; "
                                  f"use 'bench resume {path}' or choose another --out")
        (path / "steps").mkdir(parents=True, exist_ok=True)
        store = cls(path)
        write_json(path / "run.json", dict(metadata, format_version=RUN_FORMAT_VERSION, status=RunStatus.RUNNING,
                                           started=now_iso()))
        store.event("start")
        return store

    @classmethod
    def open(cls, path: Path) -> RunStore:
        store = cls(path)
        if not store.path.exists():
            raise RunDirError(f"{path}: no such directory (expected a run directory made by 'bench run')")
        if not (store.path / "run.json").is_file():
            raise RunDirError(f"{path}: not a run directory (no run.json; expected a directory made by 'bench run')")
        version = store.metadata.get("format_version", 1)   # a damaged run.json is named now, not deep inside a reader
        if not isinstance(version, int) or isinstance(version, bool) or version > RUN_FORMAT_VERSION:
            raise RunDirError(f"{store.path / 'run.json'}: run format version {version!r}, written by a newer "
                              f"guideway-bench (this one reads versions up to {RUN_FORMAT_VERSION}); update to read it")
        return store

    @property
    def metadata(self) -> dict:
        p = self.path / "run.json"
        try:
            meta = json.loads(p.read_bytes())
        except FileNotFoundError:
            raise RunDirError(f"{p}: missing (not a run directory?)") from None
        except json.JSONDecodeError as e:
            raise RunDirError(f"{p}: damaged ({_json_reason(e)})") from None
        except UnicodeDecodeError:
            raise RunDirError(f"{p}: damaged (not text)") from None
        if not isinstance(meta, dict):
            raise RunDirError(f"{p}: damaged (a JSON object was expected, found {type(meta).__name__})")
        return meta

    def update(self, **fields) -> None:
        write_json(self.path / "run.json", dict(self.metadata, **fields))

    def finish(self, status: RunStatus, **fields) -> None:
        self.update(status=status, ended=now_iso(), **fields)
        self.event("end", status=status)

    # ------------------------------------------------------------------ events
    def event(self, kind: str, **fields) -> None:
        line = json.dumps(dict(time=now_iso(), event=kind, **fields), default=_json_default)
        with open(self.path / "events.jsonl", "a") as fh:
            fh.write(line + "\n")
            fh.flush()
            os.fsync(fh.fileno())

    def events(self) -> list[dict]:
        out = []
        p = self.path / "events.jsonl"
        if not p.exists():
            return out
        for n, line in enumerate(p.read_bytes().decode(errors="replace").splitlines(), 1):
            try:
                e = json.loads(line)
            except json.JSONDecodeError:
                log.warning("%s: line %d damaged (torn or not JSON); skipped", p, n)
                continue
            if isinstance(e, dict):
                out.append(e)
            else:
                log.warning("%s: line %d is not an event object; skipped", p, n)
        return out

    # ------------------------------------------------------------------ steps: writing
    def write_step(self, key: str, result: StepResult, raw: dict[str, np.ndarray]) -> None:
        buf = io.BytesIO()
        np.savez(buf, **raw)
        npz = buf.getvalue()
        atomic_write(self.steps_dir / f"{key}.npz", lambda fh: fh.write(npz))
        plain = json.loads(json.dumps(result, default=_json_default))    # what a reader will see
        plain.pop("integrity", None)
        plain["format_version"] = STEP_FORMAT_VERSION
        plain["integrity"] = {"json_sha256": _sha256(_canonical(plain)), "npz_sha256": _sha256(npz),
                              "npz_bytes": len(npz)}
        write_json(self.steps_dir / f"{key}.json", plain)
        st = (self.steps_dir / f"{key}.npz").stat()
        self._npz_ok[key] = (st.st_mtime_ns, st.st_size, plain["integrity"]["npz_sha256"])   # just written

    # ------------------------------------------------------------------ steps: reading
    def step_files(self) -> list[Path]:
        """The steps' JSON files present (intact or not), in key order."""
        return sorted(self.steps_dir.glob("*.json")) if self.steps_dir.is_dir() else []

    def verify_step(self, key: str) -> StepResult:
        """The step's result after checking both its files (JSON content, the .npz's size
        and checksum); raises :class:`DamagedStep` naming the file and why."""
        jp, zp = self.steps_dir / f"{key}.json", self.steps_dir / f"{key}.npz"
        result, integrity = _read_step_json(jp, key)
        try:
            stamp = (zp.stat().st_mtime_ns, zp.stat().st_size, (integrity or {}).get("npz_sha256"))
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
                    log.warning("skipping step %s: %s", p.stem, e)
        return out

    def raw(self, key: str) -> dict[str, np.ndarray]:
        """The step's raw block; raises :class:`DamagedStep` if its files are damaged."""
        self.verify_step(key)
        zp = self.steps_dir / f"{key}.npz"
        try:
            with np.load(zp) as z:
                return {k: z[k] for k in z.files}
        except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as e:
            raise DamagedStep(StepProblem(key, zp, "corrupt", f"unreadable ({type(e).__name__}: {e})")) from None

    def with_raw(self, results: list[dict]):
        """(result, raw block) of each given step whose block reads; damaged ones are
        skipped with a warning naming the file."""
        for r in results:
            try:
                yield r, self.raw(r["key"])
            except DamagedStep as e:
                log.warning("skipping step %s: %s", r["key"], e)

    # ------------------------------------------------------------------ checking and repair
    def check(self) -> list[StepProblem]:
        """Every problem of the run directory: damaged run.json or steps (missing, truncated,
        corrupt, checksum mismatch) and step files the plan does not know."""
        problems: list[StepProblem] = []
        try:
            meta = self.metadata
        except RunDirError as e:
            problems.append(StepProblem("", self.path / "run.json", "corrupt", str(e).split(": ", 1)[-1]))
            meta = None
        known = planned_keys(meta) if meta else None
        if not self.steps_dir.is_dir():
            problems.append(StepProblem("", self.steps_dir, "missing", "no steps/ directory"))
            return problems
        jsons = {p.stem for p in self.step_files()}
        for key in sorted(jsons):
            try:
                raw = self.raw(key)                 # verifies both files first
                if not {"force_N", "accel_m_s2", "disp_m"} <= set(raw):
                    problems.append(StepProblem(key, self.steps_dir / f"{key}.npz", "corrupt",
                                                f"raw block lacks {sorted({'force_N', 'accel_m_s2', 'disp_m'} - set(raw))}"))
            except DamagedStep as e:
                problems.append(e.problem)
            if known is not None and key not in known:
                problems.append(StepProblem(key, self.steps_dir / f"{key}.json", "unknown",
                                            "a step the run's plan does not know"))
        for p in sorted(self.steps_dir.iterdir()):
            if p.name.startswith(".") and p.name.endswith(".tmp"):
                continue       # a write cut short by a kill: harmless, replaced on resume
            if p.suffix == ".npz" and p.stem in jsons:
                continue
            if p.suffix == ".json":
                continue
            if p.suffix == ".npz":
                if known is not None and p.stem not in known:
                    problems.append(StepProblem(p.stem, p, "unknown", "a step the run's plan does not know"))
                # else: a block whose result was never written (kill -9): resume measures it
                continue
            problems.append(StepProblem("", p, "unknown", "not a step file"))
        return problems

    def account(self) -> Accounting:
        """The run's steps counted against its stored plan: intact, missing (no files, or
        only one of the pair), damaged and orphan files, each named (see :class:`Accounting`)."""
        meta = self.metadata
        plan = stored_plan(meta)
        problems = self.check()
        orphan = [p for p in problems if p.kind == "unknown" or not p.key]
        bad = {p.key: p for p in problems if p.key and p.kind != "unknown"}
        have_json = {p.stem for p in self.step_files()}
        have_npz = {p.stem for p in self.steps_dir.glob("*.npz")} if self.steps_dir.is_dir() else set()
        if plan is None:
            intact = sorted(have_json - set(bad))
            return Accounting(None, intact, [], [p for p in bad.values()], orphan)
        sweeps = _sweeps(plan)
        k = plan.adaptive_per_sweep
        intact, missing, damaged, n_planned = [], [], [], 0
        for (li, direction), keys in sweeps.items():
            n_sweep = min(len(keys), k) if k else len(keys)
            n_planned += n_sweep
            present = 0
            for key in keys:
                jp, zp = self.steps_dir / f"{key}.json", self.steps_dir / f"{key}.npz"
                if key not in have_json and key not in have_npz:
                    if not k:
                        missing.append(StepProblem(key, jp, "missing", "missing: neither .json nor .npz"))
                    continue
                present += 1
                if key not in have_json:
                    missing.append(StepProblem(key, jp, "missing", "missing: no .json (only the .npz)"))
                elif bad.get(key) and bad[key].kind == "missing":
                    missing.append(StepProblem(key, zp, "missing", "missing: no .npz (only the .json)"))
                elif key in bad:
                    damaged.append(bad[key])
                else:
                    intact.append(key)
            if k and present < n_sweep:
                label = f"L{li:02d}-{direction}"
                missing.append(StepProblem(label, self.steps_dir, "missing",
                                           f"missing: {n_sweep - present} of the {n_sweep} steps this sweep "
                                           f"measures (adaptive plan: chosen online, so not named by key)",
                                           count=n_sweep - present))
        order = {key: i for i, key in enumerate(s.key for s in plan.schedule())}
        missing.sort(key=lambda p: order.get(p.key, -1))
        return Accounting(n_planned, intact, missing, damaged, orphan)

    def set_aside_damaged(self) -> list[StepProblem]:
        """Move the files of every damaged step to ``<run>/damaged/<time>/`` (so that resume
        measures those steps again) and record it; returns the problems found."""
        damaged = [pr for pr in self.check() if pr.key and pr.kind != "unknown"]
        if not damaged:
            return []
        dest = self.path / "damaged" / now_iso().replace(":", "-")
        dest.mkdir(parents=True, exist_ok=True)
        for pr in damaged:
            for p in (self.steps_dir / f"{pr.key}.json", self.steps_dir / f"{pr.key}.npz"):
                if p.exists():
                    os.replace(p, dest / p.name)
            self._npz_ok.pop(pr.key, None)
            log.warning("step %s damaged (%s): files moved to %s; it will be measured again", pr.key, pr, dest)
            self.event("damaged_step", step=pr.key, problem=pr.kind, reason=str(pr), moved_to=str(dest))
        _fsync_dir(self.steps_dir)
        return damaged


def _json_reason(e: json.JSONDecodeError) -> str:
    cut = "truncated: " if e.pos >= len(e.doc.rstrip()) - 1 or e.msg.startswith("Unterminated") else ""
    return f"{cut}not valid JSON ({e.msg} at line {e.lineno} column {e.colno}, file of {len(e.doc)} characters)"


def _read_step_json(path: Path, key: str) -> tuple[StepResult, dict | None]:
    def bad(kind, reason):
        return DamagedStep(StepProblem(key, path, kind, reason))
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise bad("missing", "missing (the step's result file)") from None
    except OSError as e:
        raise bad("corrupt", f"unreadable ({e.strerror})") from None
    if not data.strip():
        raise bad("truncated", "empty (truncated to 0 bytes)")
    try:
        obj = json.loads(data.decode())
    except UnicodeDecodeError as e:
        raise bad("corrupt", f"not text (byte {e.start} is not UTF-8)") from None
    except json.JSONDecodeError as e:
        reason = _json_reason(e)
        raise bad("truncated" if reason.startswith("truncated") else "corrupt", reason) from None
    except RecursionError:
        raise bad("corrupt", "not a step result (nested too deeply)") from None
    if not isinstance(obj, dict):
        raise bad("corrupt", f"not a step result (a JSON object was expected, found {type(obj).__name__})")
    integrity = obj.pop("integrity", None)
    if integrity is not None:
        want = integrity.get("json_sha256") if isinstance(integrity, dict) else None
        if want != _sha256(_canonical(obj)):
            raise bad("checksum", "checksum mismatch: the content differs from what was written")
    if obj.get("key") != key:
        raise bad("corrupt", f"the result inside is for step {obj.get('key')!r}, not {key!r}")
    check_step_version(obj, str(path))       # a newer format is refused, not taken for damage
    return obj, integrity


def _check_npz(path: Path, key: str, integrity: dict | None) -> None:
    def bad(kind, reason):
        return DamagedStep(StepProblem(key, path, kind, reason))
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise bad("missing", "missing (the step's raw block; its result file is there)") from None
    if integrity is None:                       # a step written before checksums existed
        if not zipfile.is_zipfile(path):
            raise bad("corrupt", "not a readable .npz (truncated or overwritten?)")
        return
    want_bytes = integrity.get("npz_bytes")
    if isinstance(want_bytes, int) and size != want_bytes:
        kind = "truncated" if size < want_bytes else "corrupt"
        raise bad(kind, f"{'truncated: ' if size < want_bytes else ''}{size} bytes, {want_bytes} were written")
    if _sha256(path.read_bytes()) != integrity.get("npz_sha256"):
        raise bad("checksum", "checksum mismatch: the raw block differs from what was written")


def stored_plan(meta: dict | None):
    """The run's stored plan as a :class:`procedures.plan.Plan` (None if it cannot be rebuilt)."""
    from procedures.plan import Plan

    p = (meta or {}).get("plan")
    if not isinstance(p, dict):
        return None
    try:
        kw = {f.name: p[f.name] for f in fields(Plan) if f.name in p}
        kw.update(levels_N=tuple(p["levels_N"]), freqs_Hz=tuple(p["freqs_Hz"]),
                  skip=tuple(tuple(s) for s in p.get("skip") or ()))
        plan = Plan(**kw)
        plan.schedule()
        return plan
    except Exception as e:  # noqa: BLE001 - a damaged plan entry: then keys cannot be judged
        log.warning("run.json: the stored plan cannot be rebuilt (%s); step keys not checked", e)
        return None


def planned_keys(meta: dict | None) -> set[str] | None:
    """Keys of every step of the run's stored plan (None if the plan cannot be rebuilt)."""
    plan = stored_plan(meta)
    return None if plan is None else {s.key for s in plan.schedule()}


# ---------------------------------------------------------------------------- accounting


def _keys_text(keys: list[str], limit: int = 8) -> str:
    return ", ".join(keys[:limit]) + (f" and {len(keys) - limit} more" if len(keys) > limit else "")


@dataclass
class Accounting:
    """A run's steps counted against its plan (:meth:`RunStore.account`).

    ``missing``: planned steps without a complete file pair (nothing, or only one of the
    two files); in an adaptive plan, the steps a sweep still lacks of the number it
    measures (their keys are chosen online, so the sweep is named).  ``damaged``: planned
    steps whose files are both there but fail a check.  ``orphan``: files no planned step
    owns.  ``planned`` is None when run.json holds no plan this version can rebuild."""

    planned: int | None
    intact: list[str]
    missing: list[StepProblem]
    damaged: list[StepProblem]
    orphan: list[StepProblem]

    @property
    def complete(self) -> bool:
        """Every planned step is there and intact."""
        return self.planned is not None and not self.missing and not self.damaged

    @property
    def missing_count(self) -> int:
        return sum(p.count for p in self.missing)

    def resume_text(self) -> str:
        """'measures again 3 of 30 planned steps; missing: K1, K2; damaged: K3 (truncated)'."""
        n = self.missing_count + len(self.damaged)
        parts = [f"measures again {n} of {'?' if self.planned is None else self.planned} planned "
                 f"step{'s' * (self.planned != 1)}"]
        if self.missing:
            parts.append("missing: " + _keys_text([_missing_label(p) for p in self.missing], 12))
        if self.damaged:
            parts.append("damaged: " + _keys_text([f"{p.key} ({p.kind})" for p in self.damaged], 12))
        return "; ".join(parts)

    def summary(self) -> str:
        """'28 intact / 30 planned; missing: K1; damaged: K2 (truncated); orphan: none'."""
        missing = [_missing_label(p) for p in self.missing]
        return (f"{len(self.intact)} intact / {'?' if self.planned is None else self.planned} planned; "
                f"missing: {_keys_text(missing) or 'none'}; "
                f"damaged: {_keys_text([f'{p.key} ({p.kind})' for p in self.damaged]) or 'none'}; "
                f"orphan: {_keys_text([p.path.name for p in self.orphan]) or 'none'}")


def _missing_label(p: StepProblem) -> str:
    """A step's key, or an adaptive sweep with the number of steps it lacks: 'L01-up (2)'."""
    return p.key if p.path.suffix in (".json", ".npz") else f"{p.key} ({p.count})"


def _sweeps(plan) -> dict[tuple[int, str], list[str]]:
    out: dict[tuple[int, str], list[str]] = {}
    for s in plan.schedule():
        out.setdefault((s.level_index, s.direction), []).append(s.key)
    return out


def planned_count(plan) -> int:
    """Steps the plan measures: its schedule, or in adaptive mode the chosen number per sweep."""
    k = plan.adaptive_per_sweep
    return sum(min(len(keys), k) if k else len(keys) for keys in _sweeps(plan).values())
