"""Identification of the friction parameters (F_s, x_s, n) and the moving mass m from
stepped-sine steps, in the harmonic domain.

Per step the measured friction force is P(t) - m a(t).  Its first K harmonics are compared
with the harmonics of the Masing friction computed along the displacement of the period.
What that displacement is decides everything for n < 1: the model's friction turns with
infinite stiffness at a reversal, so the friction along a displacement rebuilt from a few
harmonics is not the friction along the true one (on the issue-9 rig, n = 0.46, nine
harmonics left residuals of 80 noise standard deviations on clean data; 120 were needed).
So the displacement is rebuilt from every harmonic the records hold (up to 200): each
harmonic is the inverse-variance mean of the probe's x_k and the accelerometer's
-a_k / (k w)^2 (:func:`displacement_harmonics`); the probe carries the low harmonics, the
accelerometer the high ones the probe's noise buries.  The rebuilt period is sampled at
POINTS_PER_PERIOD points, turning points lifted to their parabolic vertex, and the friction
harmonics follow by FFT.

The steady loop is built by virgin loading to the period's largest displacement and one
period from there: for a two-reversal loop this is the symmetric Masing loop, and inner
loops (VRAR orbits) follow the memory rules on their own.

Noise (errors in variables): each residual's variance is the force's, plus the
acceleration's (through m a and through the rebuilt displacement), plus the displacement's
propagated through the model by central differences of one standard deviation per
harmonic (the model is not differentiable at a reversal; the noise's own scale is the
honest step).  These weights depend on (F_s, x_s, n): they are computed at the current
estimate and refreshed when it moves.  No floors: the reduced chi-square of clean data is
about 1.  Standard errors of the harmonics come with the steps (``sim.records`` estimates
them from the scatter of the periods).

Weighted least squares (scipy.optimize.least_squares) in log-parameters; intervals from
the Jacobian, scaled by max(1, reduced chi-square).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.optimize import least_squares

from .errors import ConfigurationError
from .masing import LAMBDA_MASING, active_depth, branch_force
from .records import harmonic_sigma
from .step_result import StepResult
from .virgin import CURVE_SAKAI, virgin_g

log = logging.getLogger(__name__)

POINTS_PER_PERIOD = 1024
KINEMATIC_FLOOR = 1e-3  # a / x'' mismatch always allowed (relative, at the fundamental)
FD_STEP = 1e-6          # forward-difference step of log x_s and n
EIV_HARMONICS = 8       # harmonics of X propagated one by one into the weights
TAIL_DRAWS = 6          # random-sign draws for the rest
REWEIGHT_STEP = 0.02    # refresh a step's weights when a (log) parameter moved this much
PARAMS = ("F_s_N", "x_s_m", "n", "mass_kg")
N_BOUNDS = (0.1, 6.0)
# A weak prior at the guess (a factor 4 on F_s, x_s, m; 1.5 on n): it keeps the first
# few, uninformative steps from sending the estimate astray and gives an undetermined
# parameter an honest interval.  With a full plan its weight is negligible.
PRIOR_SIGMA = np.array([math.log(4.0), math.log(4.0), 1.5, math.log(4.0)])
MISFIT_CHI2 = 2.0          # reduced chi-square above this (and the noise's own spread) is misfit
MISFIT_SIGMAS = 5.0


def misfit_text(reduced_chi2: float, dof: int) -> str:
    """Words when the reduced chi-square says the model does not fit beyond what the noise
    explains ('' when it fits): above :data:`MISFIT_CHI2` and :data:`MISFIT_SIGMAS` standard
    deviations of the noise's own chi-square (sqrt(2 / dof)) above 1 (decision 0042)."""
    if not math.isfinite(reduced_chi2):
        return "the fit's reduced chi-square is not a number: the fit failed"
    if reduced_chi2 <= max(MISFIT_CHI2, 1 + MISFIT_SIGMAS * math.sqrt(2.0 / max(dof, 1))):
        return ""
    return (f"the model does not fit the data beyond what the noise explains (reduced chi-square {reduced_chi2:.3g}, "
            f"about 1 when it does): something acts that the model lacks, so the values are biased by an unknown "
            f"amount; the intervals are widened {math.sqrt(reduced_chi2):.3g}x (sqrt of the reduced chi-square) "
            f"but may still miss the truth; `bench analyze` names what is missing")


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
    def from_result(cls, r: StepResult) -> StepHarmonics:
        def c(fit):
            return np.asarray(fit["amplitude"]) * np.exp(1j * np.asarray(fit["phase_rad"]))
        n = r.get("n_samples", 1000)
        return cls(freq_Hz=r["freq_Hz"], force=c(r["force"]), accel=c(r["accel"]), disp=c(r["disp"]),
                   sigma_force=harmonic_sigma(r["force"]["noise_rms"], n),
                   sigma_accel=harmonic_sigma(r["accel"]["noise_rms"], n),
                   sigma_disp=harmonic_sigma(r["disp"]["noise_rms"], n))


    @classmethod
    def from_records(cls, rec) -> StepHarmonics:
        """From a :class:`sim.records.PeriodicRecords` (every harmonic the records hold)."""
        c = rec.channels
        return cls(freq_Hz=rec.freq_Hz, force=c["force"].harmonics, accel=c["accel"].harmonics,
                   disp=c["disp"].harmonics, sigma_force=c["force"].sigma, sigma_accel=c["accel"].sigma,
                   sigma_disp=c["disp"].sigma)


