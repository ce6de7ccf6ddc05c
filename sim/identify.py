"""Identification of the friction parameters (F_s, x_s, n) and the moving mass m from
stepped-sine steps, in the harmonic domain.

Per step the measured friction force is P(t) - m a(t).  Its harmonics (from the
least-squares fits the procedure stores) are compared with the harmonics of the Masing
friction computed along the measured displacement, reconstructed from its own harmonics
over one period.  Both sides are band-limited to the same harmonics, so the sharp turns of
the model at reversals (n < 1) cost nothing that the measurement could not show.

The steady loop is built by virgin loading to the period's largest displacement and one
period from there: for a two-reversal loop this is the symmetric Masing loop, and inner
loops (VRAR orbits) follow the memory rules on their own.

Weighted least squares (scipy.optimize.least_squares) in log-parameters; intervals from
the Jacobian, scaled by the reduced chi-square.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.optimize import least_squares

from .masing import LAMBDA_MASING, active_depth, branch_force, push_reversal
from .virgin import CURVE_SAKAI

log = logging.getLogger(__name__)

POINTS_PER_PERIOD = 256
PARAMS = ("F_s_N", "x_s_m", "n", "mass_kg")
N_BOUNDS = (0.1, 6.0)
# A weak prior at the guess (a factor 4 on F_s, x_s, m; 1.5 on n): it keeps the first
# few, uninformative steps from sending the estimate astray and gives an undetermined
# parameter an honest interval.  With a full plan its weight is negligible.
PRIOR_SIGMA = np.array([math.log(4.0), math.log(4.0), 1.5, math.log(4.0)])


@dataclass(frozen=True)
class StepHarmonics:
    """One step's harmonics, complex amplitudes C_k = A_k exp(i phi_k) of A_k sin(k w t + phi_k)."""

    freq_Hz: float
    force: np.ndarray      # N
    accel: np.ndarray      # m/s^2
    disp: np.ndarray       # m
    sigma_force: float     # standard error of one harmonic's real/imag part, N
    sigma_accel: float     # m/s^2
    sigma_disp: float = 0.0   # m

    @classmethod
    def from_result(cls, r: dict) -> "StepHarmonics":
        def c(fit):
            return np.asarray(fit["amplitude"]) * np.exp(1j * np.asarray(fit["phase_rad"]))
        scale = math.sqrt(2.0 / max(r.get("n_samples", 1000), 1))
        return cls(freq_Hz=r["freq_Hz"], force=c(r["force"]), accel=c(r["accel"]), disp=c(r["disp"]),
                   sigma_force=r["force"]["noise_rms"] * scale, sigma_accel=r["accel"]["noise_rms"] * scale,
                   sigma_disp=r["disp"]["noise_rms"] * scale)


@dataclass(frozen=True)
class Estimate:
    values: dict                       # PARAMS -> value
    low: dict                          # 95 % interval
    high: dict
    rel_std: dict                      # relative standard error
    steps_used: int
    cost: float                        # reduced chi-square
    warnings: tuple[str, ...] = field(default=())

    def as_dict(self) -> dict:
        return dict(values=self.values, low=self.low, high=self.high, rel_std=self.rel_std,
                    steps_used=self.steps_used, reduced_chi2=self.cost, warnings=list(self.warnings))


@njit(cache=True)
def _loop_friction(paths, tops, lam, p, out):
    """Dimensionless Masing friction along each row of ``paths`` (one period starting at
    its largest value ``tops[i]``), after virgin loading from 0 to that value."""
    su = np.empty(16)
    sF = np.empty(16)
    for i in range(paths.shape[0]):
        k = 0
        d = 1.0 if tops[i] >= 0 else -1.0
        # virgin loading to the top (any path from 0 to it gives the same state)
        prev = tops[i]
        for j in range(paths.shape[1]):
            u = paths[i, j]
            step = u - prev
            if step * d < 0.0:
                k = active_depth(prev, k, su, d)
                F_r = branch_force(prev, k, su, sF, lam, CURVE_SAKAI, p)
                k, su, sF = push_reversal(prev, F_r, k, su, sF)
                d = -d
            k = active_depth(u, k, su, d)
            out[i, j] = branch_force(u, k, su, sF, lam, CURVE_SAKAI, p)
            prev = u


def synthesize(C: np.ndarray, M: int) -> np.ndarray:
    """Rows of samples of sum_k Im(C_k exp(i k w t)) over one period (C: steps x K)."""
    k = np.arange(1, C.shape[1] + 1)
    E = np.exp(1j * 2 * np.pi * np.outer(np.arange(M) / M, k))     # M x K
    return (E @ C.T).imag.T                                          # steps x M


def analyse(samples: np.ndarray, K: int) -> np.ndarray:
    """Inverse of :func:`synthesize`: complex amplitudes of the first K harmonics."""
    M = samples.shape[1]
    spec = np.fft.rfft(samples, axis=1) * (2.0 / M)
    return 1j * spec[:, 1:K + 1]


