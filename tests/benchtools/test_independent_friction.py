"""The independent simulator of the rival friction models (benchtools/independent_friction.py)
against analytic facts of each model, so that the data made with it hide what they claim:

- Dahl: the virgin curves in closed form (i = 1, 2, 0.5: dw/ds = -(sigma/F_c) w^i), the
  steady reversal force F_c tanh(sigma X/F_c) (i = 1), a branch after a reversal that depends
  on the reversal force (F_r - F = (F_c + F_r)(1 - exp(-sigma s/F_c)), not Masing's
  2 f(s/2)), and the law integrated in time with the motion equal to its integration in
  travel along the same path, at two frequencies (rate independence);
- Iwan: the Masing rules with the virgin curve sum_i min(k_i x, f_i), inner loops closed;
- LuGre: steady sliding F = g(v) + sigma_2 v; Dahl's loop (sigma = sigma_0) at low speed;
- GMS: steady sliding F = s(v) + sigma_2 v; one element without Stribeck effect is a
  Jenkins element; several without it obey the Masing rules (non-local memory);
- generate_uff: the file reads back with bench.sources.load_source, a step per step
  written, each at its level and frequency.
"""

import math

import numpy as np
import pytest

from benchtools import friction_cases as fc
from benchtools.independent_friction import check_params, force_along, generate_uff, simulate_level

F_C, SIGMA = 10.0, 5e5                      # Dahl: x_c = F_C / SIGMA = 20 um
X_C = F_C / SIGMA


def dahl(i=1.0, F_c=F_C, sigma=SIGMA):
    return dict(F_c_N=F_c, sigma_N_per_m=sigma, exponent=i)


def polyline(vertices_m, per_um=20):
    """(t, x) along straight segments between the vertices, each vertex a sample."""
    xs = [np.array([vertices_m[0]])]
    for a, b in zip(vertices_m[:-1], vertices_m[1:]):
        n = max(2, int(abs(b - a) * 1e6 * per_um))
        xs.append(np.linspace(a, b, n + 1)[1:])
    x = np.concatenate(xs)
    return np.arange(x.size) * 1e-4, x


def sine(X, f_Hz=1.0, periods=6, per_period=400):
    t = np.arange(periods * per_period + 1) / (per_period * f_Hz)
    return t, X * np.sin(2 * math.pi * f_Hz * t)


def test_dahl_virgin_curves_are_the_closed_forms_of_its_law():
    t, x = polyline([0.0, 3 * X_C], per_um=5)
    s = x / X_C
    expected = {1.0: F_C * (1 - np.exp(-s)),
                2.0: F_C * s / (1 + s),
                0.5: F_C * (1 - np.clip(1 - s / 2, 0, None) ** 2)}   # F_c reached after 2 x_c
    for i, F_ref in expected.items():
        np.testing.assert_allclose(force_along("dahl", dahl(i), t, x), F_ref, rtol=1e-7, atol=1e-8 * F_C, err_msg=i)


@pytest.mark.parametrize("X", [0.4 * X_C, 2.0 * X_C])
def test_dahl_steady_reversal_force_is_F_c_tanh_sigma_X_over_F_c(X):
    t, x = sine(X, periods=20)                         # the start forgotten: e^(-2 sigma X/F_c) a half cycle
    F = force_along("dahl", dahl(), t, x)
    last = slice(-400, None)
    assert F[last].max() == pytest.approx(F_C * math.tanh(SIGMA * X / F_C), rel=1e-7)
    assert F[last].min() == pytest.approx(-F_C * math.tanh(SIGMA * X / F_C), rel=1e-7)


