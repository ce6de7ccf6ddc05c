"""The watch page's HTTP server (standard library ``ThreadingHTTPServer``).

    GET  /                  the page (bench/watch/page.html); needs no token
    GET  /plotly.min.js     plotly's own bundle from the installed Python package (no CDN)
    GET  /api/state         the run as JSON (bench.watch.snapshot); needs ?token=
    GET  /api/stream        the same as server-sent events, pushed whenever the directory
                            changes; needs ?token=
    POST /api/stop          ask the run to stop safely; needs the header X-Stop-Token

Binds to 127.0.0.1 unless another host is given explicitly (``::1`` too; any address off
loopback is served with a warning).  The token is random per server
(``secrets.token_urlsafe``), printed with the URL (``?token=...``) and compared in
constant time.  The page itself is answered without it, so opened from a link without the
token (or an earlier server's) it can say what is needed, while the run's data are refused
(403 with that message; decision record 0030).  Requests naming a foreign Host are refused
while bound to loopback (a web page elsewhere cannot reach the server by DNS rebinding).

Bounds (docs/decisions/0028-hardening.md): at most :data:`MAX_CONNECTIONS` connections are
served at once, :data:`STOP_RESERVE` more for a stop request only (anything else 503;
one more is closed unanswered), and :data:`MAX_STREAMS` of them event streams (503
beyond); a client silent for :data:`CLIENT_TIMEOUT_S` in the middle of a request, or
between requests, is dropped, and each whole request must arrive within
:data:`REQUEST_DEADLINE_S` however it trickles in (decision record 0041), so slow clients
cannot lock the stop control out; a client that goes away is not a traceback; a request body must have a valid
``Content-Length`` (400 otherwise) of at most :data:`MAX_BODY` bytes (413), and is read
whole, never taken for a next request.  Every answer carries a Content-Security-Policy
(scripts from this server only, no framing), ``X-Frame-Options: DENY`` and
``Referrer-Policy: no-referrer`` (the page's URL holds the token).
"""

from __future__ import annotations

import hmac
import ipaddress
import json
import logging
import math
import re
import secrets
import socket
import sys
import threading
import time
import urllib.parse
from enum import StrEnum
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from ..storage import RunStatus
from ..words import page, say, terminal_run
from . import stop
from .snapshot import RunReader

log = logging.getLogger(__name__)

PAGE = Path(__file__).with_name("page.html")
SCRIPT = Path(__file__).with_name("page.js")
MAX_CONNECTIONS = 32      # handler threads at once
MAX_STREAMS = 8           # of them, event streams
STOP_RESERVE = 4          # connections beyond MAX_CONNECTIONS, admitted for a stop request only
CLIENT_TIMEOUT_S = 10.0   # for each read of a request (headers, body) and between requests
REQUEST_DEADLINE_S = 10.0  # the whole request (line, headers, body) or the wait for the next one
STOP_DEADLINE_S = 3.0     # the same on a reserved connection
MAX_BODY = 4096           # a stop request has no body worth more
SECURITY_HEADERS = (
    # plotly sets inline styles; nothing else is needed from anywhere but this server
    ("Content-Security-Policy", "default-src 'none'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
                                "img-src 'self' data:; connect-src 'self'; frame-ancestors 'none'; "
                                "base-uri 'none'; form-action 'none'"),
    ("X-Frame-Options", "DENY"),
    ("Referrer-Policy", "no-referrer"),
    ("X-Content-Type-Options", "nosniff"),
)
POLL_S = 0.25             # how often a stream looks at the directory
HEARTBEAT_S = 10.0        # keep-alive comment on a quiet stream


def is_loopback(host: str) -> bool:
    """127.0.0.0/8, ::1 (also as [::1] or ::ffff:127.x) and localhost."""
    host = host.strip("[]").lower()
    if host == "localhost":
        return True
    try:
        ip = ipaddress.ip_address(host)
    except ValueError:
        return False
    mapped = getattr(ip, "ipv4_mapped", None)
    return (mapped or ip).is_loopback


class PageError(StrEnum):
    """Why the server answers a request with an error (the JSON's ``error``; its words:
    :data:`bench.words.page.ERROR`)."""

    NO_TOKEN = "no_token"
    WRONG_TOKEN = "wrong_token"
    BUSY = "busy"                           # connections: every ordinary one taken
    CHUNKED = "chunked"                     # Transfer-Encoding
    BAD_LENGTH = "bad_length"               # given: the Content-Length headers
    TOO_LARGE = "too_large"                 # length, most (bytes)
    HOST = "host"                           # an unexpected Host header
    NO_PAGE = "no_page"                     # path
    NO_ACTION = "no_action"                 # path
    STOP_TOKEN = "stop_token"               # a stop without a valid token
    NOT_RUNNING = "not_running"             # status, gone (the run's process)
    STOP_UNWRITTEN = "stop_unwritten"       # error
    STREAMS = "streams"                     # most: live pages


