"""The base fit on clean data (issue 9): a campaign over generated rigs (figures, no pass/fail).

Rigs drawn at random (seeded), n over [0.35, 3] with half the rigs below 1.  Each rig's
data come from the RK4 plant on the issue's grid (5 levels 0.1-0.85 F_s x 18 frequencies
0.3-3 x the friction resonance, 25 settle / 8 measured periods, noise 0.3 % F_s, 0.5 % rms,
0.2 % x_s); ``--uff`` rigs more come from the independent solve_ivp simulator through a
UFF58 file (3 levels x 8 frequencies, slower).  Prints per rig and in total: coverage of the
95 % intervals, worst error per parameter, range of the reduced chi-square, time.

``--procedure-rigs`` rigs more run the whole default plan on the simulated rig through the
real protocols and the run's final identification (tests/procedures/test_identification.py
holds two of them): errors against the 3 % / 5 % tolerance and the coverage of the intervals.

    python benchmarks/bench_identification.py [--rigs 40] [--uff 6] [--procedure-rigs 6] [--workers 2]
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchtools.clean_cases import KEYS, plant_case, uff_case  # noqa: E402
from benchtools.procedure_rigs import TOLERANCE, run_rigs  # noqa: E402


def job(args):
    kind, seed, n_range, out = args
    t = time.perf_counter()
    res = plant_case(seed, n_range) if kind == "plant" else uff_case(seed, n_range, Path(out))
    return res + (time.perf_counter() - t,)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rigs", type=int, default=40, help="rigs through the RK4 plant")
    ap.add_argument("--uff", type=int, default=6, help="rigs from the independent simulator via UFF58")
    ap.add_argument("--procedure-rigs", type=int, default=6, help="rigs through the default plan and the run's identification")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    out = tempfile.mkdtemp(prefix="bench_ident_")
    jobs = [("plant", 100 + i, (0.35, 0.95) if i % 2 == 0 else (1.1, 3.0), out) for i in range(a.rigs)]
    jobs += [("uff", 200 + i, (0.35, 0.95) if i % 2 == 0 else (1.1, 3.0), out) for i in range(a.uff)]
    t0 = time.perf_counter()
    rows = []
    with ProcessPoolExecutor(max_workers=a.workers, mp_context=multiprocessing.get_context("spawn")) as ex:
        for kind, truth, est, rejected, dt in ex.map(job, jobs):
            err = {k: est.values[k] / truth[k] - 1 for k in KEYS}
            inside = {k: est.low[k] <= truth[k] <= est.high[k] for k in KEYS}
            rows.append((kind, truth, est, err, inside))
            print(f"{kind:5s} n={truth['n']:.2f} chi2 {est.cost:5.2f} " + " ".join(
                f"{k} {100 * err[k]:+.3f}%{'' if inside[k] else '!'}" for k in KEYS)
                + f"  rejected {rejected}  {dt:.0f} s", flush=True)
    for kind in ("plant", "uff58", "all"):
        sel = [r for r in rows if kind == "all" or r[0] == kind]
        if not sel:
            continue
        cov = np.mean([r[4][k] for r in sel for k in KEYS])
        chi = [r[2].cost for r in sel]
        worst = {k: max(abs(r[3][k]) for r in sel) for k in KEYS}
        low_n = sum(r[1]["n"] < 1 for r in sel)
        print(f"{kind}: {len(sel)} rigs ({low_n} with n < 1): coverage {100 * cov:.1f} % of parameters; "
              f"reduced chi2 {min(chi):.2f}-{max(chi):.2f}; worst error "
              + ", ".join(f"{k} {100 * v:.3f} %" for k, v in worst.items()))
    print(f"wall time {time.perf_counter() - t0:.0f} s with {a.workers} workers")
    if a.procedure_rigs:
        procedure(a.procedure_rigs, out, a.workers)


def procedure(n_rigs: int, out: str, workers: int) -> None:
    """The default plan through the twins and the run's identification on generated rigs."""
    t0 = time.perf_counter()
    seeds = list(range(n_rigs))
    outcomes = run_rigs(seeds, [Path(out) / f"procedure{s}" for s in seeds], workers)
    inside, misses = [], 0
    for seed, truth, est in outcomes:
        err = {k: est.values[k] / truth[k] - 1 for k in KEYS}
        ok = {k: est.low[k] <= truth[k] <= est.high[k] for k in KEYS}
        inside += ok.values()
        misses += sum(abs(err[k]) > TOLERANCE[k] for k in KEYS)
        print(f"rig {seed} n={truth['n']:.2f} " + " ".join(
            f"{k} {100 * err[k]:+.3f}%{'' if ok[k] else '!'}" for k in KEYS), flush=True)
    print(f"default plan: {n_rigs} rigs: coverage {100 * np.mean(inside):.1f} % of parameters; "
          f"{misses} estimates outside the tolerance; wall time {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
