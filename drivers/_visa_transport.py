"""VISA resources (pyvisa with the pure-Python pyvisa-py backend) behind the byte-stream
surface the SCPI driver uses from pyserial (decision record 0030).

Many generators are reached over USB-TMC, VXI-11 or HiSLIP rather than a raw socket or a
serial line; pyvisa-py speaks those (and raw sockets and serial ports too).  The driver
keeps one code path: :class:`VisaTransport` gives it what a pyserial port gives it -
``write``, ``flush``, ``read_until(b"\\n")`` (a partial line on timeout, as pyserial),
``reset_input_buffer``, ``in_waiting``, a settable ``timeout`` in seconds and ``close`` -
so confirmed settings, the error-queue drain and the resynchronisation after an
interrupted query work on it unchanged.  A failed link raises ``ConnectionError`` (an
OSError, as pyserial's socket errors are), which the driver reports as ConnectionLost.

Accepted resource strings (:func:`is_visa_resource`)::

    TCPIP0::192.168.1.20::5025::SOCKET      raw SCPI socket
    TCPIP0::192.168.1.20::inst0::INSTR      VXI-11 (also TCPIP::host::INSTR)
    TCPIP0::192.168.1.20::hislip0::INSTR    HiSLIP
    USB0::0x0957::0x2C07::MY12345678::INSTR USB-TMC
    ASRL/dev/ttyUSB0::INSTR                 serial port through VISA
    GPIB0::10::INSTR                        GPIB (needs a GPIB backend)
"""

from __future__ import annotations

import re
import socket
import time
from typing import Any

VISA_RESOURCE = re.compile(
    r"""^(?:
        TCPIP\d*::[^:\s]+::\d+::SOCKET                      # raw socket
      | TCPIP\d*::[^:\s]+(?:::[^:\s]+)?::INSTR              # VXI-11 (inst0), HiSLIP (hislip0)
      | USB\d*::[^:\s]+::[^:\s]+::[^:\s]+(?:::\d+)?::INSTR   # USB-TMC
      | ASRL[^:\s]+::INSTR                                  # serial
      | GPIB\d*::\d+(?:::\d+)?::INSTR                       # GPIB
    )$""", re.IGNORECASE | re.VERBOSE)

CHUNK = 4096


def is_visa_resource(url: str) -> bool:
    """True for a VISA resource string the generator driver opens through pyvisa
    (``TCPIP0::host::5025::SOCKET``, ``...::INSTR``); pyserial's URLs and device paths
    (``socket://``, ``/dev/tty...``, ``loop://``) are False."""
    return bool(VISA_RESOURCE.match(url.strip()))


class VisaTransport:
    """A pyvisa resource with pyserial's read/write surface (see the module docstring).

    :param resource: a VISA resource string (:func:`is_visa_resource`).
    :param timeout: seconds a ``read_until`` waits for its line, as pyserial's ``timeout``.
    """

    def __init__(self, resource: str, timeout: float = 2.0) -> None:
        import pyvisa
        from pyvisa import constants

        self.resource, self._timeout = resource, float(timeout)
        self._buf = bytearray()
        self._errors = (pyvisa.errors.VisaIOError, pyvisa.errors.InvalidSession)
        self._timeout_code = constants.StatusCode.error_timeout
        try:
            self._rm = pyvisa.ResourceManager("@py")
            res: Any = self._rm.open_resource(resource, open_timeout=max(1, int(self._timeout * 1000)))
        except (pyvisa.errors.Error, ValueError, OSError, Exception) as exc:  # noqa: BLE001 - backends raise anything
            raise ConnectionError(f"cannot open VISA resource {resource!r}: {exc}") from exc
        self._res = res
        self._res.read_termination = "\n"        # a read returns at the end of a reply line ...
        self._res.write_termination = ""         # ... and writes send the driver's bytes as they are
        if self._res.resource_class == "SOCKET":
            self._no_delay()
        self._set_visa_timeout(self._timeout)

    # ----------------------------------------------------------------- pyserial's surface
    @property
    def timeout(self) -> float:
        return self._timeout

    @timeout.setter
    def timeout(self, seconds: float) -> None:
        self._timeout = float(seconds)

    @property
    def in_waiting(self) -> int:
        """Bytes received and not read yet (looks without waiting)."""
        self._poll()
        return len(self._buf)

    def write(self, data: bytes) -> int:
        try:
            n, _ = self._res.visalib.write(self._res.session, bytes(data))
        except self._errors as exc:
            raise ConnectionError(f"VISA write to {self.resource} failed: {exc}") from exc
        return n

    def flush(self) -> None:
        """Writes are synchronous: nothing waits in an output buffer."""

    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes:
        """Up to and including ``expected``; whatever arrived (maybe nothing) on timeout."""
        deadline = time.monotonic() + self._timeout
        while expected not in self._buf and (size is None or len(self._buf) < size):
            left = deadline - time.monotonic()
            if left <= 0 or not self._read_chunk(left):
                break
        end = self._buf.find(expected)
        n = len(self._buf) if end < 0 else end + len(expected)
        if size is not None:
            n = min(n, size)
        out = bytes(self._buf[:n])
        del self._buf[:n]
        return out

    def read(self, size: int = 1) -> bytes:
        """At most ``size`` bytes: those waiting, else what arrives within the timeout."""
        if not self._buf and self._timeout > 0:
            self._read_chunk(self._timeout)
        self._poll()
        out = bytes(self._buf[:size])
        del self._buf[:size]
        return out

    def reset_input_buffer(self) -> None:
        """Discard what was received and not read (as pyserial: what is there now)."""
        self._poll()
        self._buf.clear()

    def close(self) -> None:
        try:
            self._res.close()
        except self._errors:
            pass

    # ----------------------------------------------------------------- internals
    def _no_delay(self) -> None:
        """TCP_NODELAY on a socket resource: a command line and the ``SYST:ERR?`` after it
        must not wait for Nagle and the peer's delayed ACK (45 ms per confirmed setting
        instead of about 1.5).  pyvisa-py 0.8 refuses VI_ATTR_TCPIP_NODELAY, so the
        session's own socket is set when the attribute fails."""
        from pyvisa import constants
        try:
            self._res.set_visa_attribute(constants.ResourceAttribute.tcpip_nodelay, constants.VI_TRUE)
            return
        except Exception:  # noqa: BLE001 - unsupported by this backend: try its socket
            pass
        session = getattr(self._res.visalib, "sessions", {}).get(self._res.session)
        sock = getattr(session, "interface", None)
        if isinstance(sock, socket.socket):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def _set_visa_timeout(self, seconds: float) -> None:
        self._res.timeout = max(1, int(round(seconds * 1000)))    # ms; 0 would mean "immediate"

    def _read_chunk(self, seconds: float | None) -> bool:
        """One VISA read (a reply line or up to CHUNK bytes) within ``seconds``; None polls.
        False when nothing came."""
        try:
            if seconds is None:
                self._res.timeout = 0                             # VI_TMO_IMMEDIATE
            else:
                self._set_visa_timeout(seconds)
            data, _ = self._res.visalib.read(self._res.session, CHUNK)
        except self._errors as exc:
            if getattr(exc, "error_code", None) == self._timeout_code:
                return False
            raise ConnectionError(f"VISA read from {self.resource} failed: {exc}") from exc
        self._buf += data
        return bool(data)

    def _poll(self) -> None:
        while self._read_chunk(None):
            pass
