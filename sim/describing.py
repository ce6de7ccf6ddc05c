"""The friction element's describing function and the harmonic balance of the carriage on it
(issue 42 item 3, decision 0082).

**Describing function.**  For the displacement x = a cos(w t) the steady periodic friction
force F(t) of any model of :mod:`sim.friction` (its ``periodic_force``) has the fundamental
F_1 = (2 / M) sum_j F_j exp(-i theta_j); the describing function is the complex stiffness

    K_eq(a, w) = F_1 / a        (N/m; e^{+i w t} convention)

whose real part is the secant stiffness of the loop and whose imaginary part is its energy
per cycle: W = oint F dx = pi a^2 Im K_eq (> 0: the element dissipates).  Rate-independent
models ignore w.  At a -> 0 a Masing element with n > 1 tends to its initial tangent
stiffness n F_s / ((n - 1) x_s) and Im K_eq -> 0.

**Harmonic balance** of the carriage (mass m, driven by the force fundamental F at w) on the
friction element, with optionally a linear structure in parallel (:class:`Structure`):

    D(w, a) X = F,    D = -w^2 m + K_eq(a, w) + Z(w),    H = X / F = 1 / D

- ``SPRING``: a grounded spring and dashpot beside the friction, Z = k + i w c (a carriage on
  its own spring, a joint's elastic stiffness);
- ``MODE``: a structural mode hung on the carriage, a modal mass m_r on a spring k_r and a
  dashpot c_r (k_r = m_r w_r^2, c_r = 2 zeta_r m_r w_r):
  Z = -w^2 m_r (k_r + i w c_r) / (k_r + i w c_r - w^2 m_r); below w_r the mode moves with the
  carriage (Z -> -w^2 m_r), above it the carriage drives it through its spring; the
  driving-point FRF has the second peak of a two-degree-of-freedom system.

The friction element's displacement is the carriage's, the driving point's response, so a
**response-controlled** level gives a directly (the held amplitude, per point the measured
one) and H = 1 / D(w, a).  A **force-controlled** level gives |F|: a is the root of the
one-dimensional equation a |D(w, a)| = |F|, bracketed on a log grid of amplitudes and refined
by the Illinois method on exact evaluations of K_eq.  A softening element near resonance can
have up to three roots (the jump of a swept test); :func:`receptance` returns the one whose
amplitude is nearest the measured response's (the branch the test was on).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np
from scipy.interpolate import CubicSpline

from .friction import FrictionModel, friction_model

POINTS = 256           # samples of one period of the loop (the reversals are samples: theta = 0, pi)
GRID = 192             # log-spaced amplitudes that bracket a force-controlled point's roots
GRID_SPAN = 8.0        # the grid reaches this factor beyond the measured amplitudes either way
ROOT_TOL = 1e-12       # a refined bracket's width in ln a, or its residual relative to the bracket's
ROOT_ITER = 60
THIRD_ITER = 3         # corrections of the displacement's third harmonic (0: single-harmonic balance)


class Control(StrEnum):
    """What a level holds constant: the force amplitude or the response amplitude."""

    FORCE = "force"
    RESPONSE = "response"


class Structure(StrEnum):
    """The linear structure in parallel with the friction element (module doc)."""

    NONE = "none"
    SPRING = "spring"
    MODE = "mode"


# the structure's parameters: name, unit, fitted on a log scale (all are)
STRUCTURE_PARAMETERS: dict[Structure, tuple[tuple[str, str], ...]] = {
    Structure.NONE: (),
    Structure.SPRING: (("spring_N_per_m", "N/m"), ("dashpot_N_s_per_m", "N s/m")),
    Structure.MODE: (("mode_mass_kg", "kg"), ("mode_frequency_Hz", "Hz"), ("mode_damping_ratio", "1")),
}


def _model(model: FrictionModel | str) -> FrictionModel:
    return friction_model(model) if isinstance(model, str) else model


def describing_function(model: FrictionModel | str, values: Mapping[str, Any], amplitude_m: Any,
                        omega_rad_s: Any = 1.0, *, points: int = POINTS) -> np.ndarray:
    """K_eq(a, w) (N/m, complex; module doc) of ``model`` with parameters ``values`` at the
    displacement amplitudes ``amplitude_m`` (any shape; > 0) and angular frequencies
    ``omega_rad_s`` (broadcast with them; unused by a rate-independent model)."""
    m = _model(model)
    a = np.asarray(amplitude_m, dtype=np.float64)
    if not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise ValueError("describing_function: the amplitudes must be finite and > 0")
    w = np.asarray(omega_rad_s, dtype=np.float64)
    a_b, w_b = np.broadcast_arrays(a, w if m.rate_dependent else np.ones(()))
    shape = a_b.shape
    a_f, w_f = a_b.ravel(), w_b.ravel()
    theta = 2 * math.pi * np.arange(points) / points
    paths = a_f[:, None] * np.cos(theta)[None, :]
    F = m.periodic_force(values, paths, np.ascontiguousarray(w_f))
    F1 = np.fft.rfft(F, axis=1)[:, 1] * (2.0 / points)
    return (F1 / a_f).reshape(shape)


def structure_stiffness(structure: Structure, values: Mapping[str, float], omega_rad_s: np.ndarray) -> np.ndarray:
    """Z(w) (N/m, complex) of the linear structure in parallel with the friction (module doc)."""
    w = np.asarray(omega_rad_s, dtype=np.float64)
    if structure is Structure.NONE:
        return np.zeros(w.shape, complex)
    if structure is Structure.SPRING:
        return values["spring_N_per_m"] + 1j * w * values["dashpot_N_s_per_m"]
    m_r = values["mode_mass_kg"]
    w_r = 2 * math.pi * values["mode_frequency_Hz"]
    spring = m_r * w_r ** 2 + 2j * values["mode_damping_ratio"] * m_r * w_r * w
    return -w ** 2 * m_r * spring / (spring - w ** 2 * m_r)


@dataclass(frozen=True)
class Level:
    """One level's measured fundamentals: the receptance H = X / F (m/N, complex; X the
    displacement fundamental, phase relative to the force's) per frequency, what the level
    holds (:class:`Control`), per point the held quantity's amplitude (``drive``: |F| in N
    for FORCE, |X| in m for RESPONSE) and the standard deviation of each of H's real and
    imaginary parts (m/N).  :meth:`from_fundamentals` builds one from the response and the
    force fundamentals."""

    frequency_Hz: np.ndarray
    receptance_m_per_N: np.ndarray
    control: Control
    drive: np.ndarray
    sigma_m_per_N: np.ndarray

    def __post_init__(self):
        f = np.atleast_1d(np.asarray(self.frequency_Hz, dtype=np.float64))
        H = np.atleast_1d(np.asarray(self.receptance_m_per_N, dtype=complex))
        d = np.broadcast_to(np.asarray(self.drive, dtype=np.float64), f.shape).copy()
        s = np.broadcast_to(np.asarray(self.sigma_m_per_N, dtype=np.float64), f.shape).copy()
        if H.shape != f.shape:
            raise ValueError(f"Level: {H.size} receptance values for {f.size} frequencies")
        for name, v in (("frequency_Hz", f), ("drive", d), ("sigma_m_per_N", s)):
            if not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise ValueError(f"Level: {name} must be finite and > 0")
        if not np.all(np.isfinite(H)):
            raise ValueError("Level: receptance_m_per_N holds NaN or inf")
        object.__setattr__(self, "frequency_Hz", f)
        object.__setattr__(self, "receptance_m_per_N", H)
        object.__setattr__(self, "control", Control(self.control))
        object.__setattr__(self, "drive", d)
        object.__setattr__(self, "sigma_m_per_N", s)

    @classmethod
    def from_fundamentals(cls, frequency_Hz: Any, response: Any, force_N: Any, control: Control | str, *,
                          derivative: int = 0, sigma_response: Any, sigma_force_N: Any = 0.0,
                          held: float | None = None) -> Level:
        """A level from complex fundamentals per frequency: ``response`` (displacement m,
        velocity m/s or acceleration m/s^2 for ``derivative`` 0, 1, 2; converted by
        (i w)^-derivative), ``force_N`` (complex, or its amplitude: then ``response``'s phase
        is relative to the force's), their noise (standard deviation of a real or imaginary
        part, in their own units).  ``held``: the level's held amplitude (N or m) to use
        for every point instead of the measured |F| or |X| per point."""
        f = np.atleast_1d(np.asarray(frequency_Hz, dtype=np.float64))
        jw = 2j * math.pi * f
        X = np.asarray(response, dtype=complex) / jw ** int(derivative)
        F = np.broadcast_to(np.asarray(force_N, dtype=complex), f.shape)
        sX = np.broadcast_to(np.asarray(sigma_response, dtype=np.float64), f.shape) / np.abs(jw) ** int(derivative)
        sF = np.broadcast_to(np.asarray(sigma_force_N, dtype=np.float64), f.shape)
        H = X / F
        sigma = np.hypot(sX, np.abs(H) * sF) / np.abs(F)
        c = Control(control)
        drive = np.abs(F) if c is Control.FORCE else np.abs(X)
        if held is not None:
            drive = np.full(f.shape, float(held))
        return cls(f, H, c, drive, sigma)


def receptance(model: FrictionModel | str, values: Mapping[str, Any], mass_kg: float, level: Level,
               structure: Structure = Structure.NONE, structure_values: Mapping[str, float] | None = None,
               *, points: int = POINTS, third: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """The model's receptance H (m/N, complex) at ``level``'s points and the friction
    element's amplitude a (m) there, by the harmonic balance of the module doc; ``third``:
    with the displacement's third harmonic (:data:`THIRD_ITER` corrections), else the
    single-harmonic balance."""
    m = _model(model)
    sv = structure_values or {}
    w = 2 * math.pi * level.frequency_Hz
    base = -w ** 2 * mass_kg + structure_stiffness(structure, sv, w)
    base3 = -9 * w ** 2 * mass_kg + structure_stiffness(structure, sv, 3 * w)
    if level.control is Control.RESPONSE:
        solve, pure = (lambda dK: level.drive), None
    else:
        solve, pure = _amplitudes(m, values, base, w, level, points)
    dK = np.zeros(w.size, complex)
    a = solve(dK)
    X3 = np.zeros(w.size, complex)
    for it in range(THIRD_ITER + 1 if third else 1):
        S1p, S3p, S1, S3 = _two_paths(m, values, a, X3, w, points, pure)
        K0 = S1p / a
        dK = (S1 - S1p) / a
        if it == (THIRD_ITER if third else 0):
            break
        # the third harmonic's balance, base3 X3 + S3(X3) = 0, by a Newton step with the
        # friction's stiffness for it taken as the secant one, Re K_eq
        X3 = X3 - (base3 * X3 + S3) / (base3 + K0.real)
        a = solve(dK)
    return 1.0 / (base + K0 + dK), a


def _two_paths(m: FrictionModel, values: Mapping[str, Any], a: np.ndarray, X3: np.ndarray, w: np.ndarray,
               points: int, pure: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Harmonics 1 and 3 (complex, N) of the friction along a cos(theta) and along
    a cos(theta) + Re(X3 exp(3 i theta)), every point in one call (``pure``: the first two
    from a function of a, the splines of a rate-independent model, where there is one)."""
    theta = 2 * math.pi * np.arange(points) / points
    cos = a[:, None] * np.cos(theta)[None, :]
    third = cos + (X3[:, None] * np.exp(3j * theta)[None, :]).real
    n = a.size
    if pure is not None:
        S = np.fft.rfft(m.periodic_force(values, third, w), axis=1) * (2.0 / points)
        S1p, S3p = pure(a)
        return S1p, S3p, S[:, 1], S[:, 3]
    S = np.fft.rfft(m.periodic_force(values, np.vstack([cos, third]), np.concatenate([w, w])), axis=1) * (2.0 / points)
    return S[:n, 1], S[:n, 3], S[n:, 1], S[n:, 3]