@dataclass(frozen=True)
class Estimate:
    values: dict                       # PARAMS -> value
    low: dict                          # 95 % interval
    high: dict
    rel_std: dict                      # relative standard error
    steps_used: int
    cost: float                        # reduced chi-square
    warnings: tuple[str, ...] = field(default=())
    misfit: bool = False               # reduced chi-square beyond what the noise explains (misfit_text)
    source: str = ""                   # where the estimate came from (online, final fit, ...)
    at_bound: tuple[str, ...] = ()     # parameters at the bound of the search: not estimates (a warning says so)

    def as_dict(self) -> dict:
        return dict(values=self.values, low=self.low, high=self.high, rel_std=self.rel_std,
                    steps_used=self.steps_used, reduced_chi2=self.cost, warnings=list(self.warnings),
                    misfit=self.misfit, **({"source": self.source} if self.source else {}),
                    **({"at_bound": list(self.at_bound)} if self.at_bound else {}))


@njit(cache=True)
def _loop_friction(paths, tops, lam, p, out):
    """Dimensionless Masing friction along each row of ``paths`` (one period starting at
    its largest value ``tops[i]``), after virgin loading from 0 to that value.

    Per row, two passes: the Masing bookkeeping (reversal stack, active branch) writes each
    sample's branch as (F at its reversal, +-lam, travel s), then a plain loop evaluates
    F = F_r +- lam g(s).  The same arithmetic as :func:`sim.masing.quasi_static_path` (the
    same operations in the same order: equal to the last bit), seven times faster than one
    pass: the curve's power inside the branchy loop, and a stack that a growable array
    re-bound on every reversal, stalled it (decision 0048).  A row reverses at most once
    per sample, so a stack of M + 1 entries never grows."""
    M = paths.shape[1]
    su = np.empty(M + 1)
    sF = np.empty(M + 1)
    base = np.empty(M)
    coef = np.empty(M)
    travel = np.empty(M)
    for i in range(paths.shape[0]):
        k = 0
        d = 1.0 if tops[i] >= 0 else -1.0
        # virgin loading to the top (any path from 0 to it gives the same state)
        prev = tops[i]
        for j in range(M):
            u = paths[i, j]
            if (u - prev) * d < 0.0:
                k = active_depth(prev, k, su, d)
                su[k] = prev
                sF[k] = branch_force(prev, k, su, sF, lam, CURVE_SAKAI, p)
                k += 1
                d = -d
            k = active_depth(u, k, su, d)
            if k == 0:                 # the virgin curve: +-g(|u|)
                base[j] = 0.0
                travel[j] = abs(u)
                coef[j] = 1.0 if u >= 0.0 else -1.0
            else:                      # the branch from reversal k: F_r +- lam g(|u - u_r| / lam)
                s = (u - su[k - 1]) / lam
                base[j] = sF[k - 1]
                travel[j] = abs(s)
                coef[j] = lam if s >= 0.0 else -lam
            prev = u
        for j in range(M):
            out[i, j] = base[j] + coef[j] * virgin_g(CURVE_SAKAI, travel[j], p)


