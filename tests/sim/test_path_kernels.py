"""The two kernels every Masing fit spends its time in (decision 0048).  The loop friction
(sim.identify.path_friction) against the stateful Masing element (sim.masing.MasingFriction,
another code path through the same rule): the same forces to the last bit on periods with
noise, inner loops and a stack deeper than any fixed guess, with numba's bounds checking on.
The sampled periods (sim.identify.period_paths) against the array expressions they replaced
(to the last bit) and against a cosine's known extremes."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from sim.identify import path_friction, period_paths
from sim.masing import MasingFriction
from sim.virgin import SakaiCurve


def _periods(M: int = 512) -> np.ndarray:
    """Rows of one period each (m): a plain loop, one with inner loops from a third
    harmonic, noisy ones (many small reversals), and one of nested decaying loops."""
    rng = np.random.default_rng(3)
    X = np.zeros((6, 9), complex)
    X[:, 0] = [0.3e-6, 2e-6, 0.8e-6, 5e-6, 1e-6, 1e-6]
    X[1, 2] = 0.6e-6 * np.exp(0.4j)             # inner loops
    X[2, 1:] = 0.02e-6 * (rng.normal(size=8) + 1j * rng.normal(size=8))
    paths, _ = period_paths(X, M)
    paths[4] += 0.01e-6 * rng.normal(size=M)   # noise: a reversal at every other sample
    t = np.arange(M) / M                       # nested loops: a decaying oscillation, top first
    paths[5] = 1e-6 * np.cos(2 * np.pi * 40 * t) * (1 - t)
    return paths


@pytest.mark.parametrize("n", [0.6, 1.5, 2.7])
def test_path_friction_equals_the_masing_element_to_the_last_bit(n):
    x_s = 1e-6
    paths = _periods()
    F = path_friction(paths, x_s, n)
    for row, f in zip(paths, F):
        u = row / x_s
        ref = MasingFriction(SakaiCurve(n)).force(np.r_[u[0], u])[1:]    # virgin loading from 0 to the top first
        assert np.array_equal(f, ref), np.abs(f - ref).max()
    deep = MasingFriction(SakaiCurve(n))
    deep.force(np.r_[paths[5, 0], paths[5]] / x_s)
    assert deep.max_depth > 60                                         # the nested row's stack is deep


def test_a_row_reversing_at_every_sample_stays_in_bounds(tmp_path):
    # M + 1 reversal entries per row is the most a row can need; numba's bounds checking on,
    # in a fresh cache, on a row that reverses at every sample and one of nested loops
    code = """
import numpy as np
from sim.identify import path_friction
M = 256
zigzag = np.where(np.arange(M) % 2 == 0, 1.0, -1.0) * np.linspace(2, 0.01, M)
nested = np.cos(np.pi * np.arange(M)) * np.linspace(1.5, 0.0, M)
F = path_friction(np.array([zigzag, nested]) * 1e-6, 1e-6, 0.8)
print(int(np.isfinite(F).all()))
"""
    env = dict(os.environ, NUMBA_BOUNDSCHECK="1", NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "1"


def _period_paths_numpy(X: np.ndarray, M: int) -> tuple[np.ndarray, np.ndarray]:
    """period_paths as array expressions (the code before decision 0048)."""
    X = np.atleast_2d(X)
    spec = np.zeros((X.shape[0], M // 2 + 1), complex)
    K = min(X.shape[1], M // 2 - 1)
    spec[:, 1:K + 1] = -1j * X[:, :K] * (M / 2)
    x = np.fft.irfft(spec, M, axis=1)
    starts = np.argmax(x, axis=1)
    return _rotate_lift_centre_numpy(x, starts), starts


def _rotate_lift_centre_numpy(x: np.ndarray, starts: np.ndarray) -> np.ndarray:
    M = x.shape[1]
    x = x[np.arange(x.shape[0])[:, None], (starts[:, None] + np.arange(M)[None, :]) % M]
    prev, nxt = np.roll(x, 1, axis=1), np.roll(x, -1, axis=1)
    turn = ((x - prev) * (nxt - x) <= 0) & (x != prev)
    den = prev - 2 * x + nxt
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = x - 0.125 * (nxt - prev) ** 2 / den
    x = np.where(turn & (den != 0), vertex, x)
    x -= 0.5 * (x.max(axis=1) + x.min(axis=1))[:, None]
    return x


@pytest.mark.parametrize("K", [1, 9, 60])
def test_period_paths_equal_the_array_expressions_to_the_last_bit(K):
    rng = np.random.default_rng(K)
    X = (rng.normal(size=(40, K)) + 1j * rng.normal(size=(40, K))) * 1e-6 / np.arange(1, K + 1) ** 1.5
    paths, starts = period_paths(X, 512)
    ref, ref_starts = _period_paths_numpy(X, 512)
    assert np.array_equal(starts, ref_starts)
    assert np.array_equal(paths, ref)


def test_quantised_periods_with_flat_steps_equal_the_array_expressions():
    # a probe's quantisation: runs of equal samples, which are no turning points
    from sim.identify import _rotate_lift_centre

    t = np.arange(256) / 256
    x = np.round(np.array([np.sin(2 * np.pi * t + p) * a for p, a in ((0.3, 7), (1.1, 20), (2.0, 3.5))]) * 4) / 4
    starts = np.argmax(x, axis=1)
    out = np.empty_like(x)
    _rotate_lift_centre(x, starts, out)
    ref = _rotate_lift_centre_numpy(x, starts)
    assert np.array_equal(out, ref)
    assert not np.array_equal(out, x[np.arange(3)[:, None], (starts[:, None] + np.arange(256)) % 256]
                              - 0.5 * (x.max(axis=1) + x.min(axis=1))[:, None])       # something was lifted


def test_a_cosines_turning_points_are_lifted_to_its_amplitude():
    # x = A sin(wt + phi) sampled 64 times a period, the crest halfway between two samples:
    # the samples miss the amplitude by A (1 - cos(pi / 64)) = 1.2e-3 A; the parabola's
    # vertex through the three samples around each crest finds it to 3e-6 A
    A, M = 2e-6, 64
    phi = np.pi / 2 - np.pi / M          # crest at t = 1/2 sample
    paths, starts = period_paths(np.array([[A * np.exp(1j * phi)]]), M)
    sampled = A * np.sin(2 * np.pi * np.arange(M) / M + phi)
    assert A - sampled.max() > 1e-3 * A
    assert abs(paths[0].max() - A) < 3e-6 * A and abs(paths[0].min() + A) < 3e-6 * A
    assert paths[0, 0] == paths[0].max() and starts[0] == np.argmax(sampled)
