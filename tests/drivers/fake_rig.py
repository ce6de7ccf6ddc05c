"""A linear stand-in for ``sim.rig.SimulatedRig`` with exactly its interface.

Steady-state mass-spring-damper driven by the generator output; sensor voltages with the
sensitivities below. Its numbers are independent facts for the driver tests (force peak
= AMP_N_PER_V x Vpp/2, gap = STANDOFF_M at rest).
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass

import numpy as np
import pytest

from drivers import Channel, ChannelSpec

FORCE_V_PER_N = 0.0225          # impedance head, 22.5 mV/N
ACCEL_V_PER_M_S2 = 0.0102       # impedance head, 100 mV/g
DISP_V_PER_M = 8000.0           # eddy-current controller, 8 V/mm
AMP_N_PER_V = 10.0              # amplifier + shaker force per generator volt
STANDOFF_M = 1.0e-3

CHANNELS = (ChannelSpec(Channel.FORCE, FORCE_V_PER_N, "N"),
            ChannelSpec(Channel.ACCELERATION, ACCEL_V_PER_M_S2, "m/s^2"),
            ChannelSpec(Channel.DISPLACEMENT, DISP_V_PER_M, "m"))

# DRIVERS_TEST_REAL_RIG=1 runs the driver tests on sim.rig.SimulatedRig instead.
REAL_RIG = os.environ.get("DRIVERS_TEST_REAL_RIG") == "1"
needs_fake_rig = pytest.mark.skipif(REAL_RIG, reason="checks the stand-in plant's own numbers")


@dataclass
class RigBlock:
    t0_s: float
    fs_Hz: float
    force_V: np.ndarray
    accel_V: np.ndarray
    disp_V: np.ndarray


class FakeRig:
    """Linear mass-spring-damper in steady state, driven by the generator output."""

    def __init__(self, mass_kg: float = 2.0, stiffness_N_m: float = 2.0e6,
                 damping_ratio: float = 0.05, noise_V: float = 1e-5, seed: int = 1) -> None:
        self.lock = threading.Lock()
        self.m, self.k = mass_kg, stiffness_N_m
        self.c = 2.0 * damping_ratio * np.sqrt(stiffness_N_m * mass_kg)
        self.freq_Hz, self.amplitude_Vpp, self.offset_V, self.output_on = 1000.0, 0.1, 0.0, False
        self._t = 0.0
        self._noise_V = noise_V
        self._rng = np.random.default_rng(seed)
        self.generator_calls: list[dict] = []

    def set_generator(self, *, freq_Hz=None, amplitude_Vpp=None, offset_V=None, output_on=None):
        self.generator_calls.append(dict(freq_Hz=freq_Hz, amplitude_Vpp=amplitude_Vpp,
                                         offset_V=offset_V, output_on=output_on))
        if freq_Hz is not None:
            self.freq_Hz = freq_Hz
        if amplitude_Vpp is not None:
            self.amplitude_Vpp = amplitude_Vpp
        if offset_V is not None:
            self.offset_V = offset_V
        if output_on is not None:
            self.output_on = output_on

    def _displacement_m(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w = 2.0 * np.pi * self.freq_Hz
        f0 = AMP_N_PER_V * self.amplitude_Vpp / 2.0 if self.output_on else 0.0
        h = 1.0 / (self.k - self.m * w * w + 1j * self.c * w)
        x = np.imag(f0 * h * np.exp(1j * w * t))
        a = -w * w * x
        force = f0 * np.sin(w * t)
        return force, a, x

    def run(self, n_samples: int, fs_Hz: float) -> RigBlock:
        t = self._t + np.arange(n_samples) / fs_Hz
        force, a, x = self._displacement_m(t)
        noise = self._rng.normal(0.0, self._noise_V, size=(3, n_samples))
        block = RigBlock(self._t, fs_Hz, force * FORCE_V_PER_N + noise[0],
                         a * ACCEL_V_PER_M_S2 + noise[1], x * DISP_V_PER_M + noise[2])
        self._t += n_samples / fs_Hz
        return block

    def gap_m(self) -> float:
        return STANDOFF_M + float(self._displacement_m(np.array([self._t]))[2][0])

    @property
    def time_s(self) -> float:
        return self._t


class RecordingRig:
    """Wraps any plant with the SimulatedRig interface and remembers the last generator
    settings it was given, so tests can check what the twins pushed to the plant."""

    def __init__(self, inner) -> None:
        self._inner = inner
        self.lock = inner.lock
        self.freq_Hz = self.amplitude_Vpp = self.offset_V = None
        self.output_on = None

    def set_generator(self, *, freq_Hz=None, amplitude_Vpp=None, offset_V=None, output_on=None):
        for name, value in (("freq_Hz", freq_Hz), ("amplitude_Vpp", amplitude_Vpp),
                            ("offset_V", offset_V), ("output_on", output_on)):
            if value is not None:
                setattr(self, name, value)
        self._inner.set_generator(freq_Hz=freq_Hz, amplitude_Vpp=amplitude_Vpp,
                                  offset_V=offset_V, output_on=output_on)

    def run(self, n_samples: int, fs_Hz: float):
        return self._inner.run(n_samples, fs_Hz)

    def gap_m(self) -> float:
        return self._inner.gap_m()

    @property
    def time_s(self) -> float:
        return self._inner.time_s
