"""The analysis names an effect hidden in plant data, and only then (issue 9).

Each case is a seeded random rig (F_s 2-40 N, x_s 2-100 um, n 0.35-3, m 2-40 kg) measured
through the RK4 plant (sim.rig.SimulatedRig) on the issue's grid (5 levels 0.1-0.85 F_s,
18 frequencies 0.3-3 f_res; here 3 x 10, ``GRID``) with the issue's noise; the effect strength is drawn above the
required sensitivity.  The starting guess is the truth times 0.7-1.3, as a technician's.
"""

import numpy as np
import pytest

from sim.discrepancy import CATALOG, analyze_steps
from sim.discrepancy.cases import make_case, truth_size

# one seed per cause (the seeds only fix the random rig and strength; n below 1 and above 1)
SEEDS = {"viscous_damping": 5, "linear_spring": 6, "sensor_delay": 7, "sensor_gain_error": 8,
         "second_mode": 21, "velocity_dependent_friction": 22}
# 3 levels x 10 frequencies: each cause named alone with its size covered, 3.2-8.5 s of CPU a
# case (clean 3.7-3.8, two causes 4.0, the cubic 7.9, n < 1 19.7) against 24-53 s on the
# issue's 5 x 18 grid (decision 0062)
GRID = dict(levels=3, freqs=10)
# `make test` keeps four causes (viscous damping, linear spring, gain error, speed-dependent
# friction; the two-cause case names two of them again); the sensor delay and the second mode
# are named alone here by `make bench` (marker campaign), in `make test` on the independent
# simulator's data (tests/sim/test_independent_cases.py, tests/sim/test_second_mode_alone.py;
# decision 0083)
CAMPAIGN = {"second_mode", "sensor_delay"}


def analyse(case, seed):
    rng = np.random.default_rng(seed + 100)
    guess = {k: v * rng.uniform(0.7, 1.3) for k, v in case.rig.items()}
    return analyze_steps(case.steps, guess)


@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.parametrize("effect", [pytest.param(e, marks=pytest.mark.campaign) if e in CAMPAIGN else e
                                    for e in CATALOG])
def test_each_hidden_cause_is_named_with_its_size(effect):
    case = make_case(SEEDS[effect], (effect,), **GRID)
    a = analyse(case, SEEDS[effect])
    assert a.causes[:1] == [effect] and not a.unexplained, a.verdict()
    d = a.to_dict()
    # a catalog effect is not mistaken for (or padded with) a discovered term
    assert all(c["kind"] == "catalog" for c in d["causes"]), [c["id"] for c in d["causes"]]
    name, truth = truth_size(case, effect)
    if name:
        p = d["causes"][0]["parameters"][name]
        # the 95 % interval covers the plant's value, or the estimate is within 2 % of it
        assert p["low"] <= truth <= p["high"] or p["value"] == pytest.approx(truth, rel=0.02), (p, truth)
    assert d["causes"][0]["gain"]["heldout_error_after"] < d["causes"][0]["gain"]["heldout_error_before"]
    if effect == "second_mode":         # issue 33: a pitching mode alone, no other physical cause beside it
        assert [c["id"] for c in d["causes"]] == ["second_mode"], d["verdict"]
    if effect == "viscous_damping":     # the cause alone, its size, its gain and the verdict's words
        assert [c["id"] for c in d["causes"]] == ["viscous_damping"]
        c = d["causes"][0]
        assert c["parameters"]["c"]["value"] == pytest.approx(truth, rel=0.02)
        assert c["gain"]["heldout_error_after"] < 0.5 * c["gain"]["heldout_error_before"]
        assert c["gain"]["delta_bic"] < -10
        assert "viscous damping c =" in d["verdict"] and "N s/m" in d["verdict"]


@pytest.mark.timeout(300)
# n = 2.5 and 2.8; the second in `make bench` (decision 0083)
@pytest.mark.parametrize("seed", [2, pytest.param(4, marks=pytest.mark.campaign)])
def test_clean_data_gets_no_cause(seed):
    case = make_case(seed, (), **GRID)
    a = analyse(case, seed)
    d = a.to_dict()
    assert d["causes"] == [] and not d["unexplained"], d["verdict"]
    assert 0.5 < d["base"]["reduced_chi2"] < 2.0
    for k, truth in (("F_s_N", case.rig["F_s_N"]), ("x_s_m", case.rig["x_s_m"]), ("mass_kg", case.rig["mass_kg"])):
        assert d["parameters"][k]["value"] == pytest.approx(truth, rel=0.01)
    assert "within the noise" in d["verdict"]


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_clean_data_with_n_below_one_gets_no_cause():
    case = make_case(3, (), levels=3, freqs=6)      # n = 0.58; 12 s of CPU (3 x 10: 20 s)
    assert case.rig["n"] < 1
    d = analyse(case, 3).to_dict()
    # the friction along x rebuilt from every harmonic (decision 0015): the sharp reversals
    # of n < 1 leave no structure the noise does not account for (rebuilt from 9: reduced
    # chi-square 119 and "unexplained" on these steps, decision 0062)
    assert d["causes"] == [] and not d["unexplained"], d["verdict"]
    assert 0.5 < d["base"]["reduced_chi2"] < 2.0


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_two_hidden_effects_are_both_named():
    case = make_case(31, ("viscous_damping", "sensor_gain_error"), **GRID)
    a = analyse(case, 31)
    assert sorted(a.causes) == ["sensor_gain_error", "viscous_damping"], a.verdict()
    assert not a.unexplained
    # a rival must beat Masing with its causes, not the bare Masing fit (decision 0078)
    assert a.friction_model == "masing", a.verdict()


