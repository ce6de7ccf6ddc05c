"""The drivers satisfy the protocols procedures are written against."""

import pytest

from drivers import (
    CanFdDaq,
    Channel,
    ChannelSpec,
    Daq,
    DisplacementSensor,
    FunctionGenerator,
    GapReading,
    ModbusEddySensor,
    ScpiFunctionGenerator,
    SensorStatus,
    open_can_bus,
)
from sim.rig import RigModel
from tests.drivers.plant import channel_specs

pytestmark = pytest.mark.timeout(60)

CHANNELS = channel_specs(RigModel())


def test_generator_driver_is_a_function_generator(scpi_server):
    gen = ScpiFunctionGenerator(scpi_server.url)
    assert isinstance(gen, FunctionGenerator)
    gen.close()


def test_sensor_driver_is_a_displacement_sensor(sensor_twin):
    sensor = ModbusEddySensor(sensor_twin.url)
    assert isinstance(sensor, DisplacementSensor)
    sensor.close()


def test_daq_driver_is_a_daq(can_channel):
    daq = CanFdDaq(open_can_bus(f"virtual:{can_channel}"), CHANNELS)
    assert isinstance(daq, Daq)
    daq.close()


def test_daq_refuses_channels_in_the_wrong_order(can_channel):
    bus = open_can_bus(f"virtual:{can_channel}")
    with pytest.raises(ValueError, match="FORCE, ACCELERATION, DISPLACEMENT"):
        CanFdDaq(bus, tuple(reversed(CHANNELS)))
    bus.shutdown()


def test_zero_sensitivity_is_rejected():
    with pytest.raises(ValueError, match="FORCE"):
        ChannelSpec(Channel.FORCE, 0.0, "N")


def test_gap_reading_out_of_range_when_target_too_close():
    assert not GapReading(0.0, SensorStatus.TARGET_TOO_CLOSE, 20.0).in_range
    assert GapReading(0.0, SensorStatus.ZERO_ACTIVE, 20.0).in_range
