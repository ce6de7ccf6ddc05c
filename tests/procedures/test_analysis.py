"""fit_harmonics against synthetic records whose harmonics, offset and noise are known.

Tolerances come from least-squares theory, not from earlier output: with white noise of
rms sigma over N samples (whole periods), each sine/cosine coefficient has standard
deviation sigma sqrt(2/N), so an amplitude A_k is known to about sigma sqrt(2/N) and its
phase to sigma sqrt(2/N) / A_k; the offset to sigma / sqrt(N); the rms of the residual to a
relative 1 / sqrt(2 N).  The tests allow 5 standard deviations.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from procedures.analysis import fit_harmonics

FS_HZ = 25_600.0
FREQ_HZ = 100.0
PERIODS = 20
AMPLITUDES = np.array([2.0, 0.3, 0.1, 0.05, 0.02])
PHASES_RAD = np.array([0.4, -1.2, 2.5, 0.0, -2.9])
OFFSET = 0.7
NOISE_RMS = 0.01


def synthetic(noise_rms: float, seed: int = 12345) -> np.ndarray:
    """offset + sum_k A_k sin(k w t + phi_k) + white Gaussian noise, whole periods."""
    n = int(round(FS_HZ / FREQ_HZ)) * PERIODS
    t = np.arange(n) / FS_HZ
    k = np.arange(1, AMPLITUDES.size + 1)
    x = OFFSET + (AMPLITUDES * np.sin(2 * np.pi * FREQ_HZ * np.outer(t, k) + PHASES_RAD)).sum(axis=1)
    return x + np.random.default_rng(seed).normal(0.0, noise_rms, n)


def wrapped(angle: np.ndarray) -> np.ndarray:
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def test_noise_free_record_gives_the_exact_harmonics_offset_and_zero_residual():
    fit = fit_harmonics(synthetic(0.0), FS_HZ, FREQ_HZ, AMPLITUDES.size)
    np.testing.assert_allclose(fit.amplitude, AMPLITUDES, rtol=1e-9)
    np.testing.assert_allclose(wrapped(fit.phase_rad - PHASES_RAD), 0.0, atol=1e-9)
    assert fit.offset == pytest.approx(OFFSET, abs=1e-12)
    assert fit.noise_rms < 1e-12
    assert fit.fundamental == pytest.approx(AMPLITUDES[0] * np.exp(1j * PHASES_RAD[0]), abs=1e-9)


def test_noisy_record_recovers_amplitudes_phases_and_offset_within_the_noise():
    x = synthetic(NOISE_RMS)
    fit = fit_harmonics(x, FS_HZ, FREQ_HZ, AMPLITUDES.size)
    sd_amp = NOISE_RMS * math.sqrt(2 / x.size)
    np.testing.assert_allclose(fit.amplitude, AMPLITUDES, rtol=0, atol=5 * sd_amp)
    for k, (got, want, amp) in enumerate(zip(fit.phase_rad, PHASES_RAD, AMPLITUDES), start=1):
        assert abs(wrapped(got - want)) < 5 * sd_amp / amp, f"phase of harmonic {k}"
    assert fit.offset == pytest.approx(OFFSET, abs=5 * NOISE_RMS / math.sqrt(x.size))


def test_thd_is_the_rms_sum_of_the_harmonics_over_the_fundamental():
    truth = math.sqrt(np.sum(AMPLITUDES[1:] ** 2)) / AMPLITUDES[0]
    x = synthetic(NOISE_RMS)
    fit = fit_harmonics(x, FS_HZ, FREQ_HZ, AMPLITUDES.size)
    # error propagation: d(THD) <= sum_k |dTHD/dA_k| sd_amp, with |dTHD/dA_k| <= 1/A_1 (k >= 2)
    # and THD/A_1 for k = 1
    sd_amp = NOISE_RMS * math.sqrt(2 / x.size)
    bound = 5 * sd_amp * (len(AMPLITUDES) - 1 + truth) / AMPLITUDES[0]
    assert fit.thd == pytest.approx(truth, abs=bound)


def test_thd_of_a_pure_sine_is_zero_and_of_a_missing_fundamental_is_infinite():
    t = np.arange(2560) / FS_HZ
    assert fit_harmonics(np.sin(2 * np.pi * FREQ_HZ * t), FS_HZ, FREQ_HZ, 3).thd < 1e-12
    assert fit_harmonics(np.zeros(2560), FS_HZ, FREQ_HZ, 3).thd == math.inf


def test_noise_estimate_is_the_injected_rms():
    x = synthetic(NOISE_RMS)
    fit = fit_harmonics(x, FS_HZ, FREQ_HZ, AMPLITUDES.size)
    assert fit.noise_rms == pytest.approx(NOISE_RMS, rel=5 / math.sqrt(2 * x.size))


def test_harmonics_left_out_of_the_fit_count_as_residual():
    # fitting only the fundamental: the residual holds harmonics 2..5 (rms A_k / sqrt 2) and the noise
    x = synthetic(NOISE_RMS)
    fit = fit_harmonics(x, FS_HZ, FREQ_HZ, 1)
    expected = math.sqrt(np.sum(AMPLITUDES[1:] ** 2) / 2 + NOISE_RMS ** 2)
    assert fit.noise_rms == pytest.approx(expected, rel=0.01)
    assert fit.amplitude[0] == pytest.approx(AMPLITUDES[0], abs=5 * NOISE_RMS * math.sqrt(2 / x.size))


def test_peak_to_peak_is_that_of_the_periodic_signal_and_raw_that_of_the_record():
    x = synthetic(NOISE_RMS)
    fit = fit_harmonics(x, FS_HZ, FREQ_HZ, AMPLITUDES.size)
    # the true periodic part, evaluated on a fine grid of one period
    wt = np.linspace(0, 2 * np.pi, 100_000, endpoint=False)
    k = np.arange(1, AMPLITUDES.size + 1)
    periodic = (AMPLITUDES * np.sin(np.outer(wt, k) + PHASES_RAD)).sum(axis=1)
    truth = periodic.max() - periodic.min()
    # each harmonic's error (<= 5 sd) can move the extremes by at most its amplitude error
    assert fit.peak_to_peak == pytest.approx(truth, abs=2 * 5 * NOISE_RMS * math.sqrt(2 / x.size) * k.size)
    # the raw record's extremes carry the noise on top (about +-3 sigma here)
    assert fit.raw_peak_to_peak == x.max() - x.min()
    assert fit.raw_peak_to_peak > truth + 2 * NOISE_RMS


@pytest.mark.parametrize("bad, problem", [
    (np.nan, "NaN"),
    (np.inf, "inf"),
])
def test_a_record_with_nan_or_inf_is_refused(bad, problem):
    x = synthetic(0.0)
    x[17] = bad
    with pytest.raises(ValueError, match=problem):
        fit_harmonics(x, FS_HZ, FREQ_HZ, 5)


def test_a_record_too_short_for_the_harmonics_is_refused():
    # 5 harmonics need 2 * 5 + 1 unknowns: 11 samples cannot pin them down
    with pytest.raises(ValueError, match=r"at least 12 samples"):
        fit_harmonics(np.ones(11), FS_HZ, FREQ_HZ, 5)


def test_a_two_dimensional_record_is_refused():
    with pytest.raises(ValueError, match="1-D"):
        fit_harmonics(np.ones((100, 3)), FS_HZ, FREQ_HZ, 1)


@pytest.mark.parametrize("n_harmonics", [0, -1])
def test_fewer_than_one_harmonic_is_refused(n_harmonics):
    with pytest.raises(ValueError, match="n_harmonics must be >= 1"):
        fit_harmonics(synthetic(0.0), FS_HZ, FREQ_HZ, n_harmonics)


def test_harmonics_at_or_above_nyquist_are_refused_instead_of_aliased():
    # 26 samples per period of 1 kHz: harmonic 13 sits at Nyquist, harmonic 25 = 26 - 1 is
    # sampled exactly like the fundamental; a 30-harmonic fit would split the fundamental's
    # amplitude between such aliased columns and report about a third of it
    fs = 26_000.0
    t = np.arange(260) / fs
    x = 2.0 * np.sin(2 * np.pi * 1000.0 * t)
    assert fit_harmonics(x, fs, 1000.0, 12).amplitude[0] == pytest.approx(2.0)
    for n_harmonics in (13, 30):
        with pytest.raises(ValueError, match="Nyquist"):
            fit_harmonics(x, fs, 1000.0, n_harmonics)


@pytest.mark.parametrize("fs, f", [(0.0, 100.0), (25600.0, 0.0), (25600.0, -5.0)])
def test_non_positive_rates_are_refused(fs, f):
    with pytest.raises(ValueError, match="fs_Hz > 0 and freq_Hz > 0"):
        fit_harmonics(np.ones(100), fs, f, 1)
