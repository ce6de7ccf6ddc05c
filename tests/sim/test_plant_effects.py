"""The rig's optional effects, each against an independent fact.

The pieces of the kernel are checked against their formulas; the plant with an effect on
is checked against linear vibration theory (2-DOF eigenproblem and receptance), harmonic
balance of a cubic spring, and the energy a rate-dependent Masing loop dissipates
(computed from the quasi-static Masing element, a separate code path from the RK4 kernel).
"""

import math

import numpy as np
import pytest

from sim import _plant_kernel as pk
from sim import plant_effects
from sim.masing import MasingFriction
from sim.rig import RigModel, SimulatedRig
from sim.virgin import SakaiCurve

FS = 10240.0
PITCH = dict(pitch_inertia_kg_m2=0.3, pitch_stiffness_N_m_per_rad=3e5, drive_height_m=0.2, cg_height_m=0.1)
# friction made negligible (1 mN against newton forces) so linear theory applies exactly
LINEAR = dict(F_s_N=1e-3, spring_N_per_m=1e6, viscous_N_s_per_m=300.0)


def harmonic(x, f):
    """Complex amplitude of ``f`` (sin + j cos convention) over whole periods, with offset."""
    t = np.arange(x.size) / FS
    A = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t), np.ones_like(t)])
    c = np.linalg.lstsq(A, x, rcond=None)[0]
    return complex(c[0], c[1])


def measure(rig, f, force_N, settle_s=0.3, periods=10):
    """(P, a, x) first harmonics in N, m/s^2, m after settling at ``f``."""
    m = rig.model
    rig.set_generator(freq_Hz=f, amplitude_Vpp=2 * force_N / m.amp_gain_N_per_V, output_on=True)
    rig.run(int(settle_s * FS), FS)
    b = rig.run(int(round(periods * FS / f)), FS)
    return (harmonic(b.force_V / m.force_sens_V_per_N, f), harmonic(b.accel_V / m.accel_sens_V_per_m_s2, f),
            harmonic(b.disp_V / m.disp_sens_V_per_m, f))


def linear_accelerance(model, f):
    """a/P at the drive point of the linear 2-DOF plant: -w^2 b^T (K + j w C - w^2 M)^-1 b."""
    w = 2 * np.pi * f
    M = plant_effects.mass_matrix(model)
    K = np.diag([model.spring_N_per_m, model.pitch_stiffness_N_m_per_rad])
    C = np.diag([model.viscous_N_s_per_m, model.pitch_damping_N_m_s_per_rad])
    b = np.array([1.0, model.drive_height_m])
    return -w**2 * b @ np.linalg.solve(K + 1j * w * C - w**2 * M, b)


# --- the pieces --------------------------------------------------------------------------

def test_rate_factor_is_one_plus_alpha_speed_over_vref():
    assert pk.rate_factor(-3.0, 0.5) == pytest.approx(2.5)
    assert pk.rate_factor(3.0, 0.0) == 1.0


def test_cubic_spring_is_odd_and_cubic():
    assert pk.cubic_spring(2.0, 0.25) == pytest.approx(2.0)
    assert pk.cubic_spring(-2.0, 0.25) == pytest.approx(-2.0)


def test_accelerations_solve_the_mass_matrix():
    model = RigModel(**PITCH)
    coef = plant_effects.coefficients(model)
    r1, r2 = 0.7, -0.03                     # scaled right-hand sides (1, m)
    a_u, a_th = pk.accelerations(r1, r2, coef)
    x_dd, th_dd = np.linalg.solve(plant_effects.mass_matrix(model), model.F_s_N * np.array([r1, r2]))
    assert a_u * model.x_s_m == pytest.approx(x_dd, rel=1e-12)
    assert a_th == pytest.approx(th_dd, rel=1e-12)


def test_pitch_moment_is_drive_minus_spring_and_damper():
    model = RigModel(**PITCH, pitch_damping_N_m_s_per_rad=4.0)
    coef = plant_effects.coefficients(model)
    got = pk.pitch_moment(0.5, 1e-4, 2e-2, coef) * model.F_s_N
    assert got == pytest.approx(0.2 * 0.5 * model.F_s_N - 3e5 * 1e-4 - 4.0 * 2e-2)


def test_no_effect_keeps_the_plain_kernel():
    assert plant_effects.coefficients(RigModel()) is None
    assert plant_effects.coefficients(RigModel(friction_alpha=0.1, friction_v_ref_m_per_s=1e-3)) is not None


