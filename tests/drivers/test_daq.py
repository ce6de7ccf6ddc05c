"""CanFdDaq against the DAQ twin: physical units, integer periods, integrity, failures."""

import os
import subprocess
import sys
import time

import can
import numpy as np
import pytest

from tests.drivers.fake_rig import AMP_N_PER_V, CHANNELS, needs_fake_rig
from drivers import (BlockIntegrityError, CanFdDaq, InstrumentError, InstrumentTimeout,
                     ScpiFunctionGenerator, open_can_bus, plan_block)
from drivers import _daq_codec as codec

pytestmark = pytest.mark.timeout(60)


def drive(rig, freq_Hz=100.0, amplitude_Vpp=1.0):
    rig.set_generator(freq_Hz=freq_Hz, amplitude_Vpp=amplitude_Vpp, output_on=True)


@needs_fake_rig
def test_block_is_in_physical_units_of_the_channel_sensitivities(rig, daq):
    drive(rig, amplitude_Vpp=1.0)
    block = daq.acquire_periods(100.0, 20)
    expected_force_N = AMP_N_PER_V * 1.0 / 2.0       # amplifier gain x half of Vpp
    assert np.max(np.abs(block.force_N)) == pytest.approx(expected_force_N, rel=2e-3)
    assert block.force_V == pytest.approx(block.force_N * CHANNELS[0].sensitivity_V_per_unit)


def test_block_covers_an_integer_number_of_periods(rig, daq):
    drive(rig, freq_Hz=999.0)
    block = daq.acquire_periods(999.0, 7)
    periods = block.n_samples * 999.0 / block.fs_Hz
    assert periods == pytest.approx(7.0, abs=1e-6)
    assert block.fs_Hz >= 25_600.0


def test_plan_block_picks_integer_samples_per_period():
    rate, n = plan_block(1000.0, 10)
    assert (rate, n) == (26_000.0, 260)


def test_consecutive_blocks_advance_the_plant_clock(rig, daq):
    drive(rig)
    first = daq.acquire_periods(100.0, 2)
    second = daq.acquire()
    assert second.t0_s == pytest.approx(first.t0_s + first.duration_s, abs=1e-6)
    assert second.block_id == first.block_id + 1


@pytest.mark.parametrize("fault", [
    lambda f: f[:10] + f[11:],                          # lost frame
    lambda f: f[:10] + [f[10]] + f[10:],                # duplicated frame
    lambda f: f[:10] + [bytes(64)] + f[11:],            # corrupt frame
    lambda f: f[:10] + [f[10][:32]] + f[11:],           # wrong length
    lambda f: f[:-1],                                   # last frame lost
])
def test_bad_block_is_resent_and_the_clean_copy_returned(rig, daq, daq_twin, fault):
    drive(rig)
    reference = daq.acquire_periods(100.0, 4)
    daq_twin.inject_fault(fault)
    block = daq.acquire()
    assert block.resends == 1
    assert block.n_samples == reference.n_samples
    # the resent copy is the same block (same plant time), not a new acquisition
    assert block.t0_s == pytest.approx(reference.t0_s + reference.duration_s, abs=1e-6)


def test_persistently_bad_block_raises_instead_of_returning_data(rig, daq, daq_twin):
    drive(rig)
    daq.configure(25_600.0, 256)
    for _ in range(daq.max_resends + 1):
        daq_twin.inject_fault(lambda f: f[:3] + f[4:])
    with pytest.raises(BlockIntegrityError, match="RESEND"):
        daq.acquire()


def test_lost_end_of_block_triggers_resend(rig, daq, daq_twin, mocker):
    drive(rig)
    daq.configure(25_600.0, 256)
    real_send = daq_twin._send
    dropped = []

    def drop_first_end(frame_id, data):
        if frame_id == codec.ID_BLOCK_END and not dropped:
            dropped.append(data)
            return
        real_send(frame_id, data)

    mocker.patch.object(daq_twin, "_send", side_effect=drop_first_end)
    daq.timeout_s = 0.3
    block = daq.acquire()
    assert dropped and block.resends == 1


def test_trigger_without_arm_is_reported(daq):
    daq.configure(25_600.0, 100)
    daq.trigger()
    with pytest.raises(InstrumentError, match="NOT_ARMED"):
        daq.read_block(timeout_s=1.0)


def test_absent_daq_times_out_in_bounded_time(can_channel):
    daq = CanFdDaq(open_can_bus(f"virtual:{can_channel}-nobody"), CHANNELS, timeout_s=0.2)
    start = time.monotonic()
    with pytest.raises(InstrumentTimeout):
        daq.configure(25_600.0, 100)
    assert time.monotonic() - start < 1.0
    daq.close()


def test_invalid_configuration_is_refused_by_the_driver(daq):
    with pytest.raises(ValueError, match="sample rate"):
        daq.configure(500e3, 100)


def test_data_frames_on_the_bus_decode_with_cantools(rig, daq, can_channel):
    import cantools
    drive(rig)
    listener_bus = can.Bus(interface="virtual", channel=can_channel)
    block = daq.acquire_periods(100.0, 1)
    db = cantools.database.load_file(codec.dbc_path())
    frames = []
    while (msg := listener_bus.recv(timeout=0.2)) is not None:
        if msg.arbitration_id == codec.ID_BLOCK_DATA:
            frames.append(db.decode_message(msg.arbitration_id, msg.data))
    listener_bus.shutdown()
    volts = [f[f"Sample{i:02d}"] for f in frames for i in range(f["NValid"])]
    force_V = np.asarray(volts).reshape(-1, 3)[:, 0]
    assert np.allclose(force_V, block.force_V, atol=2e-6)


@needs_fake_rig
def test_daq_reachable_from_another_process_through_the_tcp_bridge():
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    script = (
        "import sys; sys.path.insert(0, %r)\n"
        "from tests.drivers.fake_rig import FakeRig\n"
        "from drivers import run_standalone\n"
        "run_standalone(FakeRig(), print_fn=lambda s: print(s, flush=True))\n" % root)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        urls = {}
        while "daq_bridge" not in urls:
            line = proc.stdout.readline()
            assert line, "standalone twins exited early"
            name, url = line.split()
            urls[name] = url
        with ScpiFunctionGenerator(urls["generator"], timeout_s=2.0) as gen:
            gen.configure_sine()
            gen.set_frequency(50.0)
            gen.set_amplitude(2.0)
            gen.set_output(True)
            daq = CanFdDaq(open_can_bus(urls["daq_bridge"]), CHANNELS, timeout_s=2.0)
            block = daq.acquire_periods(50.0, 5)
            daq.close()
        assert np.max(np.abs(block.force_N)) == pytest.approx(AMP_N_PER_V * 1.0, rel=2e-3)
    finally:
        proc.terminate()
        proc.wait(timeout=5)
