"""Coverage of the Monte-Carlo identification study on a rig file (issue 25, decision 0049).

Seeded samples of :func:`bench.studies.montecarlo.identification_sample` in this process (a
small plan around the resonances: 3, 6, 30 N x 25-400 Hz), and per parameter the pull
(estimate - truth) / sigma (log units for F_s, x_s, m), its mean and spread (a model bias
shows as a mean away from 0, intervals too narrow as a spread above 1), the coverage of the
95 % intervals, and the reduced chi-square and misfit flags.  ``--harmonics 5`` records the
plans' default instead of the study's (the code before decision 0049).  Writes pulls.png.

    python benchmarks/bench_mc_coverage.py [--rig sim_rig_pitch.toml] [--samples 30] [--harmonics 5]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.config import DEFAULTS  # noqa: E402
from bench.studies import McSpec, montecarlo  # noqa: E402
from bench.studies.engine import task_seed  # noqa: E402

PLAN = {"plan": {"name": "mc coverage", "levels_N": [3.0, 6.0, 30.0],
                 "frequencies": {"list_Hz": [25.0, 35.0, 50.0, 70.0, 100.0, 150.0, 250.0, 400.0]}}}


def pull(r: dict) -> float:
    if r["parameter"] == "n":
        return (r["estimate"] - r["truth"]) / ((r["high"] - r["low"]) / (2 * 1.959964))
    return math.log(r["estimate"] / r["truth"]) / (math.log(r["high"] / r["low"]) / (2 * 1.959964))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rig", default="sim_rig_pitch.toml")
    ap.add_argument("--samples", type=int, default=30)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--harmonics", type=int, default=montecarlo.RECORD_HARMONICS)
    ap.add_argument("--out", type=Path, default=Path("out/bench_mc_coverage"))
    a = ap.parse_args()
    montecarlo.RECORD_HARMONICS = a.harmonics
    rig = tomllib.loads((DEFAULTS / a.rig).read_text())
    spec = McSpec(plan=PLAN, rig=rig, samples=a.samples, seed=a.seed)
    rows, t0 = [], time.perf_counter()
    for inputs in spec.tasks():
        rows += montecarlo.identification_sample(inputs, task_seed(a.seed, inputs))
    print(f"{a.rig}, {a.samples} samples, harmonics recorded: {a.harmonics} "
          f"({time.perf_counter() - t0:.0f} s)")
    pulls = {}
    for p in montecarlo.PARAMS:
        R = [r for r in rows if r["parameter"] == p]
        pulls[p] = np.array([pull(r) for r in R])
        print(f"  {p:8s} pull mean {pulls[p].mean():+.2f} sd {pulls[p].std(ddof=1):.2f}  "
              f"covered {sum(r['covered'] for r in R)}/{len(R)}  "
              f"rel. error mean {np.mean([r['rel_error'] for r in R]):+.1e}")
    chi = np.array([r["reduced_chi2"] for r in rows if r["parameter"] == "n"])
    print(f"  reduced chi^2 median {np.median(chi):.3g} (min {chi.min():.3g}, max {chi.max():.3g}); "
          f"misfit flagged in {sum(r['misfit'] for r in rows if r['parameter'] == 'n')}/{chi.size}")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    a.out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(7, 4))
    for i, p in enumerate(montecarlo.PARAMS):
        ax.plot(np.full(pulls[p].size, i) + np.linspace(-0.2, 0.2, pulls[p].size), pulls[p], "o", ms=4)
    ax.axhspan(-1.96, 1.96, color="0.9", zorder=0)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xticks(range(4), montecarlo.PARAMS)
    ax.set_ylabel("pull (estimate - truth) / sigma")
    ax.set_title(f"{a.rig}: {a.samples} samples, {a.harmonics} harmonics recorded (grey: 95 %)")
    fig.tight_layout()
    fig.savefig(a.out / "pulls.png", dpi=110)
    print(f"  figure: {a.out / 'pulls.png'}")


if __name__ == "__main__":
    main()
