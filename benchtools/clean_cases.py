"""The base fit's clean-data cases (tests/sim/test_identify_clean.py; its campaign over more
rigs: benchmarks/bench_identification.py): a generated rig through the RK4 plant
(``plant_case``) or through the independent simulator as UFF58 (``uff_case``), each
identified from guesses 0.8-1.2 x the truth.
"""
import math

import numpy as np

from bench.sources import load_source
from sim.identify import StepHarmonics, identify_results
from sim.records import analyse_records
from sim.synthetic import clean_model, generate, issue_grid, random_rig

KEYS = ("F_s_N", "x_s_m", "n", "mass_kg")


def guess_of(truth, seed):
    rng = np.random.default_rng(seed + 7)
    return {k: v * rng.uniform(0.8, 1.2) for k, v in truth.items()}


def plant_case(seed, n_range):
    truth = random_rig(seed, n_range)
    model = clean_model(**truth, seed=seed)
    steps = generate(model, *issue_grid(model), seed=seed)
    harm = [StepHarmonics.from_records(analyse_records(s.force_N, s.accel_m_s2, s.disp_m, s.fs_Hz, s.freq_Hz))
            for s in steps]
    return "plant", truth, identify_results(harm, guess_of(truth, seed), 9).estimate, 0


def uff_case(seed, n_range, out):
    from benchtools.independent_masing import generate_uff
    truth = random_rig(seed, n_range)
    f_s = math.sqrt(truth["F_s_N"] / (truth["x_s_m"] * truth["mass_kg"])) / (2 * math.pi)
    path = out / f"rig{seed}.uff"
    generate_uff(path, **truth, levels_N=np.array([0.25, 0.55, 0.85]) * truth["F_s_N"],
                 freqs_Hz=np.geomspace(0.5 * f_s, 2.5 * f_s, 8), settle=12, measure=8, seed=seed)
    src = load_source(path)
    est = identify_results([s.harmonics for s in src.steps], guess_of(truth, seed), 9).estimate
    return "uff58", truth, est, len(src.rejected)
