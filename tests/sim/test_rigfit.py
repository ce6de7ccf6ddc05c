"""Identification with the model of the rig (decision 0042) on data the package did not
make: benchtools/independent_masing.py's 2-DOF pitching column, as UFF58."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.sources import load_source
from sim.discrepancy.rigfit import analysis_effects, identify_steps, rig_effects
from sim.identify import misfit_text

TRUTH = dict(F_s_N=12.0, x_s_m=7e-6, n=1.2, mass_kg=10.0)
PITCH = dict(J=0.3, k_th=3e5, c_th=25.0, h=0.2, e=0.1)
VISCOUS = 60.0
RIG_MODEL = dict(TRUTH, pitch_inertia_kg_m2=PITCH["J"], pitch_stiffness_N_m_per_rad=PITCH["k_th"],
                 pitch_damping_N_m_s_per_rad=PITCH["c_th"], drive_height_m=PITCH["h"], cg_height_m=PITCH["e"],
                 viscous_N_s_per_m=VISCOUS)
GUESS = dict(F_s_N=8.0, x_s_m=10e-6, n=2.0, mass_kg=10.0)


def test_rig_effects_map_the_rig_file_onto_the_models_parameters():
    e = rig_effects(RIG_MODEL)
    assert set(e) == {"second_mode", "viscous_damping"}
    log_f, zeta, a, r = e["second_mode"]
    w_p = math.sqrt(PITCH["k_th"] / PITCH["J"])               # the mode with the carriage held
    assert math.exp(log_f) == pytest.approx(w_p / (2 * math.pi), rel=1e-12)
    assert zeta == pytest.approx(PITCH["c_th"] / (2 * math.sqrt(PITCH["k_th"] * PITCH["J"])), rel=1e-12)
    assert a == pytest.approx(PITCH["h"] ** 2 / PITCH["J"]) and r == pytest.approx(PITCH["e"] / PITCH["h"])
    assert e["viscous_damping"][0] == VISCOUS
    assert rig_effects({"friction_alpha": 0.5, "friction_v_ref_m_per_s": 5e-3})["velocity_dependent_friction"][0] \
        == pytest.approx(100.0)
    assert rig_effects(dict(TRUTH)) == {} and rig_effects(None) == {}
    assert analysis_effects({"causes": [{"id": "second_mode", "kind": "catalog"},
                                        {"id": "line_interference", "kind": "artefact"}]}) == ("second_mode",)


def test_misfit_words_only_beyond_the_noise():
    assert misfit_text(1.05, 2000) == "" and misfit_text(1.9, 50) == ""
    assert "does not fit" in misfit_text(2.83e6, 2000)
    assert "failed" in misfit_text(math.nan, 10)


@pytest.fixture(scope="module")
def pitching_steps(tmp_path_factory):
    from benchtools.independent_masing import generate_uff
    path = tmp_path_factory.mktemp("pitch") / "pitch.uff"
    f_s = math.sqrt(TRUTH["F_s_N"] / (TRUTH["x_s_m"] * TRUTH["mass_kg"])) / (2 * math.pi)   # 66 Hz
    generate_uff(path, **TRUTH, levels_N=[3.0, 7.0, 11.0], freqs_Hz=np.geomspace(0.5 * f_s, 4 * f_s, 7),
                 settle=40, measure=8, seed=3, viscous_N_s_per_m=VISCOUS, pitch=PITCH, noise=(0.002, 0.003, 0.002))
    src = load_source(path)
    assert not src.rejected
    return src.steps


@pytest.mark.timeout(300)
def test_the_rigs_modes_recover_the_truth_the_one_mode_fit_misses(pitching_steps):
    rig = identify_steps(pitching_steps, GUESS, RIG_MODEL)
    assert rig["model"]["effects"] == ["second_mode", "viscous_damping"]
    assert not rig["misfit"], rig["reduced_chi2"]
    for k, t in TRUTH.items():
        assert rig["low"][k] <= t <= rig["high"][k], (k, rig["values"][k], rig["low"][k], rig["high"][k])
    one = identify_steps(pitching_steps, GUESS, None)
    # the one-mode model does not fit, and says so in words
    assert one["misfit"] and "does not fit" in one["warnings"][0]
    assert one["reduced_chi2"] > 10 * rig["reduced_chi2"]
