"""The generator driver over a VISA resource (pyvisa-py), against the SCPI twin's socket
resource ``TCPIP0::127.0.0.1::<port>::SOCKET``: confirmed settings, output on and off,
the byte-stream surface the resynchronisation after an interrupted query needs, and a
stepped-sine run whose generator is reached through VISA."""

from __future__ import annotations

import time

import pytest

from drivers import ConnectionLost, ScpiError, ScpiFunctionGenerator, VisaTransport, is_visa_resource, start_twins
from sim.rig import RigModel, SimulatedRig

pytestmark = pytest.mark.timeout(60)


@pytest.mark.parametrize("url", [
    "TCPIP0::127.0.0.1::5025::SOCKET", "TCPIP0::192.168.1.20::inst0::INSTR", "TCPIP::k-33522b::INSTR",
    "TCPIP0::192.168.1.20::hislip0::INSTR", "USB0::0x0957::0x2C07::MY52801234::INSTR",
    "USB::0x0957::0x2C07::MY52801234::0::INSTR", "ASRL/dev/ttyUSB0::INSTR", "GPIB0::10::INSTR",
    "tcpip0::127.0.0.1::5025::socket"])
def test_visa_resource_strings_are_recognised(url):
    assert is_visa_resource(url)


@pytest.mark.parametrize("url", [
    "socket://127.0.0.1:5025", "/dev/ttyUSB0", "loop://", "rfc2217://host:2217", "TCPIP0::127.0.0.1",
    "TCPIP0::127.0.0.1::5025", "modbus-tcp://127.0.0.1:502?unit=1", "TCPIP0::host::5025::SOCKET; rm -rf /", ""])
def test_other_urls_are_not_visa_resources(url):
    assert not is_visa_resource(url)


def test_a_confirmed_setting_output_on_and_off_and_an_instrument_error_over_visa(scpi_server, scpi_model, rig):
    with ScpiFunctionGenerator(scpi_server.visa_resource, drive_limit_V=3.0) as gen:
        assert isinstance(gen._port, VisaTransport)
        assert gen.identify().model == "33511B"
        gen.configure_sine()
        assert scpi_model.state.limit_state and scpi_model.state.limit_high_V == 3.0
        assert gen.set_frequency(432.1) == pytest.approx(432.1)
        assert rig.freq_Hz == pytest.approx(432.1)                       # the plant got it
        t0 = time.monotonic()
        for k in range(40):          # small lines are not held back (Nagle + delayed ACK: 45 ms each)
            gen.set_frequency(100.0 + k)
        assert time.monotonic() - t0 < 1.0
        assert gen.set_amplitude(1.5) == pytest.approx(1.5)
        gen.set_output(True)
        assert scpi_model.state.output_on and gen.output_enabled()
        gen.set_output(False)
        assert not scpi_model.state.output_on
        with pytest.raises(ScpiError) as err:
            gen.command("NOT:A:COMMAND")
        assert err.value.code == -113
        gen.set_output(True)
    assert not scpi_model.state.output_on                                # __exit__: safe_off


def test_the_visa_transport_has_what_a_resynchronisation_needs(scpi_server):
    t = VisaTransport(scpi_server.visa_resource, timeout=2.0)
    try:
        t.write(b"*IDN?\n")                      # a query whose reply is never read (an interrupted one)
        t.flush()
        deadline = time.monotonic() + 5
        while not t.in_waiting and time.monotonic() < deadline:
            time.sleep(0.01)
        assert t.in_waiting > 0
        t.reset_input_buffer()
        assert t.in_waiting == 0
        t.write(b"*OPC?\n")
        assert t.read_until(b"\n") == b"1\n"     # its own answer, not the stale *IDN? reply
        t.write(b"FREQ?\n*OPC?\n")               # two replies: the line ends where the first does
        assert t.read_until(b"\n").startswith(b"+")
        assert t.read_until(b"\n") == b"1\n"
        t.timeout = 0.2                           # settable, as pyserial's
        t.write(b"FREQ 100\n")                   # no reply: a bounded wait, then what came (nothing)
        t0 = time.monotonic()
        assert t.read_until(b"\n") == b""
        assert 0.15 < time.monotonic() - t0 < 1.5
        t.write(b"*OPC?\n")
        assert t.read(1) == b"1"                 # a short read, as pyserial's
        assert t.read_until(b"\n") == b"\n"
    finally:
        t.close()