class Identifier:
    """Accumulates steps and fits (F_s, x_s, n, m); warm-started from the last fit."""

    def __init__(self, guess: dict, harmonics: int = 5, lam: float = LAMBDA_MASING,
                 points_per_period: int = POINTS_PER_PERIOD):
        self.K = harmonics
        self.lam = lam
        self.M = points_per_period
        self.steps: list[StepHarmonics] = []
        self.theta = np.log([guess["F_s_N"], guess["x_s_m"], 1.0, guess["mass_kg"]])
        self.theta[2] = guess["n"]
        self.theta_prior = self.theta.copy()
        self.estimate: Estimate | None = None
        self.history: list[dict] = []

    # ------------------------------------------------------------------ data
    def add(self, step: StepHarmonics | dict) -> None:
        if isinstance(step, dict):
            step = StepHarmonics.from_result(step)
        self.steps.append(step)

    # ------------------------------------------------------------------ model
    def model_friction(self, F_s: float, x_s: float, n: float, X: np.ndarray) -> np.ndarray:
        """Harmonics of the Masing friction (N) along the displacement harmonics X (m)."""
        x = synthesize(X, self.M)
        centre = 0.5 * (x.max(axis=1) + x.min(axis=1))
        u = (x - centre[:, None]) / x_s
        start = np.argmax(u, axis=1)
        rows = np.arange(u.shape[0])[:, None]
        idx = (start[:, None] + np.arange(self.M)[None, :]) % self.M
        path = u[rows, idx]
        out = np.empty_like(path)
        _loop_friction(path, path[:, 0].copy(), self.lam, np.array([n]), out)
        F = np.empty_like(out)
        F[rows, idx] = out
        return F_s * analyse(F, X.shape[1])

    def _residual(self, th, X, P, A, wF, wA, wX):
        F_s, x_s, n, m = math.exp(th[0]), math.exp(th[1]), th[2], math.exp(th[3])
        if abs(n - 1.0) < 1e-6:
            n = 1.0 + 1e-6
        meas = P - m * A
        # displacement noise enters through the friction's stiffness (errors in variables):
        # a step whose displacement is buried in noise says little about the friction
        k_eff = np.abs(meas[:, 0]) / np.maximum(np.abs(X[:, 0]), 1e-300)
        sigma = np.sqrt(wF ** 2 + (m * wA) ** 2 + (k_eff * wX) ** 2)[:, None]
        r = (meas - self.model_friction(F_s, x_s, n, X)) / sigma
        prior = (th - self.theta_prior) / PRIOR_SIGMA
        return np.concatenate([r.real.ravel(), r.imag.ravel(), prior])

    # ------------------------------------------------------------------ fit
    def fit(self, max_nfev: int = 60) -> Estimate:
        if not self.steps:
            raise ValueError("no steps to identify from")
        # only harmonics every step measured (a missing one is not a zero)
        K = min([self.K] + [min(s.disp.size, s.force.size, s.accel.size) for s in self.steps])
        X = np.array([s.disp[:K] for s in self.steps])
        P = np.array([s.force[:K] for s in self.steps])
        A = np.array([s.accel[:K] for s in self.steps])
        # noise floor: 0.1 % of each step's force, so near-noiseless data stays well posed
        wF = np.array([max(s.sigma_force, 1e-3 * abs(s.force[0])) for s in self.steps])
        wA = np.array([max(s.sigma_accel, 1e-3 * abs(s.accel[0])) for s in self.steps])
        wX = np.array([max(s.sigma_disp, 1e-3 * abs(s.disp[0])) for s in self.steps])
        lo = [-np.inf, -np.inf, N_BOUNDS[0], -np.inf]
        hi = [np.inf, np.inf, N_BOUNDS[1], np.inf]
        th0 = np.clip(self.theta, np.array(lo) + 1e-9, np.array(hi) - 1e-9)
        res = least_squares(self._residual, th0, args=(X, P, A, wF, wA, wX), bounds=(lo, hi),
                            x_scale=np.array([0.1, 0.1, 0.1, 0.1]), max_nfev=max_nfev, method="trf")
        self.theta = res.x
        data = res.fun[:-4]                       # without the prior's rows
        dof = max(1, data.size - res.x.size)
        chi2 = float(data @ data / dof)
        # covariance from the SVD of the Jacobian (prior rows included, so it is never
        # singular), never narrower than the noise says
        _, sv, Vt = np.linalg.svd(res.jac, full_matrices=False)
        cov = (Vt.T / sv ** 2) @ Vt * max(chi2, 1.0)
        std = np.sqrt(np.clip(np.diag(cov), 0, None))
        vals = dict(F_s_N=math.exp(res.x[0]), x_s_m=math.exp(res.x[1]), n=float(res.x[2]),
                    mass_kg=math.exp(res.x[3]))
        z = 1.959964
        low, high, rel = {}, {}, {}
        for i, name in enumerate(PARAMS):
            if name == "n":
                low[name], high[name] = vals[name] - z * std[i], vals[name] + z * std[i]
                rel[name] = std[i] / abs(vals[name])
            else:   # log-parameters: asymmetric interval
                w = min(z * std[i], 700.0)   # an undetermined parameter gets (0, inf)
                low[name], high[name] = vals[name] * math.exp(-w), vals[name] * math.exp(w)
                rel[name] = float(std[i])
        warnings = tuple(f"{name} is poorly determined by these steps (relative standard error "
                         f"{100 * rel[name]:.0f} %)" for name in PARAMS if not rel[name] < 0.1)
        self.estimate = Estimate(vals, low, high, rel, len(self.steps), chi2, warnings)
        self.history.append(dict(steps=len(self.steps), **self.estimate.as_dict()))
        return self.estimate


def identify_results(results: list[dict], guess: dict, harmonics: int = 9) -> Identifier:
    """Offline identification from stored step results (or imported UFF58 data)."""
    ident = Identifier(guess, harmonics)
    for r in results:
        ident.add(r)
    ident.fit(max_nfev=200)
    return ident
