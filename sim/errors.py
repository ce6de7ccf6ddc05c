"""The project's error tree, in the lowest layer so that every layer can raise from it.

    BenchError                    anything this project reports on purpose
    +-- ConfigurationError        a bad argument, file or value (also a ValueError)
    +-- EnvelopeError             a plan the rig's limits refuse before anything moves
    +-- LimitError                a safety limit stopped a run (procedures.safety.LimitExceeded)
    +-- InstrumentError           a driver's error (drivers: ConnectionLost, ScpiError, ...)
    +-- RunDirectoryError         not a readable run directory (also a ValueError)
    +-- StorageError              a run directory that cannot be written (full disk, steps/ deleted)

``bench`` maps these to exit codes by ``isinstance`` (2, 3, 3, 1, 2, 1); anything else that
reaches the command line is a bug and is reported as an internal error (decision record
0027).  The layers are bench -> procedures -> drivers -> sim; this module imports nothing,
so drivers and sim raise from the same tree as the application.
"""

from __future__ import annotations


class BenchError(Exception):
    """Base class of every error this project raises on purpose."""


class ConfigurationError(BenchError, ValueError):
    """A configuration value, argument or input file is missing, unknown or out of range;
    the message names it and what is allowed."""


class EnvelopeError(BenchError):
    """The rig's limits cannot hold the plan (refused before the output is switched on)."""


class LimitError(BenchError):
    """A safety limit was reached; the output has been ramped down and switched off."""


class InstrumentError(BenchError):
    """Base class of every error reported by an instrument driver."""


class RunDirectoryError(BenchError, ValueError):
    """The directory is not a readable run directory (missing, or run.json damaged)."""


class StorageError(BenchError):
    """A run directory could not be written (a full disk, ``steps/`` deleted, a permission
    taken away); the message names the file and the cause.  A runtime failure, not a usage
    error: the output is switched off and the steps stored so far stay intact."""
