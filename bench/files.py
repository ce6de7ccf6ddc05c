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
from pathlib import Path

from sim.errors import RunDirectoryError

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
        said = f"{size} bytes" if size is not None else "grew while read"
        super().__init__(f"{path}: {said}, more than the {limit} bytes a file of this kind may have; not read")
        self.size, self.limit = size, limit


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
            raise UnreadableFile(f"{path}: is a symbolic link; a run's files are read only as regular "
                                 f"files inside the run directory") from None
        raise
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        os.close(fd)
        raise UnreadableFile(f"{path}: not a regular file ({file_kind(st.st_mode)}); not read")
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


def file_kind(mode: int) -> str:
    for test, name in ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISDIR, "a directory"), (stat.S_ISREG, "a regular file")):
        if test(mode):
            return name
    return "not a regular file"
