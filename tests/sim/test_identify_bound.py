"""The parameters a bounded fit leaves at the bound of its search are a value
(``Estimate.at_bound``), the one the run's status line reads, and the warnings name the same
ones (decision 0059)."""

import math

import numpy as np

from sim.discrepancy.models import Model
from sim.identify import Identifier, StepHarmonics
from tests.sim.sine_steps import OMEGA, TRUTH, sine_steps


def test_a_mass_the_bound_stops_is_named_at_the_bound_and_in_the_warnings():
    X, P, A = sine_steps(np.array([0.3, 1.0, 3.0]), Model())
    truth = dict(F_s_N=math.exp(TRUTH[0]), x_s_m=math.exp(TRUTH[1]), n=TRUTH[2], mass_kg=math.exp(TRUTH[3]))
    guess = dict(truth, mass_kg=4 * truth["mass_kg"])           # 20 kg, searched within 10-40 kg: 5 kg is out
    ident = Identifier(guess, harmonics=X.shape[1], bound_factor=2.0)
    for i in range(OMEGA.size):
        ident.add(StepHarmonics(OMEGA[i] / (2 * math.pi), P[i], A[i], X[i], 1e-3, 1e-3, 1e-9))
    est = ident.fit(max_nfev=200)
    assert est.values["mass_kg"] < 10.5                        # held at the bound, 10 kg
    assert "mass_kg" in est.at_bound and est.as_dict()["at_bound"] == list(est.at_bound)
    assert {w.split()[0] for w in est.warnings if "bound of the search" in w} == set(est.at_bound)
    free = Identifier(truth, harmonics=X.shape[1], bound_factor=2.0)
    for i in range(OMEGA.size):
        free.add(StepHarmonics(OMEGA[i] / (2 * math.pi), P[i], A[i], X[i], 1e-3, 1e-3, 1e-9))
    assert free.fit(max_nfev=200).at_bound == () and "at_bound" not in free.estimate.as_dict()
