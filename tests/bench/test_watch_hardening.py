"""The watch server under hostile or careless clients, on loopback: bad and oversized
bodies, slow clients, too many connections or streams, markup in the run's data, and the
headers that keep the page from being framed or leaking its token; IPv6 loopback."""

from __future__ import annotations

import json
import logging
import re
import shutil
import socket
import struct
import threading
import time
import urllib.request
from unittest.mock import PropertyMock

import pytest

from bench.storage import RunStore
from bench.watch import WatchServer, serve
from bench.watch import server as watch_server
from bench.watch.server import is_loopback
from bench.watch.stop import STOP_FILE

from .chromium import CHROMIUM, Browser
from .test_watch import listening_addresses

pytestmark = pytest.mark.timeout(120)


def exchange(server: WatchServer, raw: bytes, timeout: float = 5.0) -> bytes:
    """Send raw bytes; everything the server answers until it closes the connection."""
    with socket.create_connection(server.server_address[:2], timeout=timeout) as s:
        s.sendall(raw)
        out = b""
        while chunk := s.recv(65536):
            out += chunk
    return out


def post(path: str, length: str, body: bytes = b"", close: bool = True) -> bytes:
    head = (f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: {length}\r\n"
            + ("Connection: close\r\n" if close else "") + "\r\n")
    return head.encode() + body


def statuses(reply: bytes) -> list[int]:
    return [int(code) for code in re.findall(rb"HTTP/1\.[01] (\d{3}) ", reply)]


@pytest.mark.parametrize("length", ["-1", "abc", "1e3", " 12x", "99999999999999999999"])
def test_a_bad_content_length_is_answered_400_and_the_connection_closed(small_run, length):
    with serve(small_run.path) as server:
        t = time.monotonic()
        reply = exchange(server, post("/api/stop", length, close=False))
        assert statuses(reply) == [400], reply[:200]
        assert b"bad Content-Length" in reply
        assert time.monotonic() - t < 4                  # not held until a timeout


def test_a_body_over_the_limit_is_413_and_never_read_as_a_request(small_run):
    smuggled = b"GET /api/state HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
    big = smuggled + b"x" * (watch_server.MAX_BODY + 100 - len(smuggled))
    with serve(small_run.path) as server:
        reply = exchange(server, post("/api/stop", str(len(big)), big, close=False))
        assert statuses(reply) == [413] and b'"status"' not in reply
        # a body within the limit is read whole: the next request is the one sent next
        small = smuggled + b"y" * 100
        then = b"GET /nothing-here HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
        reply = exchange(server, post("/api/stop", str(len(small)), small, close=False) + then)
        assert statuses(reply) == [403, 404] and b'"status"' not in reply
    assert not (small_run.path / STOP_FILE).exists()


def test_a_silent_client_is_dropped(small_run, monkeypatch):
    monkeypatch.setattr(watch_server._Handler, "timeout", 0.3)
    with serve(small_run.path) as server:
        for raw in (b"", b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n"):     # nothing; headers unfinished
            t = time.monotonic()
            assert exchange(server, raw, timeout=10) == b""
            assert time.monotonic() - t < 5


def wait_until(predicate, timeout_s: float, what: str):
    deadline = time.monotonic() + timeout_s
    while not (value := predicate()):
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)
    return value


