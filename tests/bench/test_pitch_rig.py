"""The demo rig with the pitching mode and velocity-dependent friction, end to end through the
twins: a short stepped-sine run, then the stored accelerance must show the extra
resonance / anti-resonance pair where the linearised 2-DOF plant puts it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.config import DEFAULTS, load_rig, parse_plan
from bench.session import run_plan
from sim.rig import RigModel

FREQS_HZ = [100.0, 140.0, 160.0, 170.0, 175.0, 180.0, 185.0, 190.0, 195.0, 200.0, 205.0,
            210.0, 220.0, 250.0, 320.0]


def two_dof(model: RigModel, k_feed: float) -> tuple[float, float]:
    """(anti-resonance, pitch resonance) in Hz of the undamped linear plant with feed
    stiffness ``k_feed``: the zero of b^T adj(K - w^2 M) b and the upper eigenvalue."""
    m, e, J, h = model.mass_kg, model.cg_height_m, model.pitch_inertia_kg_m2, model.drive_height_m
    M = np.array([[m, m * e], [m * e, J]])
    K = np.diag([k_feed, model.pitch_stiffness_N_m_per_rad])
    w2 = np.linalg.eigvals(np.linalg.solve(M, K)).real.max()
    w2_anti = (model.pitch_stiffness_N_m_per_rad + h * h * k_feed) / (J - 2 * h * m * e + h * h * m)
    return math.sqrt(w2_anti) / (2 * math.pi), math.sqrt(w2) / (2 * math.pi)


@pytest.fixture(scope="module")
def pitch_run(tmp_path_factory):
    plan = parse_plan({"plan": {"name": "pitch pair", "levels_N": [1.0],
                                "frequencies": {"list_Hz": FREQS_HZ, "direction": "up"}}})
    rig = load_rig(DEFAULTS / "sim_rig_pitch.toml")
    store = run_plan(plan, rig, tmp_path_factory.mktemp("pitch") / "run", identify=False)
    assert store.metadata["status"] == "completed"
    return rig.model, sorted(store.results(), key=lambda r: r["freq_Hz"])


def test_the_stored_accelerance_has_the_pitch_pair_where_2dof_theory_puts_it(pitch_run):
    model, results = pitch_run
    f = np.array([r["freq_Hz"] for r in results])
    acc = np.array([r["accelerance_abs_kg_inv"] for r in results])
    # the friction's tangent stiffness at these sub-micrometre amplitudes lies between its
    # secant F_s/x_s and its initial stiffness n/(n-1) F_s/x_s
    K_s = model.F_s_N / model.x_s_m
    lo, hi = two_dof(model, K_s), two_dof(model, model.n / (model.n - 1) * K_s)
    i_min, i_max = int(np.argmin(acc)), int(np.argmax(acc))
    assert 0.95 * lo[0] <= f[i_min] <= 1.05 * hi[0]          # anti-resonance
    assert 0.95 * lo[1] <= f[i_max] <= 1.05 * hi[1]          # pitch resonance above it
    assert f[i_min] < f[i_max]
    mass_line = 1.0 / model.mass_kg
    assert acc[i_min] < 0.3 * mass_line < 3 * mass_line < acc[i_max]


def test_the_probe_does_not_see_the_pitch_but_the_accelerometer_does(pitch_run):
    # the eddy-current probe reads the feed x, the accelerometer x'' + h th'': their ratio
    # |a| / (w^2 |x|) leaves 1 near the pitch pair (a rigid carriage would keep it at 1)
    _, results = pitch_run
    ratio = {r["freq_Hz"]: r["accelerance_abs_kg_inv"]
             / ((2 * math.pi * r["freq_Hz"]) ** 2 * r["compliance_abs_m_per_N"]) for r in results}
    assert ratio[100.0] == pytest.approx(1.0, abs=0.25)
    assert min(ratio.values()) < 0.3 and max(ratio.values()) > 3.0


def test_the_analysis_finds_the_pair_the_2dof_theory_puts_in_the_measured_accelerance(pitch_run):
    """Issue 19: the analysis said "second (pitching) mode at 159.15 Hz", sqrt(k_th/J), a
    model-internal number; the technician sees the dip and the peak of the accelerance."""
    from sim.discrepancy.terms import accelerance_pair, second_mode_phrase
    model, results = pitch_run
    f = np.array([r["freq_Hz"] for r in results])
    acc = np.array([r["accelerance_abs_kg_inv"] for r in results])
    K_s = model.F_s_N / model.x_s_m
    lo, hi = two_dof(model, K_s), two_dof(model, model.n / (model.n - 1) * K_s)
    anti, res = accelerance_pair(f, acc, np.zeros(f.size), (80.0, 640.0))
    assert 0.95 * lo[0] <= anti.freq_Hz <= 1.05 * hi[0]
    assert 0.95 * lo[1] <= res.freq_Hz <= 1.05 * hi[1]
    f_p = math.sqrt(model.pitch_stiffness_N_m_per_rad / model.pitch_inertia_kg_m2) / (2 * math.pi)
    assert f_p < 0.95 * lo[0]                       # sqrt(k_th/J) is neither of them
    for e in (anti, res):
        assert e.low_Hz < e.freq_Hz < e.high_Hz and e.levels == 1
    p = {"frequency": dict(value=f_p, low=f_p - 0.3, high=f_p + 0.3), "damping_ratio": dict(value=0.02, low=0.015,
         high=0.025), "coupling": dict(value=1.33, low=1.2, high=1.5),
         "anti_resonance_Hz": dict(value=anti.freq_Hz, low=anti.low_Hz, high=anti.high_Hz),
         "resonance_Hz": dict(value=res.freq_Hz, low=res.low_Hz, high=res.high_Hz)}
    text = second_mode_phrase(p)
    assert f"an anti-resonance at {anti.text()} and a resonance at {res.text()}" in text, text
    assert f"(grid points {anti.low_Hz:.3g} to {anti.high_Hz:.3g} Hz)" in text
    assert text.index("anti-resonance") < text.index("sqrt(k_th/J)/2 pi = 159.2 Hz (95 %: 158.9 to 159.5 Hz)")


def test_speed_dependent_friction_is_stated_at_the_rig_files_v_ref():
    """Only alpha/v_ref is identifiable: at the rig file's 5 mm/s the pitch rig's
    alpha = 0.5 must read as 50 %, whatever speed the fit used inside."""
    from sim.discrepancy.terms import speed_friction, speed_friction_phrase
    beta = (0.5 / 5e-3, 0.46 / 5e-3, 0.54 / 5e-3)          # alpha/v_ref in s/m, with its interval
    at_rig = dict(alpha=speed_friction(beta, 5e-3), v_ref=dict(value=5e-3, source="rig"))
    assert "50 % (95 %: 46 to 54 %) higher at v_ref = 5 mm/s (the rig file's friction_v_ref_m_per_s" \
        in speed_friction_phrase(at_rig)
    chosen = dict(alpha=speed_friction(beta, 2e-3), v_ref=dict(value=2e-3, source="friction resonance"))
    text = speed_friction_phrase(chosen)
    assert "20.0 % (95 %: 18.4 to 21.6 %) higher at v_ref = 2 mm/s (chosen here" in text, text
