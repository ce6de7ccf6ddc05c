"""Issue 41 items 3 and 4: which friction model the data prefer (decision 0078), on data
this project did not make (benchtools/friction_cases.py: the independent simulators of
benchtools/independent_friction.py and independent_masing.py, the rig's noise, levels up
to 1.5 times the friction level, gross sliding included).

A small seeded grid per case (3 levels x 5 frequencies, the Iwan and GMS cases 5 x 3: their elements need
the levels closer together; the top level always in); the campaign over the full 90-step grids is
benchmarks/bench_model_choice.py.

- a rival model's data: its family is named (``friction_model``), and its held-out error
  is within twice the noise's, measured as the Masing control's held-out error on its own
  data of the same grid and noise;
- Masing data of both virgin-curve exponents the project knows (n = 1.5 and n = 0.5)
  keep ``masing``;
- every model of sim.friction is in the table, the fitted ones with their parameters'
  95 % intervals, held-out errors, reduced chi-square and BIC.
"""

import pytest

from benchtools import friction_cases as fc

GRID = fc.small_grid(seed=3, n_levels=3, n_freqs=5)
# the elements' model is non-parametric: a held-out level is predicted from the elements
# whose slip lies between the levels kept, so it needs the levels closer together
GRID_IWAN = fc.small_grid(seed=3, n_levels=5, n_freqs=3)


@pytest.fixture(scope="module")
def analyses(tmp_path_factory):
    from bench.sources import load_source
    from sim.discrepancy import analyze_steps

    out = {}
    tmp = tmp_path_factory.mktemp("cases")
    for name in ("masing_n15", "masing_n05", "dahl_i05", "dahl_i2", "masing_iwan", "lugre", "gms"):
        levels, freqs = GRID_IWAN if name in ("masing_iwan", "gms") else GRID
        path, truth = fc.write_case(name, tmp, levels=levels, freqs=freqs, settle=15, measure=6, seed=5)
        out[name] = analyze_steps(load_source(path).steps)
    return out


@pytest.fixture(scope="module")
def analysed(analyses):
    return {name: a.to_dict() for name, a in analyses.items()}


def noise_heldout(analysed):
    return analysed["masing_n15"]["friction_models"]["table"][0]["heldout_error"]


@pytest.mark.parametrize("case,family", [("dahl_i05", "dahl"), ("dahl_i2", "dahl"), ("masing_iwan", "masing_iwan"),
                                         ("lugre", "lugre"), ("gms", "gms")])
def test_a_rival_models_data_name_its_family_with_a_heldout_error_within_twice_the_noise(analysed, case, family):
    d = analysed[case]
    assert d["friction_model"] == family, d["verdict"]
    row = next(r for r in d["friction_models"]["table"] if r["model"] == family)
    assert row["heldout_error"] <= 2 * noise_heldout(analysed), (row["heldout_error"], noise_heldout(analysed))
    assert "The hysteresis is not Masing" in d["verdict"]


@pytest.mark.parametrize("case", ["masing_n15", "masing_n05"])
def test_masing_data_keep_masing(analysed, case):
    d = analysed[case]
    assert d["friction_model"] == "masing", d["verdict"]
    assert not d["friction_models"]["passed_against_masing_with_causes"]


def test_the_table_has_every_model_with_intervals_heldout_errors_chi2_and_bic(analysed):
    from sim.friction import MODELS

    table = analysed["dahl_i2"]["friction_models"]["table"]
    assert [r["model"] for r in table] == list(MODELS)
    dahl = next(r for r in table if r["model"] == "dahl")
    for name, truth in fc.CASES["dahl_i2"].params.items():
        p = dahl["parameters"][name]
        assert p["low"] <= truth <= p["high"], (name, p, truth)
    for r in table:
        if r["fitted"]:
            assert {"heldout_error_compliance", "heldout_error_accelerance", "reduced_chi2", "bic"} <= set(r)


