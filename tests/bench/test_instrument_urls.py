"""Instrument URLs: only the schemes the bench uses are opened, from a rig file, a stored
run.json or a driver called directly.  pyserial's ``spy://PORT?file=PATH`` truncates PATH
even when the port then fails to open; a rig file naming it must write nothing."""

from __future__ import annotations

import json
import shutil

import pytest
import serial

from bench.cli import main
from bench.config import ConfigError, load_rig
from drivers import ModbusEddySensor, ScpiFunctionGenerator, open_can_bus

from .test_config import RIG, edit, write

KEEP = b"precious data\n"


@pytest.fixture
def victim(tmp_path):
    path = tmp_path / "victim.txt"
    path.write_bytes(KEEP)
    return path


def test_pyserial_itself_would_truncate_the_file(victim):
    """The hazard is real: without the allow-list, opening the URL empties the file."""
    with pytest.raises(serial.SerialException):
        serial.serial_for_url(f"spy:///nonexistent-port?file={victim}")
    assert victim.read_bytes() == b""


@pytest.mark.parametrize("key, old, bad, allowed", [
    ("generator", "socket://192.0.2.10:5025", "spy:///dev/null?file={victim}", "socket://host:port"),
    ("generator", "socket://192.0.2.10:5025", "hwgrep://.*", "socket://host:port"),
    ("sensor", "modbus-tcp://192.0.2.11:502?unit=1", "modbus-rtu://spy:///dev/null?file={victim}",
     "modbus-rtu:///dev/<port>"),
    ("sensor", "modbus-tcp://192.0.2.11:502?unit=1", "spy:///dev/null?file={victim}", "modbus-tcp://"),
    ("daq", "tcp://192.0.2.12:29536", "slcan:spy:///dev/null?file={victim}", "serial device path"),
    ("daq", "tcp://192.0.2.12:29536", "udp_multicast:239.0.0.1", "socketcan"),
])
def test_a_rig_file_naming_another_scheme_is_refused_naming_the_key(tmp_path, victim, key, old, bad, allowed):
    url = bad.format(victim=victim)
    path = write(tmp_path, "rig.toml", edit(RIG, old, url))
    with pytest.raises(ConfigError) as e:
        load_rig(path)
    assert f"[rig.instruments] {key}" in str(e.value) and allowed in str(e.value)
    assert victim.read_bytes() == KEEP


@pytest.mark.parametrize("generator, sensor, daq", [
    ("/dev/ttyUSB0", "modbus-rtu:///dev/ttyUSB1?baud=115200&unit=1", "socketcan:can0"),
    ("socket://[::1]:5025", "modbus-tcp://[::1]:502?unit=2", "slcan:/dev/ttyACM0@115200"),
    ("loop://", "modbus-tcp://127.0.0.1:5020", "virtual:bench"),
])
def test_the_documented_forms_are_accepted(tmp_path, generator, sensor, daq):
    text = edit(edit(edit(RIG, "socket://192.0.2.10:5025", generator),
                     "modbus-tcp://192.0.2.11:502?unit=1", sensor), "tcp://192.0.2.12:29536", daq)
    rig = load_rig(write(tmp_path, "rig.toml", text))
    assert (rig.generator_url, rig.sensor_url, rig.daq_url) == (generator, sensor, daq)


def test_a_stored_run_json_naming_spy_is_refused_by_resume_and_writes_nothing(tmp_path, victim, small_run, capsys):
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run)
    meta = json.loads((run / "run.json").read_text())
    meta["rig"].update(simulated=False, generator_url=f"spy:///dev/null?file={victim}",
                       sensor_url="modbus-tcp://127.0.0.1:9", daq_url="virtual:x", model={})
    meta["status"] = "interrupted"
    (run / "run.json").write_text(json.dumps(meta))
    last = sorted((run / "steps").glob("*.json"))[-1]
    last.unlink()
    last.with_suffix(".npz").unlink()                          # a step left to measure
    assert main(["resume", str(run)]) == 2
    err = capsys.readouterr().err
    assert "run.json" in err and "[rig.instruments] generator" in err and "spy://" in err
    assert victim.read_bytes() == KEEP


def test_the_drivers_refuse_it_too_before_opening_anything(victim):
    spy = f"spy:///dev/null?file={victim}"
    with pytest.raises(ValueError, match="function generator"):
        ScpiFunctionGenerator(spy)
    with pytest.raises(ValueError, match="modbus-rtu:///dev/<port>"):
        ModbusEddySensor(f"modbus-rtu://{spy}")
    with pytest.raises(ValueError, match="serial device path"):
        open_can_bus(f"serial:{spy}")
    with pytest.raises(ValueError, match="allowed"):
        open_can_bus("udp_multicast:239.0.0.1")
    assert victim.read_bytes() == KEEP
