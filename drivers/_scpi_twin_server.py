"""Transports for the SCPI twin: a raw TCP socket server and a serial-port server.

Both feed LF-terminated lines to one shared :class:`ScpiGeneratorModel` (the instrument
has a single error queue whatever port a command came from) and keep serving after bad
input. A query left without its terminator when the peer closes (TCP) or goes quiet
(serial, :data:`SERIAL_IDLE_S`) is reported as -420.

Bounds (docs/decisions/0028-hardening.md): a program message longer than
:data:`MAX_LINE_BYTES` is discarded unread (-100); at most :data:`MAX_CLIENTS` TCP clients
are served at once (one more is accepted and closed at once); a client silent for
:data:`CLIENT_IDLE_S` or not reading its replies for as long is dropped.
"""

from __future__ import annotations

import logging
import socket
import threading

import serial

from ._scpi_twin_model import ScpiGeneratorModel

log = logging.getLogger(__name__)

SERIAL_IDLE_S = 1.0
MAX_LINE_BYTES = 4096
MAX_CLIENTS = 16
CLIENT_IDLE_S = 300.0


class _LineAssembler:
    """Bytes in, complete lines out; oversize garbage is dropped, not buffered forever."""

    def __init__(self, model: ScpiGeneratorModel) -> None:
        self.model = model
        self.buffer = bytearray()

    def feed(self, data: bytes) -> list[bytes]:
        self.buffer += data
        responses = []
        while (end := self.buffer.find(b"\n")) >= 0:
            line = bytes(self.buffer[:end]).rstrip(b"\r")
            del self.buffer[:end + 1]
            if len(line) > MAX_LINE_BYTES:      # completed across reads: still too long
                self.model.push_error(-100, "program message too long, discarded")
                continue
            response = self.model.execute(line.decode("ascii", errors="replace"))
            if response is not None:
                responses.append(response.encode("ascii", errors="replace") + b"\n")
        if len(self.buffer) > MAX_LINE_BYTES:
            self.model.push_error(-100, "program message too long, discarded")
            self.buffer.clear()
        return responses

    def flush_unterminated(self) -> None:
        if b"?" in self.buffer:
            self.model.unterminated_query(self.buffer.decode("ascii", errors="replace"))
        self.buffer.clear()


class ScpiTcpServer:
    """Raw SCPI socket (like port 5025 on the instrument), one thread per connection."""

    def __init__(self, model: ScpiGeneratorModel, host: str = "127.0.0.1", port: int = 0, *,
                 max_clients: int = MAX_CLIENTS, idle_s: float = CLIENT_IDLE_S) -> None:
        self.model = model
        self.max_clients, self.idle_s = max_clients, idle_s
        self._sock = socket.create_server((host, port))
        self.host, self.port = self._sock.getsockname()[:2]
        self._stop = threading.Event()
        self._clients: set[socket.socket] = set()
        self._clients_lock = threading.Lock()
        self._thread = threading.Thread(target=self._accept_loop, name="scpi-twin-tcp",
                                        daemon=True)
        self._thread.start()
        log.info("SCPI twin listening on %s", self.url)

    @property
    def url(self) -> str:
        return f"socket://{self.host}:{self.port}"

    @property
    def visa_resource(self) -> str:
        return f"TCPIP0::{self.host}::{self.port}::SOCKET"

    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                conn, peer = self._sock.accept()
            except OSError:
                return
            with self._clients_lock:
                full = len(self._clients) >= self.max_clients
                if not full:
                    self._clients.add(conn)
            if full:
                log.warning("SCPI twin: %d clients already; refused %s", self.max_clients, peer)
                conn.close()
                continue
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn.settimeout(self.idle_s)       # a silent or non-reading client is dropped
            threading.Thread(target=self._serve, args=(conn, peer), daemon=True,
                             name=f"scpi-twin-conn-{peer[1]}").start()

    def _serve(self, conn: socket.socket, peer: tuple) -> None:
        assembler = _LineAssembler(self.model)
        log.debug("SCPI twin: connection from %s", peer)
        try:
            while True:
                data = conn.recv(4096)
                if not data:
                    assembler.flush_unterminated()
                    return
                for response in assembler.feed(data):
                    conn.sendall(response)
        except OSError as exc:
            log.debug("SCPI twin: connection %s ended: %s", peer, exc)
        finally:
            with self._clients_lock:
                self._clients.discard(conn)
            conn.close()

    def drop_connections(self) -> None:
        """Close every client connection (fault injection: the instrument reboots)."""
        with self._clients_lock:
            clients = list(self._clients)
        for conn in clients:
            try:
                conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def close(self) -> None:
        self._stop.set()
        try:
            self._sock.shutdown(socket.SHUT_RDWR)  # wakes the thread blocked in accept()
        except OSError:
            pass
        self._sock.close()
        self.drop_connections()
        self._thread.join(timeout=2.0)


class ScpiSerialServer:
    """The SCPI twin on a serial port (one end of a socat pty pair in tests)."""

    def __init__(self, model: ScpiGeneratorModel, port: str, baudrate: int = 115200,
                 idle_s: float = SERIAL_IDLE_S) -> None:
        self.model = model
        self.idle_s = idle_s
        self.port = port
        self._serial = serial.Serial(port, baudrate=baudrate, timeout=0.05)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="scpi-twin-serial", daemon=True)
        self._thread.start()
        log.info("SCPI twin serving on %s", port)

    def _loop(self) -> None:
        assembler = _LineAssembler(self.model)
        idle = 0.0
        while not self._stop.is_set():
            try:
                data = self._serial.read(self._serial.in_waiting or 1)
            except (serial.SerialException, OSError, TypeError) as exc:
                if not self._stop.is_set():
                    log.warning("SCPI twin serial port %s failed: %s", self.port, exc)
                return
            if not data:
                idle += 0.05
                if assembler.buffer and idle >= self.idle_s:
                    assembler.flush_unterminated()
                continue
            idle = 0.0
            for response in assembler.feed(data):
                try:
                    self._serial.write(response)
                except (serial.SerialException, OSError) as exc:
                    log.warning("SCPI twin serial write failed: %s", exc)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._serial.close()
