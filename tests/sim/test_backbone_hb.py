"""The single-harmonic-balance backbone of the Masing loop (sim.backbone) against facts it
does not compute itself: the loop of the independent simulator's force law
(benchtools/independent_masing.py), the small-amplitude limit (the virgin curve's initial
stiffness, no damping) and the gross-rolling limit (Coulomb friction's describing
function 4 F_s / pi)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchtools.independent_masing import MasingCarriage
from sim.backbone import backbone_at_force, backbone_point, loop_coefficients

F_S, X_S, MASS = 10.0, 10e-6, 10.0


def independent_coefficients(X_m: float, n: float, points: int = 20000) -> tuple[float, float]:
    """a1, b1 of the steady loop x = X cos(theta), force from the independent carriage's
    branches: descending from the reversal (X, f(X)), ascending from (-X, -f(X))."""
    car = MasingCarriage(n)
    u = X_m / X_S
    top = car.virgin(u)
    theta = (np.arange(points) + 0.5) * 2 * math.pi / points
    F = np.empty(points)
    for i, th in enumerate(theta):
        car.stack = [(u, top)] if th <= math.pi else [(-u, -top)]
        F[i] = car.force(u * math.cos(th)) * F_S
    d = 2 * math.pi / points / math.pi
    return float(F @ np.cos(theta) * d), float(F @ np.sin(theta) * d)


@pytest.mark.parametrize("n", [0.5, 1.5, 3.0])
@pytest.mark.parametrize("X_over_xs", [0.05, 0.4, 1.0, 1.7, 5.0])
def test_loop_coefficients_match_the_independent_loop(n, X_over_xs):
    a1, b1 = loop_coefficients(X_over_xs * X_S, F_S, X_S, n)
    ia1, ib1 = independent_coefficients(X_over_xs * X_S, n)
    assert a1 == pytest.approx(ia1, rel=2e-3)
    assert b1 == pytest.approx(ib1, rel=2e-3)
    assert b1 < 0          # clockwise loop: the friction takes energy, the force's quadrature part gives it


def test_small_amplitudes_ring_at_the_initial_stiffness_without_damping():
    n = 1.5
    k0 = n / (n - 1) * F_S / X_S                       # the virgin curve's slope at 0
    p = backbone_point(1e-8 * X_S, MASS, F_S, X_S, n)    # stiffness falls as (X/x_s)^(n-1)
    assert p.frequency_Hz == pytest.approx(math.sqrt(k0 / MASS) / (2 * math.pi), rel=1e-3)
    assert p.damping_ratio < 1e-3


def test_gross_rolling_is_coulomb_friction():
    X = 200 * X_S
    p = backbone_point(X, MASS, F_S, X_S, 1.5)
    assert p.force_N == pytest.approx(4 * F_S / math.pi, rel=0.01)     # square wave's fundamental


def test_the_backbone_falls_and_its_damping_rises_with_amplitude():
    pts = [backbone_point(r * X_S, MASS, F_S, X_S, 1.5) for r in (0.05, 0.2, 0.5, 1.0, 2.0)]
    assert all(a.frequency_Hz > b.frequency_Hz for a, b in zip(pts, pts[1:]))
    assert all(a.damping_ratio < b.damping_ratio for a, b in zip(pts, pts[1:]))


def test_a_linear_spring_and_damper_give_the_analytic_mode():
    k, c = 4e5, 80.0
    p = backbone_point(5e-5, MASS, 1e-6, 1e-2, 1.5, spring_N_per_m=k, viscous_N_s_per_m=c)
    assert p.frequency_Hz == pytest.approx(math.sqrt(k / MASS) / (2 * math.pi), rel=1e-6)
    assert p.damping_ratio == pytest.approx(c / (2 * math.sqrt(k * MASS)), rel=1e-4)


def test_backbone_at_force_inverts_the_holding_force():
    for F in (0.1, 1.0, 3.0):
        p = backbone_at_force(F, MASS, F_S, X_S, 1.5)
        assert p.force_N == pytest.approx(F, rel=1e-9)
        assert backbone_point(p.amplitude_m, MASS, F_S, X_S, 1.5).force_N == pytest.approx(F, rel=1e-9)
