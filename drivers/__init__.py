"""Instrument drivers of the test bench, and the simulated twins they can talk to.

Public surface (everything else is private implementation):

- protocols: FunctionGenerator, Daq, DisplacementSensor; records Identity, ChannelSpec,
  Channel, DaqBlock, GapReading, SensorStatus, TargetMaterial
- drivers: ScpiFunctionGenerator (SCPI over serial/TCP or a VISA resource; is_visa_resource
  tells which strings go to pyvisa, VisaTransport), CanFdDaq (CAN FD, python-can),
  ModbusEddySensor (Modbus TCP/RTU), open_can_bus, plan_block (and the DAQ's
  MAX_BLOCK_SAMPLES, MAX_SAMPLE_RATE_HZ)
- twins: start_twins, run_standalone, Twins
- errors: InstrumentError and its subclasses
- URL allow-lists: check_generator_url, check_sensor_url, check_daq_url
"""

import logging

from ._can_transport import CanTcpBridge, TcpCanBus, open_can_bus
from ._daq import MAX_BLOCK_SAMPLES, MAX_SAMPLE_RATE_HZ, CanFdDaq, plan_block
from ._daq_codec import dbc_path
from ._eddy_sensor import ModbusEddySensor
from ._errors import (
    BlockIntegrityError,
    ConnectionLost,
    FrameError,
    InstrumentError,
    InstrumentTimeout,
    ModbusError,
    ProtocolError,
    SafetyInterlock,
    ScpiError,
)
from ._function_generator import ScpiFunctionGenerator
from ._interfaces import (
    Channel,
    ChannelSpec,
    Daq,
    DaqBlock,
    DisplacementSensor,
    FunctionGenerator,
    GapReading,
    Identity,
    SensorStatus,
    TargetMaterial,
)
from ._twins import Twins, run_standalone, start_twins
from ._urls import check_daq_url, check_generator_url, check_sensor_url
from ._visa_transport import VisaTransport, is_visa_resource

log = logging.getLogger(__name__)

__all__ = [
    "MAX_BLOCK_SAMPLES", "MAX_SAMPLE_RATE_HZ",
    "BlockIntegrityError", "CanFdDaq", "CanTcpBridge", "Channel", "ChannelSpec",
    "ConnectionLost", "Daq", "DaqBlock", "DisplacementSensor", "FrameError",
    "FunctionGenerator", "GapReading", "Identity", "InstrumentError", "InstrumentTimeout",
    "ModbusEddySensor", "ModbusError", "ProtocolError", "SafetyInterlock", "ScpiError",
    "ScpiFunctionGenerator", "SensorStatus", "TargetMaterial", "TcpCanBus", "Twins",
    "VisaTransport", "check_daq_url", "check_generator_url", "check_sensor_url", "dbc_path",
    "is_visa_resource", "open_can_bus", "plan_block", "run_standalone", "start_twins",
]
