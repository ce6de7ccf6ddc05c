"""Speed of studies on the dask engine, as figures and ratios measured in one run.

    python benchmarks/bench_studies.py [--gamma0-points 50] [--beta-points 200] [--rk4-sample 8]

- per-task overhead: trivial tasks through the study engine (submit, run, gather, one
  Parquet part each) on the local cluster;
- scaling from 1 to 2 local workers on the same map rows, with the efficiency;
- a gamma0 x beta map for n = 1.5 (the issue's 50 x 200) with the shooting engine,
  against the same points computed one by one from rest with the RK4 engine: RK4 is
  timed on a random sample of the map's points and extrapolated (said in the output);
- per-task cost of map rows at other n (n < 1 falls back to RK4 more often), and from
  these the projected time of a 20 n x 100 gamma0 x 400 beta study on 64 workers.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.studies.engine import Engine, Study
from bench.studies.maps import MapSpec, map_row


def trivial(inputs: dict, seed: int) -> list[dict]:
    return [dict(x=inputs["i"] * 2, seed=seed)]


def timed_run(study: Study, fn, engine: Engine) -> float:
    t = time.perf_counter()
    out = study.run(fn, engine)
    assert not out.failures, out.failures
    return time.perf_counter() - t


def row_costs(tmp: Path, engine: Engine, spec: MapSpec, name: str) -> list[float]:
    """Per-row compute time (measured inside the task, so without scheduling)."""
    def costed(inputs, seed):
        t = time.perf_counter()
        rows = map_row(inputs, seed)
        dt = time.perf_counter() - t
        return [dict(r, row_seconds=dt) for r in rows]
    study = Study(tmp / name, "bench", spec.to_dict(), spec.tasks())
    study.run(costed, engine)
    import pyarrow.parquet as pq
    t = pq.read_table(study.dir / "results.parquet")
    per_task = {}
    for task, s in zip(t.column("task").to_pylist(), t.column("row_seconds").to_pylist()):
        per_task[task] = s
    return list(per_task.values())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--gamma0-points", type=int, default=50)
    ap.add_argument("--beta-points", type=int, default=200)
    ap.add_argument("--rk4-sample", type=int, default=8, help="map points timed with RK4 (extrapolated)")
    ap.add_argument("--trivial-tasks", type=int, default=200)
    a = ap.parse_args()
    cores = os.cpu_count() or 1
    print(f"machine: {cores} cores; local cluster: one single-threaded worker process per core")
    tmp = Path(tempfile.mkdtemp(prefix="bench_studies_"))

    with Engine(workers=2) as eng:
        # -- per-task overhead
        tasks = [dict(i=i) for i in range(a.trivial_tasks)]
        t_triv = timed_run(Study(tmp / "trivial", "bench", {}, tasks), trivial, eng)
        t = time.perf_counter()
        eng.map(abs, list(range(len(tasks))))
        t_dask = time.perf_counter() - t
        print(f"per-task overhead, 2 workers, {len(tasks)} trivial tasks: {1e3 * t_triv / len(tasks):.1f} ms/task "
              f"through the study engine (submit, gather, one Parquet part), of which dask alone "
              f"{1e3 * t_dask / len(tasks):.1f} ms/task")

    # -- scaling 1 -> 2 workers on the same rows (clusters started outside the timing)
    scal = MapSpec(n=(1.5,), gamma0=tuple(np.round(np.linspace(0.2, 0.9, 8), 6)), beta_points=100)
    times = {}
    for w in (1, 2):
        with Engine(workers=w) as eng:
            times[w] = timed_run(Study(tmp / f"scale{w}", "bench", scal.to_dict(), scal.tasks()), map_row, eng)
    eff = times[1] / (2 * times[2])
    print(f"scaling, 8 rows x 100 beta (n = 1.5): 1 worker {times[1]:.2f} s, 2 workers {times[2]:.2f} s "
          f"-> speed-up {times[1] / times[2]:.2f}x, efficiency {100 * eff:.0f} %")

    # -- the 50 x 200 map for one n, shooting, all local cores
    gammas = tuple(np.round(np.linspace(0.05, 0.95, a.gamma0_points), 6))
    spec = MapSpec(n=(1.5,), gamma0=gammas, beta_min=0.2, beta_max=3.0, beta_points=a.beta_points)
    with Engine(workers=cores) as eng:
        t = time.perf_counter()
        costs = row_costs(tmp, eng, spec, "map")
        t_map = time.perf_counter() - t
    points = a.gamma0_points * a.beta_points
    print(f"{a.gamma0_points} x {a.beta_points} map (gamma0 x beta), n = 1.5, shooting up + down sweeps, "
          f"{cores} workers: {t_map:.1f} s wall; per row (task) median {statistics.median(costs):.2f} s, "
          f"max {max(costs):.2f} s")

    # -- the same map point by point with RK4 from rest: a random sample, extrapolated
    from sim.dynamics import steady_state
    rng = np.random.default_rng(0)
    betas = spec.betas()
    sample = [(float(rng.choice(gammas)), float(rng.choice(betas))) for _ in range(a.rk4_sample)]
    steady_state(0.5, 1.5, 1.5, max_cycles=3)   # compiled
    t = time.perf_counter()
    for g, b in sample:
        steady_state(g, b, 1.5)
    per_point = (time.perf_counter() - t) / len(sample)
    t_rk4 = per_point * points / cores
    print(f"same map with RK4 point by point (one sweep, from rest), extrapolated from {len(sample)} random "
          f"points ({per_point:.2f} s each, 1 core) to {points} points on {cores} cores: {t_rk4:.0f} s "
          f"-> the study engine with shooting is {t_rk4 / t_map:.0f}x faster (and computes both sweeps)")

    # -- per-task cost at other n, and the projection
    other = MapSpec(n=(0.5, 3.0), gamma0=(0.2, 0.6), beta_min=0.2, beta_max=3.0, beta_points=a.beta_points)
    with Engine(workers=cores) as eng:
        c_other = row_costs(tmp, eng, other, "other")   # task order: (0.5, 0.2), (0.5, 0.6), (3, 0.2), (3, 0.6)
    by_n = {1.5: statistics.mean(costs), 0.5: statistics.mean(c_other[:2]), 3.0: statistics.mean(c_other[2:])}
    print("mean row cost by n (n = 0.5 and 3 at gamma0 0.2 and 0.6): "
          + ", ".join(f"n = {n:g}: {c:.2f} s" for n, c in sorted(by_n.items())))
    per_row = statistics.mean(by_n.values()) * (400 / a.beta_points)    # cost is linear in the points
    tasks = 20 * 100
    overhead = t_triv / a.trivial_tasks
    total = tasks * (per_row + overhead)
    wall = max(total / 64, max(costs + c_other) * 400 / a.beta_points)
    print(f"projection, 20 n x 100 gamma0 x 400 beta = {tasks} row tasks of 400 points: mean task "
          f"{per_row:.2f} s (sampled n = 0.5, 1.5, 3, scaled from {a.beta_points} to 400 points) + "
          f"{1e3 * overhead:.0f} ms overhead = {total / 3600:.1f} CPU-hours; on 64 workers about "
          f"{wall / 60:.0f} min (one machine with {cores} cores: {total / cores / 3600:.1f} h)")


if __name__ == "__main__":
    main()