def test_a_resource_nobody_answers_is_a_connection_lost_naming_it():
    with pytest.raises(ConnectionLost, match=r"TCPIP0::127\.0\.0\.1::1::SOCKET"):
        gen = ScpiFunctionGenerator("TCPIP0::127.0.0.1::1::SOCKET", timeout_s=0.5)
        gen.identify()


@pytest.mark.timeout(120)
def test_a_stepped_sine_run_reaches_its_generator_through_visa(tmp_path):
    from bench.config import parse_rig, read_toml
    from bench.session import run_plan
    from bench.storage import RunStore
    from benchtools.plans import small_plan
    from benchtools.procs import rig_toml_for

    with start_twins(SimulatedRig(RigModel(seed=5))) as twins:
        rig_path = tmp_path / "rig.toml"
        rig_path.write_text(rig_toml_for(twins).replace(twins.generator_url, twins.generator_visa))
        rig = parse_rig(read_toml(rig_path), str(rig_path))
        assert rig.generator_url.startswith("TCPIP0::127.0.0.1::") and rig.generator_url.endswith("::SOCKET")
        seen = []
        real = twins.generator.execute
        twins.generator.execute = lambda line: (seen.append(line), real(line))[1]
        store = run_plan(small_plan(freqs=(60.0, 100.0)), rig, tmp_path / "run", identify=False)
        assert not twins.generator.state.output_on
    meta = store.metadata
    assert (meta["status"], meta["steps_done"]) == ("completed", 2)
    results = sorted(RunStore(tmp_path / "run").results(), key=lambda r: r["freq_Hz"])
    assert [r["freq_Hz"] for r in results] == [60.0, 100.0]
    assert all(abs(r["force_N"] - 1.0) < 0.05 for r in results)         # force control worked over VISA
    assert "OUTP ON" in seen and seen.index("OUTP ON") < len(seen) - seen[::-1].index("OUTP OFF") - 1
    assert [e["confirmed"] for e in RunStore(tmp_path / "run").events() if e["event"] == "output_off"] == [True]


def test_ctrl_c_inside_a_query_over_visa_then_the_link_resynchronises_and_safe_off_is_confirmed(
        scpi_server, rig, mocker, caplog):
    from tests.drivers.test_function_generator import driving, interrupt_once

    gen = ScpiFunctionGenerator(scpi_server.visa_resource, drive_limit_V=3.0)
    try:
        driving(gen)
        interrupt_once(mocker, gen._port, "read_until")
        with pytest.raises(KeyboardInterrupt):
            gen.query("OUTP?")                  # its "1" stays in the link, unread
        assert not gen.in_step
        assert gen.query_float("VOLT?") == 1.2  # resynchronised first: its own reply
        interrupt_once(mocker, gen._port, "read_until", before=lambda *a: gen._port.read(3))
        with pytest.raises(KeyboardInterrupt):
            gen.query("VOLT?")                  # cut after half a reply ('+1.' read, the rest pending)
        assert not gen.in_step
        assert gen.set_amplitude(0.6) == 0.6    # confirmed read-back: in step again
        assert rig.amplitude_Vpp == pytest.approx(0.6)
        gen.safe_off()
        assert rig.output_on is False and gen.output_enabled() is False
        assert "safe_off" not in caplog.text
        assert gen.query_float("FREQ?") == 80.0
    finally:
        gen.close()
