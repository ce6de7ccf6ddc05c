"""Fixtures for the driver tests: the real plant, and twins on ephemeral loopback ports.

``rig`` is ``sim.rig.SimulatedRig`` with its default model, wrapped in
:class:`~tests.drivers.plant.RecordingRig` so tests can see the generator settings the
twins pushed into it.
"""

from __future__ import annotations

import itertools
import os

import pytest

from drivers import CanFdDaq, open_can_bus, start_twins
from drivers._daq_twin import DaqTwin
from drivers._eddy_twin import EddySensorModel, EddySensorTcpTwin
from drivers._pty import PtyPair
from drivers._scpi_twin_model import ScpiGeneratorModel
from drivers._scpi_twin_server import ScpiTcpServer
from sim.rig import SimulatedRig
from tests.drivers.plant import RecordingRig, channel_specs


@pytest.fixture
def rig():
    """The real plant, wrapped so tests can see the generator settings pushed into it."""
    return RecordingRig(SimulatedRig())


@pytest.fixture
def channels(rig):
    """DAQ channel specs with the plant's own sensor sensitivities."""
    return channel_specs(rig.model)


@pytest.fixture
def twins(rig):
    """All three twins on ephemeral loopback ports, closed after the test."""
    t = start_twins(rig)
    yield t
    t.close()


# --------------------------------------------------------------------- single twins
_virtual_channels = itertools.count(1)


@pytest.fixture
def scpi_model(rig):
    return ScpiGeneratorModel(rig)


@pytest.fixture
def scpi_server(scpi_model):
    """The SCPI twin on an ephemeral loopback TCP port."""
    server = ScpiTcpServer(scpi_model)
    yield server
    server.close()


@pytest.fixture
def pty_pair():
    pair = PtyPair()
    yield pair
    pair.close()


@pytest.fixture
def can_channel():
    return f"test-daq-{os.getpid()}-{next(_virtual_channels)}"


@pytest.fixture
def daq_twin(rig, can_channel):
    twin = DaqTwin(rig, open_can_bus(f"virtual:{can_channel}"))
    yield twin
    twin.close()


@pytest.fixture
def daq(daq_twin, can_channel, channels):
    driver = CanFdDaq(open_can_bus(f"virtual:{can_channel}"), channels, timeout_s=1.0)
    yield driver
    driver.close()


@pytest.fixture
def sensor_model(rig):
    return EddySensorModel(rig)


@pytest.fixture
def sensor_twin(sensor_model):
    """The eddy-current sensor twin on an ephemeral loopback Modbus TCP port."""
    twin = EddySensorTcpTwin(sensor_model)
    yield twin
    twin.close()
