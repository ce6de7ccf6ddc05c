"""Reading a run directory's files safely: one function every reader goes through.

A run directory is data from outside: a copy, an archive, a hand edit.  A step file
linked to ``/dev/zero`` must not be read until memory runs out, nor a FIFO in its place
waited on forever.  :func:`read_file` opens without following a symbolic link and without
blocking (``O_NOFOLLOW | O_NONBLOCK``), reads only a regular file, and at most the bound
of the file's kind plus one byte (to tell it is over).  See
docs/decisions/0041-bounded-readers-stored-plans-and-a-reachable-stop.md.
"""

from __future__ import annotations

import errno
import os
import stat
from enum import StrEnum
from pathlib import Path

from sim.errors import RunDirectoryError

from .words import say, terminal_run


class FileRefusal(StrEnum):
    """Why a run directory's file is not read (:data:`bench.words.terminal_run.REFUSAL`)."""

    TOO_LARGE = "too_large"                 # path, size (None: it grew while read), limit
    READ_LINK = "read_link"                 # path
    NOT_REGULAR_READ = "not_regular_read"   # path, kind (a FileKind)


class FileKind(StrEnum):
    """What is at a path (:func:`file_kind`; :data:`bench.words.terminal_run.FILE_KIND`)."""

    FIFO = "fifo"
    CHAR_DEVICE = "char_device"
    BLOCK_DEVICE = "block_device"
    SOCKET = "socket"
    DIRECTORY = "directory"
    REGULAR = "regular"
    OTHER = "other"

# The largest file of each kind a reader takes (docs/run-format.md, decision record 0041): a
# reader never reads more than this (plus one byte, to tell), so a link to /dev/zero or a
# huge file costs nothing.  A step's raw block: three channels of the DAQ driver's largest
# block (2^24 - 1 samples of float64), plus the archive's headers; a step result, a few kB
# (harmonics, control history) with a margin of 1000; run.json holds the plan (at most
# MAX_FREQUENCIES frequencies, bench.config) and the final estimate.
MAX_BYTES = {
    ".npz": 3 * 8 * 2**24 + 2**20,
    ".json": 4 * 2**20,
    "run.json": 16 * 2**20,
    "analysis.json": 256 * 2**20,   # bench analyze's result (plots' data included)
    ".jsonl": 256 * 2**20,          # events.jsonl, identification.jsonl (append-only, a line a step)
    ".request": 2**16,              # stop.request
    ".log": 256 * 2**20,
}


class UnreadableFile(RunDirectoryError):
    """A file of a run directory that is not a regular file (a link, a FIFO, a device) or
    larger than its kind's bound; the message names it."""


class TooLarge(UnreadableFile):
    """A regular file larger than its kind's bound."""

    def __init__(self, path: Path, size: int | None, limit: int):
        fields = dict(path=path, size=size, limit=limit)
        super().__init__(say(terminal_run.REFUSAL, FileRefusal.TOO_LARGE, fields))
        self.size, self.limit = size, limit
        self.code, self.fields = FileRefusal.TOO_LARGE, fields


def max_bytes(path: Path) -> int:
    path = Path(path)
    return MAX_BYTES.get(path.name, MAX_BYTES.get(path.suffix, MAX_BYTES[".json"]))


def open_regular(path: Path) -> int:
    """A file descriptor of ``path`` for reading, if it is a regular file: a symbolic link is
    not followed, a FIFO not waited on (:class:`UnreadableFile` naming it); a missing file
    raises ``FileNotFoundError`` as ``open`` does."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as e:
        if e.errno == errno.ELOOP:
            raise terminal_run.refused(UnreadableFile, FileRefusal.READ_LINK, path=path) from None
        raise
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        os.close(fd)
        raise terminal_run.refused(UnreadableFile, FileRefusal.NOT_REGULAR_READ, path=path, kind=kind_of(st.st_mode))
    return fd


def read_file(path: Path, limit: int | None = None) -> bytes:
    """The bytes of ``path``, read only if it is a regular file (:func:`open_regular`) of at
    most ``limit`` bytes (default: the bound of its kind, :data:`MAX_BYTES`); every reader
    of a run directory reads through this.  :class:`UnreadableFile` names the file and why;
    a missing file raises ``FileNotFoundError`` as ``open`` does."""
    path = Path(path)
    limit = max_bytes(path) if limit is None else limit
    fd = open_regular(path)
    try:
        size = os.fstat(fd).st_size
        if size > limit:
            raise TooLarge(path, size, limit)
        chunks, got = [], 0
        while got <= limit:
            chunk = os.read(fd, min(limit + 1 - got, 2**20))
            if not chunk:
                break
            chunks.append(chunk)
            got += len(chunk)
        if got > limit:                          # grew while being read
            raise TooLarge(path, None, limit)
        return b"".join(chunks)
    finally:
        os.close(fd)


def kind_of(mode: int) -> FileKind:
    """What a ``stat`` mode says is at a path."""
    for test, kind in ((stat.S_ISFIFO, FileKind.FIFO), (stat.S_ISCHR, FileKind.CHAR_DEVICE),
                       (stat.S_ISBLK, FileKind.BLOCK_DEVICE), (stat.S_ISSOCK, FileKind.SOCKET),
                       (stat.S_ISDIR, FileKind.DIRECTORY), (stat.S_ISREG, FileKind.REGULAR)):
        if test(mode):
            return kind
    return FileKind.OTHER


def file_kind(mode: int) -> str:
    """What is at a path, in words ('a FIFO')."""
    return say(terminal_run.FILE_KIND, kind_of(mode), {})
