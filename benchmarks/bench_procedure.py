"""The default plan on the simulated rig: wall time vs the test's duration on a real rig,
and the online identification's update time and accuracy (figures, no pass/fail).

    python benchmarks/bench_procedure.py [--out /tmp/bench_run]
"""

from __future__ import annotations

import argparse
import shutil
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from bench.config import DEFAULTS, load_plan, load_rig
from bench.session import run_plan
from procedures.online_id import history


def steps_to_accuracy(h: list[dict], truth: dict, tol: float) -> int | None:
    """First step count from which every estimate stays within ``tol`` of the truth."""
    ok = [all(abs(r["values"][k] / truth[k] - 1) < tol for k in ("F_s_N", "x_s_m", "n", "mass_kg")) for r in h]
    for i in range(len(ok)):
        if all(ok[i:]):
            return i + 1
    return None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="/tmp/bench_procedure")
    a = ap.parse_args()
    plan, rig = load_plan(DEFAULTS / "demo_plan.toml"), load_rig(DEFAULTS / "sim_rig.toml")
    plan = replace(plan, refine=False)       # the 7 x 24 grid (168 steps) the figures are of
    histories = {}
    for identify in (False, True):
        out = Path(a.out) / ("with_id" if identify else "no_id")
        shutil.rmtree(out, ignore_errors=True)
        t = time.perf_counter()
        store = run_plan(plan, rig, out, identify=identify)
        wall = time.perf_counter() - t
        res = store.results()
        last = res[-1]
        rig_time = last["t0_s"] + last["n_samples"] / last["fs_Hz"]
        print(f"default plan ({len(res)} steps), identification {'on' if identify else 'off'}: "
              f"{wall:.1f} s wall for {rig_time:.1f} s of rig time "
              f"({rig_time / wall:.1f}x faster than the real test; target <= 60 s wall)")
        if identify:
            h = history(out)
            histories["fixed grid"] = (h, len(res))
            ms = np.array([r["update_s"] for r in h]) * 1e3
            print(f"  identification update per step: median {np.median(ms):.0f} ms, "
                  f"p90 {np.percentile(ms, 90):.0f} ms, max {ms.max():.0f} ms (target median <= 100 ms)")
            final = store.metadata["identification"]
            truth = asdict(rig.model)
            for k in ("F_s_N", "x_s_m", "n", "mass_kg"):
                v, lo, hi = final["values"][k], final["low"][k], final["high"][k]
                print(f"  {k:8s} {v:.5g} (truth {truth[k]:.5g}, error {100 * (v / truth[k] - 1):+.2f} %, "
                      f"95 % [{lo:.5g}, {hi:.5g}])")
            for k in ("F_s_N", "n"):
                for r in h:
                    if abs(r["values"][k] / truth[k] - 1) < 0.05 and all(
                            abs(q["values"][k] / truth[k] - 1) < 0.05 for q in h[h.index(r):]):
                        print(f"  {k} within 5 % of the truth from step {h.index(r) + 1} on")
                        break


    # adaptive mode: 6 frequencies per sweep chosen around the predicted resonance
    adaptive = replace(plan, adaptive_per_sweep=6)
    out = Path(a.out) / "adaptive"
    shutil.rmtree(out, ignore_errors=True)
    t = time.perf_counter()
    store = run_plan(adaptive, rig, out)
    wall = time.perf_counter() - t
    histories["adaptive (6 per sweep)"] = (history(out), len(store.results()))
    print(f"adaptive plan: {len(store.results())} steps, {wall:.1f} s wall")
    truth = asdict(rig.model)
    for tol in (0.01, 0.002):
        cells = []
        for name, (h, n_steps) in histories.items():
            k = steps_to_accuracy(h, truth, tol)
            cells.append(f"{name}: {k if k else 'never'} of {n_steps}")
        print(f"  steps until all four estimates stay within {100 * tol:g} % of the truth: " + "; ".join(cells))


if __name__ == "__main__":
    main()
