"""A free vibration where harmonics above Nyquist fold back (sim.artefacts, decision 0088),
on a record built here from closed forms that share no code with the detector.

The case it comes from: issue 41's Maxwell-slip case (benchmarks/bench_model_choice.py,
seed 0), the 0.87 x friction-level sweep's 173.3 Hz step: 7-8 periods at 132.7 samples a
period (46 ms), 0.83 um of drive response, and the carriage's undamped free vibration at
its 57.8 Hz resonance (below the smallest element's slip the elements are linear springs),
1.38 um on the probe.  The record has no anti-alias filter, so the fitted harmonics near
Nyquist showed content (4.75 standard errors by chance) and the line search skipped every
frequency a harmonic up to 8 x Nyquist folds to: the whole band.  The free vibration stayed
in the probe, harmonic 1 read 0.953 um where the accelerometer said 0.828 um, and the
elements' held-out error was 1.17 % against the noise's 0.26 %.  A fold is no larger than
the top harmonics (they decay); a component 200 x larger is not one.
"""

import numpy as np
import pytest

from sim.artefacts import assess_step

F, FS, N = 173.33, 23007.23, 1061          # the step's drive, sample rate and record (8 periods)
X1, F_FREE, X_FREE = 0.83e-6, 57.78, 1.38e-6


def _step(seed, free=True):
    """Force, accelerometer and probe records: the drive response, on the probe with
    harmonics decaying as 1/k up to 8 x Nyquist (sampled as they are, so they fold: no
    anti-alias filter), and, if ``free``, the free vibration on both motion channels
    (a = x''); white noise as the rig's."""
    t = np.arange(N) / FS
    rng = np.random.default_rng(seed)
    x = np.zeros(N)
    a = np.zeros(N)
    for k in range(1, 8 * 67):
        amp = X1 if k == 1 else 4e-9 * 60 / k          # 4 nm at harmonic 60: above the noise's harmonics
        w = 2 * np.pi * k * F
        x += amp * np.sin(w * t + 0.3 * k)
    a -= (2 * np.pi * F) ** 2 * X1 * np.sin(2 * np.pi * F * t + 0.3)
    if free:
        w = 2 * np.pi * F_FREE
        x += X_FREE * np.sin(w * t + 2.0)
        a -= w * w * X_FREE * np.sin(w * t + 2.0)
    force = 10.47 * np.sin(2 * np.pi * F * t + 3.1) + 0.036 * rng.standard_normal(N)
    accel = a + 0.005 * np.std(a) * rng.standard_normal(N)
    disp = x + 20e-9 * rng.standard_normal(N)
    return assess_step(force, accel, disp, FS, F)


@pytest.mark.parametrize("seed", range(4))
def test_a_free_vibration_far_above_the_folded_harmonics_is_removed_from_the_probe(seed):
    a = _step(seed)
    assert a.records is not None, a.quality.reason
    d = a.records.channels["disp"]
    se = d.noise_rms * np.sqrt(2.0 / N)
    # without the vibration the same record's harmonic 1 is X1 within its noise: the folds are kept
    assert abs(abs(_step(seed, free=False).records.channels["disp"].harmonics[0]) - X1) < 5 * se
    assert abs(abs(d.harmonics[0]) - X1) < 0.005 * X1, (abs(d.harmonics[0]), a.quality.notes)
    vib = [v for v in a.quality.artefacts if v.channel == "disp" and v.kind == "unsettled_transient"]
    assert vib and vib[0].freq_Hz == pytest.approx(F_FREE, abs=0.5), a.quality.notes
    assert vib[0].size == pytest.approx(X_FREE, rel=0.02)
