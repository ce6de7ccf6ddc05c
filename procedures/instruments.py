"""What the procedures need from the instruments, declared where it is used.

Like a bluesky plan that takes ``Sequence[Readable]``, a procedure names the few methods
it calls, not a driver class: the supervised instruments of a run, the plant of a
Monte-Carlo study (:mod:`bench.studies.montecarlo`) and the raw drivers all fit these
protocols.  ``drivers._interfaces`` says what each driver offers; these say what is needed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np

from drivers import GapReading


class Block(Protocol):
    """One acquired block of whole periods, in physical units (drivers.DaqBlock fits)."""

    @property
    def force_N(self) -> np.ndarray: ...
    @property
    def accel_m_s2(self) -> np.ndarray: ...
    @property
    def disp_m(self) -> np.ndarray: ...
    @property
    def fs_Hz(self) -> float: ...
    @property
    def t0_s(self) -> float: ...
    @property
    def block_id(self) -> int: ...
    @property
    def resends(self) -> int: ...
    @property
    def n_samples(self) -> int: ...


class SineSource(Protocol):
    """The drive as the stepped-sine procedure changes it; setters return the value the
    instrument confirmed."""

    def set_frequency(self, freq_Hz: float) -> float: ...
    def set_amplitude(self, amplitude_Vpp: float) -> float: ...
    def set_output(self, on: bool) -> None: ...


class BlockSource(Protocol):
    """Blocks of whole periods (the procedure's measurements) or of a number of samples
    (waiting for a phase)."""

    def acquire_periods(self, freq_Hz: float, n_periods: int, min_rate_Hz: float = 25_600.0) -> Block: ...
    def acquire_samples(self, rate_Hz: float, n_samples: int) -> Block: ...


class StepMarker(Protocol):
    """Optional: told the step key before each measured block.  A simulated rig reseeds its
    noise there (decision record 0013); a real generator sends nothing."""

    def mark_step(self, key: str) -> None: ...


class Generator(Protocol):
    """What the safety supervisor needs from the raw function generator."""

    def set_frequency(self, freq_Hz: float) -> float: ...
    def set_amplitude(self, amplitude_Vpp: float) -> float: ...
    def set_output(self, on: bool) -> None: ...
    def safe_off(self) -> None: ...


class Daq(Protocol):
    """What the safety supervisor needs from the raw DAQ (drivers.CanFdDaq fits)."""

    def configure(self, sample_rate_Hz: float, n_samples: int) -> None: ...
    def acquire(self) -> Block: ...
    def acquire_periods(self, freq_Hz: float, n_periods: int, min_rate_Hz: float = 25_600.0) -> Block: ...
    def acquire_samples(self, rate_Hz: float, n_samples: int) -> Block: ...


class GapSensor(Protocol):
    """What the gap check before each sweep needs from the displacement sensor."""

    def read_gap(self) -> GapReading: ...


if TYPE_CHECKING:      # the real drivers fit these protocols: `make check` (mypy) proves it
    from drivers import CanFdDaq, ModbusEddySensor, ScpiFunctionGenerator

    def _drivers_fit(g: ScpiFunctionGenerator, d: CanFdDaq, s: ModbusEddySensor
                     ) -> tuple[Generator, StepMarker, Daq, GapSensor]:
        return g, g, d, s
