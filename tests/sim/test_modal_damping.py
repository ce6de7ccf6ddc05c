"""Damping ratios with a name (decision record 0056) against exact facts: a linear
spring-mass FRF (the energy balance at resonance and the half-power bracket hold its zeta)
and a linear two-degree-of-freedom pitching carriage with modal (Rayleigh) damping, whose
drive-point modal mass and modal damping ratios follow from scipy's generalized
eigenproblem, not from the code under test."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import eigh

from sim.modal_damping import StepFRF, energy_balance, energy_balance_zeta, half_power_interval, pitch_modal_mass_kg
from sim.rig import RigModel

M_KG, K_N_M, ZETA = 10.0, 2.0e6, 0.03
F_N = math.sqrt(K_N_M / M_KG) / (2 * math.pi)


def sdof(f):
    w = 2 * np.pi * np.asarray(f, float)
    return 1.0 / (K_N_M - M_KG * w * w + 2j * ZETA * math.sqrt(K_N_M * M_KG) * w)


def test_energy_balance_at_resonance_is_the_linear_modes_zeta():
    assert energy_balance_zeta(F_N, complex(sdof(F_N)), M_KG) == pytest.approx(ZETA, rel=1e-9)
    # a step 0.5 % off the resonance: the interval holds zeta through the frequency offset
    f = F_N * 1.005
    eb = energy_balance([StepFRF("s", F_N * 1.2, complex(sdof(F_N * 1.2))), StepFRF("d", f, complex(sdof(f)), 0.0,
                                                                                     "dwell")],
                        F_N * 1.001, F_N * 0.999, F_N * 1.003, M_KG, "carriage")
    assert eb is not None and eb.step_key == "d" and eb.source == "dwell"     # the dwell is preferred
    assert eb.value != pytest.approx(ZETA, rel=1e-3)                         # off resonance: not zeta itself ...
    assert eb.low <= ZETA <= eb.high                                         # ... but inside its interval
    assert eb.high - eb.low < 0.02 * ZETA


def test_half_power_bracket_holds_the_linear_zeta():
    f = np.geomspace(0.8 * F_N, 1.25 * F_N, 17)
    mag = np.abs(sdof(f))
    peak = float(np.abs(sdof(F_N * math.sqrt(1 - 2 * ZETA ** 2))))
    z, lo, hi = half_power_interval(f, mag, F_N * math.sqrt(1 - 2 * ZETA ** 2), peak)
    assert lo <= ZETA <= hi and lo < z < hi
    assert z == pytest.approx(ZETA, rel=0.1)
    # the band not measured on one side: no value
    assert all(math.isnan(v) for v in half_power_interval(f[f < F_N], mag[f < F_N], F_N, peak))


def pitching_model(**kw) -> RigModel:
    return RigModel(mass_kg=10.0, F_s_N=10.0, x_s_m=1e-5, n=1.5, spring_N_per_m=1.5e6, pitch_inertia_kg_m2=0.02,
                    pitch_stiffness_N_m_per_rad=2.0e4, cg_height_m=0.03, drive_height_m=0.05, **kw)


def test_pitch_modal_mass_and_energy_balance_on_a_linear_two_dof_carriage():
    """The pitching mode's energy balance with the model's drive-point modal mass gives the
    mode's exact modal damping ratio (Rayleigh damping: zeta_r = (alpha / w_r + beta w_r) / 2);
    with the carriage mass it would not."""
    m = pitching_model()
    M = np.array([[m.mass_kg, m.mass_kg * m.cg_height_m], [m.mass_kg * m.cg_height_m, m.pitch_inertia_kg_m2]])
    K = np.diag([m.spring_N_per_m, m.pitch_stiffness_N_m_per_rad])
    w2, phi = eigh(K, M)                           # mass-normalised: phi^T M phi = I
    w = np.sqrt(w2)
    b = np.array([1.0, m.drive_height_m])
    m_drive = 1.0 / (b @ phi[:, 1]) ** 2           # the upper (pitching) mode's drive-point modal mass
    f_p = w[1] / (2 * math.pi)
    got, note = pitch_modal_mass_kg(m, f_p)
    assert got == pytest.approx(m_drive, rel=1e-6) and "modal mass" in note
    assert abs(got / m.mass_kg - 1) > 0.5          # not the carriage's mass
    beta = 2 * 0.02 / w[1]                          # stiffness-proportional: zeta_pitch = 2 %
    C = beta * K
    zeta_p = beta * w[1] / 2

    def H(f):
        ww = 2 * math.pi * f
        return b @ np.linalg.solve(K - ww * ww * M + 1j * ww * C, b)
    z = energy_balance_zeta(f_p, complex(H(f_p)), got)
    assert z == pytest.approx(zeta_p, rel=0.03)    # the feed mode's tail is the rest
    assert energy_balance_zeta(f_p, complex(H(f_p)), m.mass_kg) != pytest.approx(zeta_p, rel=0.5)
    # friction stiffens the feed direction: a measured pitch resonance above the friction-free one
    # takes the k_x that puts the model's upper mode there
    got_hi, note_hi = pitch_modal_mass_kg(m, 1.05 * f_p)
    assert math.isfinite(got_hi) and "measured frequency" in note_hi
    assert math.isnan(pitch_modal_mass_kg(RigModel(mass_kg=10.0), f_p)[0])
