"""One step's two files read and checked (moved from :mod:`bench.storage`): a problem of a run
directory (:class:`StepProblem`: its kind as a value, its words for a person), the result file's
and the raw block's checks (missing, cut short, corrupt, checksum)."""

from __future__ import annotations

import hashlib
import io
import json
import logging
import os
import re
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

from sim.errors import RunDirectoryError
from sim.step_result import StepResult, check_step_version, step_fields_problem

from .durable import _canonical, _sha256
from .files import UnreadableFile, read_file
from .words import terminal

log = logging.getLogger(__name__)

_OPEN_STRING = re.compile(r'"(?:[^"\\\x00-\x1f]|\\.)*\\?')     # a JSON string that runs to the end


class DamagedStep(RunDirectoryError):
    """A completed step's files are missing, truncated or fail their checksum."""

    def __init__(self, problem: StepProblem):
        super().__init__(str(problem))
        self.problem = problem


class Problem(StrEnum):
    """What is wrong (:attr:`StepProblem.code`); its words are made by the renderers
    (:mod:`bench.words`), from the problem's ``fields`` (named after each member)."""

    MISSING_PAIR = "missing_pair"        # files: which of the step's .json and .npz are absent
    MISSING_FILE = "missing_file"        # file: the one a reader wanted (".json" or ".npz")
    UNREADABLE = "unreadable"            # detail: the file reader's words (not a regular file, too large)
    OS_ERROR = "os_error"                # strerror
    EMPTY = "empty"
    NOT_UTF8 = "not_utf8"                # byte
    NOT_JSON = "not_json"                # cut, msg, line, column, chars
    TOO_DEEP = "too_deep"
    NOT_OBJECT = "not_object"            # found: the JSON type
    JSON_CHECKSUM = "json_checksum"
    WRONG_KEY = "wrong_key"              # inside, key
    BAD_FIELDS = "bad_fields"            # detail: sim.step_result's words
    NOT_NPZ = "not_npz"
    NPZ_SIZE = "npz_size"                # size, written (bytes)
    NPZ_CHECKSUM = "npz_checksum"
    NPZ_UNREADABLE = "npz_unreadable"    # error (the exception's type), detail
    RUN_JSON = "run_json"                # detail: run.json's error
    STEPS_LINK = "steps_link"
    NO_STEPS_DIR = "no_steps_dir"
    RAW_LACKS = "raw_lacks"              # channels
    NOT_IN_PLAN = "not_in_plan"
    NAME_NOT_UTF8 = "name_not_utf8"
    NOT_A_STEP_FILE = "not_a_step_file"
    SKIPPED = "skipped"                  # why: the step_skipped event's reason
    SWEEP_SHORT = "sweep_short"          # short, planned
    REFINEMENT_OPEN = "refinement_open"  # mode, force_N, done, most, swept, dwell
    DWELL_OWED = "dwell_owed"            # cycles, mode, force_N, dwell (its key), end (the refinement's end)


@dataclass(frozen=True)
class StepProblem:
    """One problem of a run directory, found by :meth:`RunStore.check` or a reader: a value
    (``kind``, ``code`` and ``fields``); :attr:`reason` is its words (the terminal's)."""

    key: str          # the step key ("" for a file that is not a step)
    path: Path        # the file concerned
    kind: str         # one of PROBLEM_KINDS
    code: Problem
    fields: Mapping[str, Any] = field(default_factory=dict)
    count: int = 1    # steps concerned (more than one: an adaptive sweep's shortfall)
    files: tuple[str, ...] = ()    # "missing": the step's files absent (".json", ".npz"), when known

    @property
    def reason(self) -> str:
        """The problem in the terminal's words."""
        return terminal.problem(self.code, self.fields)

    def __str__(self) -> str:
        return f"{shown(self.path)}: {self.reason}"

    def __hash__(self) -> int:           # fields is a dict: hashed by its items
        return hash((self.key, self.path, self.kind, self.code, tuple(sorted(self.fields.items(), key=str)),
                     self.count, self.files))


def _utf8(name: str) -> bool:
    """A file name that is text (a name of bytes that are not UTF-8 is never a step's)."""
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def shown(name) -> str:
    """A file name as it can be printed: bytes that are not UTF-8 (a name made elsewhere)
    as ``\\xff`` escapes, not an error on the terminal."""
    return os.fsencode(str(name)).decode("utf-8", "backslashreplace")


