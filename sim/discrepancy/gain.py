"""Out-of-sample gain: leave one force level out, predict its compliance, accelerance and
force waveform.

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
    """Per step: sqrt of the mean squared relative error of compliance and accelerance, plus
    the squared error of the force's waveform (the force balance's residual at harmonics
    2..K with the measured motion, relative to the force's fundamental; predicted from the
    probe alone, the upper harmonics of m a would be the probe's noise times (k w)^2).  The waveform term is what a form that
    leaves the fundamental alone (an asymmetry, whose signature is harmonic 2) is judged
    by; on a model that fits it is at the noise level (1e-4 of the fundamental)."""
    P, A = model.predict(theta, d)
    C_pred, Acc_pred = frf(P, A, d.X)
    C_meas, Acc_meas = frf(d.P, d.A, d.X)
    eC = np.abs(C_pred / C_meas - 1.0)
    eA = np.abs(Acc_pred / Acc_meas - 1.0)
    rF, _ = model.residuals(theta, d)       # the force balance with the measured motion
    eH2 = np.sum(np.abs(rF[:, 1:]) ** 2, axis=1) / np.abs(d.P[:, 0]) ** 2
    return np.sqrt(0.5 * (eC ** 2 + eA ** 2) + eH2)


def heldout_error(model: Model, theta: np.ndarray, d: Data, W: Weights, max_nfev: int = 20,
                  thetas: list | None = None) -> float:
    """Leave-one-level-out prediction error (rms relative error, a fraction).  ``thetas``,
    when given, receives each refit's parameter vector (a jackknife over force levels)."""
    levels = np.unique(d.level)
    if levels.size < 2:
        raise ConfigurationError("need at least two force levels to hold one out")
    errs = []
    for lv in levels:
        train = d.level != lv
        f = fit(model, theta, d.subset(train), W.subset(train), max_nfev=max_nfev)
        errs.append(relative_errors(model, f.theta, d.subset(~train)))
        if thetas is not None:
            thetas.append(f.theta)
    e = np.concatenate(errs)
    return float(np.sqrt(np.mean(e ** 2)))