@pytest.mark.parametrize("case", ["lugre", "gms"])
def test_a_rate_dependent_rivals_row_has_its_own_parameters_with_intervals(analysed, case):
    from sim.friction import MODELS

    row = next(r for r in analysed[case]["friction_models"]["table"] if r["model"] == case)
    names = [p.name for p in MODELS[case].parameters]
    assert set(names) <= set(row["parameters"]), (names, list(row["parameters"]))
    truth = fc.CASES[case].params
    for name in names:
        p = row["parameters"][name]
        for q in (p if isinstance(p, list) else [p]):
            assert q["low"] <= q["value"] <= q["high"] and q["high"] > q["low"], (name, q)
        if not isinstance(p, list):      # the scalars against the independent simulator's truth (10 %)
            assert p["value"] == pytest.approx(truth[name], rel=0.1, abs=1.0 if "sigma" in name else 0.0), (name, p)
    # (not asserted here: the truth inside each 95 % interval.  At this seed LuGre's F_c and
    # sigma_2 are -2.8 and +3.0 standard errors off, one of the 5 and 7 seeds in 100 on this
    # grid whose F_c and sigma_2 miss (decision 0089); coverage is a campaign's, below)


def test_the_gms_unit_elements_sum_to_the_models_own_periodic_force():
    # rate_rivals writes gms_advance's update per unit element (the projection needs each
    # element's force); sum f_i u_i + sigma_2 v must be the model's own steady force
    import numpy as np

    from sim.discrepancy import gms_rival
    from sim.discrepancy import rate_rivals as rr
    from sim.friction import MODELS
    from sim.identify import path_harmonics, period_paths

    p = fc.CASES["gms"].params
    w = 2 * np.pi * np.array([20.0, 42.0, 90.0, 42.0])
    X = np.zeros((4, 3), complex)
    X[:, 0] = [2e-6, 8e-6, 25e-6, 60e-6]
    X[:, 2] = 0.1j * X[:, 0]
    paths, starts = period_paths(X, rr.M_RATE)
    vel = rr.path_velocity(paths, w)
    s = rr._Setup(None, None, paths, starts, vel, None, None, None, 0.5 * np.ptp(paths, axis=1))
    s.d = type("D", (), dict(omega=w, X=X))()
    slips = np.array([a * p["F_c_N"] / k for a, k in zip(p["alpha"], p["k_N_per_m"])])
    rows = np.arange(4)
    H = gms_rival.gms_units(s, slips, p["F_s_N"] / p["F_c_N"], p["v_s_m_per_s"], p["delta"], p["C_N_per_s"] / p["F_c_N"], rows)
    G = H @ (np.array(p["alpha"]) * p["F_c_N"]) + p["sigma2_N_s_per_m"] * path_harmonics(vel, starts, 3)
    G_model = path_harmonics(MODELS["gms"].periodic_force(p, paths, w), starts, 3)
    assert np.abs(G - G_model).max() < 1e-6 * np.abs(G_model).max()


def _fit(name, chi2, p, held, n_data=3000):
    from sim.discrepancy.rivals import ModelFit
    return ModelFit(name, chi2=chi2, n_data=n_data, n_params=p, heldout=held)


def test_a_rival_that_beats_bare_masing_but_not_masing_with_its_causes_is_not_preferred():
    # the lost first attempt's failure (decision 0078): on Masing + damping + a gain error
    # bare Dahl beat bare Masing; Masing with the two causes fits to the noise
    from sim.discrepancy.rivals import ModelFit, choose

    fits = {"masing": _fit("masing", 9e5, 4, 0.30), "masing_iwan": ModelFit("masing_iwan", fitted=False),
            "dahl": _fit("dahl", 3e5, 4, 0.10), "lugre": ModelFit("lugre", fitted=False),
            "gms": ModelFit("gms", fitted=False)}
    c = choose(fits, final_chi2=3000.0, final_params=6, final_dof=2994, final_heldout=0.003)
    assert c.passed_bare == ["dahl"] and c.passed_final == [] and c.name == "masing"
    # the same rival against a Masing whose causes leave the misfit: preferred
    c = choose(fits, final_chi2=8e5, final_params=6, final_dof=2994, final_heldout=0.25)
    assert c.name == "dahl" and c.gain == (0.30, 0.10)


