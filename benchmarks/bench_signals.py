"""The random-signal campaign (issue 24): `bench run` in a process of its own against twins
held by this process; at a random moment after the output came on, one of SIGHUP, SIGQUIT,
SIGTERM, SIGINT; on every other run the terminal's pipes are closed first (writes then
raise BrokenPipe).  Per run: exit code, the generator twin's own output state and `OUTP?`
over a new link, the `output_off` event and its confirmation, run.json's status.  Bar:
every run exit 130, output off and confirmed, status interrupted.  The test suite runs a
seeded sample of three (tests/bench/test_signals.py).

    python benchmarks/bench_signals.py [--runs 24] [--seed 24]   (delays 0-1.5 s after the output came on)
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.storage import RunStore  # noqa: E402
from drivers import ScpiFunctionGenerator, start_twins  # noqa: E402
from sim.rig import RigModel, SimulatedRig  # noqa: E402
from tests.bench.test_signals import bench_run, campaign_moments, stop  # noqa: E402


def one(tmp: Path, twins, signum: int, delay: float, closed: bool) -> dict:
    out = tmp / "run"
    pipe = subprocess.PIPE if closed else subprocess.DEVNULL
    proc = bench_run(tmp, twins, out, stdout=pipe, stderr=pipe)
    try:
        t0 = time.monotonic()
        while not twins.generator.state.output_on:
            if proc.poll() is not None or time.monotonic() - t0 > 90:
                return {"outcome": f"ended ({proc.returncode}) before the output came on"}
            time.sleep(0.01)
        if closed:
            proc.stdout.close()
            proc.stderr.close()
        time.sleep(delay)
        proc.send_signal(signum)
        rc = proc.wait(timeout=60)
    finally:
        stop(proc)
    with ScpiFunctionGenerator(twins.generator_url) as gen:
        outp = gen.output_enabled()
    events = RunStore(out).events()
    offs = [e.get("confirmed") for e in events if e["event"] == "output_off"]
    status = RunStore(out).metadata.get("status")
    ok = rc == 130 and not outp and not twins.generator.state.output_on and offs == [True] and status == "interrupted"
    return {"outcome": "ok" if ok else f"rc {rc}, OUTP? {int(outp)}, output_off {offs}, status {status}"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=24)
    ap.add_argument("--seed", type=int, default=24)
    args = ap.parse_args()
    tally: Counter = Counter()
    with start_twins(SimulatedRig(RigModel(seed=3))) as twins:
        for i, (signum, delay) in enumerate(campaign_moments(args.runs, args.seed)):
            with tempfile.TemporaryDirectory() as tmp:
                r = one(Path(tmp), twins, signum, delay, closed=i % 2 == 0)
            name = signal.Signals(signum).name
            tally[(name, r["outcome"] == "ok")] += 1
            print(f"{i:3d} {name:8s} +{delay:4.2f} s {'pipes closed' if i % 2 == 0 else 'pipes open  '} "
                  f"{r['outcome']}", flush=True)
    for (name, ok), n in sorted(tally.items()):
        print(f"{name:8s} {'ok' if ok else 'FAILED'}: {n}")


if __name__ == "__main__":
    main()
