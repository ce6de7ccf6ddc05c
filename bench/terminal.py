"""What `bench` writes on the terminal: one progress line that fits the window, and log
lines that pass above it (decision record 0030).

- :class:`Progress` redraws a single line in place on a terminal (``\\r``, the line cut to
  the window's width minus one column so it never wraps, ``ESC [K`` clears what an earlier,
  longer line left); written to a file or a pipe it prints a plain line now and then.
- :class:`TerminalHandler` is the application's logging handler on stderr: it clears the
  progress line, writes the record, and draws the progress line again below it.
- :func:`setup_logging` scopes verbosity to the project's own loggers: by default the
  terminal shows warnings and errors only (a run prints its progress line and its result);
  ``-v`` adds the project's INFO lines, ``-vv`` its DEBUG lines (every SCPI line).  Other
  libraries (numba, matplotlib, pymodbus, dask, ...) reach the terminal only with a
  warning or worse, whatever the verbosity.  The root logger stays at INFO, so a run's
  ``bench.log`` keeps the INFO lines it always had.
- :func:`tolerant_streams`: a terminal that is gone (closed window, lost SSH link, a pipe
  whose reader ended) makes writes raise ``EIO`` or ``BrokenPipeError``; nothing the bench
  does may depend on them (the switch-off, the ``output_off`` event, run.json's status).
  A failed write silences that stream for the rest of the process (decision record 0040).
"""

from __future__ import annotations

import logging
import math
import os
import shutil
import sys
import threading
import time
from contextlib import contextmanager

PROJECT = ("bench", "procedures", "drivers", "sim")     # the loggers -v speaks for

_lock = threading.RLock()          # one writer at a time: progress redraws and log records
_active: Progress | None = None  # the progress line now on the terminal, if any


def columns(stream) -> int:
    """The width of the terminal ``stream`` writes to (``COLUMNS`` wins, as in shutil)."""
    env = os.environ.get("COLUMNS", "")
    if env.isdigit() and int(env) > 0:
        return int(env)
    try:
        return os.get_terminal_size(stream.fileno()).columns
    except (AttributeError, OSError, ValueError):
        return shutil.get_terminal_size().columns


def _duration(s: float) -> str:
    if not math.isfinite(s):
        return "--"
    s = int(round(s))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else \
        f"{s // 60}:{s % 60:02d}" if s >= 60 else f"{s}s"


def end_line() -> None:
    """End the progress line where it stands (before a message that is not a log record,
    such as the one-line error of an interrupted run), so nothing is glued to it."""
    global _active
    with _lock:
        if _active is not None:
            _active.stream.write("\n")
            _active.stream.flush()
            _active = None


class Progress:
    """One status line with a bar and an ETA, redrawn in place on a terminal."""

    def __init__(self, label: str, stream=None):
        self.label, self.stream, self.t0 = label, stream or sys.stderr, time.monotonic()
        self.tty = self.stream.isatty()
        self.t_start, self.done0 = self.t0, 0
        self.line = ""

    def restart(self, done: int = 0) -> None:
        """Count the ETA from now and from ``done`` steps (set-up and resumed steps excluded)."""
        self.t_start, self.done0 = time.monotonic(), done

    def format(self, done: int, total: int, note: str, width: int) -> str:
        """The line for ``width`` columns: the bar shrinks first, then the note is cut."""
        now = time.monotonic()
        eta = (now - self.t_start) / (done - self.done0) * (total - done) if done > self.done0 else float("nan")
        counts = f" {done}/{total} {_duration(now - self.t0)} eta {_duration(eta)}"
        bar_w = max(0, min(30, width - len(self.label) - len(counts) - 3 - 20))   # keep ~20 for the note
        bar = f" [{'#' * int(bar_w * done / max(total, 1)):<{bar_w}}]" if bar_w >= 5 else ""
        line = f"{self.label}{bar}{counts} {note}".rstrip()
        return line[:max(width, 1)]

    def __call__(self, done: int, total: int, note: str = "") -> None:
        global _active
        with _lock:
            if self.tty:
                self.line = self.format(done, total, note, columns(self.stream) - 1)
                self.stream.write("\r" + self.line + "\x1b[K")
                if done >= total:
                    self.stream.write("\n")
                    _active = None
                else:
                    _active = self
            elif done >= total or done == 1 or done % max(1, total // 10) == 0:
                self.stream.write(self.format(done, total, note, 10_000) + "\n")
            self.stream.flush()

    def redraw(self) -> None:
        self.stream.write(self.line + "\x1b[K")


class TerminalHandler(logging.Handler):
    """Log records on stderr (the one of the moment), above the progress line."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = self.format(record)
            with _lock:
                stream = sys.stderr
                active = _active if _active is not None and _active.stream is stream else None
                stream.write(("\r\x1b[K" if active else "") + text + "\n")
                if active:
                    active.redraw()
                stream.flush()
        except Exception:  # noqa: BLE001 - logging's own convention
            self.handleError(record)


def _in_scope(record: logging.LogRecord) -> bool:
    """The project's records at the handler's level; anyone else's only from WARNING up."""
    return record.levelno >= logging.WARNING or record.name.split(".")[0] in PROJECT


def setup_logging(verbosity: int) -> TerminalHandler:
    """The terminal handler for ``verbosity`` (0 default, 1 ``-v``, 2+ ``-vv``); the caller
    removes it (``logging.getLogger().removeHandler``) when the command ends."""
    root = logging.getLogger()
    for h in [h for h in root.handlers if isinstance(h, TerminalHandler)]:
        root.removeHandler(h)
    handler = TerminalHandler(level=(logging.WARNING, logging.INFO, logging.DEBUG)[min(verbosity, 2)])
    handler.addFilter(_in_scope)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s" if verbosity else
                                           "%(levelname)s: %(message)s"))
    if root.level == logging.NOTSET or root.level > logging.INFO:
        root.setLevel(logging.INFO)
    for name in PROJECT:
        logging.getLogger(name).setLevel(logging.DEBUG if verbosity >= 2 else logging.NOTSET)
    root.addHandler(handler)
    return handler


class TolerantStream:
    """A text stream whose writes never raise: the first that fails (the terminal is gone)
    points the file descriptor at /dev/null, so that what is still buffered, and Python's
    own flush at exit, go nowhere instead of raising again (exit status 120)."""

    def __init__(self, stream):
        self._stream, self.gone = stream, False

    def write(self, text: str) -> int:
        if not self.gone:
            try:
                return self._stream.write(text)
            except (OSError, ValueError):       # EIO, EPIPE; ValueError: closed file
                self._lost()
        return len(text)

    def flush(self) -> None:
        if not self.gone:
            try:
                self._stream.flush()
            except (OSError, ValueError):
                self._lost()

    def isatty(self) -> bool:
        try:
            return not self.gone and self._stream.isatty()
        except (OSError, ValueError):
            return False

    def _lost(self) -> None:
        self.gone = True
        try:
            fd = self._stream.fileno()
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, fd)
            os.close(null)
        except (OSError, ValueError, AttributeError):      # no descriptor (a test's capture)
            pass

    def __getattr__(self, name):
        return getattr(self._stream, name)


@contextmanager
def tolerant_streams():
    """``sys.stdout`` and ``sys.stderr`` as :class:`TolerantStream` while the block runs."""
    saved = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = (s if isinstance(s, TolerantStream) else TolerantStream(s) for s in saved)
    try:
        yield
    finally:
        for s in (sys.stdout, sys.stderr):      # what is still buffered: now, where a failure is caught
            s.flush()
        sys.stdout, sys.stderr = saved
