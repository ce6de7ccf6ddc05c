"""The fit's loop friction (sim.identify.path_friction, the kernel every Masing fit spends
its time in) against the stateful Masing element (sim.masing.MasingFriction, another code
path through the same rule): the same forces to the last bit on periods with noise, inner
loops and a stack deeper than any fixed guess, with numba's bounds checking on."""

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