def test_dahl_branch_after_a_reversal_depends_on_the_reversal_force():
    """Two loops: the drop F_r - F after the same travel s from the upper reversal differs
    by the factor (F_c + F_r1)/(F_c + F_r2) (Masing's drop 2 f(s/2) would be the same)."""
    drops = []
    for X in (0.5 * X_C, 1.5 * X_C):
        t, x = sine(X, periods=20, per_period=2000)
        F = force_along("dahl", dahl(), t, x)
        top = 19 * 2000 + 500                           # the last upper reversal (x = X)
        s = X - x[top:top + 1000]                       # travel down from it
        F_r = F[top]
        assert F_r == pytest.approx(F_C * math.tanh(SIGMA * X / F_C), rel=1e-7)
        np.testing.assert_allclose(F_r - F[top:top + 1000], (F_C + F_r) * (1 - np.exp(-SIGMA * s / F_C)),
                                   rtol=1e-6, atol=1e-7 * F_C)
        drops.append(np.interp(0.4 * X_C, s[:500], (F_r - F[top:top + 1000])[:500]))
    assert drops[1] / drops[0] > 1.2                    # not one curve (Masing: ratio 1)


@pytest.mark.parametrize("f_ratio, level", [(0.6, 0.6), (1.8, 1.2)])
def test_dahl_in_time_with_the_motion_equals_its_law_in_travel_at_any_rate(f_ratio, level):
    """The generator integrates dF/dt = v dF/dx with m x'' = P sin - F; along the x(t) it
    makes from rest (no settle: the record starts virgin), the rate-free integration of dF/dx
    (force_along) gives the same force F = P - m x''."""
    m = 8.0
    f_r = math.sqrt(SIGMA / m) / (2 * math.pi)
    fs = 4000 * f_ratio * f_r
    (t, x, acc, P), = simulate_level("dahl", dahl(), m, level * F_C, [f_ratio * f_r], 0, 8, fs, rtol=1e-11)
    F_motion = P - m * acc
    F_law = force_along("dahl", dahl(), t, x)
    assert np.ptp(x[-4000:]) > 0.5 * X_C                # hysteresis, not a linear spring
    np.testing.assert_allclose(F_law, F_motion, atol=2e-6 * F_C)


def virgin_iwan(x, k, f):
    return np.sign(x) * np.minimum(np.multiply.outer(np.abs(x), k), f).sum(axis=-1)


def masing_expected(x, vertices, virgin):
    """The force along ``polyline(vertices)`` by Masing's rules for the path 0 -> 30 -> 5 ->
    20 -> 10 -> 30 -> 40 um (the inner loop 20-10 and the loop 30-5 close, then the virgin
    curve): written out branch by branch."""
    v = np.asarray(vertices)
    F1 = virgin(v[1])
    F2 = F1 - 2 * virgin((v[1] - v[2]) / 2)
    F3 = F2 + 2 * virgin((v[3] - v[2]) / 2)
    F4 = F3 - 2 * virgin((v[3] - v[4]) / 2)
    out = np.empty(x.size)
    seg = np.cumsum([0] + [max(2, int(abs(b - a) * 1e6 * 20)) for a, b in zip(v[:-1], v[1:])])
    for j in range(x.size):
        leg = np.searchsorted(seg, j, side="left") if j else 1      # j in (seg[leg-1], seg[leg]]
        xx = x[j]
        if leg == 1:
            out[j] = virgin(xx)
        elif leg == 2:
            out[j] = F1 - 2 * virgin((v[1] - xx) / 2)
        elif leg == 3:
            out[j] = F2 + 2 * virgin((xx - v[2]) / 2)
        elif leg == 4:
            out[j] = F3 - 2 * virgin((v[3] - xx) / 2)
        elif leg == 5 and xx <= v[3]:
            out[j] = F4 + 2 * virgin((xx - v[4]) / 2)           # the inner branch
        elif leg == 5:
            out[j] = F2 + 2 * virgin((xx - v[2]) / 2)           # 20-10 closed: the branch from 5
        else:
            out[j] = virgin(xx)                                 # 30-5 closed: the virgin curve
    return out


VERTICES = [0.0, 30e-6, 5e-6, 20e-6, 10e-6, 30e-6, 40e-6]


