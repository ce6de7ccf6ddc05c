"""Steps made by closed form for the fit's tests: a pure-sine displacement on 3 levels x 4
frequencies (20-160 Hz), with the force and acceleration the base model predicts at a truth."""
import math

import numpy as np

from sim.discrepancy.models import Data, Model

K = 5
TRUTH = np.array([math.log(10.0), math.log(20e-6), 2.0, math.log(5.0)])    # F_s 10 N, x_s 20 um, n 2, m 5 kg
OMEGA = 2 * np.pi * np.tile([20.0, 40.0, 80.0, 160.0], 3)
LEVEL = np.repeat(np.arange(3), 4)


def sine_steps(amp_per_level, model: Model):
    """(X, P, A) of the 12 steps: displacement harmonics X (amplitudes ``amp_per_level`` x x_s,
    one per level), and the force and acceleration ``model`` predicts at TRUTH."""
    amp = np.repeat(amp_per_level, 4) * math.exp(TRUTH[1])
    X = np.zeros((OMEGA.size, K), complex)
    X[:, 0] = amp
    zero = np.zeros(OMEGA.size)
    clean = Data(OMEGA, np.zeros_like(X), -(OMEGA[:, None] * np.arange(1, K + 1)) ** 2 * X, X,
                 zero, zero, zero, LEVEL)
    P, A = model.predict(TRUTH, clean)
    return X, P, A
