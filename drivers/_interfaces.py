"""What each instrument can do, as small structural protocols.

A real driver and its simulated twin's client satisfy the same protocol; nothing above
the driver layer (procedures, bench) needs to know which one it holds. The records
returned by the drivers are small frozen dataclasses with units in their field names.
"""

from __future__ import annotations

import enum
import logging
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from sim.errors import ConfigurationError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Identity:
    """Who the instrument says it is (stored with the data)."""

    manufacturer: str
    model: str
    serial: str
    firmware: str


@runtime_checkable
class FunctionGenerator(Protocol):
    """A sine source driving the power amplifier."""

    def identify(self) -> Identity: ...
    def set_frequency(self, freq_Hz: float) -> float: ...
    def set_amplitude(self, amplitude_Vpp: float) -> float: ...
    def set_offset(self, offset_V: float) -> float: ...
    def set_output(self, on: bool) -> None: ...
    def output_enabled(self) -> bool: ...
    def set_voltage_limits(self, low_V: float, high_V: float) -> None: ...
    def read_errors(self) -> list[tuple[int, str]]: ...
    def safe_off(self) -> None: ...
    def close(self) -> None: ...


class Channel(enum.Enum):
    """The three simultaneously sampled DAQ inputs, in wire order."""

    FORCE = 0
    ACCELERATION = 1
    DISPLACEMENT = 2


@dataclass(frozen=True)
class ChannelSpec:
    """Transducer on one DAQ input: sensitivity in volts per physical unit."""

    channel: Channel
    sensitivity_V_per_unit: float
    unit: str

    def __post_init__(self) -> None:
        if not np.isfinite(self.sensitivity_V_per_unit) or self.sensitivity_V_per_unit == 0.0:
            raise ConfigurationError(f"{self.channel.name}: sensitivity must be finite and non-zero, "
                             f"got {self.sensitivity_V_per_unit!r}")


@dataclass(frozen=True)
class DaqBlock:
    """One acquired block, all channels sampled on the same clock.

    ``force_N``, ``accel_m_s2`` and ``disp_m`` are in physical units (SI) after the channel
    sensitivities; the ``*_V`` arrays are the input voltages as the ADC saw them.
    """

    block_id: int
    t0_s: float
    fs_Hz: float
    force_N: np.ndarray
    accel_m_s2: np.ndarray
    disp_m: np.ndarray
    force_V: np.ndarray = field(repr=False)
    accel_V: np.ndarray = field(repr=False)
    disp_V: np.ndarray = field(repr=False)
    resends: int = 0

    @property
    def n_samples(self) -> int:
        return int(self.force_N.shape[0])

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.fs_Hz


@runtime_checkable
class Daq(Protocol):
    """Arm -> trigger -> read one block (``acquire``), or one of an integer number of periods
    at a sample rate of at least ``min_rate_Hz`` (``acquire_periods``)."""

    channels: tuple[ChannelSpec, ...]

    def configure(self, sample_rate_Hz: float, n_samples: int) -> None: ...
    @property
    def sample_rate_Hz(self) -> float: ...
    def arm(self) -> None: ...
    def trigger(self) -> None: ...
    def read_block(self, timeout_s: float | None = None) -> DaqBlock: ...
    def acquire(self) -> DaqBlock: ...
    def acquire_periods(self, freq_Hz: float, n_periods: int, min_rate_Hz: float = 25_600.0) -> DaqBlock: ...
    def acquire_samples(self, sample_rate_Hz: float, n_samples: int) -> DaqBlock: ...
    def close(self) -> None: ...


class TargetMaterial(enum.IntEnum):
    """Target calibrations of the eddy-current controller (register 101)."""

    STEEL = 0
    ALUMINIUM = 1
    STAINLESS = 2
    CUSTOM = 3


class SensorStatus(enum.IntFlag):
    """Status bits of the eddy-current controller (register 4)."""

    OK = 0
    TARGET_TOO_FAR = 0x0001
    TARGET_TOO_CLOSE = 0x0002
    PROBE_FAULT = 0x0004
    TEMPERATURE_WARNING = 0x0008
    ZERO_ACTIVE = 0x0010


@dataclass(frozen=True)
class GapReading:
    """A slow gap reading with the status that qualifies it."""

    gap_mm: float
    status: SensorStatus
    temperature_C: float

    @property
    def in_range(self) -> bool:
        return not (self.status & (SensorStatus.TARGET_TOO_FAR | SensorStatus.TARGET_TOO_CLOSE
                                   | SensorStatus.PROBE_FAULT))


@runtime_checkable
class DisplacementSensor(Protocol):
    """Eddy-current displacement sensor: configuration and slow readings."""

    def identify(self) -> Identity: ...
    def range_mm(self) -> float: ...
    def read_gap(self) -> GapReading: ...
    def zero(self) -> float: ...
    def clear_zero(self) -> None: ...
    def zero_offset_mm(self) -> float: ...
    def set_target_material(self, material: TargetMaterial) -> None: ...
    def target_material(self) -> TargetMaterial: ...
    def set_filter(self, cutoff_code: int) -> None: ...
    def status(self) -> SensorStatus: ...
    def close(self) -> None: ...