def test_models_within_the_gates_of_the_preferred_one_are_said_not_separable_with_the_measurement():
    from sim.discrepancy.rivals import SEPARATING, ModelFit, choose

    fits = {"masing": _fit("masing", 9e5, 4, 0.30), "masing_iwan": _fit("masing_iwan", 2999.0, 5, 0.0031),
            "dahl": _fit("dahl", 3000.0, 4, 0.003), "lugre": ModelFit("lugre", fitted=False),
            "gms": ModelFit("gms", fitted=False)}
    c = choose(fits, final_chi2=8e5, final_params=6, final_dof=2994, final_heldout=0.25)
    assert c.name == "dahl"
    assert c.not_separable == [("masing_iwan", SEPARATING[frozenset(("dahl", "masing_iwan"))])]
    fits["masing_iwan"] = _fit("masing_iwan", 3500.0, 5, 0.0031)       # BIC worse by about 500: separable
    assert choose(fits, 8e5, 6, 2994, 0.25).not_separable == []


def test_the_report_and_the_page_show_the_table_with_the_preferred_model_marked(analysed):
    from bench.reports._analysis import analysis_data, friction_rows
    from bench.reports._html import _friction

    a = analysis_data(analysed["dahl_i2"])
    rows = friction_rows(a)
    assert [r[0].endswith("- preferred") for r in rows] == [False, False, True, False, False]
    assert rows[2][1].startswith("F_c_N = ") and rows[3][1].startswith("sigma0_N_per_m = ")
    assert "k_N_per_m: " in rows[4][1]
    assert "Friction models" in _friction(a) and "<code>dahl</code>" in _friction(a)


@pytest.mark.parametrize("case", ["lugre", "gms", "masing_iwan"])
def test_a_preferred_model_that_leaves_structure_is_named_as_what_does_not_explain_it(analyses, case):
    # the catalog is not searched on top of LuGre, GMS or the elements: the misfit the verdict
    # names is the preferred model's own, not the Masing base's residuals
    import dataclasses

    a = analyses[case]
    assert a.friction.name == case and not a.unexplained, a.verdict()
    fits = dict(a.friction.fits)
    fits[case] = dataclasses.replace(fits[case], chi2=40.0 * fits[case].n_data)
    a = dataclasses.replace(a, friction=dataclasses.replace(a.friction, fits=fits))
    assert a.unexplained
    from sim.friction import MODELS
    verdict = a.verdict()
    assert f"Structure remains that the {MODELS[case].label} model does not explain: its reduced chi-square is 4" in verdict, verdict
    assert "Masing model does not explain" not in verdict, verdict


# ---------------------------------------------------------------- LuGre's 95 % intervals (decision 0089)
LUGRE_SCALARS = ("sigma0_N_per_m", "sigma1_N_s_per_m", "sigma2_N_s_per_m", "F_c_N", "F_s_N", "v_s_m_per_s")


def _lugre_inputs(tmp, seed):
    """The LuGre case on the test grid as the analysis gives it to the rivals: (Data, the base
    fit's weights, Dahl's F_c and sigma, the truth with the mass)."""
    from bench.sources import load_source
    from sim.discrepancy import rivals
    from sim.discrepancy.analysis import base_fit, data_from_steps

    path, truth = fc.write_case("lugre", tmp, levels=GRID[0], freqs=GRID[1], settle=15, measure=6, seed=seed)
    steps = load_source(path).steps
    d = data_from_steps(steps, 9)
    base, W = base_fit(steps, d, None, 9)
    dahl = rivals.dahl_fit(base, d, W)
    return d, W, (dahl.values["F_c_N"], dahl.values["sigma_N_per_m"]), dict(truth["params"], mass_kg=truth["mass_kg"])


def _covered(d, W, start, truth, names):
    from sim.discrepancy import rate_rivals as rr

    _, _, params = rr.lugre_fit(rr.setup(d, W), *start)
    return {n: params[n]["low"] <= truth[n] <= params[n]["high"] for n in names}


