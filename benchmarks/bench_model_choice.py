"""Which friction model (issue 41 items 3-4, decision 0078) over the issue's cases
(benchtools/friction_cases.py: the independent simulators, 6 levels 0.1-1.5 x the friction
level x 15 frequencies, 90 steps, the rig's noise), several seeds each: per case and seed
the model named, the preferred model's held-out error against the Masing control's (the
noise's held-out error, same grid and noise, the same run), and the analysis's CPU seconds
(``bench analyze``'s analyze_steps on one core, the clean Masing case's time beside it).

Every fitted model of sim.discrepancy.rivals.FITTED has its cases here (LuGre and GMS since
decision 0086); each row also gives the named model's reduced chi-square and each rival
fit's CPU seconds.

Bars: the right family named; held-out error within twice the noise's; median CPU per
90-step case at most 15 s, maximum 30 s.

    python benchmarks/bench_model_choice.py [--cases dahl,dahl_i2,...] [--seeds 2] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.sources import load_source  # noqa: E402
from benchtools.friction_cases import CASES, write_case  # noqa: E402
from sim.discrepancy import analyze_steps  # noqa: E402
from sim.discrepancy.rivals import FITTED  # noqa: E402

REFERENCE = "masing_n15"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(n for n, c in CASES.items() if c.model in FITTED))
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    names = [n for n in args.cases.split(",") if n]
    unknown = [n for n in names if n not in CASES]
    if unknown:
        print(f"--cases: unknown {', '.join(unknown)} (known: {', '.join(CASES)})", file=sys.stderr)
        return 2
    if REFERENCE not in names:
        names.insert(0, REFERENCE)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            for name in names:
                path, truth = write_case(name, tmp, seed=seed)
                steps = load_source(path).steps
                t0 = time.process_time()
                d = analyze_steps(steps).to_dict()
                cpu = time.process_time() - t0
                fm = d["friction_models"]
                row = next(r for r in fm["table"] if r["model"] == d["friction_model"])
                rows.append(dict(case=name, seed=seed, truth=truth["friction_model"], named=d["friction_model"],
                                 heldout=row.get("heldout_error"), masing_heldout=fm["table"][0]["heldout_error"],
                                 causes=[c["id"] for c in d["causes"] if c["kind"] != "artefact"],
                                 unexplained=d["unexplained"], steps=len(steps), cpu_s=cpu,
                                 reduced_chi2=row.get("reduced_chi2"),
                                 model_s={r["model"]: r.get("seconds") for r in fm["table"] if r["fitted"]}))
                r = rows[-1]
                print(f"{name:12s} seed {seed}  {r['steps']:3d} steps  named {r['named']:12s} (truth {r['truth']:12s})"
                      f"  held-out {100 * r['heldout']:.3f} % (Masing {100 * r['masing_heldout']:.2f} %)"
                      f"  rchi2 {r['reduced_chi2']:.3g}  causes {r['causes']}  {cpu:5.1f} s  (fits: "
                      + ", ".join(f"{k} {v:.1f}" for k, v in r["model_s"].items() if k != "masing") + " s)", flush=True)
    noise = {r["seed"]: r["heldout"] for r in rows if r["case"] == REFERENCE}
    right = sum(r["named"] == r["truth"] for r in rows)
    within = sum(r["heldout"] <= 2 * noise[r["seed"]] for r in rows)
    cpu = [r["cpu_s"] for r in rows]
    print(f"\nright family {right}/{len(rows)}; held-out within 2x the noise {within}/{len(rows)}; "
          f"CPU median {statistics.median(cpu):.1f} s, max {max(cpu):.1f} s (bars 15 s, 30 s); "
          f"clean Masing {statistics.median(r['cpu_s'] for r in rows if r['case'] == REFERENCE):.1f} s")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
