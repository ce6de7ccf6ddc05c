import math

import numpy as np
import pytest

from sim.virgin import SakaiCurve


@pytest.mark.parametrize("n", [0.3, 0.5, 1.5, 3.0])
def test_curve_is_continuous_in_value_and_slope_at_x_s(n):
    c = SakaiCurve(n)
    eps = 1e-7
    assert c(np.array([1.0]))[0] == pytest.approx(1.0, abs=1e-12)
    slope_left = (c(np.array([1.0]))[0] - c(np.array([1.0 - eps]))[0]) / eps
    assert abs(slope_left) < 1e-5  # Eq. 5: df1/dx = df2/dx = 0 at x_s


@pytest.mark.parametrize("n", [0.5, 1.5, 3.0])
def test_coefficients_A_B_reproduce_the_curve_in_SI(n):
    F_s, x_s = 12.0, 20e-6
    A, B = SakaiCurve(n).coefficients(F_s, x_s)
    x = np.linspace(0, x_s, 7)
    assert np.allclose(A * x**n + B * x, F_s * SakaiCurve(n)(x / x_s), rtol=1e-12, atol=1e-12)


def test_initial_stiffness_finite_only_for_n_above_one():
    assert math.isinf(SakaiCurve(0.5).stiffness0)
    assert SakaiCurve(1.5).stiffness0 == pytest.approx(3.0)
    s = 1e-8
    assert SakaiCurve(3.0)(np.array([s]))[0] / s == pytest.approx(1.5, rel=1e-6)


@pytest.mark.parametrize("bad", [1.0, 1 + 1e-12, 0.0, -0.5, float("nan"), float("inf"), "x"])
def test_invalid_shape_factor_is_refused_with_its_name(bad):
    with pytest.raises(ValueError, match="shape factor n"):
        SakaiCurve(bad)


def test_curve_monotone_and_bounded():
    for n in (0.3, 0.5, 1.5, 3.0):
        f = SakaiCurve(n)(np.linspace(0, 2, 2001))
        assert np.all(np.diff(f) >= -1e-15) and f.max() == pytest.approx(1.0)
