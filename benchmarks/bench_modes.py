"""Benchmark of the modes per force level and the resonance search (issue 26's bars,
decision record 0043).

1. Feed mode, plain simulated rig (bench/defaults/sim_rig.toml): a coarse plan (12 log
   points, 30-300 Hz, levels 0.3, 1, 3 N) with ``[plan.resonance] refine = true``; each
   level's resonance against the independent reference, the peak of compliance_pp of the
   shooting engine (sim.shooting) on a dense grid (0.25 Hz, refined by a parabola).
   Bar: within 1 %, with a damping ratio and its interval at each level.
2. Pitching mode, bench/defaults/sim_rig_pitch.toml, same plan: the pitching mode at 1 N
   against the accelerance peak of a brute-force dense run (0.5 Hz steps, 190-225 Hz) of
   the same rig, its damping ratio against that run's half-power value.  Bars: within
   0.5 % and 20 %; the mode reported at every level.
3. Both runs in one modes.csv (`bench modes`).
4. Interval coverage: seeded Monte-Carlo on a spring-mass-damper's FRF (analytic
   resonance and damping ratio; 1 % complex noise; receptance and accelerance; 9 points
   in the half-power band) - how often the 95 % intervals hold the truth; with ``--seeds N``
   also on the Masing rig: the feed interval against the engine's peak over N noise seeds.

    python benchmarks/bench_modes.py [--out DIR] [--mc 1000] [--skip-runs] [--seeds 6]
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from bench.cli import main  # noqa: E402
from bench.config import DEFAULTS, load_rig, parse_plan  # noqa: E402
from bench.reports import run_modes  # noqa: E402
from bench.session import run_plan  # noqa: E402
from sim.frf import find_peaks  # noqa: E402
from sim.modal import LevelData, estimate_mode, half_power_zeta  # noqa: E402
from sim.shooting import frf_shooting  # noqa: E402

LEVELS = [0.3, 1.0, 3.0]
COARSE = {"start_Hz": 30.0, "stop_Hz": 300.0, "points": 12}


def coarse_run(rig: str, out: Path, label: str):
    plan = parse_plan({"plan": {"name": "coarse, refined", "levels_N": LEVELS, "frequencies": COARSE,
                                "resonance": {"refine": True}}})
    t = time.perf_counter()
    store = run_plan(plan, load_rig(DEFAULTS / rig), out, identify=False, labels={"rig": label})
    res = store.results()
    print(f"{rig}: {len(res)} steps ({sum('-R' in r['key'] for r in res)} refined) in "
          f"{time.perf_counter() - t:.0f} s wall, {max(r['t0_s'] for r in res):.0f} s rig time")
    return store


def feed_reference(level: float) -> float:
    ws = math.sqrt(10.0 / (10e-6 * 10.0))          # sim_rig.toml's F_s, x_s, m (n = 1.5)
    f = np.arange(45.0, 85.0, 0.25)
    fr, _ = frf_shooting(2 * np.pi * f / ws, level / 10.0, 1.5)
    return find_peaks(fr)[0].beta * ws / (2 * math.pi)


def dense_pitch(out: Path) -> tuple[float, float]:
    freqs = [190.0 + 0.5 * k for k in range(71)]
    plan = parse_plan({"plan": {"name": "dense pitch", "levels_N": [1.0], "frequencies": {"list_Hz": freqs}}})
    t = time.perf_counter()
    store = run_plan(plan, load_rig(DEFAULTS / "sim_rig_pitch.toml"), out, identify=False)
    d = LevelData.from_steps(1.0, store.results())
    m = np.abs(d.accelerance)
    i = int(np.argmax(m))
    a, b, c = np.polyfit(d.f_Hz[i - 1:i + 2], m[i - 1:i + 2], 2)
    fp = -b / (2 * a)
    zeta = half_power_zeta(d.f_Hz, m, fp, float(np.polyval([a, b, c], fp)))
    print(f"dense pitch run: {len(freqs)} steps in {time.perf_counter() - t:.0f} s; accelerance peak {fp:.3f} Hz "
          f"(grid max {d.f_Hz[i]:g} Hz), half-power damping ratio {100 * zeta:.3f} %")
    return fp, zeta


def coverage(n: int, seed: int = 11) -> None:
    fn, zeta, m = 50.0, 0.03, 10.0
    f = fn * np.array([0.9, 0.95, 0.97, 0.99, 1.0, 1.01, 1.02, 1.04, 1.07])
    rng = np.random.default_rng(seed)
    for kind in ("receptance", "accelerance"):
        w, wn = 2 * np.pi * f, 2 * np.pi * fn
        h0 = 1 / (m * (wn ** 2 - w ** 2 + 2j * zeta * wn * w))
        if kind == "accelerance":
            h0 = -w ** 2 * h0
        peak = fn * math.sqrt(1 - 2 * zeta ** 2) if kind == "receptance" else fn / math.sqrt(1 - 2 * zeta ** 2)
        cf = cz = 0
        for _ in range(n):
            noise = 0.01 * np.abs(h0).max() * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) / math.sqrt(2)
            e = estimate_mode(f, h0 + noise, mode="x", kind=kind)
            cf += e.resonance_low_Hz <= peak <= e.resonance_high_Hz
            cz += e.damping_ratio_low <= zeta <= e.damping_ratio_high
        print(f"coverage ({kind}, {n} seeded FRFs): resonance {cf}/{n} = {100 * cf / n:.1f} %, "
              f"damping ratio {cz}/{n} = {100 * cz / n:.1f} % (claimed 95 %)")


def masing_coverage(seeds: list[int], out: Path) -> None:
    """The feed resonance's 95 % intervals against the engine's dense peak over noise seeds of
    the plain rig (the coarse refined plan each time)."""
    refs = {lv: feed_reference(lv) for lv in LEVELS}
    hits = n = 0
    errs = []
    for seed in seeds:
        plan = parse_plan({"plan": {"name": "coarse, refined", "levels_N": LEVELS, "frequencies": COARSE,
                                    "resonance": {"refine": True, "modes": ["feed"]}}})
        store = run_plan(plan, load_rig(DEFAULTS / "sim_rig.toml"), out / f"seed{seed}", identify=False,
                         sim_seed=seed)
        for e in run_modes(store.path, model=False).modes:
            if e.mode != "feed":
                continue
            n += 1
            hits += e.ok and e.resonance_low_Hz <= refs[e.level_N] <= e.resonance_high_Hz
            errs.append(e.resonance_Hz / refs[e.level_N] - 1)
    print(f"Masing rig, {len(seeds)} noise seeds x {len(LEVELS)} levels: the feed interval holds the engine's peak "
          f"{hits}/{n}; largest error {100 * max(map(abs, errs)):.3f} %, median {100 * float(np.median(np.abs(errs))):.3f} %")


def main_(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="keep the runs and modes.csv here (default: a temporary directory)")
    ap.add_argument("--mc", type=int, default=1000, help="Monte-Carlo repetitions of the coverage check")
    ap.add_argument("--skip-runs", action="store_true", help="only the coverage check")
    ap.add_argument("--seeds", type=int, default=0,
                    help="also: the feed interval's coverage of the engine's peak over this many noise seeds")
    args = ap.parse_args(argv)
    coverage(args.mc)
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench_modes_"))
    if args.seeds:
        masing_coverage(list(range(1, args.seeds + 1)), out / "seeds")
    if args.skip_runs:
        return 0
    ok = True
    feed = coarse_run("sim_rig.toml", out / "plain", "plain")
    fm = {e.level_N: e for e in run_modes(feed.path, model=False).modes if e.mode == "feed"}
    for lv in LEVELS:
        ref, e = feed_reference(lv), fm[lv]
        err = e.resonance_Hz / ref - 1
        good = e.ok and abs(err) <= 0.01 and math.isfinite(e.damping_ratio_low)
        ok &= good
        print(f"feed {lv:g} N: {e.resonance_Hz:.3f} Hz [{e.resonance_low_Hz:.3f}, {e.resonance_high_Hz:.3f}] vs engine "
              f"{ref:.3f} Hz: {100 * err:+.3f} %; damping ratio {100 * e.damping_ratio:.2f} % "
              f"[{100 * e.damping_ratio_low:.2f}, {100 * e.damping_ratio_high:.2f}], half-power "
              f"{100 * e.half_power_damping_ratio:.2f} %  {'ok' if good else 'FAILS the 1 % bar'}")
    pitch = coarse_run("sim_rig_pitch.toml", out / "pitch", "pitching")
    pm = {e.level_N: e for e in run_modes(pitch.path, model=False).modes if e.mode == "pitch"}
    every = all(pm.get(lv) is not None and pm[lv].ok for lv in LEVELS)
    ok &= every
    for lv in LEVELS:
        e = pm[lv]
        print(f"pitch {lv:g} N: {e.status} {e.resonance_Hz:.3f} Hz [{e.resonance_low_Hz:.3f}, {e.resonance_high_Hz:.3f}], "
              f"damping ratio {100 * e.damping_ratio:.3f} % [{100 * e.damping_ratio_low:.3f}, "
              f"{100 * e.damping_ratio_high:.3f}]")
    fp, zeta = dense_pitch(out / "dense_pitch")
    e = pm[1.0]
    ef, ez = e.resonance_Hz / fp - 1, e.damping_ratio / zeta - 1
    good = abs(ef) <= 0.005 and abs(ez) <= 0.2
    ok &= good
    print(f"pitch 1 N vs the dense run: resonance {100 * ef:+.3f} % (bar 0.5 %), damping ratio {100 * ez:+.1f} % "
          f"of its half-power value (bar 20 %); the interval [{e.resonance_low_Hz:.3f}, {e.resonance_high_Hz:.3f}] "
          f"{'holds' if e.resonance_low_Hz <= fp <= e.resonance_high_Hz else 'misses'} the dense peak  "
          f"{'ok' if good else 'FAILS'}")
    main(["modes", str(feed.path), str(pitch.path), "--out", str(out / "modes")])
    rows = list(csv.DictReader(open(out / "modes" / "modes.csv")))
    two = len({r["run"] for r in rows}) == 2
    ok &= two
    print(f"modes.csv: {len(rows)} rows from {len({r['run'] for r in rows})} runs ({out / 'modes'})")
    print("all bars met" if ok else "SOME BAR NOT MET")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main_())