class ServerLine(StrEnum):
    """What the watch page's server logs (:data:`bench.words.terminal_run.SERVER`)."""

    OFF_LOOPBACK = "off_loopback"           # host
    FULL = "full"                           # connections, client
    LATE = "late"                           # a request not read within its deadline
    WENT_AWAY = "went_away"                 # client, error
    ERROR = "error"                         # client, kind, error
    STOP_REFUSED = "stop_refused"           # client, given (a wrong token, or none)
    STOP_UNWRITTEN = "stop_unwritten"       # path, error


def _error(code: PageError, **fields) -> dict:
    return {"error": say(page.ERROR, code, fields)}


def _logged(code: ServerLine, **fields) -> str:
    return say(terminal_run.SERVER, code, fields)


def _plotly_js() -> bytes:
    """plotly.js as shipped inside the plotly Python package."""
    import plotly
    bundled = Path(plotly.__file__).parent / "package_data" / "plotly.min.js"
    if bundled.is_file():
        return bundled.read_bytes()
    from plotly.offline import get_plotlyjs
    return get_plotlyjs().encode()


def _finite(obj):
    """NaN and infinities as null: the browser's JSON.parse rejects them."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def _json(obj) -> bytes:
    return json.dumps(_finite(obj), separators=(",", ":")).encode()


class WatchServer(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, run_dir: Path, host: str = "127.0.0.1", port: int = 0, token: str | None = None):
        host = host.strip("[]")                       # "[::1]" as in a URL
        if ":" in host:
            self.address_family = socket.AF_INET6
        self.run_dir = Path(run_dir)
        self.reader = RunReader(self.run_dir)
        self.token = token or secrets.token_urlsafe(24)
        self.closing = threading.Event()
        self.streams = 0                  # open event streams (told goodbye on close)
        self._streams_lock = threading.Lock()
        self._plotly: bytes | None = None
        self._thread: threading.Thread | None = None
        self._slots = threading.BoundedSemaphore(MAX_CONNECTIONS)
        self._reserve = threading.BoundedSemaphore(STOP_RESERVE)
        self._reserved: set = set()       # connections admitted on the stop reserve
        self.connections = 0              # served now (each holds a slot)
        self._deadlines: dict = {}        # connection -> monotonic time its request must be read by
        self._deadlines_lock = threading.Lock()
        self._watchdog = threading.Thread(target=self._enforce_deadlines, name="bench-watch-deadlines", daemon=True)
        self._watchdog.start()
        super().__init__((host, port), _Handler)
        if not self.loopback:
            log.warning(_logged(ServerLine.OFF_LOOPBACK, host=self.server_address[0]))

    # one thread per connection, at most MAX_CONNECTIONS of them, and STOP_RESERVE more that
    # serve a stop request only (so slow clients filling the others cannot lock the stop out)
    def process_request(self, request, client_address):
        if self._slots.acquire(blocking=False):
            reserved = False
        elif self._reserve.acquire(blocking=False):
            reserved = True
            self._reserved.add(request)
        else:
            log.warning(_logged(ServerLine.FULL, connections=MAX_CONNECTIONS + STOP_RESERVE, client=client_address[0]))
            self.shutdown_request(request)
            return
        with self._streams_lock:
            self.connections += 1
        try:
            super().process_request(request, client_address)
        except BaseException:
            self._release(request, reserved)
            raise

    def process_request_thread(self, request, client_address):
        reserved = request in self._reserved
        try:
            super().process_request_thread(request, client_address)
        finally:
            self._release(request, reserved)

    def _release(self, request, reserved: bool) -> None:
        with self._streams_lock:
            self.connections -= 1
        self.disarm(request)
        if reserved:
            self._reserved.discard(request)
            self._reserve.release()
        else:
            self._slots.release()

    def is_reserved(self, request) -> bool:
        return request in self._reserved

    # a deadline for each whole request: a client trickling a header line every few seconds
    # (each read within CLIENT_TIMEOUT_S) is cut off all the same
    def arm(self, request, seconds: float) -> None:
        with self._deadlines_lock:
            self._deadlines[request] = time.monotonic() + seconds

    def disarm(self, request) -> None:
        with self._deadlines_lock:
            self._deadlines.pop(request, None)

    def _enforce_deadlines(self) -> None:
        while not self.closing.wait(0.1):
            now = time.monotonic()
            with self._deadlines_lock:
                late = [r for r, t in self._deadlines.items() if t < now]
                for r in late:
                    del self._deadlines[r]
            for r in late:
                try:
                    r.shutdown(socket.SHUT_RDWR)       # the handler's read ends; it closes
                except OSError:
                    pass
                log.debug(_logged(ServerLine.LATE))

    def handle_error(self, request, client_address):
        """A client that went away (a closed tab, a reset) is routine: no traceback on the
        terminal; anything else is one warning line (-vv: the traceback)."""
        exc = sys.exc_info()[1]
        if isinstance(exc, (ConnectionError, TimeoutError)):
            log.debug(_logged(ServerLine.WENT_AWAY, client=client_address[0], error=exc))
            return
        log.warning(_logged(ServerLine.ERROR, client=client_address[0], kind=type(exc).__name__, error=exc),
                    exc_info=log.isEnabledFor(logging.DEBUG))

    @property
    def loopback(self) -> bool:
        return is_loopback(self.server_address[0])

    @property
    def url(self) -> str:
        host, port = self.server_address[:2]
        shown = f"[{host}]" if ":" in host else host
        return f"http://{shown}:{port}/?token={self.token}"

    def plotly_js(self) -> bytes:
        if self._plotly is None:
            self._plotly = _plotly_js()
        return self._plotly

    def start(self) -> WatchServer:
        """Serve from a daemon thread (beside a run in this process)."""
        self._thread = threading.Thread(target=self.serve_forever, args=(0.05,), name="bench-watch", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Streams send the final state and say goodbye; then the socket closes."""
        self.closing.set()
        deadline = time.monotonic() + 2.0
        while self.streams and time.monotonic() < deadline:
            time.sleep(0.02)
        if self._thread is not None:
            self.shutdown()
            self._thread.join(timeout=5)
        self.server_close()

    def __exit__(self, *exc) -> None:
        self.close()