@pytest.mark.parametrize("bad, key", [
    (dict(friction_alpha=-0.1), "friction_alpha"),
    (dict(friction_alpha=0.5), "friction_v_ref_m_per_s"),
    (dict(PITCH, pitch_stiffness_N_m_per_rad=0.0), "pitch_stiffness_N_m_per_rad"),
    (dict(PITCH, pitch_inertia_kg_m2=0.05), "pitch_inertia_kg_m2"),     # < m e^2 = 0.1
    (dict(cubic_spring_N_per_m3=float("nan")), "cubic_spring_N_per_m3"),
    (dict(drive_height_m=-1.0), "drive_height_m"),
    (dict(quadratic_damping_N_s2_per_m2=-1.0), "quadratic_damping_N_s2_per_m2"),
    (dict(friction_asymmetry=0.5), "friction_asymmetry"),
    (dict(friction_asymmetry=float("nan")), "friction_asymmetry"),
])
def test_bad_effect_parameters_are_refused_by_name(bad, key):
    with pytest.raises(ValueError, match=key):
        RigModel(**bad)


# --- the plant with an effect on ---------------------------------------------------------

def test_without_effects_the_plant_is_the_plain_one():
    # the 2-DOF kernel with the pitch off and every new effect at zero must reproduce the
    # plain kernel's data (a vanishing alpha switches the effect kernel on)
    plain = SimulatedRig(RigModel(seed=4))
    other = SimulatedRig(RigModel(seed=4, friction_alpha=1e-15, friction_v_ref_m_per_s=1.0))
    for rig in (plain, other):
        rig.set_generator(freq_Hz=60.0, amplitude_Vpp=0.8, output_on=True)
    a, b = plain.run(4096, FS), other.run(4096, FS)
    assert np.allclose(a.disp_V, b.disp_V, rtol=0, atol=1e-9)
    assert np.allclose(a.accel_V, b.accel_V, rtol=0, atol=1e-9)


def test_pitch_mode_follows_linear_two_dof_theory():
    # Drive-point accelerance of the linear 2-DOF system: the pitch mode adds a resonance and,
    # below it, an anti-resonance; both frequencies from the eigenproblem / the zero of
    # b^T adj(K - w^2 M) b, the curve from the receptance matrix.
    model = RigModel(**PITCH, **LINEAR, pitch_damping_N_m_s_per_rad=6.0, seed=2)
    M = plant_effects.mass_matrix(model)
    K = np.diag([model.spring_N_per_m, model.pitch_stiffness_N_m_per_rad])
    f_modes = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(M, K)).real)) / (2 * np.pi)
    h, e, m, J = 0.2, 0.1, model.mass_kg, model.pitch_inertia_kg_m2
    f_anti = math.sqrt((3e5 + h**2 * 1e6) / (J - 2 * h * m * e + h**2 * m)) / (2 * np.pi)
    assert 2 * f_modes[0] < f_anti < f_modes[1]
    rig = SimulatedRig(model)
    freqs = [0.7 * f_anti, f_anti, 0.5 * (f_anti + f_modes[1]), f_modes[1], 1.4 * f_modes[1]]
    meas = []
    for f in freqs:
        P, a, _ = measure(rig, f, 1.0)
        meas.append(a / P)
        theory = linear_accelerance(model, f)
        assert abs(a / P - theory) < 0.03 * abs(theory) + 0.002, f
    mags = np.abs(meas)
    assert mags[1] < 0.3 * mags[0] and mags[3] > 5 * mags[1]   # the pair is there


def test_pitch_damping_lowers_and_broadens_the_pitch_resonance():
    peaks = {}
    for c_th in (3.0, 12.0):
        model = RigModel(**PITCH, **LINEAR, pitch_damping_N_m_s_per_rad=c_th, seed=3)
        M = plant_effects.mass_matrix(model)
        K = np.diag([model.spring_N_per_m, model.pitch_stiffness_N_m_per_rad])
        f_r = math.sqrt(np.linalg.eigvals(np.linalg.solve(M, K)).real.max()) / (2 * np.pi)
        rig = SimulatedRig(model)
        P0, a0, _ = measure(rig, f_r, 0.5)
        P1, a1, _ = measure(rig, 1.03 * f_r, 0.5)
        peaks[c_th] = abs(a0 / P0), abs(a1 / P1) / abs(a0 / P0)
    assert peaks[12.0][0] < 0.5 * peaks[3.0][0]        # lower
    assert peaks[12.0][1] > peaks[3.0][1] + 0.1        # broader: 3 % off the peak keeps more


