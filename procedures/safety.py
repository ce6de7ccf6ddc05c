"""Safety supervisor: limits checked on every drive command and every acquired block.

The procedure never holds the raw instruments: it gets :class:`SupervisedGenerator` and
:class:`SupervisedDaq`, through which every amplitude request and every block passes,
whatever code path asked for it (control iterations, settling, ramps, measurement).  A
violation ramps the output down, switches it off, records why, and raises
:class:`LimitExceeded`; after a trip nothing can switch the output on again.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from drivers import GapReading
from sim.errors import LimitError

from .instruments import Block, Daq, GapSensor, Generator
from .plan import Limits

log = logging.getLogger(__name__)


class LimitExceeded(LimitError):
    """A safety limit was reached; the output has been ramped down and switched off."""


def tightest(a: Limits, b: Limits | None) -> Limits:
    """Each limit the smaller of the two; a limit ``b`` leaves out (None) is ``a``'s."""
    if b is None:
        return a
    return Limits(*(x if y is None else min(x, y) for x, y in zip(
        (a.drive_V, a.force_N, a.disp_m, a.accel_m_s2), (b.drive_V, b.force_N, b.disp_m, b.accel_m_s2))))


@dataclass
class Trip:
    reason: str
    value: float
    limit: float


class Supervisor:
    def __init__(self, limits: Limits, generator: Generator, ramp_steps: int = 8):
        self.limits = limits
        self._gen = generator
        self.ramp_steps = ramp_steps
        self.trip_record: Trip | None = None
        self.x_ref_m = 0.0
        self.amplitude_Vpp = 0.0

    # ------------------------------------------------------------------ checks
    def check_drive(self, amplitude_Vpp: float, offset_V: float = 0.0) -> None:
        peak = abs(offset_V) + amplitude_Vpp / 2
        if peak > self.limits.drive_V * (1 + 1e-9):
            self.trip("drive voltage", peak, self.limits.drive_V, "V amplitude", "drive_V")

    def check_block(self, block: Block) -> None:
        checks = (("force", float(np.max(np.abs(block.force_N))), self.limits.force_N, "N", "force_N"),
                  ("acceleration", float(np.max(np.abs(block.accel_m_s2))), self.limits.accel_m_s2, "m/s^2",
                   "accel_m_s2"),
                  ("displacement", float(np.max(np.abs(block.disp_m - self.x_ref_m))), self.limits.disp_m, "m",
                   "disp_m"))
        for name, value, limit, unit, key in checks:
            if value > limit:
                self.trip(name, value, limit, unit, key)

    # ------------------------------------------------------------------ shutdown
    def trip(self, reason: str, value: float, limit: float, unit: str = "", key: str = "") -> None:
        """Record the first trip, ramp down and switch off; raise LimitExceeded.  The text
        gives the unit and the limit's key, e.g. 'drive voltage 7.2 V amplitude exceeds the
        limit 7 V (drive_V)': voltages are amplitudes, |offset| + Vpp/2 (decision 0029)."""
        u = f" {unit}" if unit else ""
        text = f"{reason} {value:.4g}{u} exceeds the limit {limit:.4g}{u.replace(' amplitude', '')}" + \
            (f" ({key})" if key else "")
        if self.trip_record is None:
            self.trip_record = Trip(reason, value, limit)
            log.error("LIMIT: %s; ramping down and switching off", text)
            self.shutdown()
        raise LimitExceeded(text)

    def shutdown(self) -> None:
        """Ramp the amplitude down, then output off.  Never raises."""
        try:
            v = self.amplitude_Vpp
            for k in range(self.ramp_steps - 1, 0, -1):
                if v <= 0:
                    break
                self._gen.set_amplitude(max(v * k / self.ramp_steps, 2e-3))
        except Exception as exc:  # noqa: BLE001 - output off must still be tried
            log.error("ramp-down failed (%s); switching off directly", exc)
        self._gen.safe_off()
        self.amplitude_Vpp = 0.0


class SupervisedGenerator:
    """The function generator as the procedure sees it."""

    def __init__(self, generator: Generator, supervisor: Supervisor):
        self._gen, self._sup = generator, supervisor

    def set_frequency(self, freq_Hz: float) -> float:
        return self._gen.set_frequency(freq_Hz)

    def set_amplitude(self, amplitude_Vpp: float) -> float:
        self._sup.check_drive(amplitude_Vpp)
        got = self._gen.set_amplitude(amplitude_Vpp)
        self._sup.amplitude_Vpp = got
        return got

    def set_output(self, on: bool) -> None:
        if on and self._sup.trip_record is not None:
            raise LimitExceeded(f"output stays off after a trip ({self._sup.trip_record.reason})")
        self._gen.set_output(on)

    def safe_off(self) -> None:
        self._gen.safe_off()
        self._sup.amplitude_Vpp = 0.0


class SupervisedDaq:
    """The DAQ as the procedure sees it: every block is checked before it is returned."""

    def __init__(self, daq: Daq, supervisor: Supervisor):
        self._daq, self._sup = daq, supervisor

    def acquire_periods(self, freq_Hz: float, n_periods: int, min_rate_Hz: float = 25600.0) -> Block:
        block = self._daq.acquire_periods(freq_Hz, n_periods, min_rate_Hz)
        self._sup.check_block(block)
        return block

    def acquire_samples(self, rate_Hz: float, n_samples: int) -> Block:
        block = self._daq.acquire_samples(rate_Hz, n_samples)
        self._sup.check_block(block)
        return block


def check_gap(sensor: GapSensor) -> GapReading:
    """The displacement sensor's reading, or :class:`LimitExceeded` when the target is out
    of its range (checked before each sweep: a lost target makes every limit blind)."""
    reading = sensor.read_gap()
    if not reading.in_range:
        raise LimitExceeded(f"displacement sensor reports {reading.status!r} "
                            f"(gap {reading.gap_mm:.4f} mm): target out of range")
    return reading


if TYPE_CHECKING:      # what the procedure is given fits what it asks for (mypy, `make check`)
    from .instruments import BlockSource, SineSource

    def _supervised_fit(g: SupervisedGenerator, d: SupervisedDaq) -> tuple[SineSource, BlockSource]:
        return g, d
