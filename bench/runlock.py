"""One session at a time on a run directory, and on an instrument: operating-system locks.

A session (``bench run``, ``bench resume``, ``bench demo``) holds ``flock(LOCK_EX)`` on
``<run>/session.lock`` from before it writes anything until it has switched the output off
and recorded how it ended; a second session on the same directory is refused at once with
a message naming the holder (process, host, since when, command), measuring nothing.
The kernel releases the lock when its holder dies, however it dies (kill -9 included), so
a lock left by a dead process is simply taken: the holder information in the file is
only information (decision record 0040).

A rig's instruments get the same lock, one file per instrument URL in a per-user lock
directory (``GUIDEWAY_LOCK_DIR``, else ``$XDG_RUNTIME_DIR/guideway-bench``, else
``<tmp>/guideway-bench-<uid>``): two sessions of one user on one computer cannot drive
the same generator from two run directories.  What this does not cover (another user,
another computer, the same instrument under another URL) is in docs/reliability.md.

Locks are re-entrant within a process (the command line takes the run directory's lock
before it reads a run to resume, the session takes it again).
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import socket
import stat
import sys
import tempfile
import threading
from contextlib import contextmanager
from datetime import UTC, datetime
from enum import StrEnum
from pathlib import Path

from sim.errors import BenchError

from .files import read_file
from .words.terminal import refused

LOCK_NAME = "session.lock"          # in a run directory

_held: dict[str, int] = {}           # lock file (real path) -> how many holds this process has on it
_guard = threading.Lock()


class InUse(BenchError):
    """A run directory or an instrument is held by another session."""


class LockRefusal(StrEnum):
    """Why a lock was refused (:class:`InUse`'s ``code``; its words: :mod:`bench.words.terminal`)."""

    LINK = "lock_link"                  # path
    NOT_A_FILE = "lock_not_a_file"      # path, held, name
    IN_USE = "in_use"                   # held ("run_dir" | "instrument"), name, holder (the lock file's info, or {})
    LOCK_DIR = "lock_dir"               # path, uid


def _holder(path: Path) -> dict:
    """Who holds the lock, as its file says: pid, host, since, command, run ({}: not said yet)."""
    try:
        info = json.loads(read_file(path, 4096))       # regular file, bounded (bench.files)
        return dict(pid=int(info["pid"]), host=info["host"], since=info["since"],
                    command=info.get("command", "bench"), run=info.get("run") or "")
    except (OSError, ValueError, KeyError, TypeError):
        return {}


@contextmanager
def hold(path: Path, held: str, name: str, run: Path | None = None):
    """Hold the exclusive lock ``path`` while the block runs, or raise :class:`InUse`
    naming what is ``held`` ("run_dir" or "instrument") by ``name`` and the holder.
    ``run``: the run directory, told to whoever is refused."""
    path = Path(path)
    key = os.path.realpath(path)
    with _guard:
        if key in _held:
            _held[key] += 1
            reentered = True
        else:
            reentered = False
    if reentered:
        try:
            yield
        finally:
            with _guard:
                _held[key] -= 1
        return
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o666)
    except OSError as e:
        if e.errno == errno.ELOOP:
            raise refused(InUse, LockRefusal.LINK, path=path) from None
        raise
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise refused(InUse, LockRefusal.NOT_A_FILE, path=path, held=held, name=name)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise refused(InUse, LockRefusal.IN_USE, held=held, name=name, holder=_holder(path)) from None
        info = {"pid": os.getpid(), "host": socket.gethostname(),
                "since": datetime.now(UTC).isoformat(timespec="seconds"),
                "command": " ".join(["bench", *sys.argv[1:2]]) if sys.argv else "bench"}
        if run is not None:
            info["run"] = str(run)
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(info) + "\n").encode(), 0)
        with _guard:
            _held[key] = 1
        try:
            yield
        finally:
            with _guard:
                del _held[key]
            try:
                os.ftruncate(fd, 0)          # nobody holds it now (a dead holder's info stays: harmless)
            except OSError:
                pass
    finally:
        os.close(fd)                         # releases the lock


def run_dir(path: Path):
    """The lock of the run directory ``path`` (which must exist)."""
    return hold(Path(path) / LOCK_NAME, "run_dir", str(path))


def lock_dir() -> Path:
    """The per-user directory of the instruments' locks (made, mode 0o700, if missing)."""
    env = os.environ.get("GUIDEWAY_LOCK_DIR")
    if env:
        d = Path(env)
    elif os.environ.get("XDG_RUNTIME_DIR"):
        d = Path(os.environ["XDG_RUNTIME_DIR"]) / "guideway-bench"
    else:
        d = Path(tempfile.gettempdir()) / f"guideway-bench-{os.getuid()}"
    d.mkdir(mode=0o700, parents=True, exist_ok=True)
    st = os.lstat(d)
    if stat.S_ISLNK(st.st_mode) or not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid():
        raise refused(InUse, LockRefusal.LOCK_DIR, path=d, uid=os.getuid())
    return d


def instrument(url: str, run: Path):
    """The lock of the instrument at ``url`` (by its URL as written) for a session of ``run``."""
    name = hashlib.sha256(url.encode()).hexdigest()[:24] + ".lock"
    return hold(lock_dir() / name, "instrument", url, run=run)
