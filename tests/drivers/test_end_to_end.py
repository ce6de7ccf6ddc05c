"""The whole chain on the real plant: SCPI drive -> SimulatedRig -> CAN FD DAQ and Modbus
sensor, each instrument reached through its own driver and transport."""

import math

import numpy as np
import pytest

from drivers import CanFdDaq, ModbusEddySensor, ScpiFunctionGenerator, open_can_bus, start_twins
from sim.rig import SimulatedRig
from tests.drivers.plant import channel_specs, fundamental

pytestmark = pytest.mark.timeout(60)

FREQ_HZ = 1000.0        # far above the friction resonance (~50-80 Hz): a free mass
DRIVE_VPP = 1.0


def test_drive_measure_and_switch_off_through_all_three_drivers():
    rig = SimulatedRig()
    model = rig.model
    with start_twins(rig) as twins:
        sensor = ModbusEddySensor(twins.sensor_url)
        daq = CanFdDaq(open_can_bus(twins.daq_url), channel_specs(model))
        gen = ScpiFunctionGenerator(twins.generator_url, drive_limit_V=2.0)
        try:
            at_rest = sensor.read_gap()
            gen.configure_sine()
            gen.set_frequency(FREQ_HZ)
            gen.set_amplitude(DRIVE_VPP)
            gen.set_output(True)
            daq.acquire_periods(FREQ_HZ, 50)               # let the start transient ring down
            driven = daq.acquire_periods(FREQ_HZ, 100)
            gap_driven = sensor.read_gap()
            gen.safe_off()
            output_after_safe_off = gen.output_enabled()
            after_off = daq.acquire_periods(FREQ_HZ, 100)
        finally:
            gen.safe_off()
            gen.close()
            daq.close()
            sensor.close()

    # the probe sees its stand-off at rest, and the carriage stays in micro-slip (<< x_s)
    assert at_rest.gap_mm == pytest.approx(model.probe_standoff_m * 1e3, abs=1e-6)
    assert gap_driven.in_range
    assert gap_driven.gap_mm == pytest.approx(model.probe_standoff_m * 1e3, abs=model.x_s_m * 1e3)

    # force = amplifier gain x generator amplitude (Vpp / 2)
    force = fundamental(driven.force_N, driven.fs_Hz, FREQ_HZ)
    assert abs(force) == pytest.approx(model.amp_gain_N_per_V * DRIVE_VPP / 2.0, rel=1e-3)

    # far above resonance the carriage is a free mass: a / P = 1 / m, in phase
    accel = fundamental(driven.accel_m_s2, driven.fs_Hz, FREQ_HZ)
    ratio = accel / force
    assert ratio.real == pytest.approx(1.0 / model.mass_kg, rel=0.02)
    assert abs(math.atan2(ratio.imag, ratio.real)) < 0.01

    # after safe_off the output is off and the DAQ sees only the force sensor's noise
    assert output_after_safe_off is False
    assert not rig.gen.output_on
    assert np.max(np.abs(after_off.force_N)) < 6.0 * model.force_noise_N
