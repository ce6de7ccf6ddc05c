"""Phase resonance (decision 0044) on the plain simulated rig: issue 27's bar (each locked
point against the Masing backbone by single-harmonic balance at its measured amplitude),
periods per point, and the rig time to know the feed resonance at four levels against a
stepped sine with resonance refinement (9 log points over 50-90 Hz, `[plan.resonance]
refine = true`, tolerance 0.5 %) and a dense stepped sine whose grid (1 % log spacing over
50-90 Hz: the grid maximum within 0.5 %) covers the same resonances, as ratios.  Figures,
no pass/fail.

    python benchmarks/bench_backbone.py [--out /tmp/bench_backbone] [--no-refined] [--no-dense]
"""

from __future__ import annotations

import argparse
import math
import shutil
import time
from dataclasses import asdict
from pathlib import Path

from bench.backbone import backbone_rows
from bench.config import DEFAULTS, load_rig, parse_plan
from bench.reports import run_modes
from bench.session import run_plan
from sim.backbone import backbone_point

LEVELS = [0.1, 0.3, 1.0, 3.0]


def rig_time(store) -> float:
    last = max(store.results(), key=lambda r: r["t0_s"])
    return last["t0_s"] + last["n_samples"] / last["fs_Hz"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="/tmp/bench_backbone")
    ap.add_argument("--no-refined", action="store_true")
    ap.add_argument("--no-dense", action="store_true")
    a = ap.parse_args()
    rig = load_rig(DEFAULTS / "sim_rig.toml")
    m = asdict(rig.model)
    out = Path(a.out) / "phase_resonance"
    shutil.rmtree(out, ignore_errors=True)
    plan = parse_plan({"plan": {"procedure": "phase_resonance", "levels_N": LEVELS, "backbone": {"start_Hz": 80.0},
                                "control": {"settle_cycles": 10, "measure_cycles": 10}}})
    t = time.perf_counter()
    store = run_plan(plan, rig, out)
    wall = time.perf_counter() - t
    t_pr = rig_time(store)
    print(f"phase resonance, {len(LEVELS)} levels: {t_pr:.2f} s rig time, {wall:.1f} s wall")
    print(f"{'level N':>8} {'f Hz':>8} {'X um':>7} {'zeta %':>7} {'df %':>6} {'dF %':>6} {'dzeta %':>7} "
          f"{'phase err':>9} {'periods':>7} locked")
    for r in backbone_rows(store.results()):
        hb = backbone_point(r["amplitude_m"], m["mass_kg"], m["F_s_N"], m["x_s_m"], m["n"])
        print(f"{r['level_N']:8g} {r['frequency_Hz']:8.3f} {1e6 * r['amplitude_m']:7.3f} "
              f"{100 * r['damping_ratio']:7.3f} {100 * (r['frequency_Hz'] / hb.frequency_Hz - 1):+6.2f} "
              f"{100 * (r['force_N'] / hb.force_N - 1):+6.2f} {100 * (r['damping_ratio'] / hb.damping_ratio - 1):+7.2f} "
              f"{r['phase_error_deg']:+9.2f} {r['periods']:7d} {r['locked']}")
    if not a.no_refined:
        refined = parse_plan({"plan": {"levels_N": LEVELS, "frequencies": {"start_Hz": 50.0, "stop_Hz": 90.0,
                                                                            "points": 9},
                                       "resonance": {"refine": True, "tolerance": 0.005, "modes": ["feed"]}}})
        out = Path(a.out) / "refined"
        shutil.rmtree(out, ignore_errors=True)
        t = time.perf_counter()
        store = run_plan(refined, rig, out, identify=False)
        wall = time.perf_counter() - t
        t_rf = rig_time(store)
        n = len(store.results())
        feed = [e for e in run_modes(out, model=False).modes if e.mode == "feed"]
        print(f"stepped sine with refinement (9 points over 50-90 Hz + {n - 9 * len(LEVELS)} refinement steps): "
              f"{t_rf:.1f} s rig time, {wall:.1f} s wall; phase resonance is {t_rf / t_pr:.1f}x faster in rig time")
        for e in feed:
            print(f"  {e.level_N:g} N: {e.status} {e.resonance_Hz:.3f} Hz [{e.resonance_low_Hz:.3f}, "
                  f"{e.resonance_high_Hz:.3f}] ({100 * (e.resonance_high_Hz - e.resonance_low_Hz) / 2 / e.resonance_Hz:.2f} %)")
    if a.no_dense:
        return
    points = math.ceil(math.log(90 / 50) / math.log(1.01)) + 1
    dense = parse_plan({"plan": {"levels_N": LEVELS, "frequencies": {"start_Hz": 50.0, "stop_Hz": 90.0,
                                                                        "points": points}}})
    out = Path(a.out) / "dense"
    shutil.rmtree(out, ignore_errors=True)
    t = time.perf_counter()
    store = run_plan(dense, rig, out, identify=False)
    wall = time.perf_counter() - t
    t_ss = rig_time(store)
    print(f"dense stepped sine, {len(LEVELS)} levels x {points} frequencies (1 % spacing): {t_ss:.1f} s rig time, "
          f"{wall:.1f} s wall; phase resonance is {t_ss / t_pr:.1f}x faster in rig time"
          + ("" if a.no_refined else f", the refined stepped sine {t_ss / t_rf:.1f}x"))


if __name__ == "__main__":
    main()
