"""A mode the rig does not have is never reported (issue 32 item 1, decision record 0056):
on synthetic FRF points of a linear two-degree-of-freedom carriage (sim.rig's pitching
plant, its modes from scipy's eigenproblem) and of a one-mode carriage whose accelerometer
has a gain bump (a maximum with no phase turn)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import eigh

from bench.reports._modes import modes_of

M, E, J, H = 10.0, 0.1, 0.3, 0.2          # the pitching rig file's carriage (bench/defaults/sim_rig_pitch.toml)
KX, KTH = 2.0e6, 3.0e5
F = np.geomspace(30.0, 300.0, 41)


def two_dof():
    Mm = np.array([[M, M * E], [M * E, J]])
    K = np.diag([KX, KTH])
    C = 4e-5 * K + 60.0 * Mm                # Rayleigh damping: 7.8 % (feed), 4.9 % (pitch)
    b = np.array([1.0, H])
    X, A = [], []
    for f in F:
        w = 2 * math.pi * f
        q = np.linalg.solve(K - w * w * Mm + 1j * w * C, b)
        X.append(q[0])
        A.append(-w * w * (b @ q))
    w2 = eigh(K, Mm, eigvals_only=True)
    return np.array(X), np.array(A), np.sqrt(w2) / (2 * math.pi)


def results(X, A):
    return [dict(key=f"{i:05d}-L00-F{i:03d}-up", index=i, level_index=0, freq_index=i, direction="up",
                 target_force_N=1.0, freq_Hz=float(f), compliance_m_per_N={"re": x.real, "im": x.imag},
                 compliance_pp_m_per_N=abs(x), accelerance_abs_kg_inv=abs(a), accelerance_phase_rad=float(np.angle(a)))
            for i, (f, x, a) in enumerate(zip(F, X, A))]


def meta(model):
    return {"plan": {"levels_N": [1.0]}, "rig": {"simulated": bool(model), "model": model, "expected_mass_kg": M}}


def pitch_rows(X, A, model):
    return [e for e in modes_of(Path("synthetic"), meta(model), results(X, A), None).modes if e.mode == "pitch"]


def test_a_real_pitching_mode_earns_its_place_without_a_model():
    X, A, f_modes = two_dof()
    (p,) = pitch_rows(X, A, {})
    assert p.ok and p.resonance_Hz == pytest.approx(f_modes[1], rel=0.02)
    turn_a, turn_x = p.extra["phase_turn_deg"]
    assert turn_a > 30 and turn_x > 10


def test_no_pitch_rows_for_a_model_without_a_pitching_mode():
    X, A, _ = two_dof()
    plain = {"F_s_N": 10.0, "x_s_m": 1e-5, "n": 1.5, "mass_kg": M, "amp_gain_N_per_V": 20.0}
    assert pitch_rows(X, A, plain) == []


def test_an_accelerometer_bump_without_a_phase_turn_is_not_a_mode():
    w = 2 * np.pi * F
    X = 1 / (KX - M * w * w + 2j * 0.15 * math.sqrt(KX * M) * w)          # one mode only
    bump = 1 + 0.5 * np.exp(-0.5 * (np.log(F / 200.0) / 0.05) ** 2)       # a gain ripple at 200 Hz, real
    A = -w * w * X * bump
    assert pitch_rows(X, A, {}) == []
