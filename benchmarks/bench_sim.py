"""Speed of the physics core, as figures and ratios measured in one run (no pass/fail).

    python benchmarks/bench_sim.py [--points 200] [--gamma0 0.6] [--n 1.5]
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from sim import _kernel
from sim.dynamics import FrictionState, Integrator
from sim.frf import frf_rk4
from sim.shooting import frf_shooting


def ns_per_step(fn, n, steps):
    c = Integrator(n=n).curve
    st = FrictionState()
    args = (2.0, c.kind, c.params, 1 / 1.2**2, 0.6, 1.0, 0.0, 0.0, 0.0, 0.0, 2 * math.pi / 10000)
    fn(st.u, st.v, 0.0, st.k, st.d, st.su, st.sF, *args, 10, 1, np.empty((0, 5)))  # warm up
    t = time.perf_counter()
    fn(st.u, st.v, 0.0, st.k, st.d, st.su, st.sF, *args, steps, 1, np.empty((0, 5)))
    return (time.perf_counter() - t) / steps * 1e9


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=200)
    ap.add_argument("--gamma0", type=float, default=0.6)
    ap.add_argument("--n", type=float, default=1.5)
    a = ap.parse_args()
    cores = os.cpu_count()
    print(f"machine: {cores} cores")

    jit = min(ns_per_step(_kernel.rk4_run, a.n, 500_000) for _ in range(3))
    # the same code with numba off everywhere (inner calls too), in a fresh process
    code = ("from benchmarks.bench_sim import ns_per_step; from sim import _kernel; "
            f"print(ns_per_step(_kernel.rk4_run, {a.n}, 5000))")
    root = Path(__file__).resolve().parents[1]
    py = float(subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, check=True,
                              env=dict(os.environ, NUMBA_DISABLE_JIT="1", PYTHONPATH=str(root))).stdout)
    print(f"RK4 step (4 friction evaluations): {jit:.0f} ns compiled, {py:.0f} ns plain Python "
          f"-> {py / jit:.0f}x; target <= 100 ns")

    betas = np.linspace(0.2, 2.0, a.points)
    frf_shooting(betas[:3], a.gamma0, a.n)   # compile
    t = time.perf_counter(); r1 = frf_rk4(betas, a.gamma0, a.n, workers=1); t1 = time.perf_counter() - t
    t = time.perf_counter(); rk = frf_rk4(betas, a.gamma0, a.n); tall = time.perf_counter() - t
    t = time.perf_counter(); sh, fb = frf_shooting(betas, a.gamma0, a.n); ts = time.perf_counter() - t
    rel = np.abs(sh.G - rk.G) / rk.G
    print(f"{a.points}-point FRF gamma0={a.gamma0} n={a.n}:")
    print(f"  RK4, 1 core:          {t1:6.2f} s")
    print(f"  RK4, {cores} cores:         {tall:6.2f} s  ({t1 / tall:.2f}x of 1 core; target <= 5 s)")
    print(f"  shooting, 1 core:     {ts:6.2f} s  ({tall / ts:.1f}x faster than RK4 on all cores; "
          f"target <= 0.5 s); {fb.sum()} points fell back to RK4")
    print(f"  shooting vs RK4: max relative difference of G {rel.max():.1e} (target <= 1e-3)")
    print(f"  largest reversal stack depth seen (RK4): {max(rk.max_depth, r1.max_depth)}")
    assert np.array_equal(r1.G, rk.G)  # threads must not change results


if __name__ == "__main__":
    main()