def displacement_harmonics(step: StepHarmonics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The displacement's harmonics rebuilt from both motion channels.

    A rigid carriage has x_k = -a_k / (k w)^2.  Each harmonic is the inverse-variance
    weighted mean of the displacement channel and the acceleration channel so divided:
    the probe carries the low harmonics, the accelerometer the high ones that the probe's
    noise buries (a sharp reversal for n < 1 needs dozens of harmonics).  How far the
    double integral of the acceleration can be trusted is measured on the step itself:
    the mismatch of the two channels at the fundamental beyond their noise, relative to the
    fundamental (at least KINEMATIC_FLOOR), is taken as an error of the acceleration of that
    size in every harmonic (so eps |x_1| / k^2 in displacement) and added to the
    acceleration channel's variance.  Returns (X, weight of the displacement channel, variance of one
    real/imag part of X)."""
    K = min(step.disp.size, step.accel.size)
    k = np.arange(1, K + 1)
    w = 2 * np.pi * step.freq_Hz
    XA = -step.accel[:K] / (k * w) ** 2
    sD, sA1 = float(step.sigma_disp), float(step.sigma_accel) / w ** 2
    D1 = abs(step.disp[0])
    mismatch = abs(XA[0] - step.disp[0]) - 2.0 * math.sqrt(2.0) * math.hypot(sD, sA1)
    eps = max(KINEMATIC_FLOOR, mismatch / D1) if D1 > 0 else 1.0
    vD = np.full(K, sD ** 2)
    vA = (float(step.sigma_accel) / (k * w) ** 2) ** 2 + (eps * D1 / k ** 2) ** 2 / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        wD = np.where(vD + vA > 0, vA / (vD + vA), 1.0)
    X = wD * step.disp[:K] + (1 - wD) * XA
    return X, wD, wD ** 2 * vD + (1 - wD) ** 2 * vA


def period_paths(X: np.ndarray, M: int) -> tuple[np.ndarray, np.ndarray]:
    """Periods of the displacement (rows of M samples) from rows of harmonics X, each
    centred between its extremes and rotated to start at its largest value; every turning
    point is lifted to the vertex of the parabola through it and its neighbours (the
    reversal's true extent).  Returns (paths, rotations)."""
    X = np.atleast_2d(X)
    spec = np.zeros((X.shape[0], M // 2 + 1), complex)
    K = min(X.shape[1], M // 2 - 1)
    spec[:, 1:K + 1] = -1j * X[:, :K] * (M / 2)
    x = np.fft.irfft(spec, M, axis=1)
    starts = np.argmax(x, axis=1)
    out = np.empty_like(x)
    _rotate_lift_centre(x, starts, out)
    return out, starts


@njit(cache=True)
def _rotate_lift_centre(x, starts, out):
    """:func:`period_paths` after the inverse FFT, one row at a time: rotate the row to
    start at ``starts[i]``; lift every turning point (a sample not beyond both neighbours,
    cyclically, and not equal to the one before) to the vertex of the parabola through the
    three, x - (x+ - x-)^2 / (8 (x- - 2 x + x+)), unless that is flat; centre the row
    between its extremes.  The arithmetic of the array expressions it replaced, in the same
    order (equal to the last bit), five times faster: no index arrays, rolls or masks
    (decision 0048)."""
    R, M = x.shape
    r = np.empty(M)
    for i in range(R):
        s = starts[i]
        for j in range(M):
            r[j] = x[i, (s + j) % M]
        for j in range(M):
            prev = r[j - 1] if j > 0 else r[M - 1]
            nxt = r[j + 1] if j < M - 1 else r[0]
            v = r[j]
            if (v - prev) * (nxt - v) <= 0.0 and v != prev:
                den = prev - 2 * v + nxt
                if den != 0.0:
                    v = v - 0.125 * (nxt - prev) ** 2 / den
            out[i, j] = v
        out[i] -= 0.5 * (out[i].max() + out[i].min())


def path_friction(paths: np.ndarray, x_s: float, n: float, lam: float = LAMBDA_MASING) -> np.ndarray:
    """Dimensionless Masing friction sampled along rows of ``paths`` (m, from :func:`period_paths`)."""
    u = paths / x_s
    out = np.empty_like(u)
    _loop_friction(u, u[:, 0].copy(), lam, np.array([n]), out)
    return out


def path_harmonics(samples: np.ndarray, starts: np.ndarray, K: int) -> np.ndarray:
    """Harmonics 1..K of rows of samples taken along :func:`period_paths`' rotated periods, in
    the period's own time."""
    M = samples.shape[1]
    k = np.arange(1, K + 1)
    spec = np.fft.rfft(samples, axis=1)[:, 1:K + 1] * (2.0 / M)
    # undo the rotation: sample j of the path is sample j + start of the period
    return 1j * spec * np.exp(-2j * np.pi * np.outer(starts, k) / M)


def _friction_harmonics(paths: np.ndarray, starts: np.ndarray, x_s: float, n: float, lam: float,
                        K: int) -> np.ndarray:
    """Harmonics 1..K of the dimensionless Masing friction along rows of ``paths`` (m)."""
    return path_harmonics(path_friction(paths, x_s, n, lam), starts, K)


def synthesize(C: np.ndarray, M: int) -> np.ndarray:
    """Rows of samples of sum_k Im(C_k exp(i k w t)) over one period (C: steps x K, K < M / 2),
    by inverse FFT: no BLAS product, which a loaded machine's multi-threaded OpenBLAS made
    40x slower than its arithmetic."""
    C = np.atleast_2d(C)
    if C.shape[1] >= M // 2:
        raise ValueError(f"{C.shape[1]} harmonics need more than {M} samples per period")
    Z = np.zeros((C.shape[0], M // 2 + 1), complex)
    Z[:, 1:C.shape[1] + 1] = -0.5j * M * C
    return np.fft.irfft(Z, n=M, axis=1)


def analyse(samples: np.ndarray, K: int) -> np.ndarray:
    """Inverse of :func:`synthesize`: complex amplitudes of the first K harmonics."""
    M = samples.shape[1]
    spec = np.fft.rfft(samples, axis=1) * (2.0 / M)
    return 1j * spec[:, 1:K + 1]


@dataclass
class _Prepared:
    """What a step contributes to the fit, computed once (parameter-free parts) or
    refreshed when the estimate moves (the errors-in-variables weights)."""

    step: StepHarmonics
    X: np.ndarray
    wD: np.ndarray
    vA: np.ndarray        # variance of the acceleration-derived displacement (per part)
    path: np.ndarray
    start: int
    sig_re: np.ndarray = field(default_factory=lambda: np.empty(0))   # empty until weighed
    sig_im: np.ndarray = field(default_factory=lambda: np.empty(0))
    cov: np.ndarray = field(default_factory=lambda: np.empty((2, 0)))   # with the kinematic residual (real, imaginary part; 2 x K)
    theta: np.ndarray | None = None


class Identifier:
    """Accumulates steps and fits (F_s, x_s, n, m); warm-started from the last fit."""

    def __init__(self, guess: dict, harmonics: int = 5, lam: float = LAMBDA_MASING,
                 points_per_period: int = POINTS_PER_PERIOD, bound_factor: float | None = None):
        self.K = harmonics
        self.lam = lam
        self.M = points_per_period
        self.steps: list[StepHarmonics] = []
        self._prep: list[_Prepared] = []
        self._cache: tuple[tuple[float, float], np.ndarray] | None = None
        self.theta = np.log([guess["F_s_N"], guess["x_s_m"], 1.0, guess["mass_kg"]])
        self.theta[2] = guess["n"]
        self.theta_prior = self.theta.copy()
        # F_s, x_s, m kept within this factor of the guess (online: an estimate on the bound
        # is flagged, never reported as one; None: unbounded)
        self.bound_factor = bound_factor
        self.estimate: Estimate | None = None
        self.history: list[dict] = []

    # ------------------------------------------------------------------ data
    def add(self, step: StepHarmonics | StepResult) -> None:
        if isinstance(step, dict):
            step = StepHarmonics.from_result(step)
        X, wD, vX = displacement_harmonics(step)
        paths, starts = period_paths(X, self.M)
        self.steps.append(step)
        with np.errstate(divide="ignore", invalid="ignore"):
            vA = np.where(wD < 1, (vX - wD ** 2 * float(step.sigma_disp) ** 2) / (1 - wD) ** 2, 0.0)
        self._prep.append(_Prepared(step, X, wD, vA, paths[0], int(starts[0])))

    # ------------------------------------------------------------------ model
    def model_friction(self, F_s: float, x_s: float, n: float, X: np.ndarray, harmonics: int | None = None) -> np.ndarray:
        """Harmonics (N) of the Masing friction along the displacement harmonics X (m, steps x Kx)."""
        paths, starts = period_paths(X, self.M)
        return F_s * _friction_harmonics(paths, starts, x_s, n, self.lam, harmonics or np.atleast_2d(X).shape[1])

    def _weights(self, p: _Prepared, F_s: float, x_s: float, n: float, m: float, K: int) -> None:
        """Standard deviations of the real and imaginary residual of each harmonic.

        Independent noise sources: the force's harmonics; the acceleration's (directly
        through m a, and through the displacement rebuilt from it); the displacement's
        (and the kinematic mismatch allowed to the acceleration-derived part).  The
        friction's response to harmonic j of the rebuilt displacement is a central
        difference of the model over one standard deviation of that harmonic (the model is
        not differentiable at a reversal for n < 1; the noise's own scale is the honest
        step), for each part of the first EIV_HARMONICS harmonics; the rest act together
        through TAIL_DRAWS random-sign perturbations (their summed variance, unbiased)."""
        s = p.step
        w = 2 * np.pi * s.freq_Hz
        sD, sA, sP = float(s.sigma_disp), float(s.sigma_accel), float(s.sigma_force)
        k = np.arange(1, p.X.size + 1)
        vAn = (sA / (k * w) ** 2) ** 2                       # accel noise in X units
        sdX = np.sqrt(p.wD ** 2 * sD ** 2 + (1 - p.wD) ** 2 * p.vA)
        var_re = np.full(K, sP ** 2) + (m * sA) ** 2          # force; accel's direct term
        var_im = var_re.copy()
        # covariance with the kinematic residual a_j + (j w)^2 x_j of the probe (direct term
        # of the acceleration; the friction's part follows for the propagated harmonics)
        cov = np.full((2, K), -m * sA ** 2)
        live = np.flatnonzero(sdX[:EIV_HARMONICS] > 0)
        rng = np.random.default_rng(len(self._prep))
        tail = np.arange(EIV_HARMONICS, p.X.size)
        signs = rng.choice([-1.0, 1.0], size=(TAIL_DRAWS, tail.size)) + 1j * rng.choice(
            [-1.0, 1.0], size=(TAIL_DRAWS, tail.size)) if tail.size else np.zeros((0, 0))
        deltas = [np.zeros(p.X.size, complex) for _ in range(2 * live.size + signs.shape[0])]
        for i, j in enumerate(live):
            deltas[2 * i][j] = sdX[j]
            deltas[2 * i + 1][j] = 1j * sdX[j]
        for r in range(signs.shape[0]):
            deltas[2 * live.size + r][tail] = signs[r] * sdX[tail]
        if deltas:
            D = np.array(deltas)
            F = F_s * _friction_harmonics(*period_paths(np.concatenate([p.X + D, p.X - D]), self.M), x_s, n, self.lam, K)
            resp = (F[:len(D)] - F[len(D):]) / 2                # response to one sd (per row)
            for i, j in enumerate(live):
                for part, unit in ((0, 1.0), (1, 1j)):
                    d = resp[2 * i + part] / sdX[j]             # dF/d(part of X_j)
                    # probe noise, kinematic mismatch, accelerometer noise (with m a)
                    e_D = -d * p.wD[j] * sD
                    e_K = d * (1 - p.wD[j]) * math.sqrt(max(p.vA[j] - vAn[j], 0.0))
                    e_A = (d * (1 - p.wD[j]) * math.sqrt(vAn[j])).astype(complex)
                    if j < K:   # the direct term is counted above; here only its correlation
                        e_A[j] -= m * sA * unit
                        cov[part, j] = ((e_D[j] * (j + 1) ** 2 * w ** 2 * sD + e_A[j] * sA) / unit).real
                        var_re[j] -= (m * sA * unit).real ** 2
                        var_im[j] -= (m * sA * unit).imag ** 2
                    for e in (e_D, e_K, e_A):
                        var_re += e.real ** 2
                        var_im += e.imag ** 2
            if signs.shape[0]:
                t = resp[2 * live.size:]
                var_re += np.mean(t.real ** 2, axis=0)
                var_im += np.mean(t.imag ** 2, axis=0)
        tiny = 1e-12 * max(abs(s.force[0]), 1e-300)    # numerical safety only
        p.sig_re = np.sqrt(np.maximum(var_re, tiny ** 2))
        p.sig_im = np.sqrt(np.maximum(var_im, tiny ** 2))
        p.cov = cov

    def residual_noise(self, K: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Noise of the friction residual P - m a - F(x) at the current estimate (errors in
        variables, as the fit weighs them): standard deviations (N) of its real and
        imaginary parts (each steps x K), and their covariances with the same parts of the
        kinematic residual a_k + (k w)^2 x_k of the probe (2 x steps x K; the probe's and
        the accelerometer's noise enter both)."""
        self._refresh_weights(self.theta, K)
        return (np.array([p.sig_re for p in self._prep]), np.array([p.sig_im for p in self._prep]),
                np.stack([p.cov for p in self._prep], axis=1))

    def _refresh_weights(self, th: np.ndarray, K: int, force: bool = False, budget: int | None = None) -> None:
        """Recompute the weights of steps whose weights were computed far from ``th``
        (all with ``force``); at most ``budget`` of them, the stalest first."""
        F_s, x_s, n, m = math.exp(th[0]), math.exp(th[1]), _n(th[2]), math.exp(th[3])
        def stale(p):
            if p.theta is None or p.sig_re.size != K:
                return np.inf
            return float(np.max(np.abs(p.theta - th)))
        todo = [p for p in self._prep if force or stale(p) > REWEIGHT_STEP]
        if budget is not None:
            todo = sorted(todo, key=stale, reverse=True)[:max(budget, sum(p.theta is None for p in todo))]
        for p in todo:
            self._weights(p, F_s, x_s, n, m, K)
            p.theta = th.copy()

    def _model(self, th, paths, starts, K) -> np.ndarray:
        """Friction harmonics per F_s (cached for the Jacobian at the same point)."""
        key = (th[1], th[2])
        if self._cache is None or self._cache[0] != key:
            self._cache = (key, _friction_harmonics(paths, starts, math.exp(th[1]), _n(th[2]), self.lam, K))
        return self._cache[1]

    def _residual(self, th, paths, starts, P, A, sig_re, sig_im, K):
        F_s, m = math.exp(th[0]), math.exp(th[3])
        r = P - m * A - F_s * self._model(th, paths, starts, K)
        prior = (th - self.theta_prior) / PRIOR_SIGMA
        return np.concatenate([(r.real / sig_re).ravel(), (r.imag / sig_im).ravel(), prior])

    def _jacobian(self, th, paths, starts, P, A, sig_re, sig_im, K):
        """F_s and m enter linearly (analytic columns); x_s and n by forward differences."""
        F_s, m = math.exp(th[0]), math.exp(th[3])
        phi = self._model(th, paths, starts, K)
        cols = [-F_s * phi, None, None, -m * A]
        for i in (1, 2):
            h = FD_STEP * max(1.0, abs(th[i]))
            tp = th.copy()
            tp[i] += h
            self._cache = None
            cols[i] = -F_s * (_friction_harmonics(paths, starts, math.exp(tp[1]), _n(tp[2]), self.lam, K) - phi) / h
        self._cache = ((th[1], th[2]), phi)
        J = np.empty((2 * P.size + 4, 4))
        for i, c in enumerate(cols):
            J[:P.size, i] = (c.real / sig_re).ravel()
            J[P.size:2 * P.size, i] = (c.imag / sig_im).ravel()
        J[2 * P.size:] = np.diag(1.0 / PRIOR_SIGMA)
        return J

    # ------------------------------------------------------------------ fit
    def fit(self, max_nfev: int = 60, reweight_rounds: int = 2, reweight_budget: int | None = None,
            tol: float = 1e-8) -> Estimate:
        """Weighted least squares; the errors-in-variables weights are refreshed at the new
        estimate and the fit repeated (at most ``reweight_rounds`` times) while it moves.
        ``reweight_budget`` caps how many stale weights one call refreshes (online use;
        new steps always get theirs); ``tol`` is least_squares' ftol and xtol."""
        if not self.steps:
            raise ConfigurationError("no steps to identify from")
        # only harmonics every step measured (a missing one is not a zero)
        K = min([self.K] + [min(s.disp.size, s.force.size, s.accel.size) for s in self.steps])
        paths = np.array([p.path for p in self._prep])
        starts = np.array([p.start for p in self._prep])
        P = np.array([s.force[:K] for s in self.steps])
        A = np.array([s.accel[:K] for s in self.steps])
        lo = [-np.inf, -np.inf, N_BOUNDS[0], -np.inf]
        hi = [np.inf, np.inf, N_BOUNDS[1], np.inf]
        # never further than e^50 from the guess: a diverging trial step must not overflow
        # exp() (an OverflowError ended a run's final fit, issue 25); online, a factor
        # bound_factor, and an estimate on it is flagged
        b = math.log(self.bound_factor) if self.bound_factor else 50.0
        for i in (0, 1, 3):
            lo[i], hi[i] = self.theta_prior[i] - b, self.theta_prior[i] + b
        th = np.clip(self.theta, np.array(lo) + 1e-9, np.array(hi) - 1e-9)
        for rnd in range(reweight_rounds + 1):
            self._refresh_weights(th, K, force=rnd > 0, budget=reweight_budget)
            sig_re = np.array([p.sig_re for p in self._prep])
            sig_im = np.array([p.sig_im for p in self._prep])
            self._cache = None
            res = least_squares(self._residual, th, jac=self._jacobian, args=(paths, starts, P, A, sig_re, sig_im, K),
                                bounds=(lo, hi), x_scale=np.array([0.1, 0.1, 0.1, 0.1]),
                                max_nfev=max_nfev, method="trf", ftol=tol, xtol=tol)
            moved = np.max(np.abs(res.x - th))
            th = res.x
            if moved < REWEIGHT_STEP:
                break
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
        at_bound: tuple[str, ...] = ()
        if self.bound_factor:   # (the e^50 reach is never an answer)
            at_bound = tuple(PARAMS[i] for i in (0, 1, 3) if min(res.x[i] - lo[i], hi[i] - res.x[i]) < 1e-3)
            warnings = tuple(f"{name} reached the bound of the search ({self.bound_factor:g}x the expected "
                             f"value): not an estimate" for name in at_bound) + warnings
        mis = misfit_text(chi2, dof)
        if mis:
            warnings = (mis,) + warnings
        self.estimate = Estimate(vals, low, high, rel, len(self.steps), chi2, warnings, bool(mis), at_bound=at_bound)
        self.history.append(dict(steps=len(self.steps), **self.estimate.as_dict()))
        return self.estimate


def _n(n: float) -> float:
    return 1.0 + 1e-6 if abs(n - 1.0) < 1e-6 else n


def identify_results(results: list, guess: dict, harmonics: int = 9) -> Identifier:
    """Offline identification from stored step results (dicts) or :class:`StepHarmonics`
    (e.g. ``bench.sources`` steps' ``harmonics``)."""
    ident = Identifier(guess, harmonics)
    for r in results:
        ident.add(r)
    ident.fit(max_nfev=200)
    return ident
