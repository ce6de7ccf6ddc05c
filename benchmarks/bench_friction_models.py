"""The cost of each friction model of sim.friction.MODELS where the analysis and the
simulation pay it (issue 41, decision 0074).

- ``periodic_force`` on the analysis's shape: 90 steps (rows) of POINTS_PER_PERIOD samples,
  amplitudes 0.05-5 pre-rolling lengths with a third harmonic, frequencies 10-100 Hz, at
  the parameters of the issue's cases (benchtools/friction_cases.py; Masing: F_s 10 N,
  x_s 20 um, n 1.5): the median of repeats and its ratio to Masing's (the project's own
  loop, same run);
- the Iwan elements' design matrix on the same rows for a grid of 12 slip displacements
  (what one NNLS fit of the non-parametric virgin curve builds), in the same unit;
- ``advance`` stepped in a compiled loop over 1e5 samples of a sine (as a simulation
  kernel steps it): nanoseconds a step, and the ratio to Dahl's.

    python benchmarks/bench_friction_models.py [--repeats 7] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

from benchtools.friction_cases import CASES  # noqa: E402
from sim.friction import MODELS  # noqa: E402
from sim.friction.iwan import design_matrix  # noqa: E402
from sim.identify import POINTS_PER_PERIOD  # noqa: E402
from sim.kernel_cache import invalidate_stale_kernels  # noqa: E402

ROWS = 90
LENGTH_M = 2e-5
MASING = dict(F_s_N=10.0, x_s_m=20e-6, n=1.5)
STEPS = 100_000


@njit(cache=True)
def _step_all(advance, p, state, x, v, dt):
    F = 0.0
    for j in range(1, x.shape[0]):
        F += advance(p, state, x[j] - x[j - 1], dt, v[j])
    return F


def values_of(name: str) -> dict:
    return MASING if name == "masing" else CASES[name].params


def median_s(fn, repeats: int) -> float:
    fn()                                    # compiled and cached before it is timed
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return float(np.median(out))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    invalidate_stale_kernels()
    M = POINTS_PER_PERIOD
    tau = 2 * math.pi * np.arange(M) / M
    amps = LENGTH_M * np.geomspace(0.05, 5.0, ROWS)
    paths = amps[:, None] * (np.cos(tau) + 0.05 * np.cos(3 * tau + 0.3))[None, :]
    omega = 2 * math.pi * np.geomspace(10.0, 100.0, ROWS)
    t = np.arange(STEPS) / 25600.0
    x, v = LENGTH_M * np.sin(2 * math.pi * 40 * t), LENGTH_M * 2 * math.pi * 40 * np.cos(2 * math.pi * 40 * t)
    rows = []
    for name, model in MODELS.items():
        vals = values_of(name)
        s = median_s(lambda: model.periodic_force(vals, paths, omega), args.repeats)
        step_ns = None
        if model.advance is not None:
            p = model.kernel_params(vals)
            step_ns = 1e9 * median_s(lambda: _step_all(model.advance, p, np.zeros(model.state_length(vals)), x, v,
                                                       t[1]), args.repeats) / (STEPS - 1)
        rows.append(dict(model=name, periodic_ms=1e3 * s, step_ns=step_ns))
    grid = np.geomspace(1e-6, 60e-6, 12)
    rows.append(dict(model="masing_iwan design matrix (12 elements)",
                     periodic_ms=1e3 * median_s(lambda: design_matrix(paths, grid), args.repeats),
                     step_ns=None))
    ref = rows[0]["periodic_ms"]
    dahl = next(r["step_ns"] for r in rows if r["model"] == "dahl")
    print(f"periodic_force on {ROWS} rows of {M} samples (median of {args.repeats}); advance over {STEPS} steps")
    for r in rows:
        step = f"{r['step_ns']:6.1f} ns/step ({r['step_ns'] / dahl:4.2f}x dahl)" if r["step_ns"] else ""
        print(f"{r['model']:40s} {r['periodic_ms']:7.2f} ms ({r['periodic_ms'] / ref:5.2f}x masing)  {step}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
