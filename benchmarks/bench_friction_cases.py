"""Generation time of the cases of issue 41 (benchtools/friction_cases.py): each case's
90-step file made by the independent simulators, then read back by bench.sources.load_source.

Prints per case the steps written, the process seconds of the generation, its ratio to the
Masing control's (benchtools/independent_masing.py, made in the same run), and the steps
the reader keeps, flags and rejects (the rival models without linear damping keep the
carriage's free vibration after a frequency change: Iwan's below its first slip, GMS's
through sigma_2 only).

    python benchmarks/bench_friction_cases.py [--cases dahl,lugre,...] [--levels 6] [--freqs 15] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.sources import load_source  # noqa: E402
from benchtools.friction_cases import CASES, FREQS, LEVELS, write_case  # noqa: E402

REFERENCE = "masing_n15"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--levels", type=int, default=len(LEVELS), help="the first N levels of the grid (the top one kept)")
    ap.add_argument("--freqs", type=int, default=len(FREQS), help="every k-th frequency so that N remain")
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    names = [n for n in args.cases.split(",") if n]
    unknown = [n for n in names if n not in CASES]
    if unknown:
        print(f"--cases: unknown {', '.join(unknown)} (known: {', '.join(CASES)})", file=sys.stderr)
        return 2
    if REFERENCE not in names:
        names.insert(0, REFERENCE)
    levels = LEVELS[:args.levels - 1] + LEVELS[-1:] if args.levels < len(LEVELS) else LEVELS
    stride = max(1, len(FREQS) // max(1, args.freqs))
    freqs = FREQS[::stride][:args.freqs]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            path, truth = write_case(name, tmp, levels=levels, freqs=freqs)
            src = load_source(path)
            flagged = sum(s.quality.status == "flagged" for s in src.steps)
            rows.append(dict(case=name, model=truth["friction_model"], steps=truth["steps"],
                             seconds=truth["generation_s"], kept=len(src.steps), flagged=flagged,
                             rejected=len(src.rejected), f_r_Hz=truth["friction_resonance_Hz"]))
            print(f"{name:12s} {truth['steps']:3d} steps  {truth['generation_s']:6.1f} s  "
                  f"f_r {truth['friction_resonance_Hz']:5.1f} Hz  kept {len(src.steps)} (flagged {flagged}) "
                  f"rejected {len(src.rejected)}", flush=True)
    ref = next(r["seconds"] for r in rows if r["case"] == REFERENCE)
    print("\ncase          s/step   x Masing control")
    for r in rows:
        print(f"{r['case']:12s} {r['seconds'] / r['steps']:7.3f}   {r['seconds'] / ref:6.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
