"""The independent simulator's effects (benchtools/independent_masing.py) against facts derived
another way, so that independent-data cases hide what they claim to hide.

In pre-rolling with n > 1 and a tiny force the Masing curve is the linear spring
K0 = n F_s / ((n - 1) x_s) (hysteresis of relative order u^(n-1)), so the rig is a linear
system whose frequency response is solved here in SI from the equations of
docs/decisions/0013 (frequency domain, no time integration); the simulator integrates the
same physics in dimensionless time.  Records are read back from the UFF58 file by pyuff.
"""

import math

import numpy as np
import pytest

from benchtools.independent_masing import generate_uff, simulate_level

F_S, X_S, N, M = 10.0, 20e-6, 2.0, 5.0
K0 = N * F_S / ((N - 1) * X_S)                 # 1e6 N/m
W_S = math.sqrt(F_S / (X_S * M))
C_DAMP = 2 * 0.1 * math.sqrt(K0 * M)           # 10 % of critical: transients die within the settle
LEVEL = 0.001 * F_S                            # amplitude ~ 0.0005 x_s


def records(tmp_path, freqs, level=LEVEL, settle=30, measure=6, **kw):
    import pyuff

    path = tmp_path / "r.uff"
    generate_uff(path, F_S, X_S, N, M, [level], freqs, settle=settle, measure=measure, noise=(0, 0, 0), **kw)
    sets = pyuff.UFF(str(path)).read_sets()
    out = []
    for i in range(0, len(sets), 3):
        fs = 1.0 / sets[i]["abscissa_inc"]
        out.append((sets[i]["data"], sets[i + 1]["data"], sets[i + 2]["data"], fs))
    return out


def phasor(x, fs, f, *others):
    """Complex amplitude of sin(2 pi f t) in x, x ~ Im(X e^{i w t}) (least squares with an
    offset, its harmonics 2-5 and the frequencies ``others``)."""
    t = np.arange(x.size) / fs
    cols = [np.ones_like(t)]
    for g in [f * k for k in range(1, 6)] + list(others):
        cols += [np.sin(2 * math.pi * g * t), np.cos(2 * math.pi * g * t)]
    coef = np.linalg.lstsq(np.column_stack(cols), x, rcond=None)[0]
    return complex(coef[1], coef[2])


def linear_frf(w, k=0.0, c=C_DAMP, pitch=None):
    """(x / P, accelerometer / P) of the linear rig, SI, from decision 0013's equations."""
    if pitch is None:
        x = 1.0 / (K0 + k + 1j * w * c - M * w * w)
        return x, -w * w * x
    J, k_th, c_th, h, e = (pitch[key] for key in ("J", "k_th", "c_th", "h", "e"))
    A = np.array([[K0 + k + 1j * w * c - M * w * w, -M * e * w * w],
                  [-M * e * w * w, k_th + 1j * w * c_th - J * w * w]])
    x, th = np.linalg.solve(A, np.array([1.0, h]))
    return x, -w * w * (x + h * th)


@pytest.mark.parametrize("k", [0.0, 0.4 * K0])
def test_viscous_damping_and_a_linear_spring_give_the_linear_frequency_response(tmp_path, k):
    freqs = [0.5 * W_S / (2 * math.pi), 1.6 * W_S / (2 * math.pi)]
    for (P, A, X, fs), f in zip(records(tmp_path, freqs, viscous_N_s_per_m=C_DAMP, spring_N_per_m=k), freqs):
        x_ref, a_ref = linear_frf(2 * math.pi * f, k=k)
        x = phasor(X, fs, f) / phasor(P, fs, f)
        a = phasor(A, fs, f) / phasor(P, fs, f)
        assert x == pytest.approx(x_ref, rel=0.01), (f, x, x_ref)
        assert a == pytest.approx(a_ref, rel=0.01), (f, a, a_ref)


def test_the_probe_delay_gain_and_mains_line_are_what_the_probe_reads(tmp_path):
    f = 0.8 * W_S / (2 * math.pi)
    tau, g, line_Hz, line_m = 0.02 / f, -0.06, 50.0, 0.3 * LEVEL / K0
    (P0, A0, X0, fs), = records(tmp_path, [f], viscous_N_s_per_m=C_DAMP)
    (P1, A1, X1, _), = records(tmp_path, [f], viscous_N_s_per_m=C_DAMP, disp_delay_s=tau, disp_gain_error=g,
                               line_Hz=line_Hz, line_m=line_m)
    np.testing.assert_allclose(P1, P0, rtol=0, atol=1e-12)          # the drive side is untouched
    np.testing.assert_allclose(A1, A0, rtol=1e-9, atol=1e-12 * np.abs(A0).max())
    ratio = phasor(X1, fs, f, line_Hz) / phasor(X0, fs, f)
    assert abs(ratio) == pytest.approx(1 + g, rel=2e-3)
    assert np.angle(ratio) == pytest.approx(-2 * math.pi * f * tau, abs=2e-3)     # a delay: phase -w tau
    # the line: not locked to the drive, its full amplitude in the probe's record only
    assert abs(phasor(X1, fs, line_Hz, f, 2 * f, 3 * f)) == pytest.approx(line_m, rel=0.02)
    assert abs(phasor(X0, fs, line_Hz, f, 2 * f, 3 * f)) < 0.01 * line_m


