"""One step's two files read and checked (moved from :mod:`bench.storage`): a problem of a run
directory (:class:`StepProblem`: its kind as a value, its words for a person), the result file's
and the raw block's checks (missing, cut short, corrupt, checksum)."""

from __future__ import annotations

import io
import json
import logging
import os
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path

from sim.errors import RunDirectoryError
from sim.step_result import StepResult, check_step_version, step_fields_problem

from .durable import _canonical, _sha256
from .files import UnreadableFile, read_file

log = logging.getLogger(__name__)

_OPEN_STRING = re.compile(r'"(?:[^"\\\x00-\x1f]|\\.)*\\?')     # a JSON string that runs to the end


class DamagedStep(RunDirectoryError):
    """A completed step's files are missing, truncated or fail their checksum."""

    def __init__(self, problem: StepProblem):
        super().__init__(str(problem))
        self.problem = problem


# the words of a step's missing files (StepProblem.files), made here only: decisions read ``files``
MISSING_WORDS = {(".json", ".npz"): "missing: neither .json nor .npz",
                 (".json",): "missing: no .json (only the .npz)",
                 (".npz",): "missing: no .npz (only the .json)"}


@dataclass(frozen=True)
class StepProblem:
    """One problem of a run directory, found by :meth:`RunStore.check` or a reader."""

    key: str          # the step key ("" for a file that is not a step)
    path: Path        # the file concerned
    kind: str         # one of PROBLEM_KINDS
    reason: str       # plain language
    count: int = 1    # steps concerned (more than one: an adaptive sweep's shortfall)
    files: tuple[str, ...] = ()    # "missing": the step's files absent (".json", ".npz"), when known

    def __str__(self) -> str:
        return f"{shown(self.path)}: {self.reason}"


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


def _json_reason(e: json.JSONDecodeError) -> str:
    cut = "truncated: " if _json_cut(e) else ""
    return f"{cut}not valid JSON ({e.msg} at line {e.lineno} column {e.colno}, file of {len(e.doc)} characters)"


def _read_step_file(path: Path, key: str, what: str) -> bytes:
    """The bytes of one of a step's two files (``what``: which, for a missing one); a file
    missing, not a regular file, over its bound or unreadable is a :class:`DamagedStep`."""
    try:
        return read_file(path)
    except FileNotFoundError:
        raise DamagedStep(StepProblem(key, path, "missing", f"missing ({what})")) from None
    except UnreadableFile as e:
        raise DamagedStep(StepProblem(key, path, "corrupt", str(e).split(": ", 1)[-1])) from None
    except OSError as e:
        raise DamagedStep(StepProblem(key, path, "corrupt", f"unreadable ({e.strerror})")) from None


def _read_step_json(path: Path, key: str) -> tuple[StepResult, dict | None]:
    def bad(kind, reason):
        return DamagedStep(StepProblem(key, path, kind, reason))
    data = _read_step_file(path, key, "the step's result file")
    if not data.strip():
        raise bad("truncated", "empty (truncated to 0 bytes)")
    try:
        obj = json.loads(data.decode())
    except UnicodeDecodeError as e:
        raise bad("corrupt", f"not text (byte {e.start} is not UTF-8)") from None
    except json.JSONDecodeError as e:
        raise bad("truncated" if _json_cut(e) else "corrupt", _json_reason(e)) from None
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
    problem = step_fields_problem(obj)       # a step of the format before checksums, crafted by hand
    if problem:
        raise bad("corrupt", problem)
    return obj, integrity


def _check_npz(path: Path, key: str, integrity: dict | None) -> None:
    def bad(kind, reason):
        return DamagedStep(StepProblem(key, path, kind, reason))
    data = _read_step_file(path, key, "the step's raw block; its result file is there")
    size = len(data)
    if integrity is None:                       # a step written before checksums existed
        if not zipfile.is_zipfile(io.BytesIO(data)):
            raise bad("corrupt", "not a readable .npz (truncated or overwritten?)")
        return
    want_bytes = integrity.get("npz_bytes")
    if isinstance(want_bytes, int) and size != want_bytes:
        kind = "truncated" if size < want_bytes else "corrupt"
        raise bad(kind, f"{'truncated: ' if size < want_bytes else ''}{size} bytes, {want_bytes} were written")
    if _sha256(data) != integrity.get("npz_sha256"):
        raise bad("checksum", "checksum mismatch: the raw block differs from what was written")
