"""Fuzzing the SCPI twin (over a real socket) and the driver's reply parsing.

Properties: the twin answers every input without dying, within a time bound, keeps its
error queue bounded, and still answers ``*IDN?`` on the same connection and a new one
afterwards; the driver turns any reply into a value or a typed InstrumentError.
"""

from __future__ import annotations

import socket
import threading
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers import InstrumentError, ScpiFunctionGenerator
from drivers._scpi_twin_model import ERROR_QUEUE_DEPTH, IDN, ScpiGeneratorModel
from drivers._scpi_twin_server import MAX_LINE_BYTES, ScpiTcpServer

from ._settings import TIME_BOUND_S, fuzz

VALID = ["*IDN?", "*RST", "*CLS", "*OPC?", "SYST:ERR?", "FUNC SIN", "FREQ 1000", "FREQ?", "VOLT 0.5",
         "VOLT?", "VOLT:OFFS 0", "VOLT:OFFS?", "VOLT:UNIT VPP", "VOLT:LIM:HIGH 5", "VOLT:LIM:LOW -5",
         "VOLT:LIM:STAT ON", "VOLT:RANG:AUTO OFF", "OUTP OFF", "OUTP?", "OUTP:LOAD INF", "OUTP:LOAD?",
         ":SOUR:FREQ:CW 2.5 KHZ", "SOUR:VOLT:LEV:IMM:AMPL 100 mV", "FREQ MIN", "VOLT MAX"]

messages = st.one_of(
    st.lists(st.sampled_from(VALID), min_size=1, max_size=4).map(";".join),
    st.text(alphabet=st.characters(min_codepoint=32, max_codepoint=126), max_size=80),
    st.text(max_size=40),                                         # any unicode
)


@st.composite
def mutated(draw):
    """A valid message with characters deleted, inserted or replaced."""
    s = list(draw(st.lists(st.sampled_from(VALID), min_size=1, max_size=3).map(";".join)))
    for _ in range(draw(st.integers(1, 4))):
        op, i = draw(st.sampled_from("dir")), draw(st.integers(0, len(s)))
        c = draw(st.sampled_from(list(":;?*, .-+e9ABCDEFINFnan\"'#\t") + ["\x00", "\xff"]))
        if op == "d" and i < len(s):
            del s[i]
        elif op == "i":
            s.insert(i, c)
        elif i < len(s):
            s[i] = c
    return "".join(s)


@pytest.fixture(scope="module")
def twin():
    model = ScpiGeneratorModel()
    server = ScpiTcpServer(model)
    yield model, server
    server.close()


def _connect(server) -> socket.socket:
    s = socket.create_connection((server.host, server.port), timeout=TIME_BOUND_S)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def _answers_idn(sock: socket.socket) -> bool:
    """``*IDN?`` is answered (after any replies still owed to earlier input)."""
    sock.sendall(b"\n*IDN?\n")
    buf, deadline = b"", time.monotonic() + TIME_BOUND_S
    while time.monotonic() < deadline:
        try:
            chunk = sock.recv(65536)
        except TimeoutError:
            return False
        if not chunk:
            return False
        buf += chunk
        if IDN.encode() + b"\n" in buf:
            return True
    return False


@given(st.one_of(messages, mutated()))
@fuzz(200)
def test_the_model_answers_any_message_with_a_reply_or_a_queued_error(message):
    model = ScpiGeneratorModel()
    t = time.monotonic()
    reply = model.execute(message)
    assert time.monotonic() - t < TIME_BOUND_S
    assert reply is None or (isinstance(reply, str) and "\n" not in reply)
    assert len(model.errors) <= ERROR_QUEUE_DEPTH
    for code, text in model.errors:
        assert -500 < code < 0 and text
    assert model.execute("*IDN?") == IDN


@given(st.one_of(st.binary(max_size=2000), messages.map(lambda m: m.encode("utf-8", "replace")),
                 mutated().map(lambda m: m.encode("utf-8", "replace") + b"\n"),
                 st.binary(min_size=MAX_LINE_BYTES + 1, max_size=3 * MAX_LINE_BYTES)))
@fuzz(60)
def test_the_twin_server_survives_any_bytes_and_still_answers(twin, data):
    model, server = twin
    with _connect(server) as sock:
        sock.sendall(data)
        assert _answers_idn(sock), f"no *IDN? reply on the same connection after {data[:80]!r}"
    with _connect(server) as sock:
        assert _answers_idn(sock), "no *IDN? reply on a new connection"
    assert len(model.errors) <= ERROR_QUEUE_DEPTH


def test_a_peer_that_closes_mid_query_leaves_the_twin_serving(twin):
    model, server = twin
    for junk in (b"FREQ?", b"\xff" * 10000, b"*IDN?;" * 1000):
        with _connect(server) as sock:
            sock.sendall(junk)
    with _connect(server) as sock:
        assert _answers_idn(sock)


# ------------------------------------------------------------------ the driver's side

class _ReplyServer:
    """A fake instrument: answers every query line with the next scripted reply bytes."""

    def __init__(self):
        self.replies: list[bytes] = []
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        threading.Thread(target=self._loop, daemon=True).start()

    def _loop(self):
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn):
        buf = b""
        with conn:
            while True:
                try:
                    data = conn.recv(4096)
                except OSError:
                    return
                if not data:
                    return
                buf += data
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    if line.endswith(b"?") and self.replies:
                        try:
                            conn.sendall(self.replies.pop(0))
                        except OSError:
                            return


@pytest.fixture(scope="module")
def reply_server():
    srv = _ReplyServer()
    yield srv
    srv.sock.close()


replies = st.one_of(
    st.sampled_from([b"1\n", b"0\n", b"1.5e+03\n", b"+0,\"No error\"\n", IDN.encode() + b"\n",
                     b"-113,\"Undefined header\"\n"]),
    st.binary(max_size=200).map(lambda b: b.replace(b"\n", b"") + b"\n"),
    st.binary(max_size=50),                                   # possibly no terminator
    st.text(max_size=60).map(lambda t: t.encode("utf-8", "replace") + b"\n"),
)


@given(st.lists(replies, min_size=1, max_size=4), st.sampled_from(
    ["identify", "output_enabled", "query_float", "read_errors", "set_frequency"]))
@fuzz(60)
def test_the_driver_turns_any_reply_into_a_value_or_a_typed_error(reply_server, script, call):
    reply_server.replies[:] = list(script) + [b"+0,\"No error\"\n"] * 3
    gen = ScpiFunctionGenerator(f"socket://127.0.0.1:{reply_server.port}", timeout_s=0.2)
    t = time.monotonic()
    try:
        if call == "identify":
            ident = gen.identify()
            assert len(ident.__dict__) == 4
        elif call == "output_enabled":
            assert gen.output_enabled() in (True, False)
        elif call == "query_float":
            assert isinstance(gen.query_float("FREQ?"), float)
        elif call == "read_errors":
            errors = gen.read_errors()
            assert all(isinstance(c, int) and c != 0 for c, _ in errors)
        else:
            gen.set_frequency(1500.0)
    except InstrumentError:
        pass
    finally:
        gen.close()
    assert time.monotonic() - t < TIME_BOUND_S + 0.2 * 25
