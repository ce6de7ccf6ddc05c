"""Replay an instrument's exact command/response exchange without hardware.

In the spirit of PyMeasure's ``expected_protocol``: the test lists what the driver must
send and what the instrument answers; any deviation fails the test, and so does an
exchange left unused.
"""

from __future__ import annotations

import socket
import threading
from contextlib import contextmanager


class ScriptedPort:
    """Stands in for a pyserial port: checks each written line, serves scripted replies."""

    def __init__(self, exchange: list[tuple[str, str | None]]) -> None:
        self.exchange = list(exchange)
        self.pending_reply = b""
        self.is_open = True

    def write(self, data: bytes) -> int:
        assert self.exchange, f"driver sent {data!r} after the script ended"
        expected, reply = self.exchange.pop(0)
        assert data == expected.encode("ascii") + b"\n", \
            f"driver sent {data!r}, script expects {expected!r}"
        if reply is not None:
            self.pending_reply += reply.encode("ascii") + b"\n"
        return len(data)

    def flush(self) -> None:
        pass

    def read_until(self, terminator: bytes = b"\n") -> bytes:
        end = self.pending_reply.find(terminator)
        assert end >= 0, "driver reads a reply the script does not provide"
        line, self.pending_reply = self.pending_reply[:end + 1], self.pending_reply[end + 1:]
        return line

    def close(self) -> None:
        self.is_open = False


@contextmanager
def expected_scpi_protocol(mocker, exchange: list[tuple[str, str | None]]):
    """Patch ``serial_for_url`` in the generator driver with a ScriptedPort."""
    port = ScriptedPort(exchange)
    mocker.patch("drivers._function_generator.serial.serial_for_url", return_value=port)
    yield port
    assert not port.exchange, f"exchange not used by the driver: {port.exchange}"
    assert not port.pending_reply, f"replies never read: {port.pending_reply!r}"


class ModbusTcpScript:
    """A loopback Modbus TCP peer answering scripted PDUs (hex) to expected request PDUs.

    The MBAP header (transaction id, protocol, length, unit) is checked for consistency
    and echoed; the PDUs must match exactly.
    """

    def __init__(self, exchange: list[tuple[str, str]], unit: int = 1) -> None:
        self.exchange = [(bytes.fromhex(a), bytes.fromhex(b)) for a, b in exchange]
        self.unit = unit
        self.errors: list[str] = []
        self._sock = socket.create_server(("127.0.0.1", 0))
        self.port = self._sock.getsockname()[1]
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        conn, _ = self._sock.accept()
        with conn:
            buffer = b""
            while self.exchange:
                data = conn.recv(4096)
                if not data:
                    return
                buffer += data
                while len(buffer) >= 6 and len(buffer) >= 6 + int.from_bytes(buffer[4:6], "big"):
                    length = int.from_bytes(buffer[4:6], "big")
                    frame, buffer = buffer[:6 + length], buffer[6 + length:]
                    tid, unit, pdu = frame[:2], frame[6], frame[7:]
                    expected, reply = self.exchange.pop(0)
                    if unit != self.unit or pdu != expected:
                        self.errors.append(f"got unit {unit} pdu {pdu.hex(' ')}, "
                                           f"expected unit {self.unit} pdu {expected.hex(' ')}")
                        return
                    conn.sendall(tid + b"\0\0" + (len(reply) + 1).to_bytes(2, "big")
                                 + bytes([unit]) + reply)

    def check(self) -> None:
        self._thread.join(timeout=2.0)
        self._sock.close()
        assert not self.errors, self.errors
        assert not self.exchange, f"exchange not used by the driver: {self.exchange}"
