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

The `bench` program installs one latch for the whole process first thing (:func:`for_process`,
before the heavy imports) and never gives the defaults back: after the command's work it
only records (:meth:`SignalLatch.finish`), and at the very end the process ignores the
ending signals (:func:`ignore_at_exit`), since Python's own finalisation would otherwise
restore their default action (exit -1, -15) while it tears the modules down.  The exit
code follows decision record 0051: 130 when a signal came before the work was done.
"""

from __future__ import annotations

import logging
import signal
from contextlib import contextmanager
from enum import StrEnum

from .words import say, terminal_run

log = logging.getLogger(__name__)


class Doing(StrEnum):
    """What a held latch or :func:`uninterruptible` lets finish, said when a signal comes
    (its words: :data:`bench.words.terminal_run.DOING`)."""

    REPORT = "report"                       # the report is written
    RAMP_DOWN = "ramp_down"
    SWITCH_OFF = "switch_off"


class SignalLine(StrEnum):
    """The log line of a signal let wait (:data:`bench.words.terminal_run.SIGNAL`)."""

    HELD = "held"                           # reason ("Ctrl-C", "signal N"), doing
    UNINTERRUPTIBLE = "uninterruptible"     # signum, doing

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
        self.reason: str | None = None      # a signal that came before the work was done
        self.late: str | None = None        # one that came after (:meth:`finish`)
        self._hold = False
        self._finished = False
        self._doing: Doing | None = None    # what a held latch lets finish (said when a signal comes)

    def handler(self, signum, frame):
        if self._finished:
            self.late = reason(signum)      # said by the caller, which knows whether work follows
            return
        self.reason = reason(signum)
        if not self._hold:
            raise KeyboardInterrupt(self.reason)
        if self._doing:
            log.warning(say(terminal_run.SIGNAL, SignalLine.HELD, dict(reason=self.reason, doing=self._doing)))

    def note(self, signum: int) -> None:
        """Record ``signum`` without raising (a handler of its own ran instead)."""
        if self._finished:
            self.late = reason(signum)
        else:
            self.reason = reason(signum)

    def check(self) -> None:
        if self.reason is not None:
            raise KeyboardInterrupt(self.reason)

    def installed(self):
        return handling(self.handler, *ENDING)

    def hold(self, doing: Doing | None = None) -> None:
        """From now on latch a signal without raising it (a run directory being set up must
        not be left half-written) until :meth:`release`; ``doing``: what is let finish, said
        on the terminal when a signal comes."""
        self._hold = True
        self._doing = doing

    def release(self) -> None:
        """Raise again at once; raise now a signal latched while held."""
        self._hold = False
        self._doing = None
        self.check()

    @property
    def finished(self) -> bool:
        return self._finished

    def finish(self) -> None:
        """The work is done (the measuring over, the report written): from now on a signal
        is only recorded as :attr:`late`; nothing is left for it to stop."""
        self._hold = self._finished = True
        self._doing = None

    def reopen(self) -> None:
        """More work follows the end (the report): held, and a signal that came since
        :meth:`finish` counts as one that came before the work was done."""
        self._finished = False
        self._hold = True
        if self.late is not None:
            self.reason, self.late = self.late, None


_process: SignalLatch | None = None


def for_process() -> SignalLatch:
    """The `bench` program's latch, installed for the ending signals at once and never
    uninstalled (a handler of a command may stand in for it and give it back)."""
    global _process
    if _process is None:
        _process = SignalLatch()
        for s in ENDING:
            signal.signal(s, _process.handler)
    return _process


def process_latch() -> SignalLatch | None:
    """The program's latch, None when the bench runs inside another program (a test)."""
    return _process


def ignore_at_exit() -> None:
    """The process only exits from now on: the ending signals are ignored (an ignored
    signal stays ignored through Python's finalisation, a handler does not)."""
    for s in ENDING:
        signal.signal(s, signal.SIG_IGN)


def uninterruptible(what: Doing, latch: SignalLatch | None = None):
    """Hold the ending signals off while ``what`` runs (switching the output off must not
    be cut short by an impatient second Ctrl-C); they are logged, not lost silently, and
    recorded in ``latch`` (so a signal during the switch-off of a completed run still
    stops what the command would do next)."""
    def handler(signum, frame):
        log.warning(say(terminal_run.SIGNAL, SignalLine.UNINTERRUPTIBLE, dict(signum=signum, doing=what)))
        if latch is not None:
            latch.note(signum)
    return handling(handler, *ENDING)
