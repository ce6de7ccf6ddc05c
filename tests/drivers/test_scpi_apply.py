"""APPLy as a user's own script sends it: a plain socket client against the SCPI twin served
the way `bench twins` serves it (drivers.run_standalone), checked on the wire and at the plant."""

from __future__ import annotations

import socket
import threading

import pytest

from drivers import run_standalone
from sim.rig import SimulatedRig

pytestmark = pytest.mark.timeout(60)


@pytest.fixture
def served():
    rig = SimulatedRig()
    lines: list[str] = []
    started = threading.Event()
    stop = threading.Event()

    def capture(line: str) -> None:
        lines.append(line)
        if line.startswith("generator_tcp") or "socket://" in line:
            started.set()

    thread = threading.Thread(target=run_standalone, args=(rig,), daemon=True,
                              kwargs=dict(print_fn=capture, stop=stop))
    thread.start()
    assert started.wait(30), lines
    url = next(l.split()[-1] for l in lines if "socket://" in l)
    host, port = url.removeprefix("socket://").rsplit(":", 1)
    sock = socket.create_connection((host, int(port)), timeout=5)
    stream = sock.makefile("rwb", buffering=0)

    def ask(text: str) -> str | None:
        stream.write(text.encode() + b"\n")
        if "?" not in text:
            return None
        return stream.readline().decode().rstrip("\n")

    yield ask, rig
    sock.close()
    stop.set()
    thread.join(10)


def test_apply_sets_function_frequency_amplitude_offset_and_switches_the_output_on(served):
    ask, rig = served
    assert ask("OUTP?") == "0"
    ask("APPL:SIN 200,0.2,0")
    assert float(ask("FREQ?")) == 200.0
    assert float(ask("VOLT?")) == 0.2
    assert float(ask("VOLT:OFFS?")) == 0.0
    assert ask("OUTP?") == "1"
    assert ask("SYST:ERR?") == '+0,"No error"'
    # the plant got it: 200 Hz, on, the open-circuit voltage of a 50 ohm load setting (x2)
    assert rig.gen.freq_Hz == 200.0 and rig.gen.output_on
    assert rig.gen.amplitude_Vpp == pytest.approx(0.4)


def test_apply_query_answers_the_33500_quoted_string(served):
    ask, _ = served
    ask("APPL:SIN 200,0.2,0")
    assert ask("APPL?") == '"SIN +2.000000000000000E+02,+2.000000000000000E-01,+0.000000000000000E+00"'
    ask("APPLy:SINusoid 5 KHZ, 3.0 VPP, -2.5 V")
    assert ask("APPLy?") == '"SIN +5.000000000000000E+03,+3.000000000000000E+00,-2.500000000000000E+00"'


def test_apply_defaults_and_keywords(served):
    ask, _ = served
    ask("APPL:SIN 300,1.0,0.1")
    ask("APPL:SIN")                                  # omitted = DEFault: 1 kHz, 0.1 Vpp, 0 V
    assert ask("APPL?") == '"SIN +1.000000000000000E+03,+1.000000000000000E-01,+0.000000000000000E+00"'
    ask("APPL:SIN 50,MAX")                           # MAX amplitude into the 50 ohm setting
    assert float(ask("VOLT?")) == pytest.approx(10.0)
    assert float(ask("FREQ?")) == 50.0
    ask("OUTP:LOAD INF;:APPL:SIN MIN,DEF,DEF")
    assert float(ask("FREQ?")) == pytest.approx(1e-6)
    assert float(ask("VOLT?")) == pytest.approx(0.1)
    assert ask("SYST:ERR?") == '+0,"No error"'


def test_bad_apply_parameters_change_nothing_and_are_reported(served):
    ask, rig = served
    ask("APPL:SIN 200,0.2,0")
    ask("APPL:SIN 300,abc")
    assert ask("SYST:ERR?").startswith("-104,")
    assert float(ask("FREQ?")) == 200.0              # nothing applied from the bad command
    ask("APPL:SIN 1,2,3,4")
    assert ask("SYST:ERR?").startswith("-108,")
    ask("APPL:SIN 1e9")                              # out of range: clipped, -222, as FREQ does
    assert ask("SYST:ERR?").startswith("-222,")
    assert float(ask("FREQ?")) == 20e6
    assert rig.gen.freq_Hz == 20e6
