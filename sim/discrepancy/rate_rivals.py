"""The rate-dependent rivals, LuGre and GMS, fitted to the same data with the same weights and
held-out levels as the others (:mod:`sim.discrepancy.rivals`; decision 0086).

Both are fitted like the Iwan elements, on a rigid carriage: the measured displacement
harmonics (rebuilt from both motion channels, :meth:`Model._displacement`) give periodic
paths (:func:`sim.identify.period_paths`, :data:`M_RATE` samples a period), the model's
force along them gives harmonics G (:func:`sim.identify.path_harmonics`), and the residual
is the force balance P - m A - G with the kinematics A + Omega^2 X, whitened by the base
fit's :class:`~sim.discrepancy.fit.Weights`.

**Variable projection.**  Each model's force is linear in some of its parameters given the
others, so those are solved by non-negative least squares inside, and only a few are
nonlinear, fitted outside by scipy.optimize.least_squares (log scales, bounds):

- LuGre: the bristle deflection z depends on sigma_0, F_c, F_s, v_s only, so
  F = sigma_0 z + sigma_1 dz/dt + sigma_2 v is linear in sigma_1, sigma_2 (and m).  The
  outer four: log sigma_0, log F_c, log F_s / F_c >= 0, log v_s.  z is the model's own
  steady periodic force (:meth:`sim.friction.lugre.LuGre.periodic_force` with
  sigma_1 = sigma_2 = 0) over sigma_0; dz/dt follows from it as the kernel takes it.
- GMS: slip displacements at F_c on a fixed geometric grid (:data:`GMS_ELEMENTS`, as the
  Iwan grid), k_i = f_i / slip_i with f_i = alpha_i F_c.  Written as F_i = f_i u_i, the
  unit element u_i depends on slip_i, F_s / F_c, v_s, delta and C / F_c alone (stick:
  du/dx = 1 / slip; slide: du/dt = (C / F_c)(sgn v - u F_c / s(v)); slip when
  u sgn v reaches s(v) / F_c), so F = sum f_i u_i + sigma_2 v is linear in the f_i,
  sigma_2 (and m); F_c = sum f_i, alpha_i = f_i / F_c.  The outer four: log F_s / F_c >= 0,
  log v_s, delta, log C / F_c.  The unit elements' steady responses come from
  :func:`_gms_units` (compiled, every element of a row at once, the Stribeck curve shared;
  an element whose slip exceeds the row's amplitude never slides and is x / slip): the
  update of :func:`sim.friction.gms.gms_advance`, written per unit element because the
  projection needs each element's force, not their sum; tests/sim/test_friction_choice.py
  checks that sum f_i u_i + sigma_2 v is the model's own periodic force.

The starts: LuGre from Dahl's fit (F_s ~ Dahl's F_c, F_c 0.85 of it, sigma_0 ~ sigma, v_s
half the median speed amplitude); GMS from F_s / F_c = 1.2, delta 2, v_s the median speed
amplitude, C / F_c twenty times the median drive frequency, on the Iwan fit's grid of
:data:`GMS_ELEMENTS` (coarse), then on that grid refined around its active elements
(:func:`refine`) in :data:`POLISH_NFEV` more.  Held-out errors: each level left out in
turn, every parameter moved from the full fit by one Gauss-Newton step on the kept levels
(the full Jacobian's rows; :data:`HELD_NFEV` > 0: the outer least squares instead), the
inner ones then solved exactly at the new outer ones; errors of compliance, accelerance
and the waveform as the Iwan fit computes them.  Intervals (95 %): the full Jacobian
(outer by finite differences, the active linear parameters' columns exact) at the
optimum, scaled by the reduced chi-square when it exceeds 1, each variance then raised to at
least the empirical per-step sandwich's (:func:`sim.discrepancy.fit.at_least_empirical`,
decision 0036) when there are at least twice as many steps as parameters (decision 0089).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.optimize import least_squares, nnls

from ..friction import MODELS, path_velocity, sample_spacing
from ..identify import _rotate_lift_centre, path_harmonics, period_paths
from .fit import Z95, Weights, at_least_empirical, step_scores
from .gain import frf
from .models import Data, Model

M_RATE = 256                 # samples a period: harmonics 1..9 of a kinked force to 1e-5 of it
GMS_ELEMENTS = 40            # slip displacements on the coarse grid (the Iwan fit's range)
GMS_REFINE = 4               # the fine grid: each active coarse element's interval cut in this many
GMS_FINE_MAX = 96            # at most this many elements on the fine grid (fewer cuts where many are active)
OUTER_NFEV = 20              # the outer least squares' evaluations (each with a Jacobian of 4 more)
POLISH_NFEV = 4              # on the fine grid, from the coarse fit
GMS_FREE_MAX = 8             # at most this many elements at free slips (more clusters: the fine grid's result)
FREE_NFEV = 20               # the free slips' fit, from the fine grid's
NO_POLISH = 100.0            # no fine grid when the coarse chi-square is this many times another model's
HELD_NFEV = 0                # a held-out refit: 0, one Gauss-Newton step from the full fit (projected_fit)
UNIT_TOL = 1e-7              # a unit element's steady state: change per period below this
PERIODS_MAX = 60
TIMED_PATHS = True           # each period started at its largest value in time (timed_paths)
EMPIRICAL_FLOOR = True       # intervals at least the empirical per-step sandwich (decisions 0036, 0089)


# ---------------------------------------------------------------- the common problem
@dataclass
class _Setup:
    """The measured side, whitened, per step (rows of steps x 4K), and the paths."""

    d: Data
    W: Weights
    paths: np.ndarray
    starts: np.ndarray
    vel: np.ndarray
    b: np.ndarray            # the whitened residual with no friction and no mass
    mcol: np.ndarray         # its change per kg of mass
    vcol: np.ndarray         # per N s/m of viscous friction
    amp: np.ndarray          # each path's amplitude (half its range), m

    @property
    def K(self) -> int:
        return self.d.X.shape[1]

    def harmonics(self, samples: np.ndarray, rows: np.ndarray) -> np.ndarray:
        return path_harmonics(samples, self.starts[rows], self.K)

    def col(self, H: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The whitened residual's change for a friction force of harmonics ``H`` (rows x K,
        or rows x K x p for p forces at once: rows x 4K x p), as :meth:`Weights.whiten`."""
        (fr, fi), (kr, ki), (cr, ci) = (np.asarray(a)[:, rows] for a in (self.W.s_F, self.W.s_Kc, self.W.c))
        if H.ndim == 3:
            fr, fi, kr, ki, cr, ci = (a[:, :, None] for a in (fr, fi, kr, ki, cr, ci))
        re, im = -H.real / fr, -H.imag / fi
        return np.concatenate([re, im, -cr / fr * re / kr, -ci / fi * im / ki], axis=1)


