"""ModbusEddySensor and its twin: register map, independent clients, malformed requests."""

import shutil
import socket
import struct
import subprocess
import threading
import time

import pytest

from drivers import ConnectionLost, InstrumentTimeout, ModbusEddySensor, ModbusError, SensorStatus, TargetMaterial
from drivers._eddy_registers import Reg
from drivers._eddy_twin import EddySensorModel, EddySensorRtuTwin
from tests.drivers.expected_protocol import ModbusTcpScript

pytestmark = pytest.mark.timeout(60)

needs_mbpoll = pytest.mark.skipif(shutil.which("mbpoll") is None, reason="mbpoll not installed")


def plant_gap_mm(rig) -> float:
    with rig.lock:
        return rig.gap_m() * 1e3


@pytest.fixture
def sensor(sensor_twin):
    s = ModbusEddySensor(sensor_twin.url, timeout_s=1.0)
    yield s
    s.close()


# --------------------------------------------------------------------- exact exchange
def test_read_gap_is_one_fc04_request_decoding_big_endian_float():
    gap = struct.pack(">f", 0.75).hex()
    script = ModbusTcpScript([("04 0001 0005", f"04 0a {gap} 1d4c 0010 00eb")])
    s = ModbusEddySensor(f"modbus-tcp://127.0.0.1:{script.port}?unit=1")
    reading = s.read_gap()
    s.close()
    script.check()
    assert reading.gap_mm == 0.75
    assert reading.status == SensorStatus.ZERO_ACTIVE
    assert reading.temperature_C == pytest.approx(23.5)


def test_set_filter_writes_fc06_and_reads_back_fc03():
    script = ModbusTcpScript([("06 000f 0003", "06 000f 0003"), ("03 000f 0001", "03 02 0003")])
    s = ModbusEddySensor(f"modbus-tcp://127.0.0.1:{script.port}?unit=1")
    s.set_filter(3)
    s.close()
    script.check()


# --------------------------------------------------------------------- against the twin
def test_gap_follows_the_plant_probe_distance(sensor, rig):
    reading = sensor.read_gap()
    assert reading.gap_mm == pytest.approx(plant_gap_mm(rig), abs=1e-5)
    assert sensor.read_gap_raw_mm() == pytest.approx(plant_gap_mm(rig), abs=1e-4)


def test_carriage_at_rest_reads_the_probe_standoff_inside_the_measuring_range(sensor, rig):
    reading = sensor.read_gap()
    # independent fact: at x = 0 the probe sees its mounting stand-off (float32 on the wire)
    assert reading.gap_mm == pytest.approx(rig.model.probe_standoff_m * 1e3, abs=1e-6)
    assert reading.in_range


def test_zero_makes_the_present_gap_zero_and_sets_status(sensor, rig):
    offset = sensor.zero()
    assert offset == pytest.approx(plant_gap_mm(rig), abs=1e-5)
    reading = sensor.read_gap()
    assert reading.gap_mm == pytest.approx(0.0, abs=1e-6)
    assert reading.status & SensorStatus.ZERO_ACTIVE
    sensor.clear_zero()
    assert not sensor.status() & SensorStatus.ZERO_ACTIVE


def test_target_out_of_range_sets_status_bit(sensor, rig, monkeypatch):
    monkeypatch.setattr(rig, "gap_m", lambda: 5e-3)
    reading = sensor.read_gap()
    assert reading.status & SensorStatus.TARGET_TOO_FAR
    assert not reading.in_range


def test_configuration_round_trips(sensor):
    sensor.set_target_material(TargetMaterial.ALUMINIUM)
    sensor.set_filter(2)
    sensor.set_zero_offset_mm(0.25)
    assert sensor.target_material() == TargetMaterial.ALUMINIUM
    assert sensor.filter_cutoff_Hz() == 100.0
    assert sensor.zero_offset_mm() == 0.25
    assert sensor.range_mm() == 2.0
    assert sensor.identify().model == "ECS-2000-TWIN"


@pytest.mark.parametrize("address, values, code", [
    (Reg.GAP_MM, [1, 2], 2),                  # read-only register
    (Reg.FILTER, [9], 3),                     # enumeration out of range
    (Reg.TARGET_MATERIAL, [42], 3),
    (Reg.COMMAND, [7], 3),                    # unknown command
    (Reg.ZERO_OFFSET_MM, [0x4000], 2),        # half of a float32
    (Reg.ZERO_OFFSET_MM, [0x7FC0, 0], 3),     # NaN offset
    (200, [1], 2),                            # unused address
])
def test_bad_writes_get_modbus_exception_responses(sensor, address, values, code):
    with pytest.raises(ModbusError) as info:
        sensor.write_registers(address, values)
    assert info.value.exception_code == code
    assert sensor.identify().serial == "4711"  # still serving


