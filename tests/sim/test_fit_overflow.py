"""A diverging trial step of the analysis' fit that overflows exp() costs the fit that step
only: the trust region shrinks and the fit goes on (an OverflowError ended a run's final fit,
issue 25; decision 0042)."""
import math

import numpy as np
import pytest

from sim.discrepancy.fit import Fit, Weights, fit
from sim.discrepancy.models import Data, Model
from tests.sim.sine_steps import LEVEL, OMEGA, TRUTH, K, sine_steps


class Overflowing(Model):
    """The base model whose residuals overflow at the fit's first trial step (call 1 is the
    start, calls 2-5 its finite-difference Jacobian, call 6 the first step)."""
    armed = False
    calls = 0
    raised = 0

    def residuals(self, theta, d):
        self.calls += self.armed
        if self.calls == 6:
            self.raised += 1
            raise OverflowError("math range error")
        return super().residuals(theta, d)


def test_an_overflowing_trial_step_shrinks_the_step_and_the_fit_converges():
    model = Overflowing((), harmonics=K)
    X, P, A = sine_steps([0.5, 1.0, 1.5], model)
    s = np.full(OMEGA.size, 1e-6)
    d = Data(OMEGA, P, A, X, s * np.abs(P[:, 0]), s * np.abs(A[:, 0]), s * np.abs(X[:, 0]), LEVEL)
    W = Weights.propagated(model, TRUTH, d)
    start = TRUTH + np.array([math.log(1.5), math.log(0.7), 0.3, math.log(1.2)])
    model.armed = True
    f = fit(model, start, d, W)
    assert model.raised == 1
    assert np.allclose(f.theta, TRUTH, atol=1e-5), f.theta - TRUTH


def test_an_interval_beyond_the_floats_is_infinite_and_named_unbounded():
    model = Model((), harmonics=K)
    f = Fit(model, np.array([42.3, 53.6, 0.64, 2.09]), np.diag([1.3e7, 2.1e7, 6e-3, 1.3e-2]) ** 2, 1.0, 100)
    v, lo, hi = f.interval(0)
    assert v == math.exp(42.3) and hi == math.inf and lo == 0.0
    assert f.unbounded() == ["F_s_N", "x_s_m"]


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_gross_sliding_beside_a_spring_is_analysed_and_the_spring_named(tmp_path):
    """Issue 33: levels at 1.5 and 3 F_s beside a spring (independent simulator).  The Masing
    model alone runs off to F_s, x_s ~ 1e30 (friction that never saturates: a spring); its
    interval's exp() ended the analysis in an OverflowError, and the candidates warm-started
    there could not find the spring."""
    from bench.sources import load_source
    from benchtools.independent_masing import generate_uff
    from sim.discrepancy import analyze_steps

    rig = dict(F_s_N=10.0, x_s_m=20e-6, n=1.4, mass_kg=8.0)
    f_res = math.sqrt(rig["F_s_N"] / (rig["x_s_m"] * rig["mass_kg"])) / (2 * math.pi)
    k = 0.3 * rig["F_s_N"] / rig["x_s_m"]
    path = tmp_path / "spring.uff"
    generate_uff(path, **rig, levels_N=[3.0, 15.0, 30.0], freqs_Hz=list(np.geomspace(0.4, 2.5, 5) * f_res),
                 settle=40, settle_first=60, measure=6, seed=4, rtol=1e-9, spring_N_per_m=k)
    src = load_source(path)
    guess = {key: v * (1.2 if i % 2 else 0.85) for i, (key, v) in enumerate(rig.items())}
    a = analyze_steps(src.steps, guess)
    d = a.to_dict()
    assert [c["id"] for c in d["causes"]] == ["linear_spring"], d["verdict"]
    p = d["causes"][0]["parameters"]["k"]
    assert p["low"] <= k <= p["high"], (p, k)
    for key, name in (("F_s_N", "F_s_N"), ("x_s_m", "x_s_m")):
        assert d["parameters"][name]["low"] <= rig[key] <= d["parameters"][name]["high"], d["parameters"][name]
    assert d["base"]["parameters"]["F_s_N"]["high"] is None and d["base"]["parameters"]["F_s_N"]["bounded"] is False
    assert "cannot bound F_s_N and x_s_m" in d["verdict"], d["verdict"]
