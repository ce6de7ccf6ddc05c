"""Identification of F_s, x_s, n and m on generated rigs (issue acceptance).

Each rig is drawn at random (seeded): F_s 2-40 N, x_s 2-100 um (log-uniform), n 0.3-3 away
from 1, m 2-40 kg; the technician's guesses are the truth times 0.7-1.3.  The default plan
runs on the simulated rig through the real protocols (infeasible steps skipped for light
rigs), then the final identification must land within 3 % (F_s, m) and 5 % (x_s, n).
"""

import numpy as np
import pytest

from bench.session import run_plan
from benchtools.procedure_rigs import TOLERANCE, TRUTH_KEYS, configs, run_rigs
from procedures.online_id import identifiability

# A seeded sample of one rig in `make test` (n 1.57: one full default plan), the two rigs this
# test held before (n 1.57 and 0.67) in `make bench` (marker campaign, decision 0083).  The
# campaign over more rigs through the same function: benchmarks/bench_identification.py
# --procedure-rigs (make bench runs six, the sample this test held until issue 25 moved it there).
SEEDS = {"sample": (0,), "two_rigs": (0, 4)}


@pytest.fixture(scope="module", params=["sample", pytest.param("two_rigs", marks=pytest.mark.campaign)])
def outcomes(request, tmp_path_factory):
    seeds = SEEDS[request.param]
    return run_rigs(seeds, [tmp_path_factory.mktemp(f"rig{seed}") for seed in seeds])


@pytest.mark.slow
@pytest.mark.timeout(1200)   # the fixture runs one or two full default plans
def test_final_estimates_within_tolerance_on_random_rigs(outcomes):
    misses = []
    for seed, truth, est in outcomes:
        for k in TRUTH_KEYS:
            err = est.values[k] / truth[k] - 1
            if abs(err) > TOLERANCE[k]:
                misses.append(f"rig {seed}: {k} {est.values[k]:.4g} vs {truth[k]:.4g} ({100 * err:+.1f} %)")
    assert not misses, "\n".join(misses)


@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_truth_inside_the_95_percent_interval_in_most_cases(outcomes):
    inside = [est.low[k] <= truth[k] <= est.high[k] for _, truth, est in outcomes for k in TRUTH_KEYS]
    assert np.mean(inside) >= 0.75, f"coverage {np.mean(inside):.2f}"


def test_identifiability_warnings_name_the_parameter():
    truth = dict(F_s_N=10.0, x_s_m=10e-6, n=1.5, mass_kg=10.0)
    plan, rig = configs(truth, dict(truth), 0)
    assert identifiability(plan, rig) == []          # the default plan pins everything
    from dataclasses import replace
    low_only = replace(plan, levels_N=(0.1, 0.3))      # gamma0 0.01-0.03: no loop shape, no plateau
    w = identifiability(low_only, rig)
    assert any(s.startswith("F_s, n:") for s in w) and any(s.startswith("F_s:") for s in w)
    high_band = replace(plan, freqs_Hz=(400.0, 600.0, 1000.0))   # resonance ~50 Hz never visited
    assert any(s.startswith("x_s, n:") for s in identifiability(high_band, rig))


def test_adaptive_mode_measures_fewer_steps_and_still_pins_the_parameters(tmp_path):
    truth = dict(F_s_N=10.0, x_s_m=10e-6, n=1.5, mass_kg=10.0)
    guess = dict(F_s_N=7.0, x_s_m=14e-6, n=2.0, mass_kg=12.0)
    plan, rig = configs(truth, guess, 3)
    from dataclasses import replace
    store = run_plan(replace(plan, adaptive_per_sweep=6), rig, tmp_path / "run")
    results = store.results()
    assert store.metadata["status"] == "completed"
    assert len(results) == 6 * len(plan.levels_N)                 # 42 of 168
    assert store.metadata["steps_total"] == 42 and store.account().complete    # counted as planned
    final = store.metadata["identification"]["values"]
    for k, v in truth.items():
        assert final[k] == pytest.approx(v, rel=0.01)
    # below F_s the chosen steps bracket the measured compliance peak of the level
    for li, F in enumerate(plan.levels_N):
        if F >= 0.5 * truth["F_s_N"]:
            continue
        level = sorted((r for r in results if r["level_index"] == li), key=lambda r: r["freq_Hz"])
        peak = max(range(len(level)), key=lambda i: level[i]["compliance_pp_m_per_N"])
        assert 0 < peak < len(level) - 1, f"{F} N: peak at the edge of the chosen band"