def test_malformed_pdu_gets_exception_response_on_raw_socket(sensor_twin):
    def request(pdu: bytes) -> bytes:
        with socket.create_connection((sensor_twin.host, sensor_twin.port), timeout=2) as s:
            s.sendall(b"\x00\x07\x00\x00" + (len(pdu) + 1).to_bytes(2, "big") + b"\x01" + pdu)
            return s.recv(256)
    reply = request(bytes([0x03, 0x00, 0x64, 0x00, 0x02]))      # read unused address 100
    assert reply[7:9] == b"\x83\x02"
    reply = request(bytes([0x05, 0x00, 0x01, 0xFF, 0x00]))      # write coil: not supported
    assert reply[7] == 0x85


# --------------------------------------------------------------------- independent clients
def _mbpoll(*args: str) -> str:
    out = subprocess.run(["mbpoll", *args, "-1", "-0", "-o", "1"], capture_output=True,
                         text=True, timeout=10)
    assert out.returncode == 0, out.stderr
    return out.stdout


def _values(stdout: str) -> list[str]:
    return [line.split("\t")[-1].strip() for line in stdout.splitlines() if line.startswith("[")]


@needs_mbpoll
def test_mbpoll_reads_float_and_uint16_gap_over_tcp(sensor_twin, rig):
    port = str(sensor_twin.port)
    floats = _values(_mbpoll("-m", "tcp", "-p", port, "-a", "1", "-r", "1", "-c", "1",
                             "-t", "3:float", "-B", "127.0.0.1"))
    raw = _values(_mbpoll("-m", "tcp", "-p", port, "-a", "1", "-r", "3", "-c", "1", "-t", "3",
                          "127.0.0.1"))
    assert float(floats[0]) == pytest.approx(plant_gap_mm(rig), abs=1e-4)
    assert int(raw[0]) == round(plant_gap_mm(rig) * 1e4)


@needs_mbpoll
def test_mbpoll_writes_filter_and_the_driver_sees_it(sensor_twin, sensor):
    _mbpoll("-m", "tcp", "-p", str(sensor_twin.port), "-a", "1", "-r", str(int(Reg.FILTER)),
            "-t", "4", "127.0.0.1", "4")
    assert sensor.filter_cutoff_Hz() == 10000.0


@needs_mbpoll
def test_mbpoll_reads_over_rtu_on_a_pty(rig, pty_pair):
    twin = EddySensorRtuTwin(EddySensorModel(rig), pty_pair.twin_port)
    try:
        values = _values(_mbpoll("-m", "rtu", "-b", "115200", "-P", "none", "-a", "1",
                                 "-r", "1", "-c", "1", "-t", "3:float", "-B",
                                 pty_pair.client_port))
        assert float(values[0]) == pytest.approx(plant_gap_mm(rig), abs=1e-4)
        s = ModbusEddySensor(f"modbus-rtu://{pty_pair.client_port}?baud=115200&unit=1")
        assert s.identify().serial == "4711"
        s.close()
    finally:
        twin.close()


# --------------------------------------------------------------------- failures
def test_unreachable_sensor_raises_connection_lost():
    sock = socket.create_server(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()
    with pytest.raises(ConnectionLost):
        ModbusEddySensor(f"modbus-tcp://127.0.0.1:{port}?unit=1", timeout_s=0.5)


def test_silent_sensor_times_out_in_bounded_time():
    sock = socket.create_server(("127.0.0.1", 0))
    held = []
    threading.Thread(target=lambda: held.append(sock.accept()), daemon=True).start()
    s = ModbusEddySensor(f"modbus-tcp://127.0.0.1:{sock.getsockname()[1]}?unit=1",
                         timeout_s=0.3, retries=0)
    start = time.monotonic()
    with pytest.raises(InstrumentTimeout):
        s.read_gap()
    assert time.monotonic() - start < 2.0
    s.close()
    sock.close()


def test_stopped_twin_gives_a_typed_error(sensor_twin, sensor):
    sensor.read_gap()
    sensor_twin.close()
    with pytest.raises(ConnectionLost):
        sensor.read_gap()


def test_bad_url_is_rejected_with_a_clear_message():
    with pytest.raises(ValueError, match="modbus-tcp or modbus-rtu"):
        ModbusEddySensor("http://127.0.0.1:80")
