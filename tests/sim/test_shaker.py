"""The electrodynamic shaker of the simulated rig (decision 0025) against circuit theory.

Independent fact: for a linear structure (mass, spring, dashpot; the Masing friction made
negligible) the coupled shaker is a linear network.  With phasors at w,

    (R + j w L) i + Bl v = e                          (coil: voltage amplifier output e)
    Bl i = (Z_a + Z_s) v                              (armature + structure at the drive point)
    P = Z_s v                                         (impedance head)

Z_a = j w m_a + c_a + k_a / (j w), Z_s = j w m + c + k / (j w); e = G_a V with the
amplifier gain G_a = amp_gain_N_per_V R / Bl.  Solved here as a 2x2 complex system.
The force drops out where |Z_s| is smallest, the structure's own resonance sqrt(k / m),
not the coupled one sqrt((k + k_a) / (m + m_a)).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from procedures.analysis import fit_harmonics
from sim.rig import RigModel, SimulatedRig

SHAKER = dict(shaker_force_constant_N_per_A=15.0, shaker_resistance_ohm=1.5, shaker_inductance_H=0.2e-3,
              shaker_armature_mass_kg=0.3, shaker_suspension_N_per_m=1e5, shaker_damping_N_s_per_m=20.0)
M, K, C = 10.0, 4e5, 50.0            # the structure: f_n = sqrt(K / M) / 2 pi = 31.83 Hz
LINEAR = dict(F_s_N=1e-3, x_s_m=1e-9, mass_kg=M, spring_N_per_m=K, viscous_N_s_per_m=C,
              force_noise_N=0.0, accel_noise_m_s2=0.0, disp_noise_m=0.0, **SHAKER)


def force_per_volt_theory(f):
    w = 2 * math.pi * f
    R, L, Bl = SHAKER["shaker_resistance_ohm"], SHAKER["shaker_inductance_H"], SHAKER["shaker_force_constant_N_per_A"]
    Za = 1j * w * SHAKER["shaker_armature_mass_kg"] + SHAKER["shaker_damping_N_s_per_m"] + SHAKER["shaker_suspension_N_per_m"] / (1j * w)
    Zs = 1j * w * M + C + K / (1j * w)
    e = RigModel().amp_gain_N_per_V * R / Bl            # amplifier output per generator volt
    i, v = np.linalg.solve(np.array([[R + 1j * w * L, Bl], [Bl, -(Za + Zs)]]), np.array([e, 0.0]))
    return Zs * v


def force_per_volt_simulated(f, model=LINEAR, volts=0.5):
    rig = SimulatedRig(RigModel(**model))
    rig.set_generator(freq_Hz=f, amplitude_Vpp=2 * volts, output_on=True)
    fs = 128 * f
    rig.run(int(128 * max(40, 1.2 * f)), fs)               # > 1 s: the coupled modes decay
    b = rig.run(128 * 10, fs)
    fit = fit_harmonics(b.force_V / rig.model.force_sens_V_per_N, fs, f, 1)
    return fit.amplitude[0] / volts


@pytest.mark.parametrize("f", [12.0, 30.0, 31.83, 34.0, 150.0, 900.0])
def test_force_per_volt_is_the_coupled_networks(f):
    assert force_per_volt_simulated(f) == pytest.approx(abs(force_per_volt_theory(f)), rel=5e-3)


def test_the_force_drops_out_at_the_structures_own_resonance():
    f_own, f_coupled = math.sqrt(K / M) / (2 * math.pi), math.sqrt((K + 1e5) / (M + 0.3)) / (2 * math.pi)
    freqs = f_own * np.array([0.94, 0.97, 1.0, 1.03, 1.06])
    gains = [force_per_volt_simulated(f) for f in freqs]
    assert int(np.argmin(gains)) == 2
    assert f_coupled / f_own - 1 > 0.06                    # the grid tells the two apart
    assert gains[2] < 0.3 * RigModel().amp_gain_N_per_V    # a deep drop-out


def test_shaker_off_is_the_ideal_force_source():
    model = {k: v for k, v in LINEAR.items() if not k.startswith("shaker_")}
    assert force_per_volt_simulated(31.83, model) == pytest.approx(RigModel().amp_gain_N_per_V, rel=1e-6)


def test_a_shaker_without_resistance_is_refused_by_name():
    with pytest.raises(ValueError, match="shaker_resistance_ohm must be > 0 when the shaker model is on"):
        RigModel(shaker_force_constant_N_per_A=10.0)


def test_the_closed_form_for_bench_twin_is_the_network():
    """plant_effects.shaker_frf (the formula decision 0025 gives for fitting a source's
    force per volt) against the 2x2 network solve."""
    from sim import plant_effects
    model = RigModel(**LINEAR)
    for f in (5.0, 31.83, 77.0, 1000.0):
        w = 2 * math.pi * f
        got = plant_effects.shaker_frf(model, f, 1j * w * M + C + K / (1j * w))
        assert got == pytest.approx(force_per_volt_theory(f), rel=1e-12)