_DIGITS = re.compile(r"[0-9]{1,12}")


class _Handler(BaseHTTPRequestHandler):
    server: WatchServer
    protocol_version = "HTTP/1.1"
    timeout = CLIENT_TIMEOUT_S          # socket timeout: a slow or silent client is dropped

    def log_message(self, fmt, *args):
        log.debug("%s %s", self.address_string(), fmt % args)

    def handle_one_request(self):
        reserved = self.server.is_reserved(self.request)
        self.server.arm(self.request, STOP_DEADLINE_S if reserved else REQUEST_DEADLINE_S)
        try:
            super().handle_one_request()
        finally:
            self.server.disarm(self.request)

    def _only_stop(self) -> bool:
        """On a connection of the stop reserve, anything but a stop request is refused (503)."""
        if not self.server.is_reserved(self.request) or (
                self.command == "POST" and self.path.split("?", 1)[0] == "/api/stop"):
            return False
        self.close_connection = True
        self._send_json(HTTPStatus.SERVICE_UNAVAILABLE, _error(PageError.BUSY, connections=MAX_CONNECTIONS))
        return True

    # ------------------------------------------------------------------ helpers
    def _send(self, code: int, body: bytes, ctype: str, cache: bool = False) -> None:
        self.send_response(code)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "max-age=86400" if cache else "no-store")
        self._security_headers()
        self.end_headers()
        self.wfile.write(body)

    def _security_headers(self) -> None:
        for name, value in SECURITY_HEADERS:
            self.send_header(name, value)

    def _body_ok(self) -> bool:
        """Read the request's body whole (so it is never taken for a next request); answer
        400 for a bad Content-Length, 413 for one over MAX_BODY, and close the connection."""
        given = self.headers.get_all("Content-Length") or []
        if self.headers.get("Transfer-Encoding"):
            self.close_connection = True
            self._send_json(HTTPStatus.NOT_IMPLEMENTED, _error(PageError.CHUNKED))
            return False
        if not given:
            self.server.disarm(self.request)
            return True
        if len(set(given)) != 1 or not _DIGITS.fullmatch(given[0].strip()):
            self.close_connection = True
            self._send_json(HTTPStatus.BAD_REQUEST, _error(PageError.BAD_LENGTH, given=given))
            return False
        length = int(given[0])
        if length > MAX_BODY:
            self.close_connection = True
            self._send_json(HTTPStatus.REQUEST_ENTITY_TOO_LARGE, _error(PageError.TOO_LARGE, length=length, most=MAX_BODY))
            return False
        if length and len(self.rfile.read(length)) < length:
            self.close_connection = True       # the client went away mid-body
            return False
        self.server.disarm(self.request)       # the request is read: no deadline for the answer
        return True

    def _send_json(self, code: int, obj) -> None:
        self._send(code, _json(obj), "application/json")

    def _token_problem(self, given: str) -> PageError | None:
        """Why ``given`` does not open the run's data (None: it does)."""
        if not given:
            return PageError.NO_TOKEN
        if not hmac.compare_digest(given.encode(), self.server.token.encode()):
            return PageError.WRONG_TOKEN
        return None

    def _host_ok(self) -> bool:
        if not self.server.loopback:
            return True
        host = (self.headers.get("Host") or "").strip()
        name = host.rsplit(":", 1)[0] if not host.endswith("]") else host
        return is_loopback(name)

    # ------------------------------------------------------------------ routes
    def do_GET(self):  # noqa: N802 - http.server's naming
        if not self._body_ok() or self._only_stop():
            return
        if not self._host_ok():
            return self._send_json(HTTPStatus.FORBIDDEN, _error(PageError.HOST))
        path, _, query = self.path.partition("?")
        if path.startswith("/api/"):
            problem = self._token_problem(urllib.parse.parse_qs(query).get("token", [""])[0])
            if problem:
                return self._send_json(HTTPStatus.FORBIDDEN, _error(problem))
        if path in ("/", "/index.html"):
            self._send(HTTPStatus.OK, PAGE.read_bytes(), "text/html; charset=utf-8")
        elif path == "/page.js":
            self._send(HTTPStatus.OK, SCRIPT.read_bytes(), "text/javascript; charset=utf-8")
        elif path == "/plotly.min.js":
            self._send(HTTPStatus.OK, self.server.plotly_js(), "text/javascript; charset=utf-8", cache=True)
        elif path == "/api/state":
            self._send_json(HTTPStatus.OK, self.server.reader.snapshot())
        elif path == "/api/stream":
            self._stream()
        else:
            self._send_json(HTTPStatus.NOT_FOUND, _error(PageError.NO_PAGE, path=path))

    def do_POST(self):  # noqa: N802
        if not self._body_ok() or self._only_stop():
            return
        if not self._host_ok():
            return self._send_json(HTTPStatus.FORBIDDEN, _error(PageError.HOST))
        if self.path.split("?", 1)[0] != "/api/stop":
            return self._send_json(HTTPStatus.NOT_FOUND, _error(PageError.NO_ACTION, path=self.path))
        given = self.headers.get("X-Stop-Token", "")
        if not hmac.compare_digest(given.encode(), self.server.token.encode()):
            log.warning(_logged(ServerLine.STOP_REFUSED, client=self.address_string(), given=bool(given)))
            return self._send_json(HTTPStatus.FORBIDDEN, _error(PageError.STOP_TOKEN))
        state = self.server.reader.snapshot()
        if state.get("status") != RunStatus.RUNNING or state.get("process_gone"):
            return self._send_json(HTTPStatus.CONFLICT, _error(PageError.NOT_RUNNING, status=state.get("status"),
                                                               gone=bool(state.get("process_gone"))))
        try:
            req = stop.request_stop(self.server.run_dir,
                                    by=say(terminal_run.STOP, stop.StopLine.BY_PAGE, dict(client=self.client_address[0])))
        except OSError as e:
            log.error(_logged(ServerLine.STOP_UNWRITTEN, path=self.server.run_dir, error=e))
            return self._send_json(HTTPStatus.INTERNAL_SERVER_ERROR, _error(PageError.STOP_UNWRITTEN, error=e))
        self._send_json(HTTPStatus.ACCEPTED, {"requested": req})

    def _stream(self) -> None:
        with self.server._streams_lock:
            full = self.server.streams >= MAX_STREAMS
            if not full:
                self.server.streams += 1
        if full:
            self.close_connection = True
            return self._send_json(HTTPStatus.SERVICE_UNAVAILABLE, _error(PageError.STREAMS, most=MAX_STREAMS))
        try:
            self.send_response(HTTPStatus.OK)
            self.send_header("Content-Type", "text/event-stream")
            self.send_header("Cache-Control", "no-store")
            self.send_header("Connection", "close")
            self._security_headers()
            self.end_headers()
            self.close_connection = True
            reader, last, beat = self.server.reader, None, time.monotonic()
            self.wfile.write(b"retry: 2000\n\n")
            while True:
                closing = self.server.closing.is_set()
                sig = reader.signature()
                if sig != last or closing:
                    last = sig
                    self.wfile.write(b"data: " + _json(reader.snapshot()) + b"\n\n")
                    beat = time.monotonic()
                elif time.monotonic() - beat > HEARTBEAT_S:
                    self.wfile.write(b": still here\n\n")
                    beat = time.monotonic()
                self.wfile.flush()
                if closing:
                    self.wfile.write(b"event: bye\ndata: {}\n\n")
                    self.wfile.flush()
                    return
                self.server.closing.wait(POLL_S)
        except (BrokenPipeError, ConnectionResetError, TimeoutError):
            return
        finally:
            with self.server._streams_lock:
                self.server.streams -= 1


def serve(run_dir: Path, host: str = "127.0.0.1", port: int = 0) -> WatchServer:
    """A started server for ``run_dir`` (call ``close()`` when done)."""
    return WatchServer(run_dir, host, port).start()
