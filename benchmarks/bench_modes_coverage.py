"""Coverage of the modes' intervals on the two-mode Masing rig with its declared effects
(issue 32 item 1, decision record 0061).

Two pitching rigs standing in for two lubricants (benchtools/masing_peaks.py: "A" is
bench/defaults/sim_rig_pitch.toml, speed-dependent friction; "B" its variant with viscous
damping; both without the twin's shaker, an ideal force source), the issue's plan (levels
0.3, 1, 3, 10 N, 16 log points 30-300 Hz, 9 harmonics, both modes refined, a 200-cycle
dwell) over noise seeds.  Each level's modes (`bench modes`' estimates) against the
brute-force references of benchtools.masing_peaks.REFERENCES (the independent integrator's
steady states, golden section), and the bars:

- feed: within 1 % with its interval holding the reference, or a not-`ok` status whose
  interval holds it;
- pitch: within 0.5 % with its interval holding it;
- coverage >= 90 % per mode over seeds and levels;
- the feed mode's energy-balance damping within 5 % of the reference's at 0.3-3 N.

    python benchmarks/bench_modes_coverage.py [--seeds 4] [--oils A B] [--out DIR]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.config import DEFAULTS, load_rig, parse_plan  # noqa: E402
from bench.reports import run_modes  # noqa: E402
from bench.session import run_plan  # noqa: E402
from bench.storage import RunStore  # noqa: E402
from benchtools.masing_peaks import LEVELS_N, REFERENCES, oil_model  # noqa: E402
from sim.rig import RigModel  # noqa: E402

PLAN = {"plan": {"name": "two oils, refined, dwell", "levels_N": list(LEVELS_N),
                 "frequencies": {"start_Hz": 30.0, "stop_Hz": 300.0, "points": 16},
                 "control": {"harmonics": 9},
                 "resonance": {"refine": True, "modes": ["feed", "pitch"], "dwell_cycles": 200}}}
BARS = {"feed": 0.01, "pitch": 0.005}


def campaign_run(oil: str, seed: int, out: Path, levels=LEVELS_N):
    """The plan on oil ``oil`` with noise seed ``seed`` into ``out`` (a completed run there is
    reused: ``--out`` keeps a campaign's runs)."""
    if (out / "run.json").exists():
        store = RunStore.open(out)
        if store.metadata.get("status") == "completed":
            return store
    plan = parse_plan({"plan": dict(PLAN["plan"], levels_N=list(levels))})
    rig = load_rig(DEFAULTS / "sim_rig_pitch.toml")
    rig = replace(rig, model=RigModel.from_dict(oil_model(oil)))
    return run_plan(plan, rig, out, identify=False, labels={"oil": oil}, sim_seed=seed)


def judge(e, oil: str) -> dict:
    """One estimate against its reference: the row the campaign prints."""
    ref, ref_zeta = REFERENCES[(oil, e.mode, e.level_N)]
    held = e.resonance_low_Hz <= ref <= e.resonance_high_Hz
    err = e.resonance_Hz / ref - 1 if math.isfinite(e.resonance_Hz) else math.nan
    if e.mode == "feed":
        good = held and (not e.ok or abs(err) <= BARS["feed"])
    else:
        good = held and abs(err) <= BARS["pitch"]          # a value within 0.5 %, whatever the status says
    balance = e.extra.get("energy_balance")
    eb = balance.value if balance is not None else math.nan
    return dict(oil=oil, mode=e.mode, level=e.level_N, status=e.status, f=e.resonance_Hz, lo=e.resonance_low_Hz,
                hi=e.resonance_high_Hz, ref=ref, err=err, held=held, good=good, eb=eb,
                eb_err=eb / ref_zeta - 1 if e.mode == "feed" else math.nan)


def main_(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4, help="noise seeds per oil")
    ap.add_argument("--oils", nargs="+", default=["A", "B"])
    ap.add_argument("--out", help="keep the runs here (default: a temporary directory)")
    args = ap.parse_args(argv)
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench_modes_coverage_"))
    rows = []
    for oil in args.oils:
        for seed in range(1, args.seeds + 1):
            t = time.perf_counter()
            store = campaign_run(oil, seed, out / f"oil{oil}-seed{seed}")
            modes = [e for e in run_modes(store.path).modes if (oil, e.mode, e.level_N) in REFERENCES]
            print(f"oil {oil}, seed {seed}: {len(store.results())} steps in {time.perf_counter() - t:.0f} s")
            for e in modes:
                r = judge(e, oil)
                rows.append(r)
                print(f"  {r['mode']:5s} {r['level']:4g} N  {r['status']:16s} {r['f']:8.3f} Hz [{r['lo']:8.3f}, "
                      f"{r['hi']:8.3f}]  ref {r['ref']:8.3f}  {100 * r['err']:+6.2f} %  "
                      f"{'holds' if r['held'] else 'MISSES'}  eb {100 * r['eb']:.2f} % ({100 * r['eb_err']:+.1f} %)"
                      f"{'' if r['good'] else '  FAILS'}", flush=True)
    ok = True
    for mode in ("feed", "pitch"):
        sel = [r for r in rows if r["mode"] == mode]
        held, good = sum(r["held"] for r in sel), sum(r["good"] for r in sel)
        ok &= bool(sel) and good == len(sel) and held >= 0.9 * len(sel)
        print(f"{mode}: interval holds the reference {held}/{len(sel)}; meets its bar {good}/{len(sel)}; "
              f"statuses {sorted({r['status'] for r in sel})}")
    eb = [r for r in rows if r["mode"] == "feed" and r["level"] <= 3.0]
    worst = max((abs(r["eb_err"]) for r in eb), default=math.nan)
    ok &= worst <= 0.05
    print(f"feed energy-balance damping at 0.3-3 N: largest error {100 * worst:.2f} % (bar 5 %)")
    print("all bars met" if ok else "SOME BAR NOT MET")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main_())
