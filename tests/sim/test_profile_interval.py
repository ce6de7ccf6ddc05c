"""Profile-likelihood intervals of the friction parameters (decision record 0035).

A rig measured only in pre-rolling (amplitudes 0.12-0.4 x_s) with a noisy force: F_s, x_s
and n are then nearly degenerate (the curve's initial stiffness n F_s / x_s is what the
data fix), the chi-square is far from quadratic over the 95 % interval and the profile
interval is asymmetric.  Checked against a brute-force scan made another way: the
parameter stepped over a grid, the others minimised by Nelder-Mead from the optimum (no
least squares, no linear start), the crossing of the threshold interpolated.  Where the
model is linear over the interval (small noise) the profile interval is the reported one.
"""

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import minimize

from sim.discrepancy.fit import Weights, fit, profile_interval, whitened
from sim.discrepancy.models import Data, Model
from tests.sim.sine_steps import LEVEL, OMEGA, TRUTH, K, sine_steps

Z95 = 1.959964


def pre_rolling_case(rel_noise: float, seed: int = 0):
    """12 steps (3 levels x 4 frequencies) of pure-sine displacement below x_s; the force
    and acceleration the base model predicts, with noise ``rel_noise`` x |P_1| on P."""
    model = Model((), harmonics=K)
    X, P, A = sine_steps([0.12, 0.24, 0.4], model)
    om, level, S, amp = OMEGA, LEVEL, OMEGA.size, np.abs(X[:, 0])
    rng = np.random.default_rng(seed)
    sP, sA, sX = rel_noise * np.abs(P[:, 0]), 1e-6 * np.abs(A[:, 0]), 1e-6 * amp

    def noise(s):
        return s[:, None] * (rng.standard_normal((S, K)) + 1j * rng.standard_normal((S, K)))
    d = Data(om, P + noise(sP), A + noise(sA), X + noise(sX), sP, sA, sX, level)
    W = Weights.from_data(d, math.exp(TRUTH[3]))
    return model, d, W, fit(model, TRUTH + np.array([0.05, 0.05, -0.1, 0.0]), d, W, max_nfev=300)


def scanned_ends(f, d, W, i: int, threshold: float, step: float, points: int = 14) -> tuple[float, float]:
    """Where the brute-force profile (Nelder-Mead over the other parameters at each grid
    value of parameter i, warm-started from the previous grid point) rises by ``threshold``."""
    others = np.arange(f.theta.size) != i

    def chi2(v: float, x: np.ndarray) -> float:
        th = f.theta.copy()
        th[i], th[others] = v, x
        r = whitened(th, f.model, d, W)
        return float(r @ r)
    ends = []
    for sign in (-1.0, 1.0):
        x, prev = f.theta[others].copy(), (0.0, 0.0)
        for k in range(1, points + 1):
            v = f.theta[i] + sign * k * step
            res = minimize(lambda y: chi2(v, y), x, method="Nelder-Mead",
                           options=dict(xatol=1e-7, fatol=1e-6, maxiter=4000, maxfev=4000))
            x, rise = res.x, res.fun - f.chi2
            if rise >= threshold:                   # linear interpolation between the grid points
                o1, r1 = prev
                o = o1 + (threshold - r1) / (rise - r1) * (k * step - o1)
                ends.append(f.theta[i] + sign * o)
                break
            prev = (k * step, rise)
        else:
            raise AssertionError(f"the scan did not reach the threshold for parameter {i} (sign {sign})")
    return ends[0], ends[1]


@pytest.mark.timeout(120)
def test_profile_interval_of_a_nearly_degenerate_case_matches_a_brute_force_scan():
    model, d, W, f = pre_rolling_case(rel_noise=0.02)
    assert f.reduced_chi2 < 1.0            # the threshold is then z^2: no reduced chi-square scaling
    for i in (0, 1):                        # log F_s and log x_s
        wald = Z95 * math.sqrt(f.cov[i, i])
        lo, hi = profile_interval(f, d, W, i)
        slo, shi = scanned_ends(f, d, W, i, Z95 ** 2, step=wald / 6)
        # the two computations agree to 5 % of the Wald half-width at each end
        assert lo == pytest.approx(slo, abs=0.05 * wald) and hi == pytest.approx(shi, abs=0.05 * wald), \
            (i, lo - f.theta[i], slo - f.theta[i], hi - f.theta[i], shi - f.theta[i], wald)
        # and the interval is asymmetric the way the scan says, by more than the tolerance
        up, down = hi - f.theta[i], f.theta[i] - lo
        s_up, s_down = shi - f.theta[i], f.theta[i] - slo
        assert abs(up - down) > 0.2 * wald and np.sign(up - down) == np.sign(s_up - s_down), (i, up, down)


@pytest.mark.timeout(60)
def test_where_the_model_is_linear_the_profile_interval_is_the_reported_one():
    model, d, W, f = pre_rolling_case(rel_noise=2e-5)
    for scale in (1.0, 4.0):                # 4: a covariance widened as select.widen does
        g = replace(f, cov=scale * f.cov)
        for i in range(4):
            wald = Z95 * math.sqrt(g.cov[i, i])
            lo, hi = profile_interval(g, d, W, i)
            assert f.theta[i] - lo == pytest.approx(wald, rel=0.03) and hi - f.theta[i] == pytest.approx(wald, rel=0.03)


def test_a_fit_without_its_jacobian_is_refused_by_name():
    model, d, W, f = pre_rolling_case(rel_noise=2e-5)
    with pytest.raises(ValueError, match="Jacobian"):
        profile_interval(replace(f, jac=None), d, W, 0)


def test_an_end_beyond_a_parameter_bound_stops_at_the_bound(monkeypatch):
    import sim.discrepancy.fit as fitmod
    model, d, W, f = pre_rolling_case(rel_noise=2e-5)
    wald = Z95 * math.sqrt(f.cov[2, 2])
    monkeypatch.setattr(fitmod, "N_BOUNDS", (f.theta[2] - 0.5 * wald, 6.0))    # n's lower bound inside its interval
    lo, hi = profile_interval(f, d, W, 2)
    assert lo == pytest.approx(f.theta[2] - 0.5 * wald, abs=1e-3 * wald)
    assert hi - f.theta[2] == pytest.approx(wald, rel=0.03)
