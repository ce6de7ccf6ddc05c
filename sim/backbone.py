"""The Masing model's backbone by single-harmonic balance (no time integration).

For x = X cos(theta) the steady Masing loop (ratio 2) is, on the descending branch
(0 <= theta <= pi), F = f(X) - 2 f((X - x)/2) and on the ascending one F = -f(X) +
2 f((x + X)/2), with f the virgin curve (odd extension).  Its first Fourier coefficients

    a1 = (1/pi) int_0^2pi F cos(theta) dtheta,   b1 = (1/pi) int_0^2pi F sin(theta) dtheta

(b1 < 0: the loop is run clockwise, the friction takes energy) give, for a carriage of
mass m driven at one point, the fundamental balance m x'' + F(x) = P at the phase
resonance (displacement lagging the force by 90 degrees):

    w^2 = a1 / (m X),   |P1| = |b1|,   zeta = |b1| / (2 a1).

A linear spring k and a viscous damper c in parallel add k X to a1 and -c w X to b1
(so a linear rig's backbone is flat at w^2 = k/m, zeta = c / (2 sqrt(k m))).  The
superharmonics the loop makes are left out; how far the true phase resonance lies from
this is measured by the phase-resonance procedure's tests (decision record 0044).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .virgin import SakaiCurve

THETA_POINTS = 4096          # midpoint rule over one period; the loop has two kinks at most


def loop_coefficients(X_m: float, F_s_N: float, x_s_m: float, n: float,
                      points: int = THETA_POINTS) -> tuple[float, float]:
    """(a1, b1) in N of the steady Masing loop at displacement amplitude ``X_m``."""
    if not (X_m > 0 and math.isfinite(X_m)):
        raise ValueError(f"amplitude X_m must be finite and > 0, got {X_m!r}")
    g = SakaiCurve(n)
    theta = (np.arange(points) + 0.5) * 2 * math.pi / points
    x = X_m * np.cos(theta)

    def f(s):                      # virgin curve in N for s >= 0 (m)
        return F_s_N * g(np.asarray(s) / x_s_m)
    fX = float(f(X_m))
    down = theta <= math.pi
    F = np.where(down, fX - 2 * f(np.clip((X_m - x) / 2, 0, None)),
                 -fX + 2 * f(np.clip((x + X_m) / 2, 0, None)))
    dth = 2 * math.pi / points
    return float(F @ np.cos(theta) * dth / math.pi), float(F @ np.sin(theta) * dth / math.pi)


@dataclass(frozen=True)
class BackbonePoint:
    amplitude_m: float
    frequency_Hz: float
    force_N: float                 # force fundamental that holds this amplitude at phase resonance
    damping_ratio: float


def backbone_point(X_m: float, mass_kg: float, F_s_N: float, x_s_m: float, n: float, *,
                   spring_N_per_m: float = 0.0, viscous_N_s_per_m: float = 0.0) -> BackbonePoint:
    """The single-harmonic-balance backbone at amplitude ``X_m`` (see the module text)."""
    a1, b1 = loop_coefficients(X_m, F_s_N, x_s_m, n)
    a1 += spring_N_per_m * X_m
    w = math.sqrt(a1 / (mass_kg * X_m))
    b = abs(b1) + viscous_N_s_per_m * w * X_m
    return BackbonePoint(X_m, w / (2 * math.pi), b, b / (2 * a1))


def backbone_at_force(force_N: float, mass_kg: float, F_s_N: float, x_s_m: float, n: float,
                      **linear) -> BackbonePoint:
    """The backbone point whose holding force is ``force_N`` (the force grows with the
    amplitude; bisection in log X between 1e-6 x_s and the onset of gross rolling)."""
    lo, hi = 1e-6 * x_s_m, 1.0 * x_s_m
    if backbone_point(hi, mass_kg, F_s_N, x_s_m, n, **linear).force_N < force_N:
        hi = 1e3 * x_s_m
    for _ in range(80):
        mid = math.sqrt(lo * hi)
        if backbone_point(mid, mass_kg, F_s_N, x_s_m, n, **linear).force_N < force_N:
            lo = mid
        else:
            hi = mid
    return backbone_point(math.sqrt(lo * hi), mass_kg, F_s_N, x_s_m, n, **linear)
