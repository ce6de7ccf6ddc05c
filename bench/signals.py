"""The signals that end a session: one clean exit, which cannot be lost.

Ctrl-C (SIGINT), SIGTERM, SIGHUP (the terminal closed, the SSH link lost: the most common
way a session at a rig ends) and SIGQUIT (Ctrl-\\) all go through the same path: the
handler raises ``KeyboardInterrupt`` ("Ctrl-C" or "signal N"), and the session ramps
down and switches the output off.  Left at Python's defaults, SIGHUP and SIGQUIT would
end the process on the spot with the generator's output on.

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

# every signal whose default action ends the process and that a session can catch
ENDING = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT)


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


def reason(signum: int) -> str:
    return "Ctrl-C" if signum == signal.SIGINT else f"signal {signum}"


class SignalLatch:
    """Ctrl-C, SIGTERM, SIGHUP and SIGQUIT raise ``KeyboardInterrupt`` ("Ctrl-C" or
    "signal N") and stay latched: :meth:`check` raises it again.  While held (:meth:`hold`),
    a signal is latched without raising (:meth:`release` raises it)."""

    def __init__(self):
        self.reason: str | None = None
        self._hold = False

    def handler(self, signum, frame):
        self.reason = reason(signum)
        if not self._hold:
            raise KeyboardInterrupt(self.reason)

    def check(self) -> None:
        if self.reason is not None:
            raise KeyboardInterrupt(self.reason)

    def installed(self):
        return handling(self.handler, *ENDING)

    def hold(self) -> None:
        """From now on latch a signal without raising it (a run directory being set up must
        not be left half-written) until :meth:`release`."""
        self._hold = True

    def release(self) -> None:
        """Raise again at once; raise now a signal latched while held."""
        self._hold = False
        self.check()


def uninterruptible(what: str):
    """Hold the ending signals off while ``what`` runs (switching the output off must not
    be cut short by an impatient second Ctrl-C); they are logged, not lost silently."""
    def handler(signum, frame):
        log.warning("signal %d while %s: finishing that first", signum, what)
    return handling(handler, *ENDING)
