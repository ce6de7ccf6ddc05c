"""Driver for a Keysight 33500-style function generator (SCPI over serial or TCP).

One driver serves every transport pyserial's ``serial_for_url`` opens: ``/dev/ttyUSB0``,
``socket://host:5025`` (raw SCPI socket), ``loop://``; and VISA resource strings
(``TCPIP0::host::inst0::INSTR``, ``USB0::...::INSTR``, ``...::SOCKET``) through pyvisa-py
behind the same byte-stream surface (:mod:`drivers._visa_transport`). Every setting is confirmed: the
driver reads the value back and drains ``SYST:ERR?``; an instrument error becomes a
:class:`ScpiError` naming the command and the instrument's message.

Settings and their commands:

=====================  ===========================  =====================================
method                 command                      check
=====================  ===========================  =====================================
set_frequency(Hz)      ``FREQ <Hz>``                read back ``FREQ?``, errors drained
set_amplitude(Vpp)     ``VOLT <Vpp>``               <= drive limit; ``VOLT?``
set_offset(V)          ``VOLT:OFFS <V>``            within drive limit; ``VOLT:OFFS?``
set_output(on)         ``OUTP ON|OFF``              ``OUTP?``
set_voltage_limits     ``VOLT:LIM:LOW/HIGH``,       hardware clamp, ``VOLT:LIM:STAT?``
                       ``VOLT:LIM:STAT ON``
configure_sine(...)    ``FUNC SIN``, ``VOLT:UNIT    load high-Z, clamp from the drive
                       VPP``, ``OUTP:LOAD INF``,    limit, optional fixed attenuator
                       ``VOLT:RANG:AUTO OFF``       range
reset()                ``*RST``; ``*CLS``           refused while the output is on
=====================  ===========================  =====================================
"""

from __future__ import annotations

import logging
import math
import re
import socket
import time
from types import TracebackType
from typing import Any

import serial

from ._errors import ConnectionLost, InstrumentTimeout, ProtocolError, SafetyInterlock, ScpiError
from ._interfaces import Identity
from ._visa_transport import VisaTransport, is_visa_resource

TWIN_MARK = "guideway-bench twin"     # in the *IDN? firmware field of the simulated generator

log = logging.getLogger(__name__)

MAX_ERRORS_DRAINED = 32
FREQ_MAX_HZ = 20e6
RESYNC_QUIET_S = 0.1      # a link silent this long after an interrupted exchange is drained
RESYNC_MAX_LINES = 64     # stale lines skipped before a marker, at most


