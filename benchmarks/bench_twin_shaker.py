"""Benchmark of the twin's shaker fit (sim.shaker_fit.shaker_model, decision record 0032).

Per case: a random shaker (each of A, L/R, Bl^2/R, m_a, k_a, c_a the default of
bench/defaults/sim_rig.toml times 0.5-2, log-uniform), 16 structures (10 kg on springs of
6e5-6e6 N/m and dampers of 5-60 N s/m: resonances near 40-120 Hz), frequencies 20 Hz to
--fmax, the force per volt |P/V| from sim.plant_effects.shaker_frf (the complex network
solution, not the fitted formula) with relative noise --noise.  Prints how often each
identifiable combination was fitted (not fixed), how often its 95 % interval covered the
truth when fitted with nothing fixed and when fitted given fixed ones, and the fitted
shaker's error in predicting |P/V| on 16 other structures (median, max).

    python benchmarks/bench_twin_shaker.py [--cases 40] [--fmax 400] [--noise 1e-4]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from bench.twin import shaker_defaults  # noqa: E402
from sim.plant_effects import shaker_frf  # noqa: E402
from sim.rig import RigModel  # noqa: E402
from sim.shaker_fit import SHAKER_PARAMS, shaker_model, shaker_ratio  # noqa: E402


def structures(rng, n: int, fmax: float):
    f = np.geomspace(20, fmax, n) * rng.uniform(0.97, 1.03, n)
    w = 2 * np.pi * f
    return f, 1j * w * 10.0 + rng.uniform(5, 60, n) + rng.uniform(6e5, 6e6, n) / (1j * w)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=40)
    ap.add_argument("--fmax", type=float, default=400.0)
    ap.add_argument("--noise", type=float, default=1e-4)
    a = ap.parse_args()
    d = shaker_defaults()
    A0, tau0, ct0, ma0, ka0, s0 = d["values"]
    ce0, ca0 = s0 * ct0, (1 - s0) * ct0
    stats = {n: dict(fitted=0, cover_free=0, n_free=0, cover_given=0, n_given=0) for n in SHAKER_PARAMS}
    pred, times = [], []
    for seed in range(a.cases):
        rng = np.random.default_rng(seed)
        A, tau, ce, ma, ka, ca = (v * np.exp(rng.uniform(np.log(0.5), np.log(2))) for v in (A0, tau0, ce0, ma0, ka0, ca0))
        R = 2.0
        model = RigModel(F_s_N=10.0, x_s_m=1e-5, n=1.5, mass_kg=10.0, amp_gain_N_per_V=A,
                         shaker_force_constant_N_per_A=float(np.sqrt(ce * R)), shaker_resistance_ohm=R,
                         shaker_inductance_H=tau * R, shaker_armature_mass_kg=ma, shaker_suspension_N_per_m=ka,
                         shaker_damping_N_s_per_m=ca)
        truth = dict(zip(SHAKER_PARAMS, (A, tau, ce + ca, ma, ka, ce / (ce + ca))))
        f, Zs = structures(rng, 16, a.fmax)
        ratio = np.abs(shaker_frf(model, f, Zs)) * (1 + a.noise * rng.standard_normal(f.size))
        t0 = time.perf_counter()
        fit = shaker_model(f, ratio, Zs, d)
        times.append(time.perf_counter() - t0)
        if not fit.keys:
            print(f"case {seed}: no shaker fitted: {fit.note}")
            continue
        for n, q in fit.parameters.items():
            if not q["fitted"]:
                continue
            st = stats[n]
            st["fitted"] += 1
            inside = q["low"] <= truth[n] <= q["high"]
            key = "given" if q.get("given") else "free"
            st[f"n_{key}"] += 1
            st[f"cover_{key}"] += int(inside)
        th = [fit.parameters[n]["value"] for n in SHAKER_PARAMS]
        f2, Z2 = structures(rng, 16, a.fmax)
        pred.append(float(np.max(np.abs(shaker_ratio(th, f2, Z2) / np.abs(shaker_frf(model, f2, Z2)) - 1))))
        if pred[-1] > 0.005:
            print(f"case {seed}: worst held-out prediction {100 * pred[-1]:.3g} % (fit rms {100 * fit.rms_residual:.3g} %, "
                  f"fixed: {[n for n, q in fit.parameters.items() if not q['fitted']]})")
    print(f"shaker fit: {a.cases} random shakers, 16 structures each, 20-{a.fmax:g} Hz, noise {a.noise:g}")
    print(f"{'parameter':<28} {'fitted':>7} {'covered (nothing fixed)':>24} {'covered (given fixed ones)':>27}")
    for n, st in stats.items():
        print(f"{n:<28} {st['fitted']:>7} {st['cover_free']:>17}/{st['n_free']:<6} {st['cover_given']:>20}/{st['n_given']:<6}")
    p = np.array(pred)
    print(f"prediction of |P/V| on 16 held-out structures, worst step per case: median {100 * np.median(p):.3g} %, "
          f"max {100 * p.max():.3g} %; fit time median {1e3 * np.median(times):.0f} ms, max {1e3 * max(times):.0f} ms")


if __name__ == "__main__":
    main()
