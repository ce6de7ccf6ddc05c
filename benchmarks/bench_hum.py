"""A humming case's analysis time against a clean one's, in one run (issue 43 item 2).

The plant is issue 43's rig without its pitching mode (m = 8.25 kg, F_s = 26.86 N,
x_s = 37 um, n = 0.406 < 1), integrated once by the independent simulator
(``benchtools.independent_masing.generate_uff_variants``); each variant is the same plant
with its own mains line on the probe (amplitude relative to x_s; 50 Hz lies near drive
harmonics of several steps) and the noise of issue 43 (force 0.3 % of F_s, acceleration
0.5 % of its rms, displacement 0.2 % of x_s).  Each file is analysed as ``bench analyze FILE``
does (``bench.analyze.analyze_source``: read and check the steps, the fits, the page), in
this one process, one BLAS thread; the clean case is analysed between the humming ones, so
each ratio is to the clean runs of the same stretch of load.

Prints per variant: CPU seconds (``time.process_time``), the line fits made
(``sim.artefacts.detectors._fit_sinusoid`` calls, counted), the causes named, the ratio
to the median clean CPU time (issue 43's bar: at most 2) and the largest shift of a named
parameter against the clean case's, in the clean case's half-widths (the same result).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")     # one core
os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

RIG = dict(F_s_N=26.86, x_s_m=37e-6, n=0.406, mass_kg=8.25)
# name -> (mains Hz, amplitude / x_s)
VARIANTS = {"clean": (0.0, 0.0), "hum50_0.1": (50.0, 0.1), "hum50_0.3": (50.0, 0.3), "hum60_0.2": (60.0, 0.2)}


def make_cases(cache: Path, levels: int, freqs: int, settle: int, seed: int) -> dict[str, Path]:
    """The variants' UFF58 files (simulated once into ``cache`` unless there already)."""
    from benchtools.independent_masing import generate_uff_variants
    from sim.discrepancy.cases import plan_grid

    cache.mkdir(parents=True, exist_ok=True)
    paths = {k: cache / f"hum43_{levels}x{freqs}_s{settle}_seed{seed}_{k}.uff" for k in VARIANTS}
    if all(p.exists() for p in paths.values()):
        return paths
    lv, fr = plan_grid(RIG, levels, freqs, 0.85)
    parts = {p.with_suffix(".part"): VARIANTS[k] for k, p in paths.items()}
    generate_uff_variants({p: (hz, rel * RIG["x_s_m"]) for p, (hz, rel) in parts.items()},
                          RIG["F_s_N"], RIG["x_s_m"], RIG["n"], RIG["mass_kg"], list(lv), list(fr),
                          settle=settle, settle_first=settle, measure=8, seed=seed, rtol=1e-9)
    for part, path in zip(parts, paths.values()):
        part.rename(path)
    return paths


def analyse(path: Path, out: Path) -> dict:
    """One ``bench analyze FILE``: CPU seconds, line fits, causes and parameters."""
    from bench.analyze import analyze_source
    from sim.artefacts import detectors

    fits = [0]
    fit = detectors._fit_sinusoid

    def counted(*args, **kw):
        fits[0] += 1
        return fit(*args, **kw)

    detectors._fit_sinusoid = counted          # the line searches (detectors._find_lines) call it through the module
    try:
        c0 = time.process_time()
        d = analyze_source(path, out_dir=out)
        cpu = time.process_time() - c0
    finally:
        detectors._fit_sinusoid = fit
    return dict(cpu_s=cpu, fits=fits[0], causes=[c["id"] for c in d["causes"]],
                physical=sorted(c["id"] for c in d["causes"] if c["kind"] != "artefact"),
                parameters=d["parameters"], steps=len(d["steps_used"]), rejected=len(d["steps_rejected"]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--levels", type=int, default=3)
    ap.add_argument("--freqs", type=int, default=10)
    ap.add_argument("--settle", type=int, default=25)
    ap.add_argument("--seed", type=int, default=43)
    ap.add_argument("--repeats", type=int, default=1, help="rounds of clean + every humming variant")
    ap.add_argument("--cache", help="directory for the generated files (kept between runs)")
    args = ap.parse_args(argv)
    cache = Path(args.cache) if args.cache else Path(tempfile.mkdtemp(prefix="bench_hum_"))
    t0 = time.perf_counter()
    paths = make_cases(cache, args.levels, args.freqs, args.settle, args.seed)
    print(f"bench_hum: {args.levels} levels x {args.freqs} frequencies, settle {args.settle}, "
          f"n = {RIG['n']}, x_s = {RIG['x_s_m'] * 1e6:g} um; files in {cache} ({time.perf_counter() - t0:.0f} s)")
    out = Path(tempfile.mkdtemp(prefix="bench_hum_out_"))
    analyse(paths["clean"], out / "warm")               # compiles the kernels (not timed)
    rows: dict[str, list[dict]] = {k: [] for k in VARIANTS}
    for _ in range(args.repeats):
        for k in VARIANTS:
            if k != "clean":
                rows["clean"].append(analyse(paths["clean"], out / "clean"))
                rows[k].append(analyse(paths[k], out / k))
    clean_cpu = float(np.median([r["cpu_s"] for r in rows["clean"]]))
    ref = rows["clean"][0]
    print(f"  {'case':12s} {'CPU s':>7s} {'/clean':>7s} {'line fits':>9s} {'steps':>5s} {'rej':>4s}  "
          "physical causes; largest parameter shift (clean half-widths); artefacts")
    worst = 0.0
    for k, rs in rows.items():
        cpu = float(np.median([r["cpu_s"] for r in rs]))
        r = rs[0]
        shift = max(abs(r["parameters"][p]["value"] - ref["parameters"][p]["value"])
                    / (0.5 * (ref["parameters"][p]["high"] - ref["parameters"][p]["low"])) for p in ref["parameters"])
        if k != "clean":
            worst = max(worst, cpu / clean_cpu)
        arts = sorted(set(r["causes"]) - set(r["physical"]))
        print(f"  {k:12s} {cpu:7.1f} {cpu / clean_cpu:7.2f} {r['fits']:9d} {r['steps']:5d} {r['rejected']:4d}  "
              f"{','.join(r['physical']) or '-'}; {shift:.2f}; {','.join(arts) or '-'}")
    print(f"  worst hum / clean (median clean of {len(rows['clean'])} runs): {worst:.2f} x (bar: 2.00)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
