"""The fast engine against the RK4 reference (issue: n in {0.5, 1.5, 3}, gamma0 in
{0.2, 0.6, 0.9}), and its fallback where its assumptions fail."""
import numpy as np
import pytest

from sim.dynamics import Integrator
from sim.frf import frf_rk4
from sim.shooting import frf_shooting

BETAS = np.linspace(0.35, 1.6, 11)


@pytest.mark.parametrize("n", [0.5, 1.5, 3.0])
@pytest.mark.parametrize("gamma0", [0.2, 0.6, 0.9])
def test_shooting_agrees_with_rk4_within_a_thousandth(n, gamma0):
    sh, fell_back = frf_shooting(BETAS, gamma0, n)
    rk = frf_rk4(BETAS, gamma0, n, max_cycles=1500)
    ok = rk.converged
    assert ok.sum() >= 8, "the reference itself did not settle"
    rel = np.abs(sh.G[ok] - rk.G[ok]) / rk.G[ok]
    assert rel.max() < 1e-3, f"worst beta {BETAS[ok][np.argmax(rel)]:.3f}: {rel.max():.2e}"
    assert fell_back.sum() < BETAS.size       # the engine did the work somewhere


def test_falls_back_to_rk4_where_the_orbit_reverses_more_than_twice():
    # n = 0.5, gamma0 = 0.6 below beta ~ 0.45: six or more reversals per period (VRAR)
    betas = np.linspace(0.25, 0.4, 4)
    sh, fell_back = frf_shooting(betas, 0.6, 0.5)
    rk = frf_rk4(betas, 0.6, 0.5)
    assert np.all(rk.reversals_per_cycle > 2)
    assert fell_back.all()
    assert np.allclose(sh.G, rk.G, rtol=1e-9)


def test_lambda_other_than_2_is_left_to_rk4():
    it = Integrator(n=1.5, lam=3.0)
    _, fell_back = frf_shooting(np.linspace(0.8, 1.2, 3), 0.6, integrator=it)
    assert fell_back.all()


@pytest.mark.parametrize("n", [1.5, 3.0])
def test_down_sweep_agrees_with_rk4_and_starts_from_the_linear_response(n):
    sh, fell_back = frf_shooting(BETAS, 0.6, n, direction="down")
    assert np.all(np.diff(sh.beta) > 0) and sh.sweep == "down"     # returned in ascending beta
    # the down sweep starts at the highest beta from the linearised response, not from an
    # RK4 run from rest (which rings for thousands of periods when n > 1)
    assert not fell_back[-1]
    rk = frf_rk4(BETAS, 0.6, n, max_cycles=1500)
    ok = rk.converged
    rel = np.abs(sh.G[ok] - rk.G[ok]) / rk.G[ok]
    assert rel.max() < 1e-3, f"worst beta {BETAS[ok][np.argmax(rel)]:.3f}: {rel.max():.2e}"


def test_direction_must_be_up_or_down():
    with pytest.raises(ValueError, match="direction"):
        frf_shooting(BETAS, 0.6, 1.5, direction="sideways")
