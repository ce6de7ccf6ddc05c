"""Fast steady-state engine: half-period shooting with natural continuation in beta.

For lam = 2 and an odd virgin curve, a steady response with two reversals per period is
half-wave symmetric about its centre: u(tau + pi) - c = -(u(tau) - c).  Put the centre at
0; then the upper reversal is (u, F) = (a, g(a)) (the Masing loop of amplitude a passes
through the virgin curve's point at a), and the half period that follows lies on one
smooth branch, F = g(a) - 2 g((a - u) / 2).  The orbit is found by solving for the
amplitude a and the reversal phase tau_r such that half a period later u = -a, u' = 0.

Each half period is one compiled RK4 integration; Newton's method with a finite-difference
Jacobian needs a few of them per frequency, warm-started from the previous frequency.
Where the assumptions fail (extra reversals inside the half period, as at the seed's
frequency A for small beta; Newton not converging; lam != 2) the point is computed with
the RK4 reference engine instead, and marked so.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .dynamics import Integrator, SteadyState, steady_state
from .errors import ConfigurationError
from .frf import FrequencyResponse, beta_grid
from .virgin import virgin_g

log = logging.getLogger(__name__)


@njit(cache=True, nogil=True)
def _half_period(a, tau_r, beta, gamma0, kind, p, m):
    """Integrate the downward branch from (a, 0) at tau_r over pi in m RK4 steps.

    Returns (u_end, v_end, v_max), v_max the largest velocity seen (> 0 means the motion
    reversed inside the half period, outside this engine's assumptions).
    """
    Fa = virgin_g(kind, a, p)
    ib2 = 1.0 / (beta * beta)
    h = math.pi / m
    u = a
    v = 0.0
    vmax = -1e300
    for i in range(m):
        t = tau_r + i * h
        # F(u) = Fa - 2 g((a - u) / 2) (u < a here; the odd extension covers u > a)
        s = 0.5 * (a - u)
        F1 = Fa - 2.0 * virgin_g(kind, s, p) if s >= 0 else Fa + 2.0 * virgin_g(kind, -s, p)
        k1v = ib2 * (-F1 + gamma0 * math.sin(t))
        u2 = u + 0.5 * h * v
        v2 = v + 0.5 * h * k1v
        s = 0.5 * (a - u2)
        F2 = Fa - 2.0 * virgin_g(kind, s, p) if s >= 0 else Fa + 2.0 * virgin_g(kind, -s, p)
        k2v = ib2 * (-F2 + gamma0 * math.sin(t + 0.5 * h))
        u3 = u + 0.5 * h * v2
        v3 = v + 0.5 * h * k2v
        s = 0.5 * (a - u3)
        F3 = Fa - 2.0 * virgin_g(kind, s, p) if s >= 0 else Fa + 2.0 * virgin_g(kind, -s, p)
        k3v = ib2 * (-F3 + gamma0 * math.sin(t + 0.5 * h))
        u4 = u + h * v3
        v4 = v + h * k3v
        s = 0.5 * (a - u4)
        F4 = Fa - 2.0 * virgin_g(kind, s, p) if s >= 0 else Fa + 2.0 * virgin_g(kind, -s, p)
        k4v = ib2 * (-F4 + gamma0 * math.sin(t + h))
        u = u + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
        v = v + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
        if i < m - 1 and v > vmax:
            vmax = v
    return u, v, vmax


@dataclass(frozen=True)
class ShootingSolution:
    a: float           # amplitude (u_max - u_min) / 2
    tau_r: float       # phase of the upper reversal, in [0, 2 pi)
    iterations: int


def solve_half_period(beta: float, gamma0: float, curve, a0: float, tau0: float, *,
                      steps: int = 1000, tol: float = 1e-10, max_iter: int = 20) -> ShootingSolution | None:
    """Newton on (a, tau_r); returns None when it does not converge or the orbit reverses
    inside the half period."""
    kind, p = curve.kind, curve.params
    x = np.array([a0, tau0], dtype=np.float64)

    def residual(x):
        u, v, vmax = _half_period(x[0], x[1], beta, gamma0, kind, p, steps)
        return np.array([u + x[0], beta * v]), vmax

    for it in range(1, max_iter + 1):
        if not (x[0] > 0 and math.isfinite(x[0]) and math.isfinite(x[1])):
            return None
        r, vmax = residual(x)
        if np.max(np.abs(r)) <= tol * max(x[0], 1e-12):
            if vmax > 1e-9 * x[0]:
                return None
            return ShootingSolution(float(x[0]), float(x[1] % (2 * math.pi)), it)
        J = np.empty((2, 2))
        for j in range(2):
            dx = np.zeros(2)
            dx[j] = 1e-7 * max(abs(x[j]), 1e-3) if j == 0 else 1e-7
            rj, _ = residual(x + dx)
            J[:, j] = (rj - r) / dx[j]
        try:
            step = np.linalg.solve(J, -r)
        except np.linalg.LinAlgError:
            return None
        # Damp steps that would make the amplitude negative or jump too far.
        scale = 1.0
        if x[0] + step[0] <= 0.2 * x[0]:
            scale = 0.8 * x[0] / max(-step[0], 1e-300)
        if abs(step[1]) * scale > 0.5:
            scale = 0.5 / abs(step[1])
        x = x + scale * step
    return None


def _seed_from_rk4(p: SteadyState) -> tuple[float, float]:
    """(a, tau_r) of a converged RK4 point: amplitude and phase of the upper reversal."""
    h = p.history
    assert h is not None, "the RK4 point was run with a history"
    i = int(np.argmax(h.u))
    return 0.5 * (p.u_max - p.u_min), float(h.tau[i] % (2 * math.pi))


def _linear_guesses(beta: float, gamma0: float, curve) -> list[tuple[float, float]]:
    """(a, tau_r) of linearised responses: with the initial stiffness k0 (n > 1), and of
    the free mass (u = -gamma0 sin(tau) / beta^2).  A down sweep starts above the
    resonance, where one of them is close (from rest, RK4 would ring for thousands of
    periods when n > 1)."""
    b2 = beta * beta
    out = []
    k0 = curve.stiffness0
    if math.isfinite(k0) and abs(k0 - b2) > 1e-9:
        out.append((gamma0 / abs(k0 - b2), 0.5 * math.pi if k0 > b2 else 1.5 * math.pi))
    out.append((gamma0 / b2, 1.5 * math.pi))
    return out


def frf_shooting(betas, gamma0: float, n: float = 1.5, *, integrator: Integrator | None = None,
                 steps: int = 1000, progress=None, direction: str = "up") -> tuple[FrequencyResponse, np.ndarray]:
    """G(beta) by shooting with continuation along the sorted grid (one core).

    ``direction="down"`` continues from the highest beta downwards, so where two steady
    responses coexist the other branch is followed (jumps, as in a down sweep).
    Returns the response (method "shooting", ordered by ascending beta) and a boolean
    array marking the points that fell back to the RK4 engine.
    """
    if direction not in ("up", "down"):
        raise ConfigurationError(f"direction must be 'up' or 'down', got {direction!r}")
    b = np.sort(beta_grid(betas))
    if direction == "down":
        b = b[::-1]
    it = integrator or Integrator(n=n)
    shooting_ok = abs(it.lam - 2.0) < 1e-12
    points: list[SteadyState] = []
    fell_back = np.zeros(b.size, dtype=bool)
    guess = None
    for i, beta in enumerate(b):
        sol = None
        if shooting_ok and guess is None and i == 0 and direction == "down":
            for a0, t0 in _linear_guesses(beta, gamma0, it.curve):
                sol = solve_half_period(beta, gamma0, it.curve, a0, t0, steps=steps)
                if sol:
                    break
        elif shooting_ok and guess is not None:
            sol = solve_half_period(beta, gamma0, it.curve, guess[0], guess[1], steps=steps)
        if sol is None:
            rk = steady_state(gamma0, beta, it.n, integrator=it, history_samples=2000)
            fell_back[i] = True
            points.append(rk)
            guess = None
            if rk.converged and rk.reversals_per_cycle == 2 and shooting_ok:
                a0, t0 = _seed_from_rk4(rk)
                sol = solve_half_period(beta, gamma0, it.curve, a0, t0, steps=steps)
                guess = (sol.a, sol.tau_r) if sol else None
        else:
            guess = (sol.a, sol.tau_r)
            points.append(SteadyState(
                gamma0=gamma0, beta=float(beta), n=it.n, G=sol.a / gamma0, u_max=sol.a, u_min=-sol.a,
                cycles=0, converged=True, gross_rolling=bool(gamma0 >= 1.0 or 2 * sol.a > it.lam),
                drift_per_cycle=0.0, reversals_per_cycle=2, max_depth=2))
        if progress:
            progress(i + 1, b.size)
    if direction == "down":
        points, fell_back = points[::-1], fell_back[::-1].copy()
    return FrequencyResponse.from_points(points, direction, "shooting"), fell_back
