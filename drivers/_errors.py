"""Typed exceptions raised by the instrument drivers.

Every driver error derives from :class:`InstrumentError` (a :class:`sim.errors.BenchError`), so a procedure can catch one
type to run its safe-stop path, and a finer type when it wants to react differently
(retry on :class:`InstrumentTimeout`, stop on :class:`ScpiError`).
"""

from __future__ import annotations

import logging

from sim.errors import InstrumentError  # the root of the driver errors, in the project's tree

log = logging.getLogger(__name__)

__all__ = ["BlockIntegrityError", "ConnectionLost", "FrameError", "InstrumentError", "InstrumentTimeout",
           "ModbusError", "ProtocolError", "SafetyInterlock", "ScpiError"]


class ConnectionLost(InstrumentError):
    """The link to the instrument closed or failed (socket reset, port gone)."""


class InstrumentTimeout(InstrumentError):
    """The instrument did not answer within the configured time."""


class ScpiError(InstrumentError):
    """The instrument reported an error in its SCPI error queue after a command.

    Attributes name the command that was sent and the instrument's own message.
    """

    def __init__(self, command: str, code: int, message: str) -> None:
        self.command = command
        self.code = code
        self.message = message
        super().__init__(f"{command!r} -> instrument error {code:+d}, {message!r}")


class ProtocolError(InstrumentError):
    """A reply could not be parsed or did not match what was set (read-back mismatch)."""


class SafetyInterlock(InstrumentError):
    """The driver refused a request that would be unsafe in the present state."""


class ModbusError(InstrumentError):
    """A Modbus request failed: exception response or transport error."""

    def __init__(self, request: str, detail: str, exception_code: int | None = None) -> None:
        self.request = request
        self.exception_code = exception_code
        self.detail = detail
        code = f" (exception code {exception_code})" if exception_code is not None else ""
        super().__init__(f"{request}: {detail}{code}")


class FrameError(InstrumentError):
    """A CAN frame of a data block was lost, duplicated, corrupt or of the wrong size.

    ``header`` is the block's header when it was received (a RESEND can then name it)."""

    def __init__(self, message: str, header: object | None = None) -> None:
        super().__init__(message)
        self.header = header


class BlockIntegrityError(FrameError):
    """A data block stayed inconsistent after every allowed RESEND."""