def test_lugre_intervals_hold_a_misfit_the_noise_model_does_not(tmp_path):
    # the records' noise is not all a step carries (decision 0036): here the top level's five
    # steps (gross sliding, where F_c, sigma_2 and m are measured) get force harmonics with 3x
    # the noise their records state, the weights unchanged, 20 seeded draws.  The Jacobian's
    # covariance alone (main before 0089) covered F_c, sigma_2, m 14, 13, 14 of 20 (41/60);
    # with the empirical per-step floor 17, 16, 19 (52/60); ~14 s
    from dataclasses import replace

    import numpy as np

    d0, W, start, truth = _lugre_inputs(tmp_path, seed=0)
    top = (d0.level == d0.level.max())[:, None]
    rng = np.random.default_rng(1)
    K = d0.X.shape[1]
    hits = 0
    for _ in range(20):
        e = 3.0 * d0.sP[:, None] * top * (rng.standard_normal(d0.Pf.shape) + 1j * rng.standard_normal(d0.Pf.shape))
        d = replace(d0, P=d0.P + e[:, :K], Pf=d0.Pf + e)
        hits += sum(_covered(d, W, start, truth, ("F_c_N", "sigma2_N_s_per_m", "mass_kg")).values())
    assert hits >= 50, hits


@pytest.mark.campaign
def test_lugre_intervals_cover_the_truth_as_often_as_they_claim(tmp_path):
    # 60 noise seeds of the test grid (15 steps), the independent simulator's data: each scalar
    # and the mass covered in at least 53 of 60 (a 95 % interval misses 8 or more in 1.2 %), all
    # 420 in 93-98.5 % (neither too narrow nor too wide: the leverage-corrected floor, CR3,
    # covered 99.4 % of 700 with intervals 1.6-3x as wide).  Measured: 59 55 56 57 59 59 59,
    # 404/420 (96.2 %); ~4 min
    names = (*LUGRE_SCALARS, "mass_kg")
    counts = dict.fromkeys(names, 0)
    for seed in range(60):
        d, W, start, truth = _lugre_inputs(tmp_path, seed)
        for n, ok in _covered(d, W, start, truth, names).items():
            counts[n] += ok
    assert all(c >= 53 for c in counts.values()), counts
    assert 391 <= sum(counts.values()) <= 414, counts


# ---------------------------------------------------------------- GMS's 95 % intervals (decision 0090)
GMS_BIASED = ("F_s_N", "C_N_per_s", "sigma2_N_s_per_m")


def test_gms_intervals_cover_the_truth_the_fixed_grid_missed(tmp_path):
    # noise seeds 0-2 of the 5 x 3 grid (benchtools/gms_coverage.py, the independent
    # simulator's data): main's fit (periods from their largest sample, slips on the fixed
    # grid) covered F_s, C and sigma_2 on none of 30 seeds, every seed off the same way (F_s
    # 12.02-12.03 N for 12, C 9200-9650 N/s for 1e4); the truth's elements are found (3, 6.5,
    # 14, 30 um to 1 %); ~15 s
    from benchtools.gms_coverage import covered, gms_inputs

    for seed in range(3):
        ok, res, p = covered(*gms_inputs(tmp_path, seed), names=GMS_BIASED)
        assert all(ok.values()), (seed, {n: p[n] for n in GMS_BIASED})
        slips = [q["value"] for q in p["slip_m"]]
        for true in (3e-6, 6.5e-6, 14e-6, 30e-6):
            assert min(abs(s / true - 1) for s in slips) < 0.01, (seed, slips)


def test_gms_fit_reaches_the_noise_at_a_hundredth_of_it(tmp_path):
    # the bias is the fit's, not the noise's: at 1 % of the rig's noise main's GMS fit left a
    # reduced chi-square of 237-240 (the misfit a half-sample-late reversal made, decision
    # 0090); measured 1.35-1.74 (seeds 0-2); ~5 s
    from benchtools.gms_coverage import covered, gms_inputs

    _, res, _ = covered(*gms_inputs(tmp_path, 0, noise_scale=0.01), names=())
    assert res.chi2 / (res.n_data - res.n_params) < 3.0


@pytest.mark.campaign
def test_gms_intervals_cover_the_truth_as_often_as_they_claim():
    # 30 noise seeds of the 5 x 3 grid: each scalar and the mass covered at least 25 of 30 (a
    # 95 % interval misses 6 or more in 1.6 %); main covered F_s, C, sigma_2 0/30, F_c 6/30; ~3 min
    from benchtools.gms_coverage import main

    counts = main(30)
    assert all(c >= 25 for c in counts.values()), counts
