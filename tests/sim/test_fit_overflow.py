"""A diverging trial step of the analysis' fit that overflows exp() costs the fit that step
only: the trust region shrinks and the fit goes on (an OverflowError ended a run's final fit,
issue 25; decision 0042)."""
import math

import numpy as np

from sim.discrepancy.fit import Weights, fit
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