def _amplitudes(m: FrictionModel, values: Mapping[str, Any], base: np.ndarray, w: np.ndarray, level: Level,
                points: int) -> Any:
    """The force-controlled level's solver, dK (N/m per point, the third harmonic's change of
    the friction's fundamental, held) -> the amplitudes a that balance |F| = a |D + dK|, and
    for a rate-independent model a -> the harmonics 1 and 3 along a cos(theta) from splines
    (None for a rate-dependent one)."""
    F = level.drive
    X_meas = np.abs(level.receptance_m_per_N) * F
    grid = np.geomspace(float(X_meas.min()) / GRID_SPAN, float(X_meas.max()) * GRID_SPAN, GRID)
    if m.rate_dependent:
        K = describing_function(m, values, grid[None, :], w[:, None], points=points)

        def K_at(a, rows):
            return describing_function(m, values, a, w[rows], points=points)
        pure = None
    else:
        # a rate-independent model: one cubic spline in ln a of harmonics 1 and 3 over a,
        # through the grid, serves every frequency (its error, about 1e-9 relative, is far
        # below any noise); the roots are found on it
        theta = 2 * math.pi * np.arange(points) / points
        S = np.fft.rfft(m.periodic_force(values, grid[:, None] * np.cos(theta)[None, :], np.ones(GRID)),
                        axis=1)[:, [1, 3]] * (2.0 / points) / grid[:, None]
        K_grid = S[:, 0]
        spline = CubicSpline(np.log(grid), np.column_stack([S.real, S.imag]))
        K = np.broadcast_to(K_grid[None, :], (w.size, GRID))

        def K_at(a, rows):
            v = spline(np.log(a))
            return v[..., 0] + 1j * v[..., 2]

        def pure(a):
            v = spline(np.log(a)) * a[:, None]
            return v[:, 0] + 1j * v[:, 2], v[:, 1] + 1j * v[:, 3]

    def solve(dK: np.ndarray) -> np.ndarray:
        lin = base + dK
        h = grid[None, :] * np.abs(lin[:, None] + K) - F[:, None]
        j, g = np.nonzero(np.signbit(h[:, :-1]) != np.signbit(h[:, 1:]))
        roots = _illinois(lambda x: np.exp(x) * np.abs(lin[j] + K_at(np.exp(x), j)) - F[j],
                          np.log(grid[g]), np.log(grid[g + 1]), h[j, g], h[j, g + 1])
        a = np.empty(w.size)
        have = np.zeros(w.size, bool)
        best = np.full(w.size, np.inf)
        for r, i in zip(roots, j):
            # the branch the measurement was on: the root whose amplitude is nearest the measured one
            dist = abs(math.log(r / X_meas[i]))
            if dist < best[i]:
                best[i], a[i], have[i] = dist, r, True
        for i in np.nonzero(~have)[0]:
            a[i] = grid[int(np.argmin(np.abs(h[i])))]        # no root on the grid: its nearest point
        return a
    return solve, pure


