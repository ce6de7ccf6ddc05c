"""Coverage of `bench modes`' 95 % intervals on imported FRFs the code under test did not
make (issue 42's last bar, decision record 0085).

The independent Masing simulator (benchtools/independent_masing.py through
benchtools/frf_coverage.py) at force-controlled levels 1, 2, 3.5 N (written as pyuff UFF58
accelerance with force spectra) and at held displacements 2 and 6 um (a pandas CSV of X/F
with the force per point), 0.2 % complex noise, a 1.5 Hz grid placed at random about the
peak per seed; `bench import`, then `bench modes`' estimates, each interval (resonance, the
fit's, the energy balance's and the half-power damping ratio) against the simulator's own
truth.  Prints each level's truth, each quantity's coverage per level kind and per level,
and the counts a true 95 % interval gives 99 % of the time (two-sided binomial): both
under- and over-coverage are reported.

    python benchmarks/bench_import_coverage.py [--seeds 40] [--out DIR]
"""

from __future__ import annotations

import argparse
import collections
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchtools.frf_coverage import (  # noqa: E402
    FORCE_LEVELS_N,
    HELD_M,
    QUANTITIES,
    Simulator,
    binomial_range,
    run_trial,
    stored_truth,
    truth,
)


def main_(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=40)
    ap.add_argument("--out", help="keep the files, runs and rows.json here (default: a temporary directory)")
    ap.add_argument("--recompute", action="store_true",
                    help="the truths from the simulator (about 4 min) instead of benchtools.frf_coverage.TRUTHS")
    args = ap.parse_args(argv)
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench_import_coverage_"))
    sim = Simulator()
    t0 = time.process_time()
    levels = [("force", P) for P in FORCE_LEVELS_N] + [("disp", X) for X in HELD_M]
    truths = [truth(sim, *k) if args.recompute else stored_truth(*k) for k in levels]
    print(f"truths ({'computed' if args.recompute else 'stored'}, {time.process_time() - t0:.0f} s CPU):")
    for t in truths:
        unit = "N" if t.kind == "force" else "m"
        print(f"  {t.kind:5s} {t.level:g} {unit}: resonance {t.resonance_Hz:.4f} Hz, damping energy balance "
              f"{100 * t.energy_balance:.3f} %, half-power {100 * t.half_power:.3f} %, fit {100 * t.fit:.3f} %")
    rows: list[dict] = []
    for seed in range(1, args.seeds + 1):
        t0 = time.process_time()
        rows += run_trial(sim, truths, seed, out / f"seed{seed}")
        print(f"seed {seed}: {time.process_time() - t0:.1f} s CPU", flush=True)
        (out / "rows.json").write_text(json.dumps(rows, indent=0))
    held: dict = collections.Counter()
    claimed: dict = collections.Counter()
    missing: dict = collections.Counter()
    for r in rows:
        for key in ((r["kind"], r["quantity"]), (r["kind"], r["quantity"], r["level"])):
            if math.isfinite(r["low"]) and math.isfinite(r["high"]):
                claimed[key] += 1
                held[key] += r["held"]
            else:
                missing[key] += 1
    ok = True
    print("coverage of the 95 % intervals (held / given; 'none': no interval given):")
    for kind in ("force", "disp"):
        for q in QUANTITIES:
            n = claimed[(kind, q)]
            lo, hi = binomial_range(n) if n else (0, 0)
            verdict = "ok" if lo <= held[(kind, q)] <= hi else ("UNDER" if held[(kind, q)] < lo else "OVER")
            ok &= verdict == "ok" and n > 0
            per = ", ".join(f"{lv:g}: {held[(kind, q, lv)]}/{claimed[(kind, q, lv)]}"
                            for lv in (FORCE_LEVELS_N if kind == "force" else HELD_M))
            print(f"  {kind:5s} {q:15s} {held[(kind, q)]:4d}/{n:<4d} ({100 * held[(kind, q)] / max(n, 1):5.1f} %; "
                  f"a true 95 % gives {lo}-{hi}) {verdict:5s} none {missing[(kind, q)]}; per level {per}")
    print("all within the binomial range" if ok else "SOME COVERAGE OUTSIDE THE BINOMIAL RANGE")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main_())
