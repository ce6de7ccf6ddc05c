"""The rate-dependent rivals, LuGre and GMS (its code in :mod:`sim.discrepancy.gms_rival`), fitted to the same data with the same weights and
held-out levels as the others (:mod:`sim.discrepancy.rivals`; decision 0086).

Both are fitted like the Iwan elements, on a rigid carriage: the measured displacement
harmonics (rebuilt from both motion channels, :meth:`Model._displacement`) give periodic
paths (:func:`timed_paths`: :func:`sim.identify.period_paths` started at the period's
largest value in time, not at its largest sample, decision 0090; :data:`M_RATE` samples a
period), the model's
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
- GMS: slip displacements at F_c on a fixed geometric grid (:data:`~sim.discrepancy.gms_rival.GMS_ELEMENTS`, as the
  Iwan grid), k_i = f_i / slip_i with f_i = alpha_i F_c.  Written as F_i = f_i u_i, the
  unit element u_i depends on slip_i, F_s / F_c, v_s, delta and C / F_c alone (stick:
  du/dx = 1 / slip; slide: du/dt = (C / F_c)(sgn v - u F_c / s(v)); slip when
  u sgn v reaches s(v) / F_c), so F = sum f_i u_i + sigma_2 v is linear in the f_i,
  sigma_2 (and m); F_c = sum f_i, alpha_i = f_i / F_c.  The outer four: log F_s / F_c >= 0,
  log v_s, delta, log C / F_c.  The unit elements' steady responses come from
  :func:`~sim.discrepancy.gms_rival._gms_units` (compiled, every element of a row at once, the Stribeck curve shared;
  an element whose slip exceeds the row's amplitude never slides and is x / slip): the
  update of :func:`sim.friction.gms.gms_advance`, written per unit element because the
  projection needs each element's force, not their sum; tests/sim/test_friction_choice.py
  checks that sum f_i u_i + sigma_2 v is the model's own periodic force.

The starts: LuGre from Dahl's fit (F_s ~ Dahl's F_c, F_c 0.85 of it, sigma_0 ~ sigma, v_s
half the median speed amplitude); GMS from F_s / F_c = 1.2, delta 2, v_s the median speed
amplitude, C / F_c twenty times the median drive frequency, on the Iwan fit's grid of
:data:`~sim.discrepancy.gms_rival.GMS_ELEMENTS` (coarse), then on that grid refined around its active elements
(:func:`~sim.discrepancy.gms_rival.refine`) in :data:`~sim.discrepancy.gms_rival.POLISH_NFEV` more; then each cluster of the fine grid's active
elements (neighbours at most one coarse interval apart) that slides at some step becomes
one element whose log-slip is an outer parameter too (start: the cluster's force-weighted
mean log-slip; bounds one coarse interval beyond the cluster), at most
:data:`~sim.discrepancy.gms_rival.GMS_FREE_MAX` of them (more: the fine grid's fit is the result), fitted in
:data:`~sim.discrepancy.gms_rival.FREE_NFEV` evaluations (:func:`~sim.discrepancy.gms_rival.gms_free`, decision 0090); an element whose slip
exceeds every amplitude is a spring whose slip the data cannot fix and stays on the grid.  Held-out errors: each level left out in
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
from scipy.optimize import least_squares, nnls

from ..friction import MODELS, path_velocity
from ..identify import _rotate_lift_centre, path_harmonics, period_paths
from .fit import Z95, Weights, at_least_empirical, step_scores
from .gain import frf
from .models import Data, Model

M_RATE = 256                 # samples a period: harmonics 1..9 of a kinked force to 1e-5 of it
OUTER_NFEV = 20              # the outer least squares' evaluations (each with a Jacobian of 4 more)
HELD_NFEV = 0                # a held-out refit: 0, one Gauss-Newton step from the full fit (projected_fit)
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
