"""The describing-function fit is generic over the friction-model interface (decision 0082):
Dahl's model fitted to fundamentals that this module's own DFT takes from time records of
benchtools' independent simulator of the rival models (solve_ivp on Dahl's law, no code
shared with sim/), with an analyser's noise."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from benchtools.independent_friction import simulate_level
from sim.describing import Control, Level
from sim.describing_fit import ParameterStatus, fit_fundamentals

DAHL = {"F_c_N": 10.0, "sigma_N_per_m": 1e6, "exponent": 1.0}
M = 10.0                                          # friction resonance near 50 Hz at small amplitude
FREQS = np.linspace(25.0, 80.0, 8)


def _fundamental(t, y, w):
    """This module's own DFT: least squares on cos, sin and a constant."""
    A = np.column_stack([np.cos(w * t), np.sin(w * t), np.ones_like(t)])
    c, s, _ = np.linalg.lstsq(A, y, rcond=None)[0]
    return c - 1j * s


@pytest.fixture(scope="module")
def dahl_levels():
    rng = np.random.default_rng(11)
    out = []
    for L in (1.5, 6.0):
        X, P = [], []
        for (t, x, _a, F), f in zip(simulate_level("dahl", DAHL, M, L, FREQS, 20, 4, 40 * FREQS.max() * 1.037), FREQS):
            X.append(_fundamental(t, x, 2 * math.pi * f))
            P.append(_fundamental(t, F, 2 * math.pi * f))
        X, P = np.array(X), np.array(P)
        sX, sF = 0.005 * np.abs(X).max(), 0.002 * np.abs(P)
        Xn = X + sX * (rng.standard_normal(X.size) + 1j * rng.standard_normal(X.size))
        Pn = P + sF * (rng.standard_normal(P.size) + 1j * rng.standard_normal(P.size))
        out.append(Level.from_fundamentals(FREQS, Xn, Pn, Control.FORCE, sigma_response=sX, sigma_force_N=sF))
    return out


def test_dahl_fitted_to_independent_fundamentals_covers_the_truth(dahl_levels):
    """F_c, sigma, the exponent and the mass from 2 levels x 8 frequencies: each identified
    and covered by its 95 % interval, chi2/dof about 1.  Flip: the interval's 1.96 -> 0.2
    (red: F_c and m missed)."""
    t0 = time.perf_counter()
    fit = fit_fundamentals(dahl_levels, "dahl", structures=("none",))
    print(f"\ndahl 2 x 8: {time.perf_counter() - t0:.2f} s, chi2/dof {fit.reduced_chi2:.2f}",
          {e.name: (f"{e.value:.4g}", f"[{e.low:.4g}, {e.high:.4g}]") for e in fit.estimates})
    truth = {**DAHL, "mass_kg": M}
    assert fit.model == "dahl" and fit.reduced_chi2 < 3
    assert all(fit.estimate(k).status is ParameterStatus.IDENTIFIED for k in truth)
    missed = {k: fit.estimate(k) for k in truth if not fit.estimate(k).low <= truth[k] <= fit.estimate(k).high}
    assert not missed, missed