def test_velocity_dependent_friction_stiffens_the_pre_rolling_spring_as_its_describing_function(tmp_path):
    """K0 x (1 + alpha |v| / v_ref) on x = X sin(w t): the fundamental of x |v| is
    (4 / 3 pi) w X^2 sin(w t), an effective stiffness K0 (1 + (4 / 3 pi) alpha w X / v_ref)."""
    f = 0.8 * W_S / (2 * math.pi)        # its third harmonic far from the linear resonance (1.41 W_S)
    w = 2 * math.pi * f
    v_ref = 1e-4
    (P0, _, X0, fs), = records(tmp_path, [f], viscous_N_s_per_m=C_DAMP)
    amp = abs(phasor(X0, fs, f))
    alpha = 0.15 * v_ref / (w * amp)         # +6 % stiffness (the describing function is first order)
    (P1, _, X1, _), = records(tmp_path, [f], viscous_N_s_per_m=C_DAMP, friction_alpha=alpha,
                              friction_v_ref_m_per_s=v_ref)
    x1 = phasor(X1, fs, f) / phasor(P1, fs, f)
    k_eff = K0 * (1 + 4 / (3 * math.pi) * alpha * w * abs(phasor(X1, fs, f)) / v_ref)
    x_ref = 1.0 / (k_eff + 1j * w * C_DAMP - M * w * w)
    x0 = phasor(X0, fs, f) / phasor(P0, fs, f)
    assert abs(x1 / x0 - 1) > 0.04                                 # the effect is there
    assert abs(x1 - x_ref) < 0.1 * abs(x1 - x0), (x1, x_ref, x0)    # and its size is the formula's


def test_the_pitching_column_gives_the_two_degree_of_freedom_response(tmp_path):
    h, e = 0.1, 0.05
    J = 2.0 * M * h * h
    w_p = 3.0 * math.sqrt(K0 / M)
    pitch = dict(J=J, k_th=(J - M * e * e) * w_p ** 2, c_th=2 * 0.03 * (J - M * e * e) * w_p, h=h, e=e)
    freqs = [r * W_S / (2 * math.pi) for r in (0.6, 2.5, 4.0)]
    for (P, A, X, fs), f in zip(records(tmp_path, freqs, viscous_N_s_per_m=C_DAMP, pitch=pitch), freqs):
        x_ref, a_ref = linear_frf(2 * math.pi * f, pitch=pitch)
        assert phasor(X, fs, f) / phasor(P, fs, f) == pytest.approx(x_ref, rel=0.01), f
        assert phasor(A, fs, f) / phasor(P, fs, f) == pytest.approx(a_ref, rel=0.01), f
    # and it is not the 1-DOF response near the mode (the test can tell)
    w = 2 * math.pi * freqs[2]
    assert abs(linear_frf(w)[1] / linear_frf(w, pitch=pitch)[1] - 1) > 0.1


def test_too_few_settle_cycles_leave_a_decaying_transient_in_the_record():
    """A step of the nonlinear rig (n < 1, half of F_s) straight from rest: the record still
    changes from period to period; after 40 settle periods it repeats to ~1e-3 of its size."""
    beta = 1.3

    def period_change(settle):
        T = 2 * math.pi / beta
        sp = 256 / T
        _, u, _, _ = next(simulate_level(0.6, 0.5, [beta], settle, 6, sp))
        k = int(round(T * sp))
        d = u[k:6 * k - k] - u[:5 * k - k]   # x(t + T) - x(t) (the sample rate is a multiple of 1/T here)
        return np.abs(d[:k]).max() / np.abs(u).max(), np.abs(d[-k:]).max() / np.abs(u).max()

    first, last = period_change(0)
    assert first > 0.02 and last < first          # unsettled: large and still decaying
    settled_first, _ = period_change(40)
    assert settled_first < 0.1 * first


def test_a_cubic_spring_acts_about_its_rest_position(tmp_path):
    """k3 (x - x_c)^3 about a rest position off the probe's zero: at a tiny amplitude about
    the measured mean position x_bar it is the linear spring 3 k3 (x_bar - x_c)^2 (the carriage
    starts at the probe's zero and settles where friction holds the spring's static force).
    With the rest position ignored (x_bar is 0.11 x_s) the added stiffness would be ~70x
    smaller."""
    x_c = X_S
    k3 = 0.4 * K0 / (3 * x_c ** 2)                 # 3 k3 x_c^2 = 0.4 K0; static force 0.27 F_s
    freqs = [0.5 * W_S / (2 * math.pi), 1.6 * W_S / (2 * math.pi)]
    recs = records(tmp_path, freqs, viscous_N_s_per_m=C_DAMP, cubic_N_per_m3=k3, spring_centre_m=x_c)
    for (P, A, X, fs), f in zip(recs, freqs):
        x_bar = float(np.mean(X))
        assert 0.02 * X_S < x_bar < 0.5 * X_S          # it moved toward the rest position and stuck
        x_ref, a_ref = linear_frf(2 * math.pi * f, k=3 * k3 * (x_bar - x_c) ** 2)
        x = phasor(X, fs, f) / phasor(P, fs, f)
        assert x == pytest.approx(x_ref, rel=0.01), (f, x, x_ref)
