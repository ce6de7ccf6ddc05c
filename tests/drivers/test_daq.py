"""CanFdDaq against the DAQ twin: physical units, integer periods, integrity, failures."""

import math
import os
import subprocess
import sys
import threading
import time

import can
import numpy as np
import pytest

from drivers import (
    BlockIntegrityError,
    CanFdDaq,
    InstrumentError,
    InstrumentTimeout,
    ScpiFunctionGenerator,
    open_can_bus,
    plan_block,
)
from drivers import _daq_codec as codec
from sim.rig import RigModel
from tests.drivers.plant import channel_specs, fundamental

pytestmark = pytest.mark.timeout(60)

FAR_ABOVE_RESONANCE_HZ = 1000.0   # the friction resonance of the default rig is ~50-80 Hz


def drive(rig, freq_Hz=100.0, amplitude_Vpp=1.0):
    rig.set_generator(freq_Hz=freq_Hz, amplitude_Vpp=amplitude_Vpp, output_on=True)


def test_block_is_in_physical_units_of_the_channel_sensitivities(rig, daq, channels):
    drive(rig, freq_Hz=FAR_ABOVE_RESONANCE_HZ, amplitude_Vpp=1.0)
    block = daq.acquire_periods(FAR_ABOVE_RESONANCE_HZ, 50)
    # independent fact: the amplifier makes amp_gain_N_per_V newton per generator volt
    expected_force_N = rig.model.amp_gain_N_per_V * 1.0 / 2.0
    force_N = abs(fundamental(block.force_N, block.fs_Hz, FAR_ABOVE_RESONANCE_HZ))
    assert force_N == pytest.approx(expected_force_N, rel=1e-3)
    assert block.force_V == pytest.approx(block.force_N * channels[0].sensitivity_V_per_unit)


def test_far_above_resonance_the_carriage_accelerates_as_a_free_mass(rig, daq):
    f = FAR_ABOVE_RESONANCE_HZ
    drive(rig, freq_Hz=f, amplitude_Vpp=1.0)
    daq.acquire_periods(f, 50)                        # let the start transient ring down
    block = daq.acquire_periods(f, 100)
    force = fundamental(block.force_N, block.fs_Hz, f)
    accel = fundamental(block.accel_m_s2, block.fs_Hz, f)
    disp = fundamental(block.disp_m, block.fs_Hz, f)
    # Newton for a free mass: a = P / m, in phase with the force (the friction's
    # stiffness adds (f_res / f)^2, under 1 % at 1 kHz)
    assert (accel / force).real == pytest.approx(1.0 / rig.model.mass_kg, rel=0.02)
    assert abs(math.atan2((accel / force).imag, (accel / force).real)) < 0.01
    # kinematics between two independent sensors: x = -a / omega^2
    assert disp == pytest.approx(-accel / (2 * math.pi * f) ** 2, rel=0.02)


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


def test_a_block_of_samples_is_the_one_asked_for_and_configured_only_when_it_changes(rig, daq, mocker):
    """The ramp's blocks (a period and the wait to a quarter phase) are all of one length:
    the DAQ is configured for the first only (decision 0083, third addendum)."""
    drive(rig)
    configure = mocker.spy(daq, "configure")
    a, b, c = (daq.acquire_samples(25_600.0, n) for n in (384, 384, 100))
    assert (a.n_samples, b.n_samples, c.n_samples) == (384, 384, 100)
    assert a.fs_Hz == b.fs_Hz == c.fs_Hz == 25_600.0
    assert b.t0_s == pytest.approx(a.t0_s + 384 / 25_600.0, abs=1e-6)
    assert [call.args for call in configure.call_args_list] == [(25_600.0, 384), (25_600.0, 100)]


class HeldPlant:
    """The real plant, but each block waits for ``release``: a plant slower than real
    time, as the first run of a process is (it compiles the kernel)."""

    def __init__(self, rig, monkeypatch) -> None:
        self.entered, self.release, self.finished = (threading.Event() for _ in range(3))
        real_run = rig.plant.run

        def held_run(n_samples, fs_Hz):
            self.entered.set()
            self.release.wait(30.0)
            try:
                return real_run(n_samples, fs_Hz)
            finally:
                self.finished.set()

        monkeypatch.setattr(rig, "run", held_run)


def test_daq_reporting_acquiring_is_waited_for_beyond_the_timeout(rig, daq, monkeypatch):
    drive(rig)
    daq.configure(25_600.0, 256)
    held = HeldPlant(rig, monkeypatch)
    release = threading.Timer(2.0 * daq.timeout_s, held.release.set)
    release.start()
    try:
        block = daq.acquire()
    finally:
        release.cancel()
        held.release.set()
    assert (block.n_samples, block.t0_s, block.resends) == (256, 0.0, 0)


def test_daq_busy_longer_than_max_busy_times_out(rig, daq, monkeypatch):
    drive(rig)
    daq.configure(25_600.0, 256)
    daq.max_busy_s = 0.5
    held = HeldPlant(rig, monkeypatch)
    start = time.monotonic()
    try:
        with pytest.raises(InstrumentTimeout):
            daq.acquire()
    finally:
        held.release.set()
    assert time.monotonic() - start < daq.timeout_s + daq.max_busy_s + 1.0


def test_twin_closed_mid_block_abandons_it_and_never_raises_in_its_thread(
        rig, daq, daq_twin, monkeypatch):
    thread_errors = []
    monkeypatch.setattr(threading, "excepthook", thread_errors.append)
    threads_before = set(threading.enumerate())
    drive(rig)
    daq.configure(25_600.0, 256)
    held = HeldPlant(rig, monkeypatch)
    daq.arm()
    daq.trigger()
    assert held.entered.wait(10.0)
    daq_twin.close()
    assert not daq_twin._thread.is_alive()      # did not wait for the plant
    frames_at_close = daq_twin.frames_sent
    held.release.set()
    assert held.finished.wait(10.0)
    for thread in set(threading.enumerate()) - threads_before:
        thread.join(timeout=5.0)
    assert daq_twin.frames_sent == frames_at_close
    assert thread_errors == []


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


def test_absent_daq_times_out_in_bounded_time(can_channel, channels):
    daq = CanFdDaq(open_can_bus(f"virtual:{can_channel}-nobody"), channels, timeout_s=0.2)
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


def test_daq_reachable_from_another_process_through_the_tcp_bridge():
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    script = (
        "import sys; sys.path.insert(0, %r)\n"
        "from drivers import run_standalone\n"
        "run_standalone(print_fn=lambda s: print(s, flush=True))\n" % root)
    model = RigModel()  # run_standalone's default plant
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
            daq = CanFdDaq(open_can_bus(urls["daq_bridge"]), channel_specs(model),
                           timeout_s=2.0)
            try:
                block = daq.acquire_periods(50.0, 5)
            finally:
                daq.close()
        force_N = abs(fundamental(block.force_N, block.fs_Hz, 50.0))
        assert force_N == pytest.approx(model.amp_gain_N_per_V * 2.0 / 2.0, rel=1e-3)
    finally:
        proc.terminate()
        proc.wait(timeout=5)