def test_connections_and_streams_are_capped(small_run, monkeypatch):
    monkeypatch.setattr(watch_server, "MAX_CONNECTIONS", 3)
    monkeypatch.setattr(watch_server, "MAX_STREAMS", 2)
    with serve(small_run.path) as server:
        addr = server.server_address[:2]
        streams = []
        for _ in range(2):
            s = socket.create_connection(addr, timeout=5)
            s.sendall(f"GET /api/stream?token={server.token} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n".encode())
            assert s.recv(100).startswith(b"HTTP/1.1 200")
            streams.append(s)
        wait_until(lambda: server.streams == 2, 5, "two streams")
        third = exchange(server, f"GET /api/stream?token={server.token} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n".encode())
        assert statuses(third) == [503]
        wait_until(lambda: server.connections == 2, 5, "the refused stream's connection to end")
        idle = socket.create_connection(addr, timeout=5)       # the third connection: held
        wait_until(lambda: server.connections == 3, 5, "the third connection served")
        # a fourth: on the stop reserve, which answers nothing but a stop
        assert statuses(exchange(server, b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")) == [503]
        # its handler gives the reserve slot back just after the client sees the close
        wait_until(lambda: server.connections == 3, 5, "the refused request's reserve slot back")
        reserve = [socket.create_connection(addr, timeout=5) for _ in range(watch_server.STOP_RESERVE)]
        wait_until(lambda: server.connections == 3 + watch_server.STOP_RESERVE, 5, "the reserve full")
        assert exchange(server, b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n") == b""   # beyond it: closed
        for s in reserve:
            s.close()
        idle.close()
        for s in streams:
            s.close()
        ok = wait_until(lambda: statuses(exchange(server, f"GET /api/state?token={server.token} HTTP/1.1\r\n"
                                                  "Host: 127.0.0.1\r\nConnection: close\r\n\r\n".encode())) == [200],
                        10, "a free slot")
        assert ok


def test_every_answer_carries_the_security_headers(small_run):
    with serve(small_run.path) as server:
        base = server.url.split("?")[0]
        for path in ("", "page.js", "api/state", "nothing-here"):
            try:
                r = urllib.request.urlopen(base + path, timeout=5)
            except urllib.error.HTTPError as e:
                r = e
            csp = r.headers["Content-Security-Policy"]
            assert "script-src 'self'" in csp and "frame-ancestors 'none'" in csp and "unsafe-eval" not in csp
            assert r.headers["X-Frame-Options"] == "DENY"
            assert r.headers["Referrer-Policy"] == "no-referrer"


def test_loopback_addresses_are_recognised():
    assert all(map(is_loopback, ["127.0.0.1", "127.3.2.1", "::1", "[::1]", "localhost", "::ffff:127.0.0.1"]))
    assert not any(map(is_loopback, ["0.0.0.0", "::", "192.0.2.1", "10.0.0.1", "example.org", "::ffff:10.0.0.1"]))


def test_a_server_off_loopback_warns(small_run, mocker, caplog):
    with caplog.at_level(logging.WARNING, logger="bench.watch.server"):
        serve(small_run.path).close()                          # loopback: quiet
        assert not caplog.records
        mocker.patch.object(WatchServer, "loopback", new_callable=PropertyMock, return_value=False)
        WatchServer(small_run.path).server_close()             # as if bound elsewhere
    assert "off loopback" in caplog.text


def ipv6_loopback() -> bool:
    try:
        with socket.socket(socket.AF_INET6) as s:
            s.bind(("::1", 0))
        return True
    except OSError:
        return False


@pytest.mark.skipif(not ipv6_loopback(), reason="no IPv6 loopback on this machine")
def test_ipv6_loopback_is_served(small_run, caplog):
    with caplog.at_level(logging.WARNING, logger="bench.watch.server"):
        with serve(small_run.path, host="::1") as server:
            port = server.server_address[1]
            assert server.url.startswith(f"http://[::1]:{port}/?token=")
            assert listening_addresses(port) == {"00000000000000000000000001000000"}
            with urllib.request.urlopen(server.url.split("?")[0] + "api/state?token=" + server.token, timeout=5) as r:
                assert json.loads(r.read())["status"] == "completed"
    assert "off loopback" not in caplog.text


MARKUP = '<img src=x onerror="window.__pwned=1"><b id=bold>'
COLLECT_CSP = ("window.__csp = []; document.addEventListener('securitypolicyviolation',"
               " (e) => window.__csp.push(e.violatedDirective + ' ' + e.blockedURI));")


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (make setup)")
def test_markup_in_the_run_s_data_is_shown_as_text_under_the_csp(small_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run)
    store = RunStore(run)
    last = store.step_files()[-1].stem
    result = store.verify_step(last)
    result.update(control_iterations=MARKUP, direction=MARKUP)
    store.write_step(last, result, store.raw(last))            # checksums recomputed: read as good
    store.event("note", detail=MARKUP)
    with serve(run) as server, Browser() as browser:
        browser.send("Page.addScriptToEvaluateOnNewDocument", source=COLLECT_CSP)
        browser.goto(server.url)
        browser.wait_for("document.getElementById('events').textContent.includes('onerror')", 30, "the events")
        assert "window.__pwned=1" in browser.js("document.getElementById('current').textContent")
        assert browser.js("document.querySelectorAll('#current img, #events img, #bold').length") == 0
        assert browser.js("window.__pwned === undefined")
        assert browser.js("document.getElementById('compliance').data.length") >= 2    # plotly runs
        assert browser.js("window.__csp") == []                # nothing the page needs is blocked


class Trickler:
    """Clients that each send a request line, then one header line every ``every_s``
    seconds, never finishing (issue 24, item 10: 32 of them kept the stop out)."""

    def __init__(self, server: WatchServer, n: int, every_s: float = 0.5):
        self.socks = []
        for _ in range(n):
            s = socket.create_connection(server.server_address[:2], timeout=5)
            s.sendall(b"GET / HTTP/1.1\r\n")
            self.socks.append(s)
        self.stop = threading.Event()
        self.dropped = 0
        self.thread = threading.Thread(target=self._run, args=(every_s,), daemon=True)
        self.thread.start()

    def _run(self, every_s: float) -> None:
        i = 0
        while not self.stop.wait(every_s):
            i += 1
            for s in list(self.socks):
                try:
                    s.sendall(f"X-Slow-{i}: {i}\r\n".encode())
                except OSError:
                    self.socks.remove(s)
                    self.dropped += 1

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        for s in self.socks:
            s.close()


def running_copy(small_run, tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "run.json").write_text(json.dumps(dict(small_run.metadata, status="running")))   # pid: this process
    return run


def test_the_stop_gets_through_while_32_clients_trickle_headers(small_run, tmp_path, monkeypatch):
    monkeypatch.setattr(watch_server, "REQUEST_DEADLINE_S", 6.0)     # 10 s in use; longer than connecting 34
    run = running_copy(small_run, tmp_path)
    with serve(run) as server:
        slow = Trickler(server, watch_server.MAX_CONNECTIONS + 2)        # every slot and two of the reserve
        try:
            wait_until(lambda: server.connections == watch_server.MAX_CONNECTIONS + 2, 5, "the slow clients in")
            assert slow.dropped == 0                             # all of them still there, trickling
            t = time.monotonic()
            reply = exchange(server, post("/api/stop", "0").replace(
                b"\r\n\r\n", f"\r\nX-Stop-Token: {server.token}\r\n\r\n".encode(), 1))
            assert statuses(reply) == [202], reply[:300]
            assert time.monotonic() - t < 2                      # at once, on the reserve
            assert json.loads((run / STOP_FILE).read_text())["by"].startswith("the watch page")
            # the reserve serves nothing else while the slots are full
            page = exchange(server, b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
            assert statuses(page) == [503] and b"only a stop request" in page
            # every trickling client is cut at the whole-request deadline, though each line came in time
            wait_until(lambda: slow.dropped == watch_server.MAX_CONNECTIONS + 2, 10, "the slow clients cut off")
            page = exchange(server, b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
            assert statuses(page) == [200]
        finally:
            slow.close()


def test_a_client_that_disconnects_mid_answer_prints_no_traceback(small_run, capfd):
    with serve(small_run.path) as server:
        for _ in range(5):
            s = socket.create_connection(server.server_address[:2], timeout=5)
            s.sendall(b"GET /plotly.min.js HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
            s.recv(100)                                       # the answer has begun
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            s.close()                                         # reset: the server's writes fail
        time.sleep(0.5)
        assert statuses(exchange(server, b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")) == [200]
    err = capfd.readouterr().err
    assert "Traceback" not in err and "BrokenPipe" not in err and "ConnectionReset" not in err, err
