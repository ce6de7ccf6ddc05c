"""Harmonics, noise, frequency and periodicity of time records (sim.records), on signals
whose answer is known in closed form."""
import math

import numpy as np
import pytest

from sim.records import analyse_records, estimate_frequency, harmonic_sigma, lsq_harmonics


def signal(t, f, amps, phases):
    return sum(a * np.sin(2 * np.pi * (k + 1) * f * t + p) for k, (a, p) in enumerate(zip(amps, phases)))


@pytest.mark.parametrize("fs_Hz", [25600.0, 10_000.0 * 1.0371])      # integer and non-integer samples per period
def test_harmonics_noise_and_frequency_of_a_known_signal(fs_Hz):
    rng = np.random.default_rng(0)
    f = 50.0
    t = np.arange(int(8.6 * fs_Hz / f)) / fs_Hz                      # 8.6 periods: 8 are used
    amps, phases = [1.0, 0.0, 0.2, 0.0, 0.05], [0.3, 0.0, -1.0, 0.0, 2.0]
    clean = signal(t, f, amps, phases)
    x = clean + 0.01 * rng.standard_normal(t.size) + 0.5
    noisy = lambda y, s: y + s * rng.standard_normal(t.size)    # noqa: E731
    rec = analyse_records(x, noisy(3 * clean, 0.001), noisy(-clean, 0.02), fs_Hz)   # frequency estimated
    assert rec.freq_Hz == pytest.approx(f, rel=1e-5)          # a few standard errors
    assert rec.periods == 8
    ch = rec.channels["force"]
    C = ch.harmonics[:5]
    want = np.array(amps) * np.exp(1j * np.array(phases))
    assert np.all(np.abs(C - want) < 5 * ch.sigma + 1e-9)
    assert ch.noise_rms == pytest.approx(0.01, rel=0.1)
    assert ch.sigma == pytest.approx(0.01 * math.sqrt(2 / rec.samples), rel=0.1)
    assert ch.offset == pytest.approx(0.5, abs=1e-3)
    assert rec.drift_sigma < 6


def test_frequency_estimate_is_finer_than_the_fft_bin():
    fs, f = 3000.0, 37.123456
    t = np.arange(2000) / fs                                            # bin width 1.5 Hz
    x = np.sin(2 * np.pi * f * t + 0.4) + 0.003 * np.random.default_rng(1).standard_normal(t.size)
    assert estimate_frequency(x, fs) == pytest.approx(f, rel=1e-5)   # 1e-4 of a bin


def test_a_response_still_settling_scores_as_not_periodic():
    fs, f = 25600.0, 40.0
    t = np.arange(int(8 * fs / f)) / fs
    rng = np.random.default_rng(2)
    steady = np.sin(2 * np.pi * f * t)
    ringing = steady * (1 + 0.03 * np.exp(-t / 0.1))          # amplitude still converging
    noise = lambda: 0.003 * rng.standard_normal(t.size)        # noqa: E731
    assert analyse_records(steady + noise(), steady + noise(), steady + noise(), fs, f).drift_sigma < 6
    rec = analyse_records(steady + noise(), ringing + noise(), steady + noise(), fs, f)
    assert rec.drift_sigma > 10 and rec.drift_detail.startswith("accel")


def test_bad_records_are_refused_with_the_reason():
    x = np.sin(np.arange(1000) / 10)
    with pytest.raises(ValueError, match="different lengths"):
        analyse_records(x, x[:-1], x, 1000.0)
    y = x.copy()
    y[5] = np.nan
    with pytest.raises(ValueError, match="disp record contains NaN"):
        analyse_records(x, x, y, 1000.0)
    with pytest.raises(ValueError, match="at least 2 are needed"):
        analyse_records(x, x, x, 1000.0, freq_Hz=1.5)


@pytest.mark.parametrize("noise", [1e-5, 1e-6])
def test_the_kernels_noise_is_exact_on_a_clean_record(noise):
    """The residual rms of the kernel's fit equals numpy's least squares' (the record minus
    its QR solution) to 1e-6, however clean the record (decision 0066: x.x - coef.rhs lost
    1.2 % at 1e-5 of the signal and all of it at 1e-6)."""
    fs, f, K = 10_000.0 * 1.0371, 50.0, 20
    n = int(8.6 * fs / f)
    t = np.arange(n) / fs
    x = 0.5 + signal(t, f, [1.0, 0.0, 0.2, 0.0, 0.05], [0.3, 0.0, -1.0, 0.0, 2.0])
    x = x + noise * np.random.default_rng(3).standard_normal(n)
    k = np.arange(1, K + 1)
    A = np.column_stack([np.ones(n), np.sin(2 * np.pi * f * np.outer(t, k)), np.cos(2 * np.pi * f * np.outer(t, k))])
    coef = np.linalg.lstsq(A, x, rcond=None)[0]
    want = math.sqrt(float(np.sum((x - A @ coef) ** 2)) / (n - A.shape[1]))
    C, offset, rms = lsq_harmonics(x, fs, f, K)
    assert np.allclose(C, coef[1:K + 1] + 1j * coef[K + 1:], rtol=0, atol=1e-11)
    assert offset == pytest.approx(coef[0], abs=1e-12)
    assert rms == pytest.approx(want, rel=1e-6)
    assert lsq_harmonics(x - (x - A @ coef), fs, f, K)[2] < 1e-11     # the model itself: no noise left


def test_the_steps_level_is_the_kernels_fundamental_free_of_the_offset_and_the_harmonics():
    """The artefact check's level (the force fundamental) on 10.6 periods of 24.2 samples,
    with an offset and a strong second harmonic: within 5 standard errors of the true 2 N
    (main's single-bin sum over floor(periods) leaked 1e-3 N into it, 100 standard errors)."""
    from sim.artefacts import assess_step
    f, fs = 41.3, 1000.0
    n = int(10.6 * fs / f)
    t = np.arange(n) / fs
    rng = np.random.default_rng(0)
    force = 0.5 + signal(t, f, [2.0, 0.6], [0.3, 1.0]) + 1e-4 * rng.standard_normal(n)
    disp = 1e-5 * np.sin(2 * np.pi * f * t - 1) + 1e-9 * rng.standard_normal(n)
    accel = -(2 * np.pi * f) ** 2 * (disp - 1e-9 * rng.standard_normal(n)) + 1e-3 * rng.standard_normal(n)
    q = assess_step(force, accel, disp, fs, f).quality
    periods = math.floor(n * f / fs)
    assert abs(q.level_N - 2.0) < 5 * harmonic_sigma(1e-4, int(periods * fs / f))
