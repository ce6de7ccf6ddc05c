"""Multi-harmonic least-squares sine fit (IEEE 1057 three-parameter fit, extended to
harmonics) at a known frequency, over an integer number of periods.

    x(t) = c + sum_k [a_k sin(k w t) + b_k cos(k w t)],  k = 1..K

gives each harmonic's amplitude and phase (phase of a sine: x_k = A_k sin(k w t + phi_k)),
THD = sqrt(sum_{k>=2} A_k^2) / A_1, and a noise estimate from the fit residual (rms).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from sim.records import lsq_harmonics

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class HarmonicFit:
    freq_Hz: float
    amplitude: np.ndarray    # A_k, k = 1..K
    phase_rad: np.ndarray    # phi_k
    offset: float
    noise_rms: float         # rms of the residual
    peak_to_peak: float      # of the fitted periodic signal (Eq. 9 uses (max - min) / 2)
    raw_peak_to_peak: float  # of the record itself (biased by noise and free vibration)

    @property
    def fundamental(self) -> complex:
        """Complex amplitude of the fundamental, A_1 exp(i phi_1)."""
        return complex(self.amplitude[0] * np.exp(1j * self.phase_rad[0]))

    @property
    def thd(self) -> float:
        if self.amplitude[0] == 0:
            return float("inf")
        return float(np.sqrt(np.sum(self.amplitude[1:] ** 2)) / self.amplitude[0])


def fit_harmonics(x: np.ndarray, fs_Hz: float, freq_Hz: float, n_harmonics: int = 5) -> HarmonicFit:
    """Least-squares fit of the fundamental and ``n_harmonics - 1`` harmonics."""
    x = np.asarray(x, dtype=np.float64)
    if n_harmonics < 1:
        raise ValueError(f"n_harmonics must be >= 1, got {n_harmonics}")
    if x.ndim != 1 or x.size < 2 * n_harmonics + 2:
        raise ValueError(f"need a 1-D record of at least {2 * n_harmonics + 2} samples, got shape {x.shape}")
    if not (fs_Hz > 0 and freq_Hz > 0):
        raise ValueError(f"need fs_Hz > 0 and freq_Hz > 0, got {fs_Hz!r}, {freq_Hz!r}")
    if 2 * n_harmonics * freq_Hz >= fs_Hz:
        # above Nyquist a harmonic's columns alias onto lower ones: the least-squares split
        # between them is arbitrary and every amplitude, the fundamental's too, comes out wrong
        raise ValueError(f"harmonic {n_harmonics} of {freq_Hz:g} Hz is at or above the Nyquist "
                         f"frequency {fs_Hz / 2:g} Hz of the record (sample rate {fs_Hz:g} S/s)")
    if not np.all(np.isfinite(x)):
        raise ValueError("record contains NaN or inf")
    C, c, noise = lsq_harmonics(x, fs_Hz, freq_Hz, n_harmonics)     # C_k = a_k + i b_k
    a, b = C.real, C.imag
    k = np.arange(1, n_harmonics + 1)
    # one period of the fitted signal, finely sampled: the steady periodic response
    wt1 = 2 * np.pi * np.outer(np.arange(1024) / 1024, k)
    periodic = np.sin(wt1) @ a + np.cos(wt1) @ b
    return HarmonicFit(freq_Hz=float(freq_Hz), amplitude=np.abs(C), phase_rad=np.angle(C),
                       offset=float(c), noise_rms=float(noise),
                       peak_to_peak=float(periodic.max() - periodic.min()),
                       raw_peak_to_peak=float(x.max() - x.min()))
