"""Benchmark of `bench twin` (issue 18's bars): does the plan run on the twin reproduce its source?

Each case is a generated source written as a foreign UFF58 file (no bench tags; one load
case per step): ``masing`` from the independent solve_ivp simulator
(benchtools/independent_masing.py, no code shared with sim/), every catalog cause and every
plant form beyond the catalog (cubic_spring, quadratic_damping, asymmetric_friction: the
discovered terms) from the RK4 plant with that effect hidden in it (sim.discrepancy.cases,
written as another program writes UFF58), ``line_interference`` a clean case with a 50 Hz
line added to the displacement records (the artefact kind).  ``shaker_run`` is a run
directory (`bench run` on the simulated rig with a non-default electrodynamic shaker), the
source whose drive-voltage-to-force ratio the twin's shaker is fitted to; for it the force
control's iterations per step of source and twin run are printed too.  Per case: `bench twin` (analysis, rig.toml, plan.toml), the plan run on the
twin through the instrument twins (`bench run`), `bench compare` of source and run; then
the same for a plain Masing twin (the base model's F_s, x_s, n, m only).  Prints per case
the causes named, what could not be put in the plant, the rms difference of the first-
harmonic compliance (and accelerance) over the matched steps for the twin and the plain
twin, and the times.  Bar: the twin within 2 % rms on every case.

    python benchmarks/bench_twin.py [--kinds masing,viscous_damping,...] [--seed 0 | --seeds 1,5,...] [--levels 3] [--freqs 8] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from bench.compare import compare_sources  # noqa: E402
from bench.config import load_plan, load_rig  # noqa: E402
from bench.session import run_plan  # noqa: E402
from bench.sources import load_source  # noqa: E402
from bench.twin import make_twin  # noqa: E402
from benchtools.independent_masing import generate_uff  # noqa: E402
from benchtools.twin_sources import shaker_plan, shaker_rig, write_foreign_uff  # noqa: E402
from sim.discrepancy.cases import CATALOG, OUTSIDE, make_case  # noqa: E402

KINDS = ("masing",) + CATALOG + OUTSIDE + ("line_interference", "shaker_run")
BAR = 0.02
LINE = dict(channel="disp", freq_Hz=50.0, relative_amplitude=0.02)    # x_s per unit


def iterations(run: Path) -> dict[str, int]:
    from bench.storage import RunStore
    return {r["key"]: int(r["control_iterations"]) for r in RunStore.open(run).results(warn=False)}


def make_source(kind: str, seed: int, levels: int, freqs: int, out: Path) -> tuple[Path, dict]:
    path = out / f"{kind}-{seed}.uff"
    if kind == "masing":
        rng = np.random.default_rng(seed)
        F_s, x_s, m = rng.uniform(4, 30), math.exp(rng.uniform(math.log(5e-6), math.log(40e-6))), rng.uniform(3, 20)
        n = float(rng.choice([rng.uniform(0.4, 0.8), rng.uniform(1.3, 2.6)]))
        f_res = math.sqrt(F_s / (x_s * m)) / (2 * math.pi)
        generate_uff(path, F_s, x_s, n, m, list(np.linspace(0.15, 0.8, levels) * F_s),
                     list(np.geomspace(0.4 * f_res, 2.5 * f_res, freqs)), seed=seed)
        return path, dict(F_s_N=F_s, x_s_m=x_s, n=n, mass_kg=m)
    if kind == "shaker_run":
        path = out / "source-run"
        # the default rig (F_s 10 N): its small-amplitude resonance near 80 Hz, where the force drops out
        plan = shaker_plan(out / "plan.toml", levels=tuple(np.round(np.linspace(1.0, 7.0, levels), 2)),
                           freqs=tuple(np.round(np.geomspace(25.0, 300.0, freqs), 1)))
        run_plan(load_plan(plan), load_rig(shaker_rig(out / "rig.toml")), path, identify=False)
        return path, dict(F_s_N=10.0, x_s_m=10e-6, n=1.5, mass_kg=10.0)
    if kind == "line_interference":
        case = make_case(seed, (), levels=levels, freqs=freqs)
        line = dict(channel=LINE["channel"], freq_Hz=LINE["freq_Hz"], amplitude=LINE["relative_amplitude"] * case.rig["x_s_m"])
        write_foreign_uff(case, path, line=line)
        return path, dict(case.rig, **{f"line_{k}": v for k, v in line.items()})
    case = make_case(seed, (kind,), levels=levels, freqs=freqs)
    write_foreign_uff(case, path)
    return path, dict(case.rig, **case.effects[kind])


def run_case(kind: str, seed: int, levels: int, freqs: int, out: Path) -> dict:
    out = out / f"{kind}-{seed}"
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    src_path, truth = make_source(kind, seed, levels, freqs, out)
    src = load_source(src_path)
    row = dict(kind=kind, seed=seed, truth=truth, steps=len(src.steps), t_source_s=time.perf_counter() - t0)
    for label, plain in (("twin", False), ("plain", True)):
        t0 = time.perf_counter()
        twin, paths = make_twin(src_path, out / "twin" / "analysis" if plain else None, out / label, plain=plain, src=src)
        t_twin = time.perf_counter() - t0
        t0 = time.perf_counter()
        store = run_plan(load_plan(paths["plan"]), load_rig(paths["rig"]), out / f"run-{label}", identify=False)
        t_run = time.perf_counter() - t0
        c = compare_sources(src, out / f"run-{label}", BAR)
        o = c["overall"]
        row[label] = dict(causes=twin.causes, applied=list(twin.applied), not_in_plant=twin.not_in_plant,
                          status=store.metadata["status"], matched=c["matched"],
                          rms_compliance=o["compliance"]["rms_rel_diff"], rms_accelerance=o["accelerance"]["rms_rel_diff"],
                          rms_compliance_all=o["compliance"]["rms_rel_diff_all"], judged=o["compliance"]["judged"],
                          noise_units=o["compliance"]["rms_noise_units"], t_twin_s=t_twin, t_run_s=t_run,
                          shaker={k: v for k, v in twin.rig["rig"]["model"].items() if k.startswith("shaker_")
                                  or k == "amp_gain_N_per_V"})
        if kind == "shaker_run":
            a, b = iterations(src_path), iterations(out / f"run-{label}")
            row[label]["iterations"] = dict(source=sum(a.values()), twin_run=sum(b[k] for k in a if k in b),
                                            steps=len(set(a) & set(b)))
    return row


def _pct(x) -> str:
    return "n/a" if x is None else f"{100 * x:.3f}%"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kinds", default=",".join(KINDS), help=f"comma-separated, from {','.join(KINDS)}")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--seeds", default="", help="comma-separated case seeds, one per kind (default 100 seed + i)")
    ap.add_argument("--levels", type=int, default=3)
    ap.add_argument("--freqs", type=int, default=8)
    ap.add_argument("--out", help="keep the sources, twins and runs here (default: a temporary directory)")
    ap.add_argument("--json", help="write the rows here")
    a = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    kinds = [k for k in a.kinds.split(",") if k]
    bad = [k for k in kinds if k not in KINDS]
    if bad:
        ap.error(f"unknown kinds {bad}; known: {KINDS}")
    tmp = None if a.out else tempfile.TemporaryDirectory(prefix="bench-twin-")
    out = Path(a.out or tmp.name)
    print(f"bench twin: {len(kinds)} cases, {a.levels} levels x {a.freqs} frequencies, foreign UFF58 sources")
    print("C rms: rms relative difference of the first-harmonic compliance over the steps precise enough to judge "
          "2 % (bench compare); all: over every matched step")
    print(f"{'case':<24} {'causes named':<40} {'twin C rms':>10} {'all':>7} {'A rms':>7} {'plain C rms':>11} "
          f"{'all':>7} {'judged/matched/source':>21} {'twin s':>6} {'run s':>6}")
    rows = []
    for i, kind in enumerate(kinds):
        seeds = [int(x) for x in a.seeds.split(",")] if a.seeds else []
        r = run_case(kind, seeds[i] if i < len(seeds) else 100 * a.seed + i, a.levels, a.freqs, out)
        rows.append(r)
        t, p = r["twin"], r["plain"]
        print(f"{kind + '-' + str(r['seed']):<24} {','.join(t['causes']) or '-':<40} {_pct(t['rms_compliance']):>10} "
              f"{_pct(t['rms_compliance_all']):>7} {_pct(t['rms_accelerance']):>7} {_pct(p['rms_compliance']):>11} "
              f"{_pct(p['rms_compliance_all']):>7} {t['judged']:>9}/{t['matched']}/{r['steps']:<5} "
              f"{t['t_twin_s']:6.0f} {t['t_run_s']:6.0f}", flush=True)
        for which in ("twin", "plain"):
            if "iterations" in r[which]:
                it = r[which]["iterations"]
                print(f"{'':<24} {which}: force-control iterations over {it['steps']} steps: source "
                      f"{it['source']}, run on the twin {it['twin_run']}; twin's shaker {r[which]['shaker']}")
        for item in t["not_in_plant"]:
            print(f"{'':<24} not in the plant: {item['cause']}: {item['reason']}")
    ok = [r for r in rows if r["twin"]["rms_compliance"] is not None and r["twin"]["rms_compliance"] <= BAR]
    med = lambda which, key: 100 * np.median([r[which][key] if r[which][key] is not None else np.inf  # noqa: E731
                                              for r in rows])
    print(f"\ntwin within {100 * BAR:g} % rms (compliance, judged steps): {len(ok)}/{len(rows)}; median twin "
          f"{med('twin', 'rms_compliance'):.3f} % ({med('twin', 'rms_compliance_all'):.3f} % over all matched steps), "
          f"median plain Masing twin {med('plain', 'rms_compliance'):.3f} % ({med('plain', 'rms_compliance_all'):.3f} %)")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1, default=str))
    if tmp:
        tmp.cleanup()


if __name__ == "__main__":
    main()
