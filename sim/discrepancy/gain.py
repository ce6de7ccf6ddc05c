"""Out-of-sample gain: leave one force level out, predict its compliance and accelerance.

For each force level the model is refitted on the other levels (warm-started) and then
predicts, for every step of the held-out level, the force and acceleration that go with
the measured displacement (:meth:`Model.predict`).  The predicted compliance X_1 / P_1 and
accelerance A_1 / P_1 are compared with the measured ones; the error of a model is the rms
over held-out steps of the relative errors of both (a fraction; the analysis reports %).
A cause is worth naming only if this error falls when it is added.
"""

from __future__ import annotations

import numpy as np

from ..errors import ConfigurationError
from .fit import Weights, fit
from .models import Data, Model


def frf(P: np.ndarray, A: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First-harmonic compliance (m/N) and accelerance (m/s^2/N) per step."""
    return X[:, 0] / P[:, 0], A[:, 0] / P[:, 0]


def relative_errors(model: Model, theta: np.ndarray, d: Data) -> np.ndarray:
    """Per step: sqrt of the mean squared relative error of compliance and accelerance."""
    P, A = model.predict(theta, d)
    C_pred, Acc_pred = frf(P, A, d.X)
    C_meas, Acc_meas = frf(d.P, d.A, d.X)
    eC = np.abs(C_pred / C_meas - 1.0)
    eA = np.abs(Acc_pred / Acc_meas - 1.0)
    return np.sqrt(0.5 * (eC ** 2 + eA ** 2))


def heldout_error(model: Model, theta: np.ndarray, d: Data, W: Weights, max_nfev: int = 20) -> float:
    """Leave-one-level-out prediction error (rms relative error, a fraction)."""
    levels = np.unique(d.level)
    if levels.size < 2:
        raise ConfigurationError("need at least two force levels to hold one out")
    errs = []
    for lv in levels:
        train = d.level != lv
        f = fit(model, theta, d.subset(train), W.subset(train), max_nfev=max_nfev)
        errs.append(relative_errors(model, f.theta, d.subset(~train)))
    e = np.concatenate(errs)
    return float(np.sqrt(np.mean(e ** 2)))
