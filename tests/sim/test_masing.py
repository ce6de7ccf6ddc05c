"""Masing rule checks against hand-worked branch values and known properties."""
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.integrate import quad

from sim.masing import MasingFriction
from sim.virgin import SakaiCurve


def path(*points, m=400):
    segs = [np.linspace(a, b, m)[1:] for a, b in zip(points[:-1], points[1:])]
    return np.concatenate(segs)


def g2(s):  # n = 2 by hand: (s^2 - 2 s) / (1 - 2) = 2 s - s^2 on [0, 1]
    return 2 * s - s * s if s < 1 else 1.0


def test_branches_follow_eqs_1_and_2_for_a_fig3_like_sequence():
    # 0 -> A(0.8) -> B(-0.4) -> C(0.2) -> back down past B, past the mirror of A, to -1.5
    m = MasingFriction(SakaiCurve(2.0))
    seg = lambda a, b: np.linspace(a, b, 4001)[1:]
    F = m.force(seg(0, 0.8))
    assert F[-1] == pytest.approx(g2(0.8))                       # virgin, Eq. 1: 0.96
    F = m.force(seg(0.8, -0.4))
    assert F[-1] == pytest.approx(0.96 - 2 * g2(0.6))           # Eq. 2 from A: -0.72
    F = m.force(seg(-0.4, 0.2))
    assert F[-1] == pytest.approx(-0.72 + 2 * g2(0.3))          # Eq. 2 from B: 0.30
    F = m.force(seg(0.2, -0.4))
    assert F[-1] == pytest.approx(-0.72, abs=1e-12)             # inner loop closes at B
    assert len(m.reversals) == 1                                 # B and C forgotten
    F = m.force(seg(-0.4, -0.6))
    assert F[-1] == pytest.approx(0.96 - 2 * g2(0.7))           # back on the branch from A
    F = m.force(seg(-0.6, -0.8))
    assert F[-1] == pytest.approx(-g2(0.8), abs=1e-12)          # meets the virgin curve at -A
    F = m.force(seg(-0.8, -0.9))
    assert F[-1] == pytest.approx(-g2(0.9))                      # Eq. 1 again, not the A branch
    assert len(m.reversals) == 0
    F = m.force(seg(-0.9, -1.5))
    assert F[-1] == -1.0                                         # rolling region


def test_inner_loop_wipes_out_and_outer_branch_is_unchanged():
    c = SakaiCurve(0.5)
    plain = MasingFriction(c)
    plain.force(path(0, 1.2, -0.3))
    ref = plain.force(np.linspace(-0.3, -0.9, 61)[1:])
    looped = MasingFriction(c)
    looped.force(path(0, 1.2, 0.1, 0.6, 0.3, 0.5, -0.3))        # nested inner loops on the way
    assert np.allclose(looped.force(np.linspace(-0.3, -0.9, 61)[1:]), ref, atol=1e-12)


def test_gross_rolling_branch_is_flat_beyond_twice_x_s():
    m = MasingFriction(SakaiCurve(1.5))
    m.force(path(0, 3.0))
    F = m.force(np.linspace(3.0, 0.0, 3001)[1:])
    u = np.linspace(3.0, 0.0, 3001)[1:]
    assert np.all(F[u < 3.0 - 2.0 - 1e-9] == -1.0)
    assert np.all(F[u > 3.0 - 2.0 + 1e-3] > -1.0)


def steady_loop(lam, a=0.7, n=1.5):
    m = MasingFriction(SakaiCurve(n), lam=lam)
    m.force(path(0, a, -a, a))
    u_dn = np.linspace(a, -a, 2001)
    F_dn = m.force(u_dn[1:])
    F_up = m.force(np.linspace(-a, a, 2001)[1:])
    return u_dn[1:], F_dn, F_up


def test_steady_loop_is_point_symmetric_for_lambda_2():
    u, F_dn, F_up = steady_loop(2.0)
    # descending at u equals minus ascending at -u
    up_at = np.interp(-u, np.linspace(-0.7, 0.7, 2001)[1:], F_up)
    assert np.max(np.abs(F_dn + up_at)) < 1e-6


@pytest.mark.parametrize("lam", [1.5, 3.0])
def test_first_branch_misses_the_mirror_point_for_lambda_not_2(lam):
    a, n = 0.7, 1.5
    g = SakaiCurve(n)
    m = MasingFriction(g, lam=lam)
    m.force(np.linspace(0, a, 2001)[1:])
    F = m.force(np.linspace(a, -a * (1 - 1e-9), 2001)[1:])
    gap = F[-1] + g(np.array([a]))[0]          # zero if the curve were symmetric
    assert abs(gap) > 1e-3
    m2 = MasingFriction(g, lam=2.0)
    m2.force(np.linspace(0, a, 2001)[1:])
    F2 = m2.force(np.linspace(a, -a * (1 - 1e-9), 2001)[1:])
    assert abs(F2[-1] + g(np.array([a]))[0]) < 1e-6


@pytest.mark.parametrize("n", [0.5, 1.5, 3.0])
def test_loop_area_equals_masing_energy_formula(n):
    # Energy per cycle of a Masing loop of amplitude a: 8 int_0^a f - 4 a f(a).
    a = 0.6
    g = SakaiCurve(n)
    u, F_dn, F_up = steady_loop(2.0, a=a, n=n)
    top = g(np.array([a]))[0]
    u_up = np.r_[-a, np.linspace(-a, a, 2001)[1:]]
    F_up = np.r_[-top, F_up]
    u_dn, F_dn = np.r_[a, u], np.r_[top, F_dn]
    area = np.trapezoid(F_up, u_up) + np.trapezoid(F_dn, u_dn)
    expected = 8 * quad(lambda s: g(np.array([s]))[0], 0, a)[0] - 4 * a * g(np.array([a]))[0]
    assert area == pytest.approx(expected, rel=2e-3)


def test_n_equal_one_refused():
    with pytest.raises(ValueError, match="n = 1"):
        MasingFriction(SakaiCurve(1.0))


def test_bad_path_refused():
    with pytest.raises(ValueError, match="NaN"):
        MasingFriction(SakaiCurve(0.5)).force([0.1, float("nan")])


def test_stack_grows_past_its_initial_size_under_bounds_checking(tmp_path):
    # A decaying oscillation nests every loop inside the previous one: the stack holds
    # every reversal.  Run with numba's bounds checking on, in a fresh cache.
    code = """
import numpy as np
from sim.masing import MasingFriction
from sim.virgin import SakaiCurve
m = MasingFriction(SakaiCurve(0.5))
amps = 1.5 * 0.995 ** np.arange(1500)
pts = np.ravel(np.column_stack([amps, -amps * 0.999]))
u = np.concatenate([np.linspace(a, b, 8)[1:] for a, b in zip(np.r_[0, pts[:-1]], pts)])
m.force(u)
print(m.max_depth, len(m.reversals))
"""
    env = dict(os.environ, NUMBA_BOUNDSCHECK="1", NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    depth, live = map(int, out.stdout.split())
    assert depth >= 2900 and live >= 2900     # far beyond the initial 16 entries
