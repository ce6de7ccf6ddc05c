"""Stop requests through the run directory: the watch page asks, the run obeys.

The page's server writes ``<run>/stop.request`` (a small JSON file: who asked, when); the
running session sees it before its next DAQ block and takes exactly the path of Ctrl-C:
:class:`StopRequested` is a ``KeyboardInterrupt``, so the session ramps down, switches the
output off and records the run as interrupted.  A file, not a signal, because the run may
live in another process (even on another host sharing the directory) and a recorded pid
can outlive its process and be reused; see docs/decisions/0018-watch-page-and-stop-requests.md.
"""

from __future__ import annotations

import json
import logging
import os
import tempfile
from enum import StrEnum
from pathlib import Path

from ..files import read_file
from ..storage import file_mode, now_iso
from ..words import say, terminal_run

log = logging.getLogger(__name__)

STOP_FILE = "stop.request"


class StopLine(StrEnum):
    """A stop request's words (:data:`bench.words.terminal_run.STOP`): the log line, and the
    interruption's reason (an ``interrupted`` event stores it)."""

    REQUESTED = "requested"                 # path (the run directory), by
    STOPPED = "stopped"                     # by
    BY_PAGE = "by_page"                     # client: who asked, the request's ``by``


class StopRequested(KeyboardInterrupt):
    """A stop asked for through the run directory; handled exactly like Ctrl-C."""


def request_stop(run_dir: Path, by: str) -> dict:
    """Ask the run in ``run_dir`` to stop safely; returns the request written."""
    req = {"time": now_iso(), "by": by}
    fd, tmp = tempfile.mkstemp(dir=run_dir, prefix=f".{STOP_FILE}.", suffix=".tmp")
    os.fchmod(fd, file_mode())            # as every file of a run (bench.storage)
    with os.fdopen(fd, "w") as fh:
        json.dump(req, fh)
    os.replace(tmp, Path(run_dir) / STOP_FILE)
    log.warning(say(terminal_run.STOP, StopLine.REQUESTED, dict(path=run_dir, by=by)))
    return req


def pending(run_dir: Path) -> dict | None:
    """The stop request waiting in ``run_dir``, if any."""
    try:
        return json.loads(read_file(Path(run_dir) / STOP_FILE))
    except FileNotFoundError:
        return None
    except (OSError, ValueError, RecursionError):    # half-written by hand, a link: still a request
        return {"time": None, "by": "unknown"}


def clear(run_dir: Path) -> None:
    try:
        (Path(run_dir) / STOP_FILE).unlink()
    except FileNotFoundError:
        pass


class StopOnRequest:
    """The DAQ as the procedure sees it, raising :class:`StopRequested` before the next
    block once a stop request is waiting.  Every step acquires blocks of at most about a
    second, so a request takes effect within about a second of rig time."""

    def __init__(self, daq, run_dir: Path, also=None):
        self._daq, self._file, self._also = daq, Path(run_dir) / STOP_FILE, also

    def _check(self) -> None:
        if self._also is not None:
            self._also()            # a stop from elsewhere (the session's signal latch)
        if self._file.exists():
            req = pending(self._file.parent) or {}
            raise StopRequested(say(terminal_run.STOP, StopLine.STOPPED, dict(by=req.get("by", "unknown"))))

    def acquire_periods(self, *args, **kw):
        self._check()
        return self._daq.acquire_periods(*args, **kw)

    def acquire_samples(self, *args, **kw):
        self._check()
        return self._daq.acquire_samples(*args, **kw)
