"""Crash-safe writing of a run directory's files (moved from :mod:`bench.storage`): atomic
writes (a temporary name, fsynced, renamed), appends that follow no link, the modes ``touch``
and ``mkdir`` give, canonical JSON and its SHA-256 (decision 0028)."""

from __future__ import annotations

import errno
import hashlib
import json
import logging
import os
import stat
import tempfile
import threading
from contextlib import contextmanager
from datetime import UTC, datetime
from enum import StrEnum
from pathlib import Path

import numpy as np

from sim.errors import RunDirectoryError as RunDirError
from sim.errors import StorageError

from .words.terminal_run import refused

log = logging.getLogger(__name__)


class WriteRefusal(StrEnum):
    """Why a run directory's file is not written (fields: path; its words:
    :data:`bench.words.terminal_run.REFUSAL`)."""

    DIR_MISSING = "dir_missing"
    DIR_LINK = "dir_link"                   # a directory where a run writes is a link
    NOT_A_DIR = "not_a_dir"
    APPEND_LINK = "append_link"             # a file a run appends to is a link
    FIFO = "fifo"
    NOT_REGULAR = "not_regular"
    CANNOT_WRITE = "cannot_write"           # path, error (the OSError's)
    NOT_SERIALISABLE = "not_serialisable"   # kind: the type's name (no path)


_umask_lock = threading.Lock()


def now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


# a directory written whole and moved into place once synced (bench import, bench.frf_run):
# its files are not synced one by one
_DEFERRED = threading.local()


@contextmanager
def deferred_sync():
    """Inside: :func:`atomic_write` renames without a fsync of the file and its directory
    (this thread only); the caller syncs the whole directory before it is used."""
    _DEFERRED.on = True
    try:
        yield
    finally:
        _DEFERRED.on = False


def _deferred() -> bool:
    return getattr(_DEFERRED, "on", False)


def _fsync_dir(path: Path) -> None:
    if _deferred():
        return
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _umask() -> int:
    with _umask_lock:          # os.umask can only be read by setting it
        old = os.umask(0o022)
        os.umask(old)
    return old


def file_mode() -> int:
    """The mode of every file a run writes: what ``open(..., "w")`` gives."""
    return 0o666 & ~_umask()


def real_dir(path: Path, *, create: bool = False) -> Path:
    """``path`` as a directory that is not a symbolic link (made if ``create``); a link or a
    file in its place raises :class:`RunDirError` naming it."""
    path = Path(path)
    if create:
        try:
            path.mkdir()
        except FileExistsError:
            pass
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        raise refused(RunDirError, WriteRefusal.DIR_MISSING, path=path) from None
    if stat.S_ISLNK(st.st_mode):
        raise refused(RunDirError, WriteRefusal.DIR_LINK, path=path)
    if not stat.S_ISDIR(st.st_mode):
        raise refused(RunDirError, WriteRefusal.NOT_A_DIR, path=path)
    return path


def open_append(path: Path):
    """``path`` opened for appending text, never through a symbolic link (``O_NOFOLLOW``)."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC,
                     0o666)
    except OSError as e:
        if os.path.islink(path):
            raise refused(RunDirError, WriteRefusal.APPEND_LINK, path=path) from None
        if e.errno == errno.ENXIO:             # a FIFO nobody reads: never waited on
            raise refused(RunDirError, WriteRefusal.FIFO, path=path) from None
        raise
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise refused(RunDirError, WriteRefusal.NOT_REGULAR, path=path)
    return os.fdopen(fd, "a")


def atomic_write(path: Path, write) -> None:
    real_dir(path.parent)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, file_mode())
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            if not _deferred():
                os.fsync(fh.fileno())
        os.replace(tmp, path)
        _fsync_dir(path.parent)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


@contextmanager
def _writing(path: Path):
    """An ``OSError`` while writing ``path`` becomes a :class:`StorageError` naming it and
    the cause (a full disk, a directory deleted, a permission taken away)."""
    try:
        yield
    except OSError as e:
        raise refused(StorageError, WriteRefusal.CANNOT_WRITE, path=path, error=e.strerror or e) from e


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, complex):
        return {"re": o.real, "im": o.imag}
    raise refused(TypeError, WriteRefusal.NOT_SERIALISABLE, kind=type(o).__name__)


def write_json(path: Path, obj) -> None:
    data = json.dumps(obj, indent=1, default=_json_default).encode()
    atomic_write(path, lambda fh: fh.write(data))


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _canonical(obj) -> bytes:
    """The bytes a step's ``json_sha256`` covers: key order and spacing do not matter
    (Python's float repr survives a JSON round trip exactly)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=_json_default).encode()
