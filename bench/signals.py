"""Ctrl-C and SIGTERM: one clean exit, which cannot be lost.

Python's own SIGINT handler raises ``KeyboardInterrupt`` wherever the main thread is, and
drops it silently when that is inside a finalizer (``Exception ignored in ... __del__``;
numba's compiler finalizes LLVM objects mid-step, dask and pyarrow objects are finalized
between tasks).  A :class:`SignalLatch` raises at once as well, but also remembers the
signal, and long loops call :meth:`SignalLatch.check` at their safe points (a run before
each DAQ block, a study after each task) to raise it again.  A SIGTERM dropped that way
once let a CI run finish all 30 of its steps.
"""

from __future__ import annotations

import logging
import signal
from contextlib import contextmanager

log = logging.getLogger(__name__)


@contextmanager
def handling(handler, *signums):
    """Run the block with ``handler`` for ``signums`` (main thread only; elsewhere as is)."""
    try:
        old = {s: signal.signal(s, handler) for s in signums}
    except ValueError:          # not the main thread
        yield
        return
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


class SignalLatch:
    """Ctrl-C and SIGTERM raise ``KeyboardInterrupt`` ("Ctrl-C" or "signal 15") and stay
    latched: :meth:`check` raises it again."""

    def __init__(self):
        self.reason: str | None = None

    def handler(self, signum, frame):
        self.reason = "Ctrl-C" if signum == signal.SIGINT else f"signal {signum}"
        raise KeyboardInterrupt(self.reason)

    def check(self) -> None:
        if self.reason is not None:
            raise KeyboardInterrupt(self.reason)

    def installed(self):
        return handling(self.handler, signal.SIGINT, signal.SIGTERM)


def uninterruptible(what: str):
    """Hold Ctrl-C and SIGTERM off while ``what`` runs (switching the output off must not
    be cut short by an impatient second Ctrl-C); they are logged, not lost silently."""
    def handler(signum, frame):
        log.warning("signal %d while %s: finishing that first", signum, what)
    return handling(handler, signal.SIGINT, signal.SIGTERM)