def _json_cut(e: json.JSONDecodeError) -> bool:
    """The document ends where the parser stopped (at its last character, or inside a
    string that never closes): cut short, not garbled."""
    return e.pos >= len(e.doc.rstrip()) - 1 or _OPEN_STRING.fullmatch(e.doc, e.pos) is not None


def _json_fields(e: json.JSONDecodeError) -> dict:
    """:attr:`Problem.NOT_JSON`'s fields: where the parser stopped and why."""
    return dict(cut=_json_cut(e), msg=e.msg, line=e.lineno, column=e.colno, chars=len(e.doc))


def _read_step_file(path: Path, key: str) -> bytes:
    """The bytes of one of a step's two files (``path``'s suffix says which); a file
    missing, not a regular file, over its bound or unreadable is a :class:`DamagedStep`."""
    try:
        return read_file(path)
    except FileNotFoundError:
        raise DamagedStep(StepProblem(key, path, "missing", Problem.MISSING_FILE, dict(file=path.suffix))) from None
    except UnreadableFile as e:
        raise DamagedStep(StepProblem(key, path, "corrupt", Problem.UNREADABLE,
                                      dict(detail=str(e).split(": ", 1)[-1]))) from None
    except OSError as e:
        raise DamagedStep(StepProblem(key, path, "corrupt", Problem.OS_ERROR, dict(strerror=e.strerror))) from None


def _read_step_json(path: Path, key: str, verified: dict[str, bytes] | None = None) -> tuple[StepResult, dict | None]:
    """One step's JSON, checked (checksum, key, version, fields).  ``verified``: key -> the
    SHA-256 of the bytes that passed before (a store's); the same bytes again are only parsed
    (a refined run reads every step after each refinement step: decision 0083)."""
    def bad(kind, code, **fields):
        return DamagedStep(StepProblem(key, path, kind, code, fields))
    data = _read_step_file(path, key)
    digest = hashlib.sha256(data).digest()
    if verified is not None and verified.get(key) == digest:
        obj = json.loads(data.decode())
        return obj, obj.pop("integrity", None)
    if not data.strip():
        raise bad("truncated", Problem.EMPTY)
    try:
        obj = json.loads(data.decode())
    except UnicodeDecodeError as e:
        raise bad("corrupt", Problem.NOT_UTF8, byte=e.start) from None
    except json.JSONDecodeError as e:
        raise bad("truncated" if _json_cut(e) else "corrupt", Problem.NOT_JSON, **_json_fields(e)) from None
    except RecursionError:
        raise bad("corrupt", Problem.TOO_DEEP) from None
    if not isinstance(obj, dict):
        raise bad("corrupt", Problem.NOT_OBJECT, found=type(obj).__name__)
    integrity = obj.pop("integrity", None)
    if integrity is not None:
        want = integrity.get("json_sha256") if isinstance(integrity, dict) else None
        if want != _sha256(_canonical(obj)):
            raise bad("checksum", Problem.JSON_CHECKSUM)
    if obj.get("key") != key:
        raise bad("corrupt", Problem.WRONG_KEY, inside=obj.get("key"), key=key)
    check_step_version(obj, str(path))       # a newer format is refused, not taken for damage
    problem = step_fields_problem(obj)       # a step of the format before checksums, crafted by hand
    if problem:
        raise bad("corrupt", Problem.BAD_FIELDS, detail=problem)
    if verified is not None:
        verified[key] = digest
    return obj, integrity


def _check_npz(path: Path, key: str, integrity: dict | None) -> None:
    def bad(kind, code, **fields):
        return DamagedStep(StepProblem(key, path, kind, code, fields))
    data = _read_step_file(path, key)
    size = len(data)
    if integrity is None:                       # a step written before checksums existed
        if not zipfile.is_zipfile(io.BytesIO(data)):
            raise bad("corrupt", Problem.NOT_NPZ)
        return
    want_bytes = integrity.get("npz_bytes")
    if isinstance(want_bytes, int) and size != want_bytes:
        raise bad("truncated" if size < want_bytes else "corrupt", Problem.NPZ_SIZE, size=size, written=want_bytes)
    if _sha256(data) != integrity.get("npz_sha256"):
        raise bad("checksum", Problem.NPZ_CHECKSUM)