def test_viscous_damping_lowers_the_friction_resonance():
    peak = []
    for c in (0.0, 500.0):
        rig = SimulatedRig(RigModel(viscous_N_s_per_m=c, seed=5))
        comp = []
        for f in np.arange(40.0, 95.0, 5.0):
            P, _, x = measure(rig, f, 3.0, settle_s=0.3, periods=5)
            comp.append(abs(x / P))
        peak.append(max(comp))
    assert peak[1] < 0.8 * peak[0]


def test_spring_raises_the_low_frequency_stiffness_by_k():
    # Friction on (realistic); at the same displacement amplitude the friction loop is the
    # same, so the in-phase dynamic stiffness Re(P/x) differs by exactly k.
    k, f = 1e6, 5.0
    stiff = {}
    for spring in (0.0, k):
        rig = SimulatedRig(RigModel(spring_N_per_m=spring, seed=6))
        amps, re = [], []
        # forces below F_s without the spring (no gross rolling), covering the same amplitudes
        for force in np.geomspace(2.0, 9.0, 12) * (1 + spring / 1.5e6):
            P, _, x = measure(rig, f, force, settle_s=0.4, periods=3)
            amps.append(abs(x))
            re.append((P / x).real)
        stiff[spring] = (np.log(amps), np.array(re))
    X = np.geomspace(2e-6, 5e-6, 4)
    lo = np.interp(np.log(X), *stiff[0.0])
    hi = np.interp(np.log(X), *stiff[k])
    assert hi - lo == pytest.approx(np.full(X.size, k), rel=0.05)


def test_cubic_spring_stiffness_grows_with_amplitude_as_harmonic_balance_says():
    # first harmonic of k3 x^3 for x = X sin: (3/4) k3 X^3, so Re(P/x) = k - m w^2 + 3/4 k3 X^2
    k3, f = 1e14, 10.0
    model = RigModel(**LINEAR, cubic_spring_N_per_m3=k3, seed=7)
    rig = SimulatedRig(model)
    got = []
    for force in (5.0, 60.0):
        P, _, x = measure(rig, f, force, periods=4)
        X = abs(x)
        expect = 1e6 - model.mass_kg * (2 * np.pi * f) ** 2 + 0.75 * k3 * X**2
        assert (P / x).real == pytest.approx(expect, rel=0.02)
        got.append((P / x).real)
    assert got[1] > 1.1 * got[0]


def _path(x, f, n_harm=7, n_pts=4000):
    """One period of the measured displacement, rebuilt from its first harmonics (which
    keeps the distortion a nonlinear plant gives x and drops the sensor noise)."""
    t = np.arange(x.size) / FS
    cols = [np.ones_like(t)]
    for k in range(1, n_harm + 1):
        cols += [np.sin(2 * np.pi * k * f * t), np.cos(2 * np.pi * k * f * t)]
    c = np.linalg.lstsq(np.column_stack(cols), x, rcond=None)[0]
    tt = np.arange(n_pts + 1) / (n_pts * f)
    xs, vs = np.full(tt.size, c[0]), np.zeros(tt.size)
    for k in range(1, n_harm + 1):
        w = 2 * np.pi * k * f
        xs += c[2 * k - 1] * np.sin(w * tt) + c[2 * k] * np.cos(w * tt)
        vs += w * (c[2 * k - 1] * np.cos(w * tt) - c[2 * k] * np.sin(w * tt))
    return xs, vs


def _loop_energy(xs, vs, alpha, v_ref, model):
    """Energy per cycle of F_Masing(x)(1 + alpha |x'|/v_ref) along the periodic path (xs, vs),
    from the quasi-static Masing element (two passes; the second is steady)."""
    F = MasingFriction(SakaiCurve(model.n)).force_SI(np.tile(xs, 2), model.F_s_N, model.x_s_m)[xs.size:]
    F = F * (1 + alpha * np.abs(vs) / v_ref)
    return float(np.sum(0.5 * (F[1:] + F[:-1]) * np.diff(xs)))


