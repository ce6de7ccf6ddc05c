"""The friction's describing function and its fit to fundamentals (issue 42 item 3, decision 0082),
checked against facts the code under test did not make: the initial tangent stiffness of
Sakai's curve, the energy per cycle of loops run by benchtools' independent Masing rule, and
fundamentals taken by this module's own DFT from time records of benchtools' independent
simulator (solve_ivp on the documented equations) with an analyser's noise."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from benchtools.independent_masing import MasingCarriage, simulate_level
from sim.describing import Control, Level, describing_function, receptance
from sim.describing_fit import ParameterStatus, Separation, fit_fundamentals

F_S, X_S, N, M = 10.0, 1e-5, 1.5, 10.0            # the rig: friction resonance near 87 Hz at small amplitude
TRUE = {"F_s_N": F_S, "x_s_m": X_S, "n": N, "mass_kg": M}
W_S = math.sqrt(F_S / (X_S * M))
NOISE_X = 0.005                                   # the analyser's noise: of the level's largest response
NOISE_F = 0.002                                   # and of the force


def independent_loop(n: float, a: float, samples: int = 20000):
    """One steady loop of amplitude a (units of x_s) from benchtools' Masing rule: virgin
    loading to a, then a -> -a -> a; returns the path of the last cycle and its force."""
    car = MasingCarriage(n)
    for u in np.linspace(0.0, a, samples // 4):       # virgin branch (no reversal yet)
        car.force(u)
    car.stack.append((a, car.virgin(a)))
    car.d = -1.0
    theta = np.linspace(0.0, 2 * math.pi, samples + 1)
    x = a * np.cos(theta)
    F = np.empty_like(x)
    for i, u in enumerate(x):
        if i and u > x[i - 1] and car.d < 0:           # the reversal at -a
            car.stack.append((x[i - 1], F[i - 1]))
            car.d = 1.0
        c = car.closure()
        if c is not None and car.d * (u - c) >= 0 and len(car.stack) >= 2:
            del car.stack[-2:]                        # the branch reached the loop's start: closed
        F[i] = car.force(u)
    return theta, x, F


@pytest.mark.parametrize("n", [0.5, 1.5, 3.0])
@pytest.mark.parametrize("a", [0.05, 0.4, 1.0, 2.5])
def test_imaginary_part_is_the_loop_energy_and_real_part_the_in_phase_fundamental(n, a):
    """Im K_eq = W / (pi a^2), W the loop's area (trapezoid of F dx along the independent
    loop); Re K_eq = (1/(pi a)) int F cos(theta) dtheta.  Flip: the describing function's
    fundamental conjugated (the exp(+i theta) convention: red, Im K_eq = -3.8e6 N/m)."""
    theta, x, F = independent_loop(n, a)
    W = np.trapezoid(F, x) * F_S * X_S              # oint F dx: falling on the lower branch, rising on the upper
    a1 = np.trapezoid(F * np.cos(theta), theta) / math.pi * F_S
    K = describing_function("masing", {"F_s_N": F_S, "x_s_m": X_S, "n": n}, a * X_S)
    assert K.imag > 0
    assert K.imag == pytest.approx(W / (math.pi * (a * X_S) ** 2), rel=2e-3)
    assert K.real == pytest.approx(a1 / (a * X_S), rel=2e-3)


def test_small_amplitude_tends_to_the_initial_tangent_stiffness():
    """n F_s / ((n - 1) x_s) (seed Eqs. 4-5: the slope of A x^n + B x at 0 is B), the
    relative gap falling as a^(n - 1) (the a^n term of the curve).  Flip: K0 = F_s / x_s
    (red: a gap of 2.0)."""
    K0 = N * F_S / ((N - 1) * X_S)
    a = X_S * np.array([1e-4, 1e-6, 1e-8])
    K = describing_function("masing", {"F_s_N": F_S, "x_s_m": X_S, "n": N}, a)
    gap = np.abs(K - K0) / K0
    assert gap[-1] < 1e-3
    assert np.all(np.diff(np.log(gap)) == pytest.approx(np.log(1e-2) * (N - 1), rel=0.05))


def _fundamental(t, y, beta):
    """This module's own DFT: the complex fundamental of a record at the frequency ``beta``
    by least squares on cos, sin and a constant (the records hold a few periods, sampled at
    a rate that is not a multiple of the drive)."""
    A = np.column_stack([np.cos(beta * t), np.sin(beta * t), np.ones_like(t)])
    c, s, _ = np.linalg.lstsq(A, y, rcond=None)[0]
    return c - 1j * s


def _force_levels(levels_N, freqs_Hz, rng):
    out = []
    betas = [2 * math.pi * f / W_S for f in freqs_Hz]
    for L in levels_N:
        X, P = [], []
        for (t, u, _acc, p), b in zip(simulate_level(N, L / F_S, betas, SETTLE, 4, 40.0 * max(betas) / (2 * math.pi) * 1.037,
                                                     rtol=1e-9), betas):
            X.append(_fundamental(t, u, b) * X_S)
            P.append(_fundamental(t, p, b) * F_S)
        out.append(_noisy(freqs_Hz, np.array(X), np.array(P), Control.FORCE, rng))
    return out


def _noisy(freqs, X, P, control, rng):
    sX = NOISE_X * np.max(np.abs(X))
    sF = NOISE_F * np.abs(P)
    Xn = X + sX * (rng.standard_normal(X.size) + 1j * rng.standard_normal(X.size))
    Pn = P + sF * (rng.standard_normal(P.size) + 1j * rng.standard_normal(P.size))
    return Level.from_fundamentals(freqs, Xn, Pn, control, sigma_response=sX, sigma_force_N=sF)


FREQS = np.linspace(40.0, 110.0, 10)
SETTLE = 24                                       # periods each step settles in the up-sweep


@pytest.fixture(scope="module")
def saturating():
    """Force-controlled levels 0.1-0.8 F_s (the largest rolls beyond x_s at resonance)."""
    return _force_levels([1.5, 4.0, 8.0], FREQS, np.random.default_rng(42))


@pytest.fixture(scope="module")
def low():
    """Force-controlled levels 0.02-0.1 F_s (at 0.28 F_s the resonance already rolls the
    carriage to x_s: the loop saturates)."""
    return _force_levels([0.2, 0.5, 1.0], FREQS, np.random.default_rng(7))


def _covers(fit, names):
    return {k: (fit.estimate(k).low <= TRUE[k] <= fit.estimate(k).high) for k in names}


def test_fit_to_independent_fundamentals_covers_the_truth(saturating):
    """The fit of the independent simulator's fundamentals (3 levels 0.15-0.8 F_s x 10
    frequencies, 0.5 % noise): every parameter identified, each 95 % interval covers the
    simulator's value, the structure BIC picks is none (the simulator has no mode), the loop
    saturated.  Flips: the interval's 1.96 -> 0.2 (red: all four missed), the balance's mass
    term +w^2 m (red: chi2/dof 6.0e3), the single-harmonic balance (THIRD_ITER 0; red: F_s
    and m missed, the neglected third harmonic biases them beyond the noise)."""
    t0 = time.perf_counter()
    fit = fit_fundamentals(saturating, "masing")
    print(f"\nindependent 3 x 10, force-controlled: {time.perf_counter() - t0:.2f} s, chi2/dof "
          f"{fit.reduced_chi2:.2f}, BIC {fit.bic_by_structure}",
          {e.name: (f"{e.value:.4g}", f"[{e.low:.4g}, {e.high:.4g}]") for e in fit.estimates})
    assert str(fit.structure) == "none" and "mode" in fit.bic_by_structure
    assert fit.reduced_chi2 < 3
    assert set(fit.identified) == set(TRUE)
    assert all(_covers(fit, TRUE).values()), _covers(fit, TRUE)
    assert fit.loop_reach > 0.9 and Separation.LEVEL_AT_SATURATION not in fit.separations


def test_levels_below_a_tenth_of_F_s_leave_F_s_to_the_curve_s_form(low):
    """At 0.1 F_s and below the loops never saturate (the largest amplitude stays below x_s).  What the Jacobian shows (decision 0082): Sakai's
    curve below x_s is A x^n + B x, three numbers for three parameters, so the fundamentals
    still fix F_s, x_s and n, the weakest direction being F_s and x_s together (F_s / x_s
    held); F_s is then the curve's extrapolation to where no level went, and the fit says a
    level at saturation would test it.  Flips: SATURATION_SEEN 0.9 -> 0.01 (red: no
    LEVEL_AT_SATURATION), the weakest direction's signs asserted opposite (red: 0.72 x 1.0)."""
    fit = fit_fundamentals(low, "masing", structures=("none",))
    print(f"\nlevels <= 0.1 F_s: loop reach {fit.loop_reach:.2f}, singular values "
          f"{[f'{s:.3g}' for s in fit.singular_values]}, weakest {fit.directions[-1]}")
    assert fit.loop_reach < 0.9
    assert Separation.LEVEL_AT_SATURATION in fit.separations
    weak = fit.directions[-1].exponents
    assert weak.get("F_s_N", 0) * weak.get("x_s_m", 0) > 0
    assert abs(weak.get("F_s_N", 0)) > 0.5 and abs(weak.get("x_s_m", 0)) > 0.5
    assert all(_covers(fit, TRUE).values()), _covers(fit, TRUE)