def test_iwan_obeys_the_masing_rules_with_its_piecewise_linear_virgin_curve():
    k = np.array([6e5, 4e5, 2.5e5, 1.7e5, 1e5, 6e4])
    f = np.array([1.2, 1.6, 2.0, 2.4, 2.4, 2.4])
    t, x = polyline(VERTICES)
    F = force_along("masing_iwan", dict(k_N_per_m=k, f_N=f), t, x)
    expected = masing_expected(x, VERTICES, lambda u: virgin_iwan(u, k, f))
    np.testing.assert_allclose(F, expected, rtol=0, atol=1e-12)
    i20 = np.flatnonzero(np.isclose(x, 20e-6, rtol=0, atol=1e-12))     # up, down, the corner, up again
    assert i20.size == 4 and F[i20[3]] == pytest.approx(F[i20[2]], abs=1e-12)     # the inner loop closed


def lugre(s1=0.0, s2=0.0, F_c=8.0, F_s=10.0, v_s=2e-3, s0=SIGMA):
    return dict(sigma0_N_per_m=s0, sigma1_N_s_per_m=s1, sigma2_N_s_per_m=s2, F_c_N=F_c, F_s_N=F_s, v_s_m_per_s=v_s)


@pytest.mark.parametrize("v", [-4e-3, 5e-4, 2e-3, 1e-2])
def test_lugre_steady_sliding_is_its_stribeck_curve_plus_viscous_friction(v):
    p = lugre(s1=300.0, s2=40.0)
    travel = 40 * X_C
    t = np.linspace(0, travel / abs(v), 200)
    F = force_along("lugre", p, t, v * t)
    g = 8.0 + 2.0 * math.exp(-((v / 2e-3) ** 2))
    assert F[-1] == pytest.approx(math.copysign(g, v) + 40.0 * v, rel=1e-6)


def test_lugre_at_low_speed_is_dahl_with_sigma_sigma0():
    t, x = sine(1.5 * X_C, f_Hz=1.0, periods=3, per_period=600)         # v <= 2e-4 m/s << v_s
    F_dahl = force_along("dahl", dahl(F_c=10.0), t, x)
    exact = force_along("lugre", lugre(F_c=10.0, F_s=10.0), t, x)
    near = force_along("lugre", lugre(s1=2.0, F_c=10.0, F_s=10.0, v_s=1.0), t, x)
    np.testing.assert_allclose(exact, F_dahl, atol=1e-6 * F_C)
    np.testing.assert_allclose(near, F_dahl, atol=1e-4 * F_C)         # sigma_1 dz/dt <= 4e-4 N
    assert np.abs(near - F_dahl).max() > 1e-6 * F_C                    # micro-damping is there


def gms(alpha, k, F_c=10.0, F_s=10.0, v_s=3e-3, delta=1.5, C=2e4, s2=0.0):
    return dict(k_N_per_m=list(k), alpha=list(alpha), F_c_N=F_c, F_s_N=F_s, v_s_m_per_s=v_s, delta=delta,
                C_N_per_s=C, sigma2_N_s_per_m=s2)


def test_gms_one_element_without_stribeck_effect_is_an_elasto_plastic_element():
    k, F_c = 4e5, 10.0                                  # slips after 25 um
    t, x = polyline([0.0, 40e-6, 0.0, 60e-6, -10e-6])
    F = force_along("gms", gms([1.0], [k], C=300.0), t, x)
    expected = np.empty(x.size)
    spring_rest = 0.0
    for j in range(x.size):                             # a spring in series with a slider
        Fj = np.clip(k * (x[j] - spring_rest), -F_c, F_c)
        spring_rest = x[j] - Fj / k
        expected[j] = Fj
    np.testing.assert_allclose(F, expected, atol=1e-7 * F_c)
    assert np.isclose(F, F_c).sum() > 100 and np.isclose(F, -F_c).sum() > 100


