"""Benchmark of the discrepancy analysis over generated cases (issue 9's bars).

Each case (``run_case(seed)``) is a seeded random rig with one catalog effect hidden in it
(or none: every seventh case is clean), measured through the RK4 plant on the issue's grid
(5 levels x 18 frequencies, the issue's noise), then analysed from a guess 0.7-1.3 times
the truth.  Prints the detection rate per cause, the false-alarm rate on clean cases (a
cause named, and separately "unexplained"), wrong causes named, the median out-of-sample
gain and the time per case, with the analysis time also as a ratio to one base
identification (sim.identify) of the same case measured in the same run.

    python benchmarks/bench_analysis.py [--cases 56] [--first 0] [--workers 1] [--scheduler tcp://host:port] [--json out.json]

The case loop is a plain map over ``run_case``, so a scheduler (dask) can run it too.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")     # one core per case
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from sim.discrepancy import analyze_steps  # noqa: E402
from sim.discrepancy.cases import CATALOG, make_case, observable_rig, truth_size  # noqa: E402
from sim.identify import Identifier, synthesize  # noqa: E402

KINDS = ("clean",) + CATALOG


def case_kind(seed: int) -> str:
    return KINDS[seed % len(KINDS)]


def run_case(seed: int) -> dict:
    """One generated case, analysed; a flat row of what happened."""
    kind = case_kind(seed)
    t0 = time.perf_counter()
    case = make_case(1000 + seed, () if kind == "clean" else (kind,))
    t_gen = time.perf_counter() - t0
    rng = np.random.default_rng(seed)
    guess = {k: v * rng.uniform(0.7, 1.3) for k, v in case.rig.items()}
    t0 = time.perf_counter()
    ident = Identifier(guess, 9)
    for s in case.steps:
        ident.add(s.harmonics)
    ident.fit(max_nfev=200)
    t_ref = time.perf_counter() - t0
    t0 = time.perf_counter()
    try:
        a = analyze_steps(case.steps, guess)
    except Exception as e:          # a failure is a result: count it, keep going
        return dict(seed=seed, kind=kind, failed=f"{type(e).__name__}: {e}", n=case.rig["n"],
                    steps=len(case.steps), named=[], unexplained=False, detected=False, wrong=[],
                    heldout_before=np.nan, heldout_after=np.nan, base_chi2=np.nan, final_chi2=np.nan,
                    t_generate_s=t_gen, t_analysis_s=time.perf_counter() - t0, t_identify_s=t_ref)
    t_an = time.perf_counter() - t0
    named = a.causes
    x = synthesize(np.array([st.harmonics.disp[:9] for st in case.steps]), 256)
    amp_over_xs = float(0.5 * (x.max(axis=1) - x.min(axis=1)).max() / case.rig["x_s_m"])
    first = a.selection.named[0] if a.selection.named else None
    size_error = covered = None
    if kind in named:
        name, truth = truth_size(case, kind)
        if name:
            p = a.cause_parameters(kind, a.final)[name]
            size_error = p["value"] / truth - 1
            covered = bool(p["low"] <= truth <= p["high"])
    # the final model's F_s, x_s, n, m against the rig (as the data can show it), when the
    # final model is the true one: pulls (error / standard error, in the fit's coordinates)
    base_pulls = None
    if set(named) == ({kind} - {"clean"}) and not a.unexplained:
        obs = observable_rig(case)
        truth = np.array([np.log(obs["F_s_N"]), np.log(obs["x_s_m"]), obs["n"], np.log(obs["mass_kg"])])
        base_pulls = ((a.final.theta[:4] - truth) / np.sqrt(np.diag(a.final.cov)[:4])).tolist()
    return dict(seed=seed, kind=kind, n=case.rig["n"], steps=len(case.steps), named=named,
                unexplained=a.unexplained, detected=kind in named, wrong=[c for c in named if c != kind],
                heldout_before=a.selection.heldout_base,
                heldout_after=(a.selection.named[-1].heldout_error if first else a.selection.heldout_base),
                base_chi2=a.base.reduced_chi2, final_chi2=a.final.reduced_chi2,
                size_error=size_error, interval_covers_truth=covered, base_pulls=base_pulls,
                amplitude_over_true_x_s=amp_over_xs,
                spring_separable=a.spring_separable(),
                t_generate_s=t_gen, t_analysis_s=t_an, t_identify_s=t_ref)


def summarise(rows: list[dict]) -> str:
    out = []
    failed = [r for r in rows if r.get("failed")]
    if failed:
        out.append(f"analysis failed in {len(failed)} case(s): " + "; ".join(f"{r['seed']}: {r['failed']}" for r in failed))
    out.append(f"{'cause':30s} {'cases':>5s} {'named':>6s} {'rate':>6s} {'n<1':>7s} {'wrong':>6s} {'unexpl':>6s}")
    eff = [r for r in rows if r["kind"] != "clean"]
    for kind in CATALOG:
        rs = [r for r in eff if r["kind"] == kind]
        if not rs:
            out.append(f"{kind:30s} {'(no cases)':>20s}")
            continue
        lo = [r for r in rs if r["n"] < 1]
        out.append(f"{kind:30s} {len(rs):5d} {sum(r['detected'] for r in rs):6d} "
                   f"{100 * np.mean([r['detected'] for r in rs]):5.0f}% "
                   f"{sum(r['detected'] for r in lo):3d}/{len(lo):<3d} {sum(bool(r['wrong']) for r in rs):6d} "
                   f"{sum(r['unexplained'] for r in rs):6d}")
    pre = [r for r in eff if r["kind"] == "linear_spring" and r.get("amplitude_over_true_x_s", 2.0) < 1.0]
    if pre:
        out.append(f"linear_spring cases that never left pre-rolling (amplitude < x_s, where a spring is a "
                   f"reparametrised Masing curve): {len(pre)}, named {sum(r['detected'] for r in pre)}, "
                   f"verdict warns in {sum(not r['spring_separable'] for r in pre)}")
    if eff:
        sep = [r for r in eff if r not in pre]
        out.append(f"{'all effects':30s} {len(eff):5d} {sum(r['detected'] for r in eff):6d} "
                   f"{100 * np.mean([r['detected'] for r in eff]):5.0f}%   (separable: "
                   f"{sum(r['detected'] for r in sep)}/{len(sep)}, {100 * np.mean([r['detected'] for r in sep]):.0f} %)")
    clean = [r for r in rows if r["kind"] == "clean"]
    if clean:
        fa = [bool(r["named"]) for r in clean]
        un = [r["unexplained"] for r in clean]
        lo = [r for r in clean if r["n"] < 1]
        out.append(f"clean cases: {len(clean)}, a cause named in {sum(fa)} ({100 * np.mean(fa):.0f} %), "
                   f"'unexplained' in {sum(un)} ({100 * np.mean(un):.0f} %; {sum(r['unexplained'] for r in lo)} "
                   f"of {len(lo)} with n < 1); base reduced chi2 median {np.median([r['base_chi2'] for r in clean]):.2f}")
    det = [r for r in eff if r["detected"]]
    if det:
        out.append(f"median held-out error (detected cases): {100 * np.median([r['heldout_before'] for r in det]):.2f} % "
                   f"-> {100 * np.median([r['heldout_after'] for r in det]):.3f} %")
    sized = [r for r in det if r.get("size_error") is not None]
    if sized:
        out.append(f"effect size (c, k, f_p, delay, gain, alpha): median |error| "
                   f"{100 * np.median([abs(r['size_error']) for r in sized]):.2f} %, 95 % interval covers the "
                   f"truth in {sum(r['interval_covers_truth'] for r in sized)} of {len(sized)}")
    pulls = np.array([r["base_pulls"] for r in rows if r.get("base_pulls")])
    if pulls.size:
        cover = np.abs(pulls) < 1.959964
        out.append(f"F_s, x_s, n, m of the final model (cases where it is the true model): 95 % intervals cover "
                   f"the rig's values in {cover.sum()} of {cover.size} ({100 * cover.mean():.1f} %); pulls "
                   f"(error / standard error) rms " + ", ".join(f"{k} {v:.2f}" for k, v in zip(
                       ("F_s", "x_s", "n", "m"), np.sqrt((pulls ** 2).mean(axis=0)))))
    ta = np.array([r["t_analysis_s"] for r in rows])
    tr = np.array([r["t_identify_s"] for r in rows])
    tg = np.array([r["t_generate_s"] for r in rows])
    out.append(f"time per case ({rows[0]['steps']} steps): analysis median {np.median(ta):.1f} s (max {ta.max():.1f} s), "
               f"{np.median(ta / tr):.1f}x one base identification; data generation median {np.median(tg):.1f} s")
    return "\n".join(out)


def _progress(row: dict) -> dict:
    """Print a case's outcome as it arrives (stderr), pass the row on."""
    print(f"case {row['seed']:3d} {row['kind']:28s} n={row['n']:.2f} named={','.join(row['named']) or '-':30s} "
          f"unexplained={row['unexplained']!s:5s} analysis {row['t_analysis_s']:.1f} s", file=sys.stderr, flush=True)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=56)
    ap.add_argument("--first", type=int, default=0, help="seed of the first case (a fresh sample: --first 56)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--scheduler", help="run the cases on this dask scheduler (tcp://host:port)")
    ap.add_argument("--json", help="write the rows here")
    args = ap.parse_args(argv)
    seeds = range(args.first, args.first + args.cases)
    t0 = time.perf_counter()
    if args.workers > 1 or args.scheduler:
        from bench.studies import map_cases  # the study engine: local cores or a dask cluster
        def done(i, total, label):
            print(f"{label}: {i}/{total} cases done, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
        rows = [_progress(r) for r in map_cases(run_case, list(seeds), scheduler=args.scheduler,
                                                  workers=args.workers, progress=done)]
    else:
        rows = list(map(_progress, map(run_case, seeds)))
    print(f"bench_analysis: {args.cases} cases in {time.perf_counter() - t0:.0f} s ({args.workers} worker(s))")
    print(summarise(rows))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