def _held_levels(amplitudes, freqs, rng, settle):
    """Response-controlled: per frequency the force that holds the amplitude (chosen by the
    harmonic balance), each point simulated from rest by the independent simulator; the
    level's points carry the amplitude each reached (as a controller holds it, within a
    tolerance)."""
    out = []
    for a_h in amplitudes:
        guess = Level(freqs, np.full(freqs.size, 1e-7 + 0j), Control.RESPONSE, a_h * X_S, 1.0)
        H, _ = receptance("masing", {k: TRUE[k] for k in ("F_s_N", "x_s_m", "n")}, M, guess)
        X, P = [], []
        for f, h in zip(freqs, H):
            b = 2 * math.pi * f / W_S
            (t, u, _a, p), = simulate_level(N, a_h * X_S / abs(h) / F_S, [b], settle, 4,
                                            40.0 * b / (2 * math.pi) * 1.037, rtol=1e-9)
            X.append(_fundamental(t, u, b) * X_S)
            P.append(_fundamental(t, p, b) * F_S)
        out.append(_noisy(freqs, np.array(X), np.array(P), Control.RESPONSE, rng))
    return out


@pytest.fixture(scope="module")
def held():
    return _held_levels((0.15, 0.5, 1.2), np.linspace(35.0, 100.0, 8), np.random.default_rng(5), SETTLE)