def _vec(wF, wK):
    return np.concatenate([wF.real, wF.imag, wK.real, wK.imag], axis=1)


def timed_paths(X: np.ndarray, M: int, newton: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """:func:`sim.identify.period_paths` with each period started at its largest value in
    time, not at the largest sample (Newton on the harmonic series from that sample): a
    reversal half a sample late moves the whole hysteresis loop, the force's error first
    order in 1 / M (decision 0090).  Returns (paths, rotations in samples, not integers)."""
    X = np.atleast_2d(X)
    _, starts = period_paths(X, M)
    k = np.arange(1, X.shape[1] + 1)
    tau = 2 * np.pi * starts / M
    for _ in range(newton):
        e = X * np.exp(1j * np.outer(tau, k))
        d1 = (e * k).real.sum(axis=1)                        # x'(tau), x = sum Im(X_k e^(i k tau))
        d2 = -(e * k ** 2).imag.sum(axis=1)
        step = np.where(d2 < 0, -d1 / np.where(d2 < 0, d2, -1.0), 0.0)
        tau = tau + np.clip(step, -2 * np.pi / M, 2 * np.pi / M)
    spec = np.zeros((X.shape[0], M // 2 + 1), complex)
    K = min(X.shape[1], M // 2 - 1)
    spec[:, 1:K + 1] = -1j * (X * np.exp(1j * np.outer(tau, k)))[:, :K] * (M / 2)
    x = np.fft.irfft(spec, M, axis=1)
    out = np.empty_like(x)
    _rotate_lift_centre(x, np.zeros(X.shape[0], dtype=np.int64), out)
    return out, tau * M / (2 * np.pi)


def setup(d: Data, W: Weights, M: int = M_RATE) -> _Setup:
    K = d.X.shape[1]
    x = Model((), K)._displacement({}, d)
    paths, starts = (timed_paths if TIMED_PATHS else period_paths)(x, M)
    vel = path_velocity(paths, d.omega)
    every = np.arange(d.X.shape[0])
    s = _Setup(d, W, paths, starts, vel, _vec(*W.whiten(d.P, d.A + d.Omega ** 2 * d.X)),
               _vec(*W.whiten(-d.A, np.zeros_like(d.A), bias=False)), np.empty(0), 0.5 * np.ptp(paths, axis=1))
    s.vcol = s.col(s.harmonics(vel, every), every)
    return s


# basis(theta, rows) -> (fixed friction harmonics or None, linear friction harmonics: rows x K x p)
Basis = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray | None, np.ndarray]]


@dataclass
class _Projected:
    """r(theta, z) = b + col(G0(theta)) + C(theta) z, z = (m, linear...) >= 0."""

    s: _Setup
    basis: Basis
    lin_viscous: bool        # the last linear column is sigma_2 v (its column precomputed)

    def system(self, theta: np.ndarray, rows: np.ndarray) -> tuple:
        """(b, C, G0, H) per row of ``rows``: b rows x 4K, C rows x 4K x (1 + p)."""
        G0, H = self.basis(theta, rows)
        b = self.s.b[rows] + (self.s.col(G0, rows) if G0 is not None else 0.0)
        parts = [self.s.mcol[rows][:, :, None], self.s.col(H, rows)]
        if self.lin_viscous:
            parts.append(self.s.vcol[rows][:, :, None])
        return b, np.concatenate(parts, axis=2), G0, H

    def solve(self, theta: np.ndarray, rows: np.ndarray, sys_: tuple | None = None):
        """(z, the whitened residual, the system) at ``theta`` on ``rows`` (``sys_``: the
        system of every row of ``rows`` made already)."""
        sys_ = self.system(theta, rows) if sys_ is None else sys_
        b, C = sys_[0].ravel(), sys_[1].reshape(-1, sys_[1].shape[-1])
        scale = np.sqrt((C ** 2).sum(axis=0))
        scale[scale == 0] = 1.0
        z, _ = nnls(C / scale, -b, maxiter=50 * C.shape[1])
        z = z / scale
        return z, b + C @ z, sys_

    def fit(self, theta0: np.ndarray, lo: np.ndarray, hi: np.ndarray, rows: np.ndarray, nfev: int) -> np.ndarray:
        th0 = np.clip(theta0, lo + 1e-9, hi - 1e-9)
        if nfev <= 0:
            return th0

        def fun(th):
            return self.solve(th, rows)[1]
        try:
            return least_squares(fun, th0, bounds=(lo, hi), max_nfev=nfev, diff_step=1e-3, x_scale=1.0).x
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            return th0

    def friction(self, sys_: tuple, z: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The fitted friction's harmonics on ``rows`` (positions in the system ``sys_``; z: m first)."""
        G0, H = sys_[2], sys_[3][rows]
        G = (G0[rows] if G0 is not None else 0.0) + H @ z[1:1 + H.shape[2]]
        if self.lin_viscous:
            G = G + z[-1] * self.s.harmonics(self.s.vel[rows], rows)
        return G


def _errors(G: np.ndarray, m: float, d: Data, rows: np.ndarray):
    """Per step of ``rows``: compliance, accelerance and waveform errors (as rivals' Iwan fit)."""
    sub = d.subset(rows)
    A_pred = -sub.Omega ** 2 * sub.X
    C_pred, Acc_pred = frf(m * A_pred + G, A_pred, sub.X)
    C_meas, Acc_meas = frf(sub.P, sub.A, sub.X)
    rF = sub.P - m * sub.A - G
    eH2 = np.sum(np.abs(rF[:, 1:]) ** 2, axis=1) / np.abs(sub.P[:, 0]) ** 2
    return np.abs(C_pred / C_meas - 1.0), np.abs(Acc_pred / Acc_meas - 1.0), eH2


@dataclass
class Result:
    theta: np.ndarray
    z: np.ndarray
    chi2: float
    n_data: int
    n_params: int
    cov: np.ndarray          # over (theta, z): z's inactive entries zero
    heldout: float
    heldout_compliance: float
    heldout_accelerance: float
    seconds: float


def projected_fit(p: _Projected, theta0: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                  nfev: int = OUTER_NFEV, held_nfev: int = HELD_NFEV) -> Result:
    """Fit, intervals and held-out errors of a variable-projection problem (module doc).
    ``held_nfev`` 0: a held-out refit is one Gauss-Newton step of every parameter from the
    full fit on the kept levels (the full Jacobian's rows), the inner ones then solved
    exactly; more: the outer least squares in that many evaluations."""
    t0 = time.process_time()
    d = p.s.d
    every = np.arange(d.X.shape[0])
    theta = p.fit(theta0, lo, hi, every, nfev)
    z, r, (b, C, _, _) = p.solve(theta, every)
    C = C.reshape(-1, C.shape[-1])
    chi2 = float(r @ r)
    active = np.flatnonzero(z > 0)
    nt = theta.size
    J = np.empty((r.size, nt + active.size))
    for i in range(nt):                      # outer columns with z held (the full Jacobian)
        h = 1e-4 * max(1.0, abs(theta[i]))
        th = theta.copy()
        th[i] += h if theta[i] + h <= hi[i] else -h
        bi, Ci, _, _ = p.system(th, every)
        J[:, i] = (bi.ravel() + Ci.reshape(r.size, -1) @ z - r) / (th[i] - theta[i])
    J[:, nt:] = C[:, active]
    n_params = nt + active.size
    phi = max(1.0, chi2 / max(1, r.size - n_params))
    H_inv = np.linalg.pinv(J.T @ J)
    cov_a = H_inv * phi
    if EMPIRICAL_FLOOR and every.size >= 2 * n_params:
        # decision 0036's floor, with at least as many steps to spare as parameters (0089);
        # fit.step_scores takes the rows as (part, step, harmonic), these are (step, part, harmonic)
        S, K4 = every.size, r.size // every.size
        Jl = J.reshape(S, 4, K4 // 4, n_params).transpose(1, 0, 2, 3).reshape(r.size, n_params)
        rl = r.reshape(S, 4, K4 // 4).transpose(1, 0, 2).ravel()
        cov_a = at_least_empirical(cov_a, H_inv, step_scores(Jl, rl, S))
    idx = np.concatenate([np.arange(nt), nt + active])
    cov = np.zeros((nt + z.size, nt + z.size))
    cov[np.ix_(idx, idx)] = cov_a
    per_row = r.size // every.size
    eC, eA, eH = [], [], []
    for lv in np.unique(d.level):
        held = np.flatnonzero(d.level == lv)
        train = np.flatnonzero(d.level != lv)
        if held_nfev > 0:
            th = p.fit(theta, lo, hi, train, held_nfev)
        else:
            keep = np.repeat(d.level != lv, per_row)
            step = np.linalg.lstsq(J[keep], -r[keep], rcond=1e-10)[0]
            th = np.clip(theta + step[:nt], lo, hi)
        sys_ = p.system(th, every)
        zt, _, _ = p.solve(th, train, tuple(None if a is None else a[train] for a in sys_))
        c, a, e = _errors(p.friction(sys_, zt, held), float(zt[0]), d, held)
        eC.append(c)
        eA.append(a)
        eH.append(e)
    cc, aa, hh = (np.concatenate(e) for e in (eC, eA, eH))
    return Result(theta, z, chi2, r.size, n_params, cov, float(np.sqrt(np.mean(0.5 * (cc ** 2 + aa ** 2) + hh))),
                  float(np.sqrt(np.mean(cc ** 2))), float(np.sqrt(np.mean(aa ** 2))), time.process_time() - t0)


# ---------------------------------------------------------------- intervals by name
def _log_q(value: float, var: float, unit: str) -> dict:
    w = Z95 * math.sqrt(max(var, 0.0))
    return dict(value=value, low=value * math.exp(-w), high=value * math.exp(min(w, 700.0)), unit=unit)


def _lin_q(value: float, var: float, unit: str, floor: float | None = 0.0) -> dict:
    w = Z95 * math.sqrt(max(var, 0.0))
    low = value - w if floor is None else max(floor, value - w)
    return dict(value=value, low=low, high=value + w, unit=unit)


def _grad_var(cov: np.ndarray, g: np.ndarray) -> float:
    return float(g @ cov @ g)


# ---------------------------------------------------------------- LuGre
def lugre_problem(s: _Setup) -> _Projected:
    lugre = MODELS["lugre"]

    def basis(theta, rows):
        s0, F_c, F_s, v_s = math.exp(theta[0]), math.exp(theta[1]), math.exp(theta[1] + theta[2]), math.exp(theta[3])
        v = dict(sigma0_N_per_m=s0, sigma1_N_s_per_m=0.0, sigma2_N_s_per_m=0.0, F_c_N=F_c, F_s_N=F_s, v_s_m_per_s=v_s)
        vel = s.vel[rows]
        F0 = lugre.periodic_force(v, s.paths[rows], s.d.omega[rows])          # sigma_0 z
        g = F_c + (F_s - F_c) * np.exp(-(vel / v_s) ** 2)
        zdot = vel - np.abs(vel) * F0 / g                                      # as the kernel takes it
        return s.harmonics(F0, rows), s.harmonics(zdot, rows)[:, :, None]
    return _Projected(s, basis, lin_viscous=True)


def lugre_fit(s: _Setup, F_c: float, sigma: float) -> tuple[Result, dict, dict]:
    """LuGre from Dahl's F_c and sigma (module doc): (result, values, parameters)."""
    speed = float(np.median(np.abs(s.vel).max(axis=1)))
    lo = np.array([math.log(sigma) - 5, math.log(F_c) - 3, 0.0, math.log(speed) - 7])
    hi = np.array([math.log(sigma) + 5, math.log(F_c) + 3, math.log(10.0), math.log(speed) + 5])
    th0 = np.array([math.log(sigma), math.log(0.85 * F_c), math.log(1 / 0.85), math.log(0.5 * speed)])
    res = projected_fit(lugre_problem(s), th0, lo, hi)
    th, z, cov = res.theta, res.z, res.cov
    s0, F_c, F_s, v_s = math.exp(th[0]), math.exp(th[1]), math.exp(th[1] + th[2]), math.exp(th[3])
    m, s1, s2 = (float(v) for v in z)
    values = dict(sigma0_N_per_m=s0, sigma1_N_s_per_m=s1, sigma2_N_s_per_m=s2, F_c_N=F_c, F_s_N=F_s, v_s_m_per_s=v_s)
    params = dict(sigma0_N_per_m=_log_q(s0, cov[0, 0], "N/m"),
                  sigma1_N_s_per_m=_lin_q(s1, cov[5, 5], "N s/m"), sigma2_N_s_per_m=_lin_q(s2, cov[6, 6], "N s/m"),
                  F_c_N=_log_q(F_c, cov[1, 1], "N"), F_s_N=_log_q(F_s, cov[1, 1] + cov[2, 2] + 2 * cov[1, 2], "N"),
                  v_s_m_per_s=_log_q(v_s, cov[3, 3], "m/s"), mass_kg=_lin_q(m, cov[4, 4], "kg"))
    return res, values, params


# ---------------------------------------------------------------- GMS
@njit(cache=True, nogil=True, inline="always")
def _s_n(r, v_s, delta, v):
    return 1.0 + (r - 1.0) * math.exp(-abs(v / v_s) ** delta)


@njit(cache=True, nogil=True)
def _gms_units(paths, vel, dts, slips, amp, r, v_s, delta, c, tol, out):
    """Steady unit-element forces u (rows x elements x samples) of the GMS with F_c = 1,
    F_s = r, C = c, alpha = 1 per element, k = 1 / slip: gms_advance's update, every element
    of a row at once (module doc).  Returns the most periods a row needed."""
    R, M = paths.shape
    N = slips.shape[0]
    s_mean = np.empty(M)
    s_end = np.empty(M)
    s_start = np.empty(M)
    decay = np.empty(M)
    u = np.empty(N)
    mode = np.empty(N)
    prev = np.empty(N)
    worst = 0
    for i in range(R):
        x = paths[i]
        n_act = 0
        for e in range(N):
            if slips[e] < amp[i]:
                n_act = e + 1
            else:
                for j in range(M):
                    out[i, e, j] = x[j] / slips[e]     # never slides: a spring
        if n_act == 0:
            continue
        dt = dts[i]
        for j in range(M):
            jn = j + 1 if j + 1 < M else 0
            dx = x[jn] - x[j]
            v_end = vel[i, jn]
            v_m = dx / dt
            s_mean[j] = _s_n(r, v_s, delta, v_m)
            s_end[j] = _s_n(r, v_s, delta, v_end)
            s_start[j] = _s_n(r, v_s, delta, 2.0 * v_m - v_end)
            decay[j] = math.exp(-c * dt / s_mean[j])
        # virgin, quasi-static to the first sample (the path starts at its largest value)
        sg0 = 1.0 if x[0] > 0.0 else -1.0
        for e in range(n_act):
            u[e] = x[0] / slips[e]
            mode[e] = 0.0
            if sg0 * u[e] > r:
                u[e] = sg0 * r
                mode[e] = 1.0
        direction = sg0 if x[0] != 0.0 else 0.0
        used = 0
        write = False
        while True:
            for e in range(n_act):
                prev[e] = u[e]
            for j in range(M):
                jn = j + 1 if j + 1 < M else 0
                dx = x[jn] - x[j]
                if dx != 0.0:
                    sg = 1.0 if dx > 0.0 else -1.0
                    if direction != sg:
                        for e in range(n_act):
                            mode[e] = 0.0
                        direction = sg
                    for e in range(n_act):
                        if mode[e] == 0.0:
                            un = u[e] + dx / slips[e]
                            after = sg * un - s_end[j]
                            if after <= 0.0:
                                u[e] = un
                                continue
                            before = sg * u[e] - s_start[j]
                            frac = before / (before - after) if before < 0.0 else 0.0
                            ui = u[e] + frac * dx / slips[e]
                            v0 = 2.0 * dx / dt - vel[i, jn]
                            ss = _s_n(r, v_s, delta, v0 + (vel[i, jn] - v0) * 0.5 * (1.0 + frac))
                            a = sg * ss
                            u[e] = a + (ui - a) * math.exp(-c * (1.0 - frac) * dt / ss)
                            mode[e] = 1.0
                        else:
                            a = sg * s_mean[j]
                            u[e] = a + (u[e] - a) * decay[j]
                if write:
                    for e in range(n_act):
                        out[i, e, jn] = u[e]
            if write:
                break
            used += 1
            change = 0.0
            for e in range(n_act):
                change = max(change, abs(u[e] - prev[e]))
            if (used >= 2 and change <= tol) or used >= PERIODS_MAX:
                write = True
        worst = max(worst, used)
    return worst


def gms_units(s: _Setup, slips: np.ndarray, r: float, v_s: float, delta: float, c: float,
              rows: np.ndarray) -> np.ndarray:
    """Harmonics (rows x K x elements) of the unit elements' steady force."""
    paths = np.ascontiguousarray(s.paths[rows])
    out = np.empty((paths.shape[0], slips.size, paths.shape[1]))
    _gms_units(paths, np.ascontiguousarray(s.vel[rows]), sample_spacing(s.d.omega[rows], paths.shape[1]), slips,
               s.amp[rows], r, v_s, delta, c, UNIT_TOL, out)
    H = path_harmonics(out.reshape(-1, out.shape[2]), np.repeat(s.starts[rows], slips.size), s.K)
    return H.reshape(paths.shape[0], slips.size, s.K).transpose(0, 2, 1)


def gms_problem(s: _Setup, slips: np.ndarray) -> _Projected:
    def basis(theta, rows):
        return None, gms_units(s, slips, math.exp(theta[0]), math.exp(theta[1]), float(theta[2]), math.exp(theta[3]),
                               rows)
    return _Projected(s, basis, lin_viscous=True)


def refine(slips: np.ndarray, active: np.ndarray, parts: int = GMS_REFINE) -> np.ndarray:
    """The geometric grid ``slips`` with each active element's neighbourhood (to the next
    element either side) cut into ``parts`` per interval, fewer where that would make more
    than :data:`GMS_FINE_MAX` (a smooth virgin curve, many elements active, needs none)."""
    ratio = float(slips[1] / slips[0]) if slips.size > 1 else 2.0
    while parts > 1:
        sub = [slips[i] * ratio ** (k / parts) for i in active for k in range(1 - parts, parts)]
        fine = np.unique(np.concatenate([slips, np.array(sub, dtype=float)]))
        if fine.size <= GMS_FINE_MAX:
            return fine
        parts -= 1
    return slips


def clusters(active: np.ndarray) -> list[np.ndarray]:
    """Runs of neighbouring grid indices in the sorted ``active`` (each run one cluster)."""
    if active.size == 0:
        return []
    cut = np.flatnonzero(np.diff(active) > 1) + 1
    return np.split(active, cut)


def gms_free_problem(s: _Setup, fixed: np.ndarray) -> _Projected:
    """GMS with the first elements' log-slips free (theta[4:]) and ``fixed`` slips after them."""
    def basis(theta, rows):
        slips = np.concatenate([np.exp(theta[4:]), fixed])
        return None, gms_units(s, slips, math.exp(theta[0]), math.exp(theta[1]), float(theta[2]), math.exp(theta[3]),
                               rows)
    return _Projected(s, basis, lin_viscous=True)


def gms_free(s: _Setup, slips: np.ndarray, z: np.ndarray, ratio: float) -> tuple | None:
    """The free-slip problem from a grid fit (module doc): each cluster of active grid
    elements that slides at some step becomes one element at a free log-slip (start: the
    cluster's force-weighted mean log-slip, bounds one coarse interval ``ratio`` beyond it),
    the springs' elements (slip above every amplitude) stay on the grid.  (problem, start
    of the slips, their bounds, the fixed slips), or None for more than :data:`GMS_FREE_MAX`."""
    f = z[1:1 + slips.size]
    free, fixed = [], []
    for c in clusters(np.flatnonzero(f > 0)):
        if slips[c].min() < s.amp.max():
            free.append(c)
        else:
            fixed.extend(c.tolist())
    if not free or len(free) > GMS_FREE_MAX:
        return None
    ls = np.log(slips)
    start = np.array([float(np.average(ls[c], weights=f[c])) for c in free])
    lo = np.array([ls[c].min() for c in free]) - math.log(ratio)
    hi = np.array([ls[c].max() for c in free]) + math.log(ratio)
    fixed_s = slips[np.array(fixed, dtype=int)]
    return gms_free_problem(s, fixed_s), start, lo, hi, fixed_s


def gms_fit(s: _Setup, slips: np.ndarray, other_chi2: float = math.inf) -> tuple[Result, dict, dict]:
    """GMS on the slip grid ``slips`` (module doc): (result, values, parameters).  The fine
    grid only where it can matter: with the coarse fit's chi-square above :data:`NO_POLISH`
    times ``other_chi2`` (the best other model's) the coarse fit is the result (the fine
    grid lowered it 15-fold on the issue's GMS case, decision 0086); else the fine grid's
    clusters become elements at free slips (:func:`gms_free`, decision 0090)."""
    speed = float(np.median(np.abs(s.vel).max(axis=1)))
    w = float(np.median(s.d.omega))
    lo = np.array([0.0, math.log(speed) - 7, 0.5, math.log(w) - 3])
    hi = np.array([math.log(5.0), math.log(speed) + 5, 5.0, math.log(w) + 9])
    th0 = np.array([math.log(1.2), math.log(speed), 2.0, math.log(20 * w)])
    coarse = gms_problem(s, slips)
    every = np.arange(s.d.X.shape[0])
    th1 = coarse.fit(th0, lo, hi, every, OUTER_NFEV)
    z1, r1, _ = coarse.solve(th1, every)
    n_free, grid = 0, slips
    if float(r1 @ r1) > NO_POLISH * other_chi2:
        res = projected_fit(coarse, th1, lo, hi, nfev=0)
    else:
        ratio = float(slips[1] / slips[0]) if slips.size > 1 else 2.0
        slips = grid = refine(slips, np.flatnonzero(z1[1:1 + slips.size] > 0))
        fine = gms_problem(s, slips)
        th2 = fine.fit(th1, lo, hi, every, POLISH_NFEV)
        z2, _, _ = fine.solve(th2, every)
        made = gms_free(s, slips, z2, ratio) if GMS_FREE_MAX > 0 else None
        if made is None:
            res = projected_fit(fine, th2, lo, hi, nfev=0)
        else:
            problem, ls0, ls_lo, ls_hi, fixed = made
            n_free = ls0.size
            res = projected_fit(problem, np.concatenate([th2, ls0]), np.concatenate([lo, ls_lo]),
                                np.concatenate([hi, ls_hi]), nfev=FREE_NFEV)
            slips = np.concatenate([np.exp(res.theta[4:]), fixed])
    return res, *_gms_report(res, slips, n_free, grid)


def _gms_report(res: Result, slips: np.ndarray, n_free: int, grid: np.ndarray) -> tuple[dict, dict]:
    """GMS's values and parameters with 95 % intervals from a fit whose first ``n_free``
    elements' log-slips are outer parameters 4.. (the others on the slip ``grid``: their
    slip's interval is its grid cell, between the geometric midpoints to its neighbours)."""
    th, z, cov = res.theta, res.z, res.cov
    nt = th.size
    N = slips.size
    f, m, s2 = z[1:1 + N], float(z[0]), float(z[-1])
    F_c = float(f.sum())
    r, v_s, delta, c = math.exp(th[0]), math.exp(th[1]), float(th[2]), math.exp(th[3])
    act = [int(i) for i in np.argsort(slips) if f[i] > 0]
    fi = nt + 1 + np.arange(N)               # f's entries in (theta, z)
    g_Fc = np.zeros(cov.shape[0])
    g_Fc[fi] = 1.0
    var_Fc = _grad_var(cov, g_Fc)
    rel_Fc = var_Fc / max(F_c, 1e-300) ** 2
    g = g_Fc / max(F_c, 1e-300)              # log F_c's gradient
    gs, gC = g.copy(), g.copy()
    gs[0] += 1.0
    gC[3] += 1.0
    values = dict(F_c_N=F_c, F_s_N=r * F_c, v_s_m_per_s=v_s, delta=delta, C_N_per_s=c * F_c, sigma2_N_s_per_m=s2,
                  k_N_per_m=[float(f[i] / slips[i]) for i in act], alpha=[float(f[i] / F_c) for i in act])
    ks, alphas, slip_q = [], [], []
    for i in act:
        k = float(f[i] / slips[i])
        gk = np.zeros(cov.shape[0])
        gk[fi[i]] = 1.0 / slips[i]
        ga = -g_Fc * f[i] / F_c ** 2
        ga[fi[i]] += 1.0 / F_c
        if i < n_free:
            gk[4 + i] = -k
            slip_q.append(_log_q(float(slips[i]), cov[4 + i, 4 + i], "m"))
        else:
            j = int(np.argmin(np.abs(grid - slips[i])))
            ratio = float(grid[1] / grid[0]) if grid.size > 1 else 2.0
            below = grid[j - 1] if j > 0 else slips[i] / ratio
            above = grid[j + 1] if j + 1 < grid.size else slips[i] * ratio
            slip_q.append(dict(value=float(slips[i]), low=float(math.sqrt(below * slips[i])),
                               high=float(math.sqrt(above * slips[i])), unit="m"))
        ks.append(_lin_q(k, _grad_var(cov, gk), "N/m"))
        alphas.append(_lin_q(float(f[i] / F_c), _grad_var(cov, ga), "1"))
    params = dict(F_c_N=_log_q(F_c, rel_Fc, "N"), F_s_N=_log_q(r * F_c, _grad_var(cov, gs), "N"),
                  v_s_m_per_s=_log_q(v_s, cov[1, 1], "m/s"),
                  delta=_lin_q(delta, cov[2, 2], "1", floor=None),
                  C_N_per_s=_log_q(c * F_c, _grad_var(cov, gC), "N/s"),
                  sigma2_N_s_per_m=_lin_q(s2, cov[-1, -1], "N s/m"), mass_kg=_lin_q(m, cov[nt, nt], "kg"),
                  k_N_per_m=ks, alpha=alphas, slip_m=slip_q)
    return values, params
