"""The contact kernel (sim/_contact_kernel.py, decision 0075) splits an RK4 step at a reversal
of the feed motion, so every segment handed to a model's ``advance`` is monotone.  With the
split the kernel is a fourth-order method on a Dahl contact (halving the step divides the
error by about 16); without it the step across each reversal is wrong at first order in the
step and the error stalls near 1e-3 of the friction level (measured: 6.5e-4 and 6.3e-4 at 100 and 200
steps per period, against 5.7e-7 and 3.9e-8 with the split)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim import _contact_kernel, plant_effects
from sim.rig import RigModel
from sim.rig_friction import contact

DAHL = {"F_c_N": 10.0, "sigma_N_per_m": 1e6, "exponent": 1.0}
FREQ_HZ, DRIVE_N, PERIODS, FINE = 40.0, 8.0, 6, 12800


def _trace(steps_per_period: int) -> np.ndarray:
    """(t, x, x', x'', th'', F, P) at every step of a Dahl rig driven from rest."""
    model = RigModel.from_dict({"friction": "dahl", **DAHL, "mass_kg": 10.0, "viscous_N_s_per_m": 20.0})
    c = contact("dahl", model.friction_values)
    n = steps_per_period * PERIODS
    rec = np.empty((n + 1, 7))
    _contact_kernel.contact_run(
        type(c.model).advance, c.params, np.zeros(c.state_size), np.empty(c.state_size),
        0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, DRIVE_N, 2 * math.pi * FREQ_HZ, 0.0, 0.0,
        plant_effects.coefficients(model, physical=True), 1.0 / (FREQ_HZ * steps_per_period), n, 1, rec)
    return rec


@pytest.fixture(scope="module")
def reference() -> np.ndarray:
    return _trace(FINE)


def _force_error(reference: np.ndarray, steps_per_period: int) -> float:
    coarse = _trace(steps_per_period)
    return float(np.max(np.abs(coarse[:, 5] - reference[:: FINE // steps_per_period, 5])) / DAHL["F_c_N"])


def test_the_drive_reverses_the_carriage_many_times(reference):
    v = reference[:, 2]
    assert np.count_nonzero(np.diff(np.sign(v[v != 0])) != 0) >= 2 * PERIODS - 1
    assert np.max(np.abs(reference[:, 5])) > 0.5 * DAHL["F_c_N"]      # well into the curve, not linear


def test_the_step_across_a_reversal_is_split_fourth_order(reference):
    e100, e200 = _force_error(reference, 100), _force_error(reference, 200)
    assert e200 < 1e-6, e200
    assert e100 / e200 > 8.0, (e100, e200)      # fourth order: 16; first order at the reversals: 1