def test_response_controlled_levels_cover_the_truth(held):
    """Three held amplitudes (0.15, 0.5, 1.2 x_s) x 8 frequencies: a is given, the harmonic
    balance direct; the intervals cover the simulator's values.  Flip: the response-
    controlled branch solving for a as if the level were a force (red: chi2/dof 5.0e3)."""
    fit = fit_fundamentals(held, "masing", structures=("none",))
    print(f"\nresponse-controlled 3 x 8: chi2/dof {fit.reduced_chi2:.2f}",
          {e.name: (f"{e.value:.4g}", f"[{e.low:.4g}, {e.high:.4g}]") for e in fit.estimates})
    assert fit.reduced_chi2 < 3
    assert all(_covers(fit, TRUE).values()), _covers(fit, TRUE)


def test_one_held_amplitude_leaves_one_combination_open(held):
    """One response-controlled level is one complex K_eq(a) for three friction parameters:
    two numbers, so one direction of (F_s, x_s, n) is open (its singular value orders below
    the others), the mass is identified (the frequencies), and the fit names the harmonics.  Flip: IDENTIFIED_WIDTH ln 2 -> 1e6 (red: the open direction
    called identified)."""
    fit = fit_fundamentals(held[1:2], "masing", structures=("none",))
    print(f"\none held amplitude: singular values {[f'{s:.3g}' for s in fit.singular_values]}, "
          f"statuses {[(e.name, str(e.status)) for e in fit.estimates]}")
    assert fit.estimate("mass_kg").status is ParameterStatus.IDENTIFIED
    assert not fit.directions[-1].identified
    assert set(fit.directions[-1].exponents) <= {"F_s_N", "x_s_m", "n"}
    assert fit.singular_values[-1] < 1e-3 * fit.singular_values[-2]
    assert fit.degenerate and Separation.HARMONICS in fit.separations


