"""The friction-model interface (decision 0073), each model against an analytic fact.

Dahl's steady symmetric loop has a closed-form reversal force for every exponent i: with
r = F_r / F_c and a = sigma X / F_c, the travel 2X from +F_r to -F_r gives
r = tanh(a) for i = 1, 2r / (1 - r^2) = 2a for i = 2, sqrt(1 + r) - sqrt(1 - r) = a for
i = 1/2 (integrating dy/ds = -(sigma/F_c) |y|^i, y = 1 - F/F_c, over the descending branch).
Masing's loop top is the virgin curve at the amplitude.
"""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from sim.errors import ConfigurationError
from sim.friction import MODELS, ParameterProblem, friction_model
from sim.virgin import SakaiCurve

M = 1024
TAU = 2 * math.pi * np.arange(M) / M
DAHL = dict(F_c_N=12.0, sigma_N_per_m=8e5, exponent=1.0)


def dahl_reversal(a: float, i: float) -> float:
    """r = F_r / F_c of the steady symmetric loop at a = sigma X / F_c (module doc)."""
    if i == 1.0:
        return math.tanh(a)
    if i == 2.0:
        return brentq(lambda r: 2 * r / (1 - r * r) - 2 * a, 0.0, 1 - 1e-15)
    if i == 0.5:
        return 1.0 if a >= math.sqrt(2) else brentq(lambda r: math.sqrt(1 + r) - math.sqrt(1 - r) - a, 0.0, 1.0)
    raise ValueError(i)


@pytest.mark.parametrize("i", [1.0, 2.0, 0.5])
@pytest.mark.parametrize("a", [0.01, 0.3, 1.0, 3.0])
def test_dahls_steady_loop_reverses_at_the_closed_form_force(i, a):
    values = dict(DAHL, exponent=i)
    X = a * values["F_c_N"] / values["sigma_N_per_m"]
    F = MODELS["dahl"].periodic_force(values, X * np.cos(TAU + 0.4)[None, :], np.array([2 * math.pi * 40]))
    r = dahl_reversal(a, i)
    assert F.max() / values["F_c_N"] == pytest.approx(r, rel=1e-6, abs=1e-9)
    assert F.min() / values["F_c_N"] == pytest.approx(-r, rel=1e-6, abs=1e-9)


def test_dahl_is_rate_independent_and_its_branch_depends_on_the_reversal_force():
    d = MODELS["dahl"]
    paths = 1e-5 * np.cos(TAU)[None, :] * np.array([[1.0], [3.0]])
    slow = d.periodic_force(DAHL, paths, np.array([1.0, 1.0]))
    fast = d.periodic_force(DAHL, paths, np.array([3000.0, 3000.0]))
    assert np.array_equal(slow, fast)
    # Masing loops at two amplitudes are one curve scaled (F(X, x) = 2 f(X) ... ); Dahl's are
    # not: the loop at 3X, shrunk by 3 in x, does not have the small loop's tip stiffness ratio
    small, big = slow
    k_small = (small[1] - small[0]) / (paths[0, 1] - paths[0, 0])
    k_big = (big[1] - big[0]) / (paths[1, 1] - paths[1, 0])
    # after a reversal Dahl's stiffness is sigma (1 + F_r / F_c): it grows with the reversal force
    for k, F_r in ((k_small, small[0]), (k_big, big[0])):
        assert k == pytest.approx(DAHL["sigma_N_per_m"] * (1 + F_r / DAHL["F_c_N"]), rel=2e-2)


def test_the_masing_model_is_the_identifications_loop_whatever_the_phase_of_the_path():
    values = dict(F_s_N=20.0, x_s_m=2e-5, n=0.6)
    X = 1.3e-5
    F = MODELS["masing"].periodic_force(values, X * np.cos(TAU + 1.1)[None, :], np.array([1.0]))
    top = values["F_s_N"] * SakaiCurve(values["n"])(np.array([X / values["x_s_m"]]))[0]
    assert F.max() == pytest.approx(top, rel=1e-6)
    assert F.min() == pytest.approx(-top, rel=1e-6)
    assert np.argmax(F) == np.argmax(np.cos(TAU + 1.1))


def test_every_problem_of_a_parameter_set_is_said_at_once():
    problems = MODELS["masing"].problems(dict(F_s_N=-1.0, n=1.0, F_c_N=3.0))
    said = {(p.name, p.problem) for p in problems}
    assert said == {("F_c_N", ParameterProblem.UNKNOWN), ("F_s_N", ParameterProblem.OUT_OF_RANGE),
                    ("x_s_m", ParameterProblem.MISSING), ("n", ParameterProblem.EXCLUDED)}
    assert MODELS["dahl"].problems(dict(DAHL, exponent=math.nan))[0].problem is ParameterProblem.NOT_A_NUMBER
    assert MODELS["dahl"].problems(DAHL) == []


def test_a_model_not_in_the_list_is_refused_with_the_list():
    with pytest.raises(ConfigurationError, match="unknown friction model 'coulomb'.*masing.*dahl"):
        friction_model("coulomb")


def test_the_fit_vector_round_trips_on_log_and_linear_scales():
    for name, values in (("dahl", DAHL), ("masing", dict(F_s_N=20.0, x_s_m=2e-5, n=0.6))):
        m = MODELS[name]
        back = m.values(m.vector(values))
        assert back == pytest.approx(values, rel=1e-12)