def test_gms_without_stribeck_effect_has_non_local_memory():
    alpha = np.array([0.2, 0.3, 0.5])
    k = np.array([8e5, 3e5, 1.5e5])                     # slips after 2.5, 10, 33 um
    t, x = polyline(VERTICES)
    F = force_along("gms", gms(alpha, k, C=500.0), t, x)
    expected = masing_expected(x, VERTICES, lambda u: virgin_iwan(u, k, alpha * 10.0))
    np.testing.assert_allclose(F, expected, atol=1e-7 * 10.0)


@pytest.mark.parametrize("v", [-6e-3, 1e-3, 3e-3, 2e-2])
def test_gms_steady_sliding_is_its_stribeck_curve_plus_viscous_friction(v):
    p = gms([0.2, 0.3, 0.5], [8e5, 3e5, 1.5e5], F_c=8.0, F_s=11.0, s2=50.0)
    travel = 200e-6
    t = np.linspace(0, travel / abs(v), 300)
    F = force_along("gms", p, t, v * t)
    s = 8.0 + 3.0 * math.exp(-abs(v / 3e-3) ** 1.5)
    assert F[-1] == pytest.approx(math.copysign(s, v) + 50.0 * v, rel=1e-6)


def test_generate_uff_reads_back_a_step_per_step_at_its_level_and_frequency(tmp_path):
    from bench.sources import load_source

    case = fc.CASES["dahl"]
    levels = [0.3 * 12.0, 1.5 * 12.0]
    f_r = fc.friction_resonance_Hz(case)
    freqs = [0.7 * f_r, 1.3 * f_r, 2.2 * f_r]
    path = tmp_path / "dahl.uff"
    n = generate_uff(path, case.model, case.params, case.mass_kg, levels, freqs, settle=10, measure=6, seed=3)
    src = load_source(path)
    assert n == 6 and len(src.steps) + len(src.rejected) == n
    assert len(src.steps) >= 5
    got = {(round(s.level_N, 1), round(s.freq_Hz, 1)) for s in src.steps}
    for s in src.steps:
        level = min(levels, key=lambda lv: abs(lv - s.level_N))
        assert s.level_N == pytest.approx(level, rel=2e-3)
        assert min(abs(s.freq_Hz / f - 1) for f in freqs) < 1e-4
    assert len(got) == len(src.steps)


def test_a_case_is_written_at_its_grid_and_says_its_truth(tmp_path):
    levels, freqs = fc.small_grid(seed=4, n_levels=2, n_freqs=2)
    assert levels[-1] == 1.5 and len(freqs) == 2
    path, truth = fc.lugre_case(tmp_path, levels=levels, freqs=freqs, settle=4, measure=3)
    assert path.exists() and truth["steps"] == 4 and truth["friction_model"] == "lugre"
    assert truth["levels_N"] == pytest.approx([lv * 13.0 for lv in levels])
    assert truth["freqs_Hz"] == pytest.approx([f * math.sqrt(4e5 / 10.0) / (2 * math.pi) for f in freqs])


def test_bad_parameters_are_named_all_at_once():
    with pytest.raises(ValueError) as e:
        check_params("gms", dict(k_N_per_m=[1e5, 2e5], alpha=[0.5, 0.6], F_c_N=10.0, F_s_N=8.0, v_s_m_per_s=-1.0,
                                 delta=1.0, C_N_per_s=1e3, sigma2_N_s_per_m=0.0))
    text = str(e.value)
    assert "alpha must sum to 1" in text and "F_s_N = 8.0 must be >= F_c_N" in text and "v_s_m_per_s" in text
    with pytest.raises(ValueError, match="sigma_N_per_m missing.*exponents is not a parameter"):
        check_params("dahl", dict(F_c_N=1.0, exponent=1.0, exponents=2.0))
    with pytest.raises(ValueError, match="not one of"):
        check_params("coulomb", {})
