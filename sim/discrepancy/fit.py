"""Weighted least-squares fit of a :class:`~sim.discrepancy.models.Model` to the two
residuals, with the noise of all three channels propagated.

Per step and harmonic the force-balance residual r_F = P - m A - G(X) and the kinematic
residual r_K = A - A_pred(X) share the noise of A and X, so they are whitened together:

    var_F = s_P^2 + m^2 s_A^2 + k^2 s_X^2,  var_K = s_A^2 + Omega^4 s_X^2,
    cov   = -m s_A^2 - k Omega^2 s_X^2

(k = |P_1 - m A_1| / |X_1|, the step's friction stiffness; real and imaginary parts are
independent with these variances).  When the base identification's errors-in-variables
noise of the friction residual is given (:meth:`sim.identify.Identifier.residual_noise`:
force, acceleration and every harmonic of the rebuilt displacement propagated through the
Masing model, which matters at the sharp reversals of n < 1, where the friction is stiff),
it replaces var_F and cov, for the real and the imaginary part each: the friction along x
then responds to the probe's noise only with the probe's weight in the rebuilt x, and
k Omega^2 s_X^2 would overstate the correlation (on a clean n = 0.58 case it made the
whitened kinematic residual 140 noise variances at the lowest level).  The weights are
fixed once per analysis (from the base fit), so the chi-square of every candidate is measured in the same noise units and their
BIC = chi2 + p ln N compare directly.  Intervals come from the Jacobian, scaled by the
reduced chi-square when it is above 1.  The final model is refitted with
:meth:`Weights.propagated`: the noise of its own residuals, and the mean the noise itself
adds to them (decision records 0020, 0022); those weights also carry how each noise
component moves every residual of its step, and the final fit's covariance is then the
sandwich H^-1 J' Sigma J H^-1 with Sigma the whitened residuals' full noise covariance
(decision record 0031): one noise component of a step (the probe's harmonic 3, say) moves
the Masing friction residual at every harmonic of that step, so the residuals are
correlated, which the Jacobian alone (Sigma = I) ignores.  Each of its variances is then
raised to at least the empirical per-step sandwich's (:func:`at_least_empirical`, decision
record 0036): the steps' actual scores also hold misfit the noise model does not.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from .models import EFFECTS, Data, Model

log = logging.getLogger(__name__)

N_BOUNDS = (0.1, 6.0)
F_P_BOUNDS_HZ = (1e-2, 1e6)
Z95 = 1.959964
REL_FLOOR = 1e-5        # noise floors relative to the fundamental (numerical safety)
TAIL_DRAWS = 8


@dataclass(frozen=True)
class Weights:
    """Whitening of (r_F, r_K): r_F / s_F and (r_K - c r_F / s_F^2) / s_Kc, per step x
    harmonic; each has a leading axis for the real and the imaginary part.  ``bias_F``,
    ``bias_K`` (complex, step x harmonic; :meth:`propagated` only) are the mean the noise
    itself adds to the residuals, subtracted before whitening."""

    s_F: np.ndarray
    c: np.ndarray
    s_Kc: np.ndarray
    bias_F: np.ndarray | float = 0.0
    bias_K: np.ndarray | float = 0.0
    # (components, 2, steps, K) complex: each noise component's effect on (r_F, r_K), weight
    # folded in (their outer products summed over components are the residuals' covariance)
    responses: np.ndarray | None = None

    @classmethod
    def from_data(cls, d: Data, mass_kg: float, rel_floor: float = REL_FLOOR,
                  friction_noise: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> Weights:
        Om = d.Omega
        k = (np.abs(d.P[:, 0] - mass_kg * d.A[:, 0]) / np.maximum(np.abs(d.X[:, 0]), 1e-300))[:, None]
        sP = np.maximum(d.sP, rel_floor * np.abs(d.P[:, 0]))[:, None]
        sA = np.maximum(d.sA, rel_floor * np.abs(d.A[:, 0]))[:, None]
        sX = np.maximum(d.sX, rel_floor * np.abs(d.X[:, 0]))[:, None]
        var_K = sA ** 2 + Om ** 4 * sX ** 2
        if friction_noise is None:
            var_F = np.broadcast_to(sP ** 2 + (mass_kg * sA) ** 2 + (k * sX) ** 2, (2,) + Om.shape)
            c = np.broadcast_to(-mass_kg * sA ** 2 - k * Om ** 2 * sX ** 2, (2,) + Om.shape)
        else:
            sig_re, sig_im, c = friction_noise
            var_F = np.stack([sig_re ** 2, sig_im ** 2])
        return cls(np.sqrt(var_F), c, np.sqrt(np.maximum(var_K - c ** 2 / var_F, 1e-6 * var_K)))

    @classmethod
    def propagated(cls, model: Model, theta: np.ndarray, d: Data, tail_draws: int = TAIL_DRAWS,
                   seed: int = 0) -> Weights:
        """The noise of this model's own residuals: every channel's noise propagated through
        ``model.residuals`` at ``theta`` by central differences of one standard deviation
        (the friction is not differentiable at a reversal for n < 1; the noise's own scale is
        the honest step).  Harmonics 1..K of each channel are propagated one part at a time
        (in every step at once: a step's residuals depend on its own data only); the higher
        harmonics of all three channels act together through ``tail_draws`` random-sign
        draws (their summed variance, unbiased).

        The same differences give the residuals' noise-induced mean, (r(+) + r(-)) / 2 - r:
        noise in the upper harmonics roughens the rebuilt path, and the Masing friction
        along a rough path runs small extra loops, so even at the true parameters the
        residuals are not centred (on a delay case it moved m by -0.8 standard errors,
        which Monte Carlo confirmed).  It is kept as ``bias_F``, ``bias_K`` and subtracted.

        Needed because a candidate can change which noise reaches its residuals: with the
        pitching mode the force balance holds m (1 - r) x'' from the probe, whose noise at
        the upper harmonics is hundreds of times the rigid model's (a pitch-mode case had
        reduced chi-square 43 at the true parameters under the base model's weights)."""
        K = d.X.shape[1]
        Xf, XAf, _, Pf = d.friction_channels()
        Kf = Xf.shape[1]
        live = (np.abs(Xf) + np.abs(XAf) + np.abs(Pf)) > 0 if d.Xf is not None else np.ones(Xf.shape, bool)
        k = np.arange(1, Kf + 1)
        to_disp = -1.0 / (d.omega[:, None] * k) ** 2
        sig = dict(P=np.maximum(d.sP, REL_FLOOR * np.abs(d.P[:, 0]))[:, None],
                   A=np.maximum(d.sA, REL_FLOOR * np.abs(d.A[:, 0]))[:, None],
                   X=np.maximum(d.sX, REL_FLOOR * np.abs(d.X[:, 0]))[:, None])
        # the noise-induced mean is the measured noise's, not the floor's: it grows with the
        # square of the step, and a floor above the noise (a large-amplitude step's X, A)
        # made it tens of times too large; on the pitching rig F_s and x_s came out 5e-5 and
        # 1e-4 low at any noise (decision 0064).  The floors stay in the variances.
        true = dict(P=np.asarray(d.sP, float)[:, None], A=np.asarray(d.sA, float)[:, None],
                    X=np.asarray(d.sX, float)[:, None])
        share = {ch: (true[ch] / np.where(sig[ch] > 0, sig[ch], 1.0)) ** 2 for ch in sig}

        def moved(dP, dA, dX, sign):
            dP, dA, dX = sign * dP * live, sign * dA * live, sign * dX * live
            return replace(d, P=d.P + dP[:, :K], A=d.A + dA[:, :K], X=d.X + dX[:, :K],
                           **({} if d.Xf is None else dict(Xf=d.Xf + dX, XAf=d.XAf + dA * to_disp, Pf=d.Pf + dP)))

        f0, k0 = model.residuals(theta, d)

        def response(dP, dA, dX) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
            (fp, kp), (fm, km) = (model.residuals(theta, moved(dP, dA, dX, s)) for s in (1.0, -1.0))
            return (fp - fm) / 2, (kp - km) / 2, (fp + fm) / 2 - f0, (kp + km) / 2 - k0

        acc = np.zeros((6,) + d.X.shape)      # var F re, im; var K re, im; cov re, im
        bias = np.zeros((2,) + d.X.shape, complex)
        responses: list[np.ndarray] = []

        def add(gF, gK, bF, bK, w: float = 1.0, share: np.ndarray | float = 1.0) -> None:
            acc[:] += w * np.stack([gF.real ** 2, gF.imag ** 2, gK.real ** 2, gK.imag ** 2,
                                    gF.real * gK.real, gF.imag * gK.imag])
            bias[:] += w * share * np.stack([bF, bK])
            responses.append(math.sqrt(w) * np.stack([gF, gK]))
        zero = np.zeros(Xf.shape, complex)
        for ch in ("P", "A", "X"):
            for j in range(min(K, Kf)):
                for unit in (1.0, 1j):
                    dch = zero.copy()
                    dch[:, j] = unit * sig[ch][:, 0]
                    add(*response(*(dch if c == ch else zero for c in ("P", "A", "X"))), share=share[ch])
        if Kf > K and tail_draws:
            rng = np.random.default_rng(seed)
            floored = any(not np.allclose(true[ch], sig[ch]) for ch in sig)

            def draw(scale: dict) -> list[np.ndarray]:
                ds = []
                for ch in ("P", "A", "X"):
                    dch = zero.copy()
                    dch[:, K:] = scale[ch] * (rng.choice([-1.0, 1.0], (Xf.shape[0], Kf - K))
                                              + 1j * rng.choice([-1.0, 1.0], (Xf.shape[0], Kf - K)))
                    ds.append(dch)
                return ds
            for _ in range(tail_draws):
                gF, gK, bF, bK = response(*draw(sig))
                add(gF, gK, bF, bK, 1.0 / tail_draws, share=0.0 if floored else 1.0)
                if floored:            # the mean from draws of the measured noise
                    bias[:] += np.stack(response(*draw(true))[2:]) / tail_draws
        tiny = 1e-24 * np.abs(d.P[:, :1]) ** 2 + 1e-300
        var_F = np.maximum(acc[:2], tiny)
        var_K = np.maximum(acc[2:4], tiny)
        c = acc[4:]
        return cls(np.sqrt(var_F), c, np.sqrt(np.maximum(var_K - c ** 2 / var_F, 1e-6 * var_K)), bias[0], bias[1],
                   responses=np.array(responses))

    def subset(self, mask: np.ndarray) -> Weights:
        pick = lambda b: b[mask] if np.ndim(b) else b       # noqa: E731
        return Weights(self.s_F[:, mask], self.c[:, mask], self.s_Kc[:, mask], pick(self.bias_F), pick(self.bias_K),
                       None if self.responses is None else self.responses[:, :, mask])

    def noise_scores(self, jac: np.ndarray) -> np.ndarray | None:
        """J' Sigma J of the whitened residuals (Sigma their noise covariance, from
        ``responses``; steps independent of each other), or None without responses."""
        if self.responses is None:
            return None
        R, _, S, K = self.responses.shape
        J4 = jac.reshape(4, S, K, -1)
        M = np.zeros((jac.shape[1], jac.shape[1]))
        for gF, gK in self.responses:
            wF, wK = self.whiten(gF, gK, bias=False)
            w4 = np.stack([wF.real, wF.imag, wK.real, wK.imag])
            U = np.einsum("bskp,bsk->sp", J4, w4)          # per step: its residuals' score
            M += U.T @ U
        return M

    def whiten(self, rF: np.ndarray, rK: np.ndarray, bias: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Whitened residuals; ``bias=False`` for a change of the residuals (linear part only)."""
        if bias:
            rF, rK = rF - self.bias_F, rK - self.bias_K
        (fr, fi), (kr, ki), (cr, ci) = self.s_F, self.s_Kc, self.c
        wF = rF.real / fr + 1j * rF.imag / fi
        wK = (rK.real - cr / fr ** 2 * rF.real) / kr + 1j * (rK.imag - ci / fi ** 2 * rF.imag) / ki
        return wF, wK


@dataclass(frozen=True)
class Fit:
    model: Model
    theta: np.ndarray
    cov: np.ndarray
    chi2: float                  # sum of squared whitened residuals
    n_data: int                  # real numbers in the residual
    jac: np.ndarray | None = None       # whitened residuals' Jacobian at theta (the screen's projection)
    resid: np.ndarray | None = None     # whitened residuals at theta
    cov_jacobian: np.ndarray | None = None   # with a sandwich ``cov``: the Jacobian's alone (for comparison)
    cov_noise_model: np.ndarray | None = None  # with a sandwich: the noise model's alone, before the empirical floor

    @property
    def dof(self) -> int:
        return max(1, self.n_data - self.model.size)

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / self.dof

    @property
    def bic(self) -> float:
        return self.chi2 + self.model.size * math.log(self.n_data)

    def interval(self, i: int) -> tuple[float, float, float]:
        """(value, low, high) of parameter ``i`` in physical units (95 %).  An end beyond
        the floats (a log parameter the data do not bound, e^(th + w) > 1e308: the base
        model's F_s and x_s in gross sliding beside a spring) is infinite, never an error:
        :meth:`unbounded` names such parameters."""
        th, s = float(self.theta[i]), math.sqrt(max(float(self.cov[i, i]), 0.0))
        w = Z95 * s
        if i in (0, 1, 3) or self._is_log(i):
            return _exp(th), _exp(th - w), _exp(th + w)
        c = self.model.scale[i]
        return float(th * c), float((th - w) * c), float((th + w) * c)

    def unbounded(self) -> list[str]:
        """The parameters whose 95 % interval reaches beyond the floats (or zero, for a
        log parameter) or whose standard error is not finite: the data do not bound them."""
        out = []
        for name, (v, lo, hi) in self.named_intervals().items():
            if not (math.isfinite(v) and math.isfinite(lo) and math.isfinite(hi)) or (lo == 0.0 < hi):
                out.append(name)
        return out

    def _is_log(self, i: int) -> bool:
        sl = self.model.slices.get("second_mode")
        return sl is not None and i == sl.start

    def named_intervals(self) -> dict:
        names = list(self.model.values(self.theta))
        return {name: self.interval(i) for i, name in enumerate(names)}


def _exp(x: float) -> float:
    """e^x, infinite above the floats' range (a math.exp overflow is an OverflowError)."""
    return math.exp(x) if x < 709.0 else (math.nan if math.isnan(x) else math.inf)


def whitened(theta: np.ndarray, model: Model, d: Data, W: Weights) -> np.ndarray:
    rF, rK = model.residuals(theta, d)
    wF, wK = W.whiten(rF, rK)
    return np.concatenate([wF.real.ravel(), wF.imag.ravel(), wK.real.ravel(), wK.imag.ravel()])


def bounds(model: Model) -> tuple[np.ndarray, np.ndarray]:
    lo = np.full(model.size, -np.inf)
    hi = np.full(model.size, np.inf)
    lo[2], hi[2] = N_BOUNDS
    for e, sl in model.slices.items():
        if e == "second_mode":        # log f_p, zeta, a, r
            lo[sl.start], hi[sl.start] = math.log(F_P_BOUNDS_HZ[0]), math.log(F_P_BOUNDS_HZ[1])
            lo[sl.start + 1], hi[sl.start + 1] = 1e-4, 0.5
            lo[sl.start + 2] = 0.0
        if e == "sensor_gain_error":
            lo[sl.start] = -0.5
        for j, (a, b) in enumerate(EFFECTS[e].bounds):
            lo[sl.start + j], hi[sl.start + j] = a, b
    return lo, hi


def fit(model: Model, theta0: np.ndarray, d: Data, W: Weights, max_nfev: int = 100) -> Fit:
    lo, hi = bounds(model)
    th0 = np.clip(theta0, lo + 1e-9, hi - 1e-9)
    size: list[int] = []

    def residuals(theta: np.ndarray) -> np.ndarray:
        # a trial step of a diverging fit that overflows exp() (OverflowError: math range
        # error ended a run's final fit, issue 25) has an infinite cost: the trust region
        # shrinks and the fit goes on.  (Bounds on the log parameters would do it too, but
        # change the path of every fit, converged ones included: decision 0042.)
        try:
            r = whitened(theta, model, d, W)
        except OverflowError:
            if not size:
                raise
            return np.full(size[0], np.inf)
        size[:] = [r.size]
        return r

    res = least_squares(residuals, th0, bounds=(lo, hi), x_scale="jac", max_nfev=max_nfev, method="trf")
    chi2 = float(res.fun @ res.fun)
    _, sv, Vt = np.linalg.svd(res.jac, full_matrices=False)
    sv = np.maximum(sv, sv.max() * 1e-12)
    phi = max(chi2 / max(1, res.fun.size - model.size), 1.0)
    H_inv = (Vt.T / sv ** 2) @ Vt
    cov = H_inv * phi
    M = W.noise_scores(res.jac)
    if M is None:
        return Fit(model, res.x, cov, chi2, res.fun.size, res.jac, res.fun)
    sandwich = H_inv @ M @ H_inv * phi
    reported = at_least_empirical(sandwich, H_inv, step_scores(res.jac, res.fun, d.X.shape[0]))
    return Fit(model, res.x, reported, chi2, res.fun.size, res.jac, res.fun, cov_jacobian=cov,
               cov_noise_model=sandwich)


def at_least_empirical(cov: np.ndarray, H_inv: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """``cov`` (the noise model's sandwich) with each variance raised to at least the
    empirical per-step sandwich's, H^-1 (sum_s u_s u_s') H^-1 S / (S - p) (Huber-White
    with the steps as the independent units, u_s = J_s' r_s each step's score, S / (S - p)
    the small-sample factor), the correlations kept (decision record 0036).  The noise
    model holds the records' noise; the steps' scores also hold what it does not (free
    vibration left in a record, a small model error per step); the larger of the two
    bounds each parameter's interval."""
    S, p = scores.shape
    emp = H_inv @ (scores.T @ scores) @ H_inv * S / max(S - p, 1)
    var = np.maximum(np.diag(cov), 1e-300)
    D = np.sqrt(np.maximum(np.diag(emp), var) / var)
    return cov * np.outer(D, D)


def profile_chi2(f: Fit, d: Data, W: Weights, i: int, value: float, start: np.ndarray | None = None,
                 max_nfev: int = 40) -> tuple[float, np.ndarray]:
    """Chi-square of ``f.model`` with parameter ``i`` held at ``value`` (fit coordinates)
    and every other parameter refitted; returns it and the refitted theta.  ``start``
    (default: the optimum moved along the covariance's regression on parameter ``i``, the
    linear prediction of the profile path)."""
    lo, hi = bounds(f.model)
    free = np.arange(f.model.size) != i
    if start is None:
        H_inv = _jacobian_inverse(f)
        start = f.theta + (value - f.theta[i]) * H_inv[:, i] / H_inv[i, i]
    th = np.array(start, float)
    th[i] = value
    x0 = np.clip(th[free], lo[free] + 1e-9, hi[free] - 1e-9)

    def r(x: np.ndarray) -> np.ndarray:
        th[free] = x
        return whitened(th, f.model, d, W)
    res = least_squares(r, x0, bounds=(lo[free], hi[free]), x_scale="jac", max_nfev=max_nfev, method="trf")
    th[free] = res.x
    return float(res.fun @ res.fun), th.copy()


def _jacobian_inverse(f: Fit) -> np.ndarray:
    if f.jac is None:
        raise ValueError("profile intervals need the fit's Jacobian (Fit.jac is None)")
    _, sv, Vt = np.linalg.svd(f.jac, full_matrices=False)
    sv = np.maximum(sv, sv.max() * 1e-12)
    return (Vt.T / sv ** 2) @ Vt


def profile_threshold(f: Fit, i: int, level_z: float = Z95) -> float:
    """The rise of the chi-square that bounds parameter ``i``'s profile interval: z^2 times
    the ratio of the reported variance (sandwich, reduced chi-square, any widening) to the
    Jacobian's (J'J)^-1, so that where the model is linear in the parameters the profile
    interval is the reported one exactly and only the nonlinearity changes it."""
    return level_z ** 2 * float(f.cov[i, i]) / float(_jacobian_inverse(f)[i, i])


def profile_interval(f: Fit, d: Data, W: Weights, i: int, level_z: float = Z95, iterations: int = 5,
                     rtol: float = 0.02) -> tuple[float, float]:
    """95 % profile-likelihood interval of parameter ``i`` (fit coordinates: log F_s, log
    x_s, n, log m for 0..3): each end is where the profile chi-square (every other parameter
    refitted, :func:`profile_chi2`) has risen by :func:`profile_threshold` above the optimum.

    Found on the signed root s(v) = +-sqrt(chi2_profile(v) - chi2_min), which is linear in v
    where the model is: the first trial is the Wald end, then secant steps on s (through
    the optimum first), until s is within ``rtol`` of its target.  An end that would cross
    a bound (n in N_BOUNDS) stops at the bound."""
    lo_b, hi_b = bounds(f.model)
    H_inv = _jacobian_inverse(f)
    T = profile_threshold(f, i, level_z)
    target = math.sqrt(T)
    th0 = f.theta[i]
    w = target * math.sqrt(H_inv[i, i])              # the Wald half-width (= reported)
    ends = []
    for sign in (-1.0, 1.0):
        bound = lo_b[i] if sign < 0 else hi_b[i]
        pts = [(0.0, 0.0)]                           # (offset from the optimum, signed root)
        off = w
        start = None
        for _ in range(iterations):
            v = th0 + sign * off
            if (v - bound) * sign >= 0:              # the bound: stop there if inside the threshold
                v = bound - sign * 1e-9
                off = abs(v - th0)
                c, start = profile_chi2(f, d, W, i, v, start)
                if c - f.chi2 <= T:
                    break
            else:
                c, start = profile_chi2(f, d, W, i, v, start)
            s = math.sqrt(max(c - f.chi2, 0.0))
            pts.append((off, s))
            if abs(s - target) <= rtol * target:
                break
            (o1, s1), (o2, s2) = pts[-2], pts[-1]
            slope = (s2 - s1) / (o2 - o1) if o2 != o1 else 0.0
            if slope <= 0:                           # the profile did not rise: step out
                off = 2.0 * o2
            else:
                off = min(max(o2 + (target - s2) / slope, 0.25 * o2), 4.0 * o2)
        ends.append(th0 + sign * off)
    return ends[0], ends[1]


def step_scores(jac: np.ndarray, resid: np.ndarray, steps: int, H_inv: np.ndarray | None = None) -> np.ndarray:
    """Each step's score J_s' r_s of the whitened residuals (steps x parameters), the rows
    laid out as :func:`whitened` lays them (real/imaginary of r_F, r_K, step, harmonic).
    With ``H_inv`` ((J'J)^-1) the residuals are first corrected for the step's leverage,
    (I - J_s H^-1 J_s')^-1 r_s (the jackknife-like small-sample form, "CR3")."""
    p = jac.shape[1]
    J = jac.reshape(4, steps, -1, p).transpose(1, 0, 2, 3).reshape(steps, -1, p)
    r = resid.reshape(4, steps, -1).transpose(1, 0, 2).reshape(steps, -1)
    if H_inv is None:
        return np.einsum("srp,sr->sp", J, r)
    out = np.empty((steps, p))
    for s in range(steps):
        A = np.eye(J.shape[1]) - J[s] @ H_inv @ J[s].T
        out[s] = J[s].T @ np.linalg.solve(A, r[s])
    return out
