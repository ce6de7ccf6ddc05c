"""start_twins: three twins around one plant, reached through the real drivers."""

import socket
import threading

import pytest

from drivers import CanFdDaq, ModbusEddySensor, ScpiFunctionGenerator, open_can_bus, run_standalone, start_twins
from tests.drivers.plant import fundamental

pytestmark = pytest.mark.timeout(60)


def test_urls_point_at_loopback_ephemeral_ports(twins):
    urls = twins.urls()
    assert urls["generator"].startswith("socket://127.0.0.1:")
    assert urls["sensor"].startswith("modbus-tcp://127.0.0.1:")
    assert urls["daq_bridge"].startswith("tcp://127.0.0.1:")
    assert urls["daq"].startswith("virtual:")


def test_generator_setting_shows_up_in_the_daq_force_through_the_shared_plant(twins, rig,
                                                                               channels):
    with ScpiFunctionGenerator(twins.generator_url, drive_limit_V=2.0) as gen:
        gen.configure_sine()
        gen.set_frequency(200.0)
        gen.set_amplitude(0.6)
        gen.set_output(True)
        daq = CanFdDaq(open_can_bus(twins.daq_url), channels)
        block = daq.acquire_periods(200.0, 10)
        daq.close()
    # independent fact: the amplifier makes amp_gain_N_per_V newton per generator volt
    force_N = abs(fundamental(block.force_N, block.fs_Hz, 200.0))
    assert force_N == pytest.approx(rig.model.amp_gain_N_per_V * 0.6 / 2.0, rel=1e-3)


def test_sensor_reads_the_plant_gap_after_acquisition_advanced_the_clock(twins, rig):
    sensor = ModbusEddySensor(twins.sensor_url)
    before = sensor.read_gap().gap_mm
    with rig.lock:
        expected = rig.gap_m() * 1e3
    sensor.close()
    assert before == pytest.approx(expected, abs=1e-6)


def test_close_releases_the_ports(rig):
    t = start_twins(rig)
    port = int(t.generator_url.rsplit(":", 1)[1])
    t.close()
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", port), timeout=0.5).close()


def test_serial_ports_option_serves_scpi_and_rtu_on_ptys(rig):
    with start_twins(rig, serial_ports=True) as t:
        gen = ScpiFunctionGenerator(t.generator_serial_port, timeout_s=1.0)
        assert gen.identify().model == "33511B"
        gen.close()
        sensor = ModbusEddySensor(t.sensor_rtu_url)
        assert sensor.read_gap().in_range
        sensor.close()


def test_run_standalone_prints_urls_and_stops_on_request(rig):
    lines, stop = [], threading.Event()
    thread = threading.Thread(target=run_standalone, args=(rig,),
                              kwargs=dict(print_fn=lines.append, stop=stop))
    thread.start()
    for _ in range(100):
        if len(lines) >= 5:
            break
        threading.Event().wait(0.02)
    stop.set()
    thread.join(timeout=5)
    assert not thread.is_alive()
    assert any(line.startswith("generator ") for line in lines)


def test_the_in_process_bus_delivers_each_receiver_its_own_copy_of_a_frame():
    """drivers.InProcessBus (decision 0091) is python-can's virtual bus without deepcopy: a
    plain python-can virtual bus on the channel gets every field of the frame, as a copy of
    its own (the sender's message changed after the send does not change it), and the
    sender does not hear itself."""
    import can

    from drivers._can_transport import InProcessBus, open_can_bus
    sender = open_can_bus("virtual:test-inprocess-copy")
    receivers = [can.Bus(interface="virtual", channel="test-inprocess-copy"), InProcessBus(channel="test-inprocess-copy")]
    try:
        assert isinstance(sender, InProcessBus)
        msg = can.Message(arbitration_id=0x123, data=bytes(range(64)), is_fd=True, bitrate_switch=True,
                          is_extended_id=False)
        sender.send(msg)
        msg.data[0] = 99
        got = [bus.recv(timeout=1.0) for bus in receivers]
        for g in got:
            assert g is not None and g is not msg
            assert (g.arbitration_id, bytes(g.data), g.dlc, g.is_fd, g.bitrate_switch, g.is_extended_id, g.is_rx) == \
                (0x123, bytes(range(64)), 64, True, True, False, True)
            assert g.channel == "test-inprocess-copy"
        assert got[0] is not got[1] and got[0].data is not got[1].data
        assert sender.recv(timeout=0.05) is None
    finally:
        for bus in (sender, *receivers):
            bus.shutdown()
