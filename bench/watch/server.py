"""The watch page's HTTP server (standard library ``ThreadingHTTPServer``).

    GET  /                  the page (bench/watch/page.html); needs no token
    GET  /plotly.min.js     plotly's own bundle from the installed Python package (no CDN)
    GET  /api/state         the run as JSON (bench.watch.snapshot); needs ?token=
    GET  /api/stream        the same as server-sent events, pushed whenever the directory
                            changes; needs ?token=
    POST /api/stop          ask the run to stop safely; needs the header X-Stop-Token

Binds to 127.0.0.1 unless another host is given explicitly.  The token is random per
server (``secrets.token_urlsafe``), printed with the URL (``?token=...``) and compared in
constant time.  The page itself is answered without it, so opened from a link without the
token (or an earlier server's) it can say what is needed, while the run's data are refused
(403 with that message; decision record 0030).  Requests naming a foreign Host are refused
while bound to loopback (a web page elsewhere cannot reach the server by DNS rebinding).
"""

from __future__ import annotations

import hmac
import json
import logging
import math
import secrets
import threading
import time
import urllib.parse
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from ..storage import RunStatus
from . import stop
from .snapshot import RunReader

log = logging.getLogger(__name__)

PAGE = Path(__file__).with_name("page.html")
POLL_S = 0.25             # how often a stream looks at the directory
HEARTBEAT_S = 10.0        # keep-alive comment on a quiet stream
LOOPBACK_NAMES = {"127.0.0.1", "localhost", "::1", "[::1]"}
NO_TOKEN = ("this link has no token: open the link with ?token=... that `bench watch` or "
            "`bench run --watch` printed")
WRONG_TOKEN = ("this link's token is not this server's (the page was restarted?): open the link "
               "that `bench watch` or `bench run --watch` printed last")


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
        self.run_dir = Path(run_dir)
        self.reader = RunReader(self.run_dir)
        self.token = token or secrets.token_urlsafe(24)
        self.closing = threading.Event()
        self.streams = 0                  # open event streams (told goodbye on close)
        self._streams_lock = threading.Lock()
        self._plotly: bytes | None = None
        self._thread: threading.Thread | None = None
        super().__init__((host, port), _Handler)

    @property
    def loopback(self) -> bool:
        return self.server_address[0] in LOOPBACK_NAMES or self.server_address[0].startswith("127.")

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
        self._thread = threading.Thread(target=self.serve_forever, name="bench-watch", daemon=True)
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


class _Handler(BaseHTTPRequestHandler):
    server: WatchServer
    protocol_version = "HTTP/1.1"

    def log_message(self, fmt, *args):
        log.debug("%s %s", self.address_string(), fmt % args)

    # ------------------------------------------------------------------ helpers
    def _send(self, code: int, body: bytes, ctype: str, cache: bool = False) -> None:
        self.send_response(code)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "max-age=86400" if cache else "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.end_headers()
        self.wfile.write(body)

    def _send_json(self, code: int, obj) -> None:
        self._send(code, _json(obj), "application/json")

    def _token_problem(self, given: str) -> str | None:
        """Why ``given`` does not open the run's data (None: it does)."""
        if not given:
            return NO_TOKEN
        if not hmac.compare_digest(given.encode(), self.server.token.encode()):
            return WRONG_TOKEN
        return None

    def _host_ok(self) -> bool:
        if not self.server.loopback:
            return True
        host = (self.headers.get("Host") or "").strip()
        name = host.rsplit(":", 1)[0] if not host.endswith("]") else host
        return name.lower() in LOOPBACK_NAMES

    # ------------------------------------------------------------------ routes
    def do_GET(self):  # noqa: N802 - http.server's naming
        if not self._host_ok():
            return self._send_json(HTTPStatus.FORBIDDEN, {"error": "unexpected Host header"})
        path, _, query = self.path.partition("?")
        if path.startswith("/api/"):
            problem = self._token_problem(urllib.parse.parse_qs(query).get("token", [""])[0])
            if problem:
                return self._send_json(HTTPStatus.FORBIDDEN, {"error": problem})
        if path in ("/", "/index.html"):
            self._send(HTTPStatus.OK, PAGE.read_bytes(), "text/html; charset=utf-8")
        elif path == "/plotly.min.js":
            self._send(HTTPStatus.OK, self.server.plotly_js(), "text/javascript; charset=utf-8", cache=True)
        elif path == "/api/state":
            self._send_json(HTTPStatus.OK, self.server.reader.snapshot())
        elif path == "/api/stream":
            self._stream()
        else:
            self._send_json(HTTPStatus.NOT_FOUND, {"error": f"no such page: {path}"})

    def do_POST(self):  # noqa: N802
        length = int(self.headers.get("Content-Length") or 0)
        if length:
            self.rfile.read(min(length, 4096))
        if not self._host_ok():
            return self._send_json(HTTPStatus.FORBIDDEN, {"error": "unexpected Host header"})
        if self.path.split("?", 1)[0] != "/api/stop":
            return self._send_json(HTTPStatus.NOT_FOUND, {"error": f"no such action: {self.path}"})
        given = self.headers.get("X-Stop-Token", "")
        if not hmac.compare_digest(given.encode(), self.server.token.encode()):
            log.warning("refused a stop request from %s: %s token", self.address_string(),
                        "wrong" if given else "no")
            return self._send_json(HTTPStatus.FORBIDDEN, {"error": "a valid stop token is needed "
                                                          "(the one printed with the page's URL)"})
        state = self.server.reader.snapshot()
        if state.get("status") != RunStatus.RUNNING or state.get("process_gone"):
            shown = "process gone" if state.get("process_gone") else state.get("status")
            return self._send_json(HTTPStatus.CONFLICT, {"error": f"the run is not running ({shown})"})
        try:
            req = stop.request_stop(self.server.run_dir, by=f"the watch page ({self.client_address[0]})")
        except OSError as e:
            log.error("could not write the stop request into %s: %s", self.server.run_dir, e)
            return self._send_json(HTTPStatus.INTERNAL_SERVER_ERROR,
                                   {"error": f"could not write the stop request: {e}; use Ctrl-C in the run's terminal"})
        self._send_json(HTTPStatus.ACCEPTED, {"requested": req})

    def _stream(self) -> None:
        self.send_response(HTTPStatus.OK)
        self.send_header("Content-Type", "text/event-stream")
        self.send_header("Cache-Control", "no-store")
        self.send_header("Connection", "close")
        self.end_headers()
        self.close_connection = True
        reader, last, beat = self.server.reader, None, time.monotonic()
        with self.server._streams_lock:
            self.server.streams += 1
        try:
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
        except (BrokenPipeError, ConnectionResetError):
            return
        finally:
            with self.server._streams_lock:
                self.server.streams -= 1


def serve(run_dir: Path, host: str = "127.0.0.1", port: int = 0) -> WatchServer:
    """A started server for ``run_dir`` (call ``close()`` when done)."""
    return WatchServer(run_dir, host, port).start()