@pytest.mark.slow
@pytest.mark.campaign    # in `make test` the cubic of tests/sim/test_discover.py (plant seed 7, decision 0083)
@pytest.mark.timeout(300)
def test_an_effect_outside_the_catalog_is_named_by_its_form_not_by_catalog_effects():
    # issue 16: this case used to come out as "linear spring + viscous damping", F_s -12 %
    case = make_case(41, ("cubic_spring",), **GRID)
    d = analyse(case, 41).to_dict()
    # the cubic first and no catalog effect (the carriage walked 4 um off centre in one step,
    # which can leave a small even term as well)
    assert d["causes"][0]["id"] == "cubic_stiffness", d["verdict"]
    assert all(c["kind"] == "discovered" for c in d["causes"]), d["verdict"]
    k3, truth = d["causes"][0]["parameters"]["k3"], case.effects["cubic_spring"]["cubic_spring_N_per_m3"]
    assert k3["low"] <= truth <= k3["high"] or k3["value"] == pytest.approx(truth, rel=0.01), k3
    assert d["parameters"]["F_s_N"]["value"] == pytest.approx(case.rig["F_s_N"], rel=0.02)


def test_one_force_level_is_refused_with_a_reason():
    case = make_case(2, (), levels=2, freqs=4)
    with pytest.raises(ValueError, match="two force levels"):
        analyze_steps([s for s in case.steps if s.key.startswith("L00")], None)


def _reparametrised(F_s, x_s, n, k):
    """F_s', x_s' of the Masing curve f1 = A x^n + (B + k) x (seed Eqs. 4-5 inverted)."""
    A, B = F_s / ((1 - n) * x_s ** n), -n * F_s / ((1 - n) * x_s) + k
    x_s2 = (-B / (n * A)) ** (1 / (n - 1))
    return A * (1 - n) * x_s2 ** n, x_s2


@pytest.mark.parametrize("n", [0.4, 2.2])
def test_a_spring_in_pre_rolling_is_exactly_a_masing_curve_with_other_parameters(n):
    # f1 = A x^n + B x: a spring k in parallel makes B + k, and the Masing rule holds for the
    # sum branch by branch, so along any path that stays below x_s the two loops coincide
    from sim.identify import path_friction
    F_s, x_s, k = 10.0, 20e-6, 0.1 * 10.0 / 20e-6
    t = np.linspace(0, 2 * np.pi, 512, endpoint=False)
    path = 0.7 * x_s * (np.cos(t) + 0.2 * np.cos(3 * t + 0.4)) / 1.2
    path = path[np.argmax(path):].tolist() + path[:np.argmax(path)].tolist()
    path = np.array([path])
    F_s2, x_s2 = _reparametrised(F_s, x_s, n, k)
    with_spring = F_s * path_friction(path, x_s, n) + k * path
    masing = F_s2 * path_friction(path, x_s2, n)
    assert np.max(np.abs(with_spring - masing)) < 1e-9 * F_s
    beyond = path * 2.2                                   # into rolling: they part
    assert np.max(np.abs(F_s * path_friction(beyond, x_s, n) + k * beyond
                         - F_s2 * path_friction(beyond, x_s2, n))) > 0.01 * F_s


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_spring_the_data_cannot_separate_is_not_named_and_the_verdict_says_why():
    # n = 0.38, every step below x_s; 3 levels x 3 frequencies: the inseparability does not
    # depend on the grid, and n < 0.5 needs the plant's raised resolution (the cost is there:
    # 17.6 s of plant for 0.2 s of analysis; 3 x 4 took 27 s, 3 x 10 59 s, with the same
    # verdict; here F_s, x_s 3.8e-4 and 1.3e-3 from the stiffer curve's, largest amplitude
    # 0.55 x_s; 2 x 4 leaves "unexplained", decisions 0062, 0083)
    case = make_case(1044, ("linear_spring",), levels=3, freqs=3)
    assert case.rig["n"] < 1
    a = analyse(case, 44)
    d = a.to_dict()
    assert d["causes"] == [] and not d["unexplained"], d["verdict"]
    F_s2, x_s2 = _reparametrised(case.rig["F_s_N"], case.rig["x_s_m"], case.rig["n"],
                                 case.effects["linear_spring"]["spring_N_per_m"])
    assert d["parameters"]["F_s_N"]["value"] == pytest.approx(F_s2, rel=0.01)
    assert d["parameters"]["x_s_m"]["value"] == pytest.approx(x_s2, rel=0.02)
    assert d["base"]["diagnostics"]["spring_separable"] is False
    assert d["base"]["diagnostics"]["largest_amplitude_over_x_s"] < 1
    assert "cannot be told from a stiffer Masing curve" in d["verdict"]