def _at_amplitude(model, f, X_target):
    """(P, x path) at half peak-to-peak displacement X_target (force by a log-log secant)."""
    force, rig = 2.0, SimulatedRig(model)
    m = model
    for _ in range(8):
        rig.set_generator(freq_Hz=f, amplitude_Vpp=2 * force / m.amp_gain_N_per_V, output_on=True)
        rig.run(int(4 / f * FS), FS)
        b = rig.run(int(round(3 * FS / f)), FS)
        xs, vs = _path(b.disp_V / m.disp_sens_V_per_m, f, n_harm=int(300 / f))
        X = 0.5 * (xs.max() - xs.min())
        if abs(X / X_target - 1) < 0.005:
            break
        force *= (X_target / X) ** 0.7
    assert abs(X / X_target - 1) < 0.005
    P, x = harmonic(b.force_V / m.force_sens_V_per_N, f), harmonic(b.disp_V / m.disp_sens_V_per_m, f)
    return P, x, xs, vs


def test_velocity_dependence_grows_loop_area_with_frequency_at_fixed_amplitude():
    # The drive is a pure sine, so its work per cycle is pi Im(P conj(x)) from the first
    # harmonics alone; it must equal the loop energy of F_Masing (1 + alpha |v| / v_ref).
    alpha, v_ref, X = 0.5, 1e-3, 4e-6
    for a in (0.0, alpha):
        model = RigModel(friction_alpha=a, friction_v_ref_m_per_s=v_ref if a else 0.0, seed=8)
        W = []
        for f in (5.0, 40.0):
            P, x, xs, vs = _at_amplitude(model, f, X)
            W_meas = math.pi * (P * x.conjugate()).imag   # work of the drive per cycle
            assert W_meas == pytest.approx(_loop_energy(xs, vs, a, v_ref, model), rel=0.01), (a, f)
            W.append(W_meas)
        if a:
            assert W[1] > 1.2 * W[0]           # rate dependent: more area at higher speed
        else:
            assert W[1] == pytest.approx(W[0], rel=0.02)   # Masing: rate independent


def test_quadratic_damping_dissipates_as_harmonic_balance_says():
    # first harmonic of c2 v|v| for v = V cos: 8/(3 pi) c2 V^2 in phase with v, so
    # Im(P/x) = c w + 8/(3 pi) c2 w^2 X: the damping grows with the amplitude
    c2, f = 1e5, 10.0
    model = RigModel(**LINEAR, quadratic_damping_N_s2_per_m2=c2, seed=7)
    rig = SimulatedRig(model)
    w = 2 * np.pi * f
    got = []
    for force in (5.0, 60.0):
        P, _, x = measure(rig, f, force, periods=4)
        expect = LINEAR["viscous_N_s_per_m"] * w + 8 / (3 * np.pi) * c2 * w ** 2 * abs(x)
        assert (P / x).imag == pytest.approx(expect, rel=0.03)
        got.append((P / x).imag)
    assert got[1] > 1.3 * got[0]


def test_asymmetric_friction_saturates_at_the_two_levels_the_definition_gives():
    # slow, large strokes through gross rolling, held by a spring: the friction
    # P - m a - k x sits at +F_s (1 + a) moving up and -F_s (1 - a) moving down
    F_s, a, k, f = 5.0, 0.2, 1e5, 2.0
    model = RigModel(F_s_N=F_s, x_s_m=10e-6, n=1.5, mass_kg=10.0, spring_N_per_m=k, friction_asymmetry=a,
                     amp_gain_N_per_V=20.0, seed=3)
    rig = SimulatedRig(model)
    rig.set_generator(freq_Hz=f, amplitude_Vpp=2 * 20.0 / model.amp_gain_N_per_V, output_on=True)
    rig.run(int(FS / f), FS)
    b = rig.run(int(2 * FS / f), FS)
    P = b.force_V / model.force_sens_V_per_N
    acc = b.accel_V / model.accel_sens_V_per_m_s2
    x = b.disp_V / model.disp_sens_V_per_m            # about the spring's origin (the probe reads x)
    F = P - model.mass_kg * acc - k * x
    v = np.gradient(x)
    far = np.abs(x - 0.5 * (x.max() + x.min())) < 0.25 * (x.max() - x.min())   # mid-stroke: gross rolling
    assert np.median(F[far & (v > 0)]) == pytest.approx(F_s * (1 + a), rel=0.03)
    assert np.median(F[far & (v < 0)]) == pytest.approx(-F_s * (1 - a), rel=0.03)
    sym = RigModel(**dict(model.__dict__, friction_asymmetry=0.0))
    assert plant_effects.coefficients(sym) is None or plant_effects.coefficients(sym)[plant_effects.ASYM] == 0.0
    assert plant_effects.coefficients(model)[plant_effects.ASYM] == a