class ScpiFunctionGenerator:
    """A function generator on a SCPI link. Satisfies :class:`FunctionGenerator`.

    :param url: anything ``serial.serial_for_url`` opens, or a VISA resource string.
    :param timeout_s: bound on every reply; a silent instrument raises InstrumentTimeout.
    :param drive_limit_V: largest instantaneous output voltage magnitude the procedures may
        ask for (|offset| + Vpp/2). Requests above it raise ValueError before anything is
        sent; :meth:`configure_sine` also sets it as the instrument's hardware clamp.
    """

    def __init__(self, url: str, *, timeout_s: float = 2.0, baudrate: int = 115200,
                 drive_limit_V: float | None = None) -> None:
        self.url = url
        self.timeout_s = timeout_s
        self.drive_limit_V = drive_limit_V
        self._twin: bool | None = None
        self._in_step = True
        self._port: Any           # pyserial's port, or the VISA transport with the same surface
        try:
            if is_visa_resource(url):     # USB-TMC, VXI-11, HiSLIP, VISA socket: pyvisa-py
                self._port = VisaTransport(url, timeout=timeout_s)
            else:
                self._port = serial.serial_for_url(url, baudrate=baudrate, timeout=timeout_s,
                                                   write_timeout=timeout_s)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise ConnectionLost(f"cannot open function generator at {url!r}: {exc}") from exc
        sock = getattr(self._port, "_socket", None)
        if sock is not None:  # socket:// - small command lines must not wait for Nagle
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        log.info("function generator opened at %s", url)

    # ----------------------------------------------------------------- transport
    #
    # The link is "in step" when every reply the instrument will send has been read.  An
    # exchange cut short (Ctrl-C or SIGTERM inside a query, a timeout, a half-sent line)
    # leaves it out of step: the next query would read the previous one's answer.  The next
    # exchange then resynchronises first (:meth:`resync`), as a device clear does.

    def _send(self, command: str) -> None:
        log.debug("-> %s", command)
        try:
            self._port.write(command.encode("ascii") + b"\n")
            self._port.flush()
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"{command!r}: link to {self.url} failed: {exc}") from exc

    def _read_line(self, command: str) -> str:
        try:
            raw = self._port.read_until(b"\n")
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"{command!r}: link to {self.url} failed: {exc}") from exc
        if not raw.endswith(b"\n"):
            raise InstrumentTimeout(f"{command!r}: no complete reply from {self.url} within "
                                    f"{self._port.timeout:g} s (got {raw!r})")
        reply = raw.decode("ascii", errors="replace").strip()
        log.debug("<- %s", reply)
        return reply

    @property
    def in_step(self) -> bool:
        """False after an exchange was cut short, until :meth:`resync` succeeds."""
        return self._in_step

    def write(self, command: str) -> None:
        """Send one program message, LF-terminated, without checking the error queue."""
        if not self._in_step:
            self.resync()
        self._in_step = False           # until the whole line is out
        self._send(command)
        self._in_step = True

    def query(self, command: str) -> str:
        """Send a query and return its response line (without the terminator)."""
        if not self._in_step:
            self.resync()
        self._in_step = False           # until its whole reply is read
        self._send(command)
        reply = self._read_line(command)
        self._in_step = True
        return reply

    def resync(self) -> None:
        """Bring the reply stream back in step after an interrupted exchange.

        As a device clear does: end a half-sent line, drain whatever input arrives until
        the link is quiet for ``RESYNC_QUIET_S``, ``*CLS``, then ``*OPC?`` read until it
        answers ``1`` and ``SYST:ERR?`` read until an error-queue entry.  The instrument
        answers in order, so a stale reply that arrives after the drain comes before the
        markers' replies; the second marker, whose answer looks like no other query's,
        catches the case where the stale reply was itself a ``1``.  Raises
        InstrumentTimeout (the link stays out of step) if the markers do not come back.
        """
        log.warning("resynchronising the link to %s after an interrupted exchange", self.url)
        port = self._port
        timeout = port.timeout
        try:
            port.reset_input_buffer()
            port.timeout = RESYNC_QUIET_S
            deadline = time.monotonic() + self.timeout_s
            while port.read(4096) and time.monotonic() < deadline:
                pass
            port.timeout = self.timeout_s
            self._send("")                  # ends a half-sent command line; empty lines are ignored
            self._send("*CLS")
            self._send("*OPC?")
            self._skip_until("*OPC?", lambda r: r == "1")
            self._send("SYST:ERR?")
            self._skip_until("SYST:ERR?", lambda r: re.fullmatch(r'[+-]?\d+,.*', r) is not None)
        finally:
            port.timeout = timeout
        self._in_step = True
        log.info("link to %s back in step", self.url)

    def _skip_until(self, command: str, is_answer) -> None:
        for _ in range(RESYNC_MAX_LINES):
            reply = self._read_line(command)
            if is_answer(reply):
                return
            log.debug("resync: skipped stale reply %r", reply)
        raise ProtocolError(f"{command!r}: no answer among {RESYNC_MAX_LINES} lines from {self.url}")

    def query_float(self, command: str) -> float:
        reply = self.query(command)
        try:
            return float(reply)
        except ValueError as exc:
            raise ProtocolError(f"{command!r}: expected a number, got {reply!r}") from exc

    def read_errors(self) -> list[tuple[int, str]]:
        """Drain the instrument's error queue: [(code, message), ...], oldest first."""
        errors: list[tuple[int, str]] = []
        for _ in range(MAX_ERRORS_DRAINED):
            reply = self.query("SYST:ERR?")
            code_text, _, message = reply.partition(",")
            try:
                code = int(code_text)
            except ValueError as exc:
                raise ProtocolError(f"'SYST:ERR?': unparsable reply {reply!r}") from exc
            if code == 0:
                return errors
            errors.append((code, message.strip().strip('"')))
        raise ProtocolError(f"error queue of {self.url} did not empty after "
                            f"{MAX_ERRORS_DRAINED} reads")

    def command(self, command: str) -> None:
        """Send a command and raise ScpiError if the instrument queued any error for it."""
        self.write(command)
        errors = self.read_errors()
        if errors:
            code, message = errors[0]
            if len(errors) > 1:
                message += "; then " + "; ".join(f"{c:+d} {m}" for c, m in errors[1:])
            raise ScpiError(command, code, message)

    def _set_confirmed(self, command: str, query: str, expected: float) -> float:
        self.command(command)
        actual = self.query_float(query)
        if not math.isclose(actual, expected, rel_tol=1e-6, abs_tol=1e-9):
            raise ProtocolError(f"{command!r}: read back {actual!r} from {query!r}, "
                                f"expected {expected!r}")
        return actual

    # ----------------------------------------------------------------- identity, reset
    def identify(self) -> Identity:
        reply = self.query("*IDN?")
        parts = [p.strip() for p in reply.split(",")]
        if len(parts) != 4:
            raise ProtocolError(f"'*IDN?': expected 4 fields, got {reply!r}")
        return Identity(*parts)

    def is_twin(self) -> bool:
        """True when the instrument is the project's simulated twin (by its *IDN? answer)."""
        if self._twin is None:
            self._twin = TWIN_MARK in self.query("*IDN?")
        return self._twin

    def mark_step(self, key: str) -> None:
        """Tell a simulated rig that step ``key`` starts its measurement (twin-only
        ``SIM:STEP``, decision record 0013: the plant's noise is reseeded from its seed and
        the key).  A real instrument is never sent it."""
        if self.is_twin():
            self.command(f'SIM:STEP "{key}"')

    def output_enabled(self) -> bool:
        reply = self.query("OUTP?")
        if reply not in ("0", "1"):
            raise ProtocolError(f"'OUTP?': expected 0 or 1, got {reply!r}")
        return reply == "1"

    def reset(self) -> None:
        """``*RST`` then ``*CLS``; refused while the output is on (a reset can briefly emit
        about 5 Vpp at 1 kHz into the amplifier)."""
        if self.output_enabled():
            raise SafetyInterlock("*RST refused: the output is on; switch it off first")
        self.write("*RST")
        self.write("*CLS")
        if self.query("*OPC?") != "1":
            raise ProtocolError("'*OPC?' after *RST did not answer 1")

    # ----------------------------------------------------------------- settings
    def configure_sine(self, *, drive_limit_V: float | None = None,
                       fixed_range: bool = True) -> None:
        """Sine into a high-impedance amplifier input with the hardware clamp set.

        ``fixed_range`` sends ``VOLT:RANG:AUTO OFF`` so the attenuator relays do not switch
        (and glitch) between small-force steps. The instrument keeps the range of the
        present amplitude, so set the largest amplitude of a level schedule first. If the
        present output already exceeds ``drive_limit_V``, enabling the clamp fails with
        ScpiError (-221) and nothing is clipped behind the caller's back.
        """
        if drive_limit_V is not None:
            self.drive_limit_V = drive_limit_V
        self.command("FUNC SIN")
        self.command("VOLT:UNIT VPP")
        self._set_confirmed("OUTP:LOAD INF", "OUTP:LOAD?", 9.9e37)
        if self.drive_limit_V is not None:
            self.set_voltage_limits(-self.drive_limit_V, self.drive_limit_V)
        if fixed_range:
            self.command("VOLT:RANG:AUTO OFF")
            if self.query("VOLT:RANG:AUTO?") != "0":
                raise ProtocolError("'VOLT:RANG:AUTO OFF' did not take effect")

    def set_voltage_limits(self, low_V: float, high_V: float) -> None:
        """Hardware output clamp: VOLT:LIM:LOW/HIGH then VOLT:LIM:STAT ON, confirmed."""
        if not low_V < high_V:
            raise ValueError(f"voltage limits need low < high, got {low_V} >= {high_V}")
        self._set_confirmed(f"VOLT:LIM:HIGH {high_V:.9g}", "VOLT:LIM:HIGH?", high_V)
        self._set_confirmed(f"VOLT:LIM:LOW {low_V:.9g}", "VOLT:LIM:LOW?", low_V)
        self.command("VOLT:LIM:STAT ON")
        if self.query("VOLT:LIM:STAT?") != "1":
            raise ProtocolError("'VOLT:LIM:STAT ON' did not take effect")

    def _check_drive(self, amplitude_Vpp: float | None, offset_V: float | None) -> None:
        """Refuse a request whose peak output would exceed the drive limit; the other
        parameter is read from the instrument, not from a cache."""
        if self.drive_limit_V is None:
            return
        if amplitude_Vpp is None:
            amplitude_Vpp = self.query_float("VOLT?")
        if offset_V is None:
            offset_V = self.query_float("VOLT:OFFS?")
        peak = abs(offset_V) + amplitude_Vpp / 2.0
        if self.drive_limit_V is not None and peak > self.drive_limit_V + 1e-12:
            raise ValueError(f"|offset| + Vpp/2 = {peak:g} V exceeds the drive limit "
                             f"{self.drive_limit_V:g} V")

    def set_frequency(self, freq_Hz: float) -> float:
        if not (0.0 < freq_Hz <= FREQ_MAX_HZ) or not math.isfinite(freq_Hz):
            raise ValueError(f"frequency {freq_Hz!r} Hz outside (0, {FREQ_MAX_HZ:g}]")
        return self._set_confirmed(f"FREQ {freq_Hz:.12g}", "FREQ?", freq_Hz)

    def set_amplitude(self, amplitude_Vpp: float) -> float:
        if not (amplitude_Vpp > 0.0) or not math.isfinite(amplitude_Vpp):
            raise ValueError(f"amplitude {amplitude_Vpp!r} Vpp must be positive and finite")
        self._check_drive(amplitude_Vpp, None)
        return self._set_confirmed(f"VOLT {amplitude_Vpp:.9g}", "VOLT?", amplitude_Vpp)

    def set_offset(self, offset_V: float) -> float:
        if not math.isfinite(offset_V):
            raise ValueError(f"offset {offset_V!r} V must be finite")
        self._check_drive(None, offset_V)
        return self._set_confirmed(f"VOLT:OFFS {offset_V:.9g}", "VOLT:OFFS?", offset_V)

    def set_output(self, on: bool) -> None:
        self.command("OUTP ON" if on else "OUTP OFF")
        if self.output_enabled() != on:
            raise ProtocolError(f"output did not switch {'on' if on else 'off'}")

    # ----------------------------------------------------------------- teardown
    def safe_off(self) -> None:
        """Output off, best effort: never raises, even on a dead link (logged instead).

        After an interrupted exchange the link is resynchronised first; if that fails,
        ``OUTP OFF`` is still sent, and the confirmation is what may fail."""
        try:
            if not self._in_step:
                try:
                    self.resync()
                except Exception as exc:  # noqa: BLE001 - the off command must still go out
                    log.error("safe_off: could not resynchronise %s (%s); sending OUTP OFF anyway",
                              self.url, exc)
            self._send("OUTP OFF" if self._in_step else "\nOUTP OFF")   # end a half-sent line
            if self.output_enabled():
                log.error("safe_off: %s still reports the output on", self.url)
        except Exception as exc:  # noqa: BLE001 - this runs on every exit path
            log.error("safe_off: could not confirm output off on %s: %s", self.url, exc)

    def close(self) -> None:
        try:
            sock = getattr(self._port, "_socket", None)
            if sock is not None:
                # pyserial's socket close sleeps 0.3 s "for quick reconnects"; skip that
                sock.close()
                self._port._socket = None
                self._port.is_open = False
            self._port.close()
        except Exception as exc:  # noqa: BLE001
            log.warning("closing %s: %s", self.url, exc)

    def __enter__(self) -> ScpiFunctionGenerator:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.safe_off()
        self.close()
