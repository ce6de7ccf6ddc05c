"""The describing-function fit's time (issue 42 item 3's bar: median <= 15 s on one core for
5 levels x 20 frequencies) and its coverage on a few seeded draws of an analyser's noise
(decision 0082).  The fundamentals come from benchtools' independent Masing simulator
(5 force levels 0.05-0.8 F_s, an up-sweep of 20 frequencies 35-110 Hz per level, 30 settle
periods, 4 measured), taken by a least-squares DFT here; each draw adds fresh noise (0.5 %
of the level's largest response, 0.2 % of the force) and fits with the structures none and
mode (BIC).  Figures, no pass/fail.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_describing_fit.py [--draws 5] [--model masing]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

from benchtools.independent_masing import simulate_level
from sim.describing import Control, Level
from sim.describing_fit import fit_fundamentals

F_S, X_S, N, M = 10.0, 1e-5, 1.5, 10.0
LEVELS = (0.5, 1.5, 3.0, 5.5, 8.0)
FREQS = np.linspace(35.0, 110.0, 20)


def fundamental(t, y, b):
    A = np.column_stack([np.cos(b * t), np.sin(b * t), np.ones_like(t)])
    c, s, _ = np.linalg.lstsq(A, y, rcond=None)[0]
    return c - 1j * s


def records():
    w_s = math.sqrt(F_S / (X_S * M))
    betas = [2 * math.pi * f / w_s for f in FREQS]
    out = []
    for L in LEVELS:
        X, P = [], []
        for (t, u, _a, p), b in zip(simulate_level(N, L / F_S, betas, 30, 4, 40 * max(betas) / (2 * math.pi) * 1.037,
                                                   rtol=1e-9), betas):
            X.append(fundamental(t, u, b) * X_S)
            P.append(fundamental(t, p, b) * F_S)
        out.append((np.array(X), np.array(P)))
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--draws", type=int, default=5)
    ap.add_argument("--model", default="masing")
    a = ap.parse_args()
    t0 = time.perf_counter()
    recs = records()
    print(f"independent simulator: {len(LEVELS)} levels x {FREQS.size} frequencies in {time.perf_counter() - t0:.1f} s")
    truth = {"F_s_N": F_S, "x_s_m": X_S, "n": N, "mass_kg": M}
    times, covered = [], {k: 0 for k in truth}
    for seed in range(a.draws):
        rng = np.random.default_rng(seed)
        levels = []
        for X, P in recs:
            sX, sF = 0.005 * np.abs(X).max(), 0.002 * np.abs(P)
            Xn = X + sX * (rng.standard_normal(X.size) + 1j * rng.standard_normal(X.size))
            Pn = P + sF * (rng.standard_normal(P.size) + 1j * rng.standard_normal(P.size))
            levels.append(Level.from_fundamentals(FREQS, Xn, Pn, Control.FORCE, sigma_response=sX, sigma_force_N=sF))
        t1 = time.process_time()
        fit = fit_fundamentals(levels, a.model)
        times.append(time.process_time() - t1)
        for k in truth:
            if k in {e.name for e in fit.estimates}:
                e = fit.estimate(k)
                covered[k] += e.low <= truth[k] <= e.high
        print(f"draw {seed}: {times[-1]:.2f} s, structure {fit.structure}, chi2/dof {fit.reduced_chi2:.2f}, "
              + ", ".join(f"{e.name} {e.value:.4g} [{e.low:.4g}, {e.high:.4g}] {e.status}" for e in fit.estimates))
    print(f"fit CPU time (process_time), {len(LEVELS)} x {FREQS.size}, one thread: median {statistics.median(times):.2f} s, "
          f"max {max(times):.2f} s (bar: median <= 15 s)")
    print("95 % intervals covering the truth: " + ", ".join(f"{k} {v}/{a.draws}" for k, v in covered.items()))


if __name__ == "__main__":
    main()