def test_velocity_and_acceleration_fundamentals_give_the_displacement_s_receptance(saturating):
    """A response given as velocity (i w X) or acceleration (-w^2 X) with its noise is the
    same level: Level.from_fundamentals divides by (i w)^k.  Flip: dividing by (-i w)^k
    (red: the velocity's receptance comes out -H)."""
    lv = saturating[0]
    f = lv.frequency_Hz
    w = 2 * math.pi * f
    F = 3.0 * np.exp(0.3j) * np.ones(f.size)
    X = lv.receptance_m_per_N * F
    for k, R in ((1, 1j * w * X), (2, -w ** 2 * X)):
        got = Level.from_fundamentals(f, R, F, Control.FORCE, derivative=k, sigma_response=1e-9 * w ** k)
        assert np.allclose(got.receptance_m_per_N, lv.receptance_m_per_N, rtol=1e-12, atol=0)
        assert np.allclose(got.sigma_m_per_N, 1e-9 / 3.0, rtol=1e-12)
        assert np.allclose(got.drive, 3.0)


def test_a_held_parameter_is_fixed_and_the_rest_still_fitted(low):
    """``fixed`` holds a value: its status is FIXED at that value, its interval a point, it
    is in no direction, and the others are fitted around it (here n at the simulator's own
    1.5: F_s, x_s and m covered).  Flip: ``fixed`` not passed on to the problem (red: n
    fitted, status identified)."""
    fit = fit_fundamentals(low, "masing", structures=("none",), fixed={"n": N})
    e = fit.estimate("n")
    assert e.status is ParameterStatus.FIXED and e.value == e.low == e.high == N
    assert all("n" not in d.exponents for d in fit.directions) and len(fit.directions) == 3
    assert all(_covers(fit, ("F_s_N", "x_s_m", "mass_kg")).values())


def test_a_linear_spring_leaves_the_friction_level_open():
    """A linear mass-spring-damper (an analytic FRF, no friction loop: 1/(k - w^2 m + i w c))
    fitted as a Masing carriage: Sakai's curve becomes a spring of F_s and x_s far beyond the
    levels, each with an interval within a factor 2 (the curve's assumed form extrapolated).
    Neither may be called identified.
    Flip: REACH_MIN = 0 (levels at 1e-5 of the fitted F_s): both identified, red."""
    k, m, c = 3.0e6, 10.0, 2 * 0.02 * math.sqrt(3.0e6 * 10.0)
    f = np.linspace(60.0, 80.0, 20)
    w = 2 * math.pi * f
    H = 1.0 / (k - w ** 2 * m + 1j * w * c)
    rng = np.random.default_rng(4)
    levels = []
    for F in (1.0, 2.0, 4.0):
        Hn = H * (1 + 0.002 * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)))
        levels.append(Level(f, Hn, Control.FORCE, np.full(f.size, F), 0.002 * np.abs(H)))
    fit = fit_fundamentals(levels, "masing", structures=("none",))
    assert fit.estimate("F_s_N").value > 100 * 4.0                   # the spring's F_s: far above every level
    assert fit.estimate("F_s_N").status is ParameterStatus.DEGENERATE
    assert fit.estimate("x_s_m").status is ParameterStatus.DEGENERATE
    assert Separation.LEVEL_AT_SATURATION in fit.separations
