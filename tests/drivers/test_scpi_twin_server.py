"""The SCPI twin served on TCP and on a pseudo-terminal, driven by independent clients."""

import socket
import time

import pytest
import pyvisa

from drivers._scpi_twin_server import ScpiSerialServer

pytestmark = pytest.mark.timeout(60)


@pytest.fixture
def visa_rm():
    rm = pyvisa.ResourceManager("@py")
    yield rm
    rm.close()


def test_pyvisa_tcp_socket_client_reads_identity_and_sets_frequency(scpi_server, visa_rm, rig):
    inst = visa_rm.open_resource(scpi_server.visa_resource, read_termination="\n",
                                 write_termination="\n", timeout=2000)
    try:
        assert inst.query("*IDN?").startswith("Keysight Technologies,33511B,")
        inst.write("FREQ 432.1")
        assert float(inst.query("FREQ?")) == pytest.approx(432.1)
        assert rig.freq_Hz == pytest.approx(432.1)
        assert inst.query("SYST:ERR?") == '+0,"No error"'
    finally:
        inst.close()


def test_pyvisa_serial_client_over_socat_pty(scpi_model, pty_pair, visa_rm):
    server = ScpiSerialServer(scpi_model, pty_pair.twin_port)
    inst = visa_rm.open_resource(f"ASRL{pty_pair.client_port}::INSTR", read_termination="\n",
                                 write_termination="\n", timeout=2000, baud_rate=115200)
    try:
        inst.write("volt:offs 0.02")
        assert float(inst.query("VOLT:OFFSet?")) == pytest.approx(0.02)
        inst.write("NOT:A:COMMAND")
        assert inst.query("SYST:ERR?").startswith("-113,")
        assert inst.query("*OPC?") == "1"
    finally:
        inst.close()
        server.close()


def test_twin_keeps_serving_after_garbage_bytes(scpi_server):
    with socket.create_connection((scpi_server.host, scpi_server.port), timeout=2) as s:
        s.sendall(b"\xff\xfe\x00garbage;;:*?\n*IDN?\n")
        reply = s.makefile("rb").readline()
    assert reply.startswith(b"Keysight")


def test_query_without_terminator_before_close_is_reported_minus_420(scpi_server, scpi_model):
    with socket.create_connection((scpi_server.host, scpi_server.port), timeout=2) as s:
        s.sendall(b"FREQ?")
    deadline = time.monotonic() + 2.0
    while not scpi_model.errors and time.monotonic() < deadline:
        time.sleep(0.01)
    assert scpi_model.next_error()[0] == -420


def test_query_left_unterminated_on_the_serial_line_is_reported_minus_420(scpi_model, pty_pair):
    import serial
    server = ScpiSerialServer(scpi_model, pty_pair.twin_port, idle_s=0.2)
    port = serial.Serial(pty_pair.client_port, timeout=1.0)
    try:
        port.write(b"VOLT?")
        deadline = time.monotonic() + 3.0
        while not scpi_model.errors and time.monotonic() < deadline:
            time.sleep(0.02)
        port.write(b"SYST:ERR?\n")
        assert port.readline().startswith(b"-420,")
    finally:
        port.close()
        server.close()


def test_two_connections_share_one_error_queue(scpi_server):
    with socket.create_connection((scpi_server.host, scpi_server.port), timeout=2) as a, \
            socket.create_connection((scpi_server.host, scpi_server.port), timeout=2) as b:
        a.sendall(b"BOGUS\n*OPC?\n")
        assert a.makefile("rb").readline() == b"1\n"
        b.sendall(b"SYST:ERR?\n")
        assert b.makefile("rb").readline().startswith(b"-113,")