def _illinois(fn: Any, x0: np.ndarray, x1: np.ndarray, h0: np.ndarray, h1: np.ndarray) -> np.ndarray:
    """Roots of ``fn`` (vectorised) in the brackets [x0, x1] (values h0, h1 of opposite sign):
    regula falsi, Illinois-modified; returns exp(root) (x is ln a)."""
    if x0.size == 0:
        return np.empty(0)
    side = np.zeros(x0.size, dtype=np.int8)
    scale = np.maximum(np.abs(h0), np.abs(h1))
    for _ in range(ROOT_ITER):
        if np.max(x1 - x0) <= ROOT_TOL or np.all(np.minimum(np.abs(h0), np.abs(h1)) <= ROOT_TOL * scale):
            break
        xn = x1 - h1 * (x1 - x0) / (h1 - h0)
        xn = np.where(np.isfinite(xn) & (xn > x0) & (xn < x1), xn, 0.5 * (x0 + x1))
        hn = fn(xn)
        left = np.signbit(hn) == np.signbit(h0)          # the root is right of xn: xn replaces x0
        h1 = np.where(left & (side == 1), 0.5 * h1, h1)
        h0 = np.where(~left & (side == -1), 0.5 * h0, h0)
        x0, h0 = np.where(left, xn, x0), np.where(left, hn, h0)
        x1, h1 = np.where(left, x1, xn), np.where(left, h1, hn)
        side = np.where(left, 1, -1).astype(np.int8)
        done = hn == 0
        x0, x1 = np.where(done, xn, x0), np.where(done, xn, x1)
    r = x1 - h1 * (x1 - x0) / np.where(h1 != h0, h1 - h0, 1.0)
    r = np.where(np.abs(h0) <= ROOT_TOL * scale, x0, np.where(np.abs(h1) <= ROOT_TOL * scale, x1, r))
    return np.exp(np.where(np.isfinite(r) & (r >= x0) & (r <= x1), r, 0.5 * (x0 + x1)))
