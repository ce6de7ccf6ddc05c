"""The random-signal campaign (issues 24 and 30): `bench run` in a process of its own; at a
random moment, one of SIGHUP, SIGQUIT, SIGTERM, SIGINT; on every other run the terminal's
pipes are closed first (writes then raise BrokenPipe).

Cases (``--cases``, each run in turn):

- ``stepped_sine``, ``response_controlled``, ``phase_resonance``: against twins held by
  this process, the signal 0-1.5 s after the generator's output came on;
- ``dwell``: a stepped sine refined at the feed resonance with a dwell of 600 cycles, the
  signal 0-1.5 s after bench.log says the dwell began;
- ``report``: the small stepped sine on the simulated rig (its model curve comes from the
  numba RK4 kernel), the signal 0-1.5 s after "run completed" (the output already off).

Per run: exit code, the generator twin's own output state and `OUTP?` over a new link,
the `output_off` events and their confirmation, run.json's status; for a dwell whether it
was cut (no dwell step stored); for the report whether it is complete (report.md with the
model figure) and whether stderr shows an exception swallowed ("exception set",
"Exception ignored").  Bars (decision records 0040, 0051): exit 130 on every run; output
off and confirmed, status interrupted (the report case: completed, the report complete).
The test suite runs seeded samples (tests/bench/test_signals.py, test_signal_edges.py).

    python benchmarks/bench_signals.py [--runs 4] [--seed 30] [--cases stepped_sine,dwell,...]
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.storage import RunStore  # noqa: E402
from benchtools.plans import FAST_CONTROL  # noqa: E402
from benchtools.procs import bench_process, rig_toml_for, stop  # noqa: E402
from drivers import ScpiFunctionGenerator, start_twins  # noqa: E402
from sim.rig import RigModel, SimulatedRig  # noqa: E402

FAST = textwrap.indent(FAST_CONTROL, "    ")    # under the plans' indentation
PLANS = {
    "stepped_sine": """\
        [plan]
        levels_N = [1.0]
        [plan.frequencies]
        list_Hz = [40.0, 50.0, 60.0, 70.0, 80.0, 90.0, 100.0, 120.0, 140.0, 160.0, 180.0, 200.0]
        """ + FAST,
    "response_controlled": """\
        [plan]
        procedure = "response_controlled"
        [plan.response]
        quantity = "disp"
        levels = [3e-6]
        [plan.frequencies]
        list_Hz = [40.0, 50.0, 55.0, 60.0, 65.0, 70.0, 80.0, 90.0, 100.0, 120.0]
        """ + FAST,
    "phase_resonance": """\
        [plan]
        procedure = "phase_resonance"
        levels_N = [0.3, 1.0, 3.0]
        [plan.backbone]
        start_Hz = 80.0
        [plan.control]
        settle_cycles = 10
        measure_cycles = 10
        ramp_s = 0.0
        """,
    "dwell": """\
        [plan]
        levels_N = [1.0]
        [plan.frequencies]
        start_Hz = 30.0
        stop_Hz = 300.0
        points = 12
        [plan.resonance]
        refine = true
        modes = ["feed"]
        max_steps = 3
        dwell_cycles = 600
        """ + FAST,
    "report": """\
        [plan]
        levels_N = [1.0]
        [plan.frequencies]
        list_Hz = [60.0, 80.0]
        """ + FAST,
}
SIGNALS = (signal.SIGHUP, signal.SIGQUIT, signal.SIGTERM, signal.SIGINT)


def bench_run(tmp: Path, case: str, rig: Path | None, out: Path, **popen) -> subprocess.Popen:
    (tmp / "plan.toml").write_text(textwrap.dedent(PLANS[case]))
    return bench_process("run", "--plan", str(tmp / "plan.toml"), *(["--rig", str(rig)] if rig else []),
                         "--out", str(out), *([] if case == "report" else ["--no-report"]),
                         env={**os.environ, "PYTHONUNBUFFERED": "1"}, **popen)


def _wait(condition, proc, timeout_s: float = 300) -> str | None:
    t0 = time.monotonic()
    while not condition():
        if proc.poll() is not None:
            return f"ended ({proc.returncode}) first"
        if time.monotonic() - t0 > timeout_s:
            return "timed out"
        time.sleep(0.01)
    return None


def one(tmp: Path, twins, case: str, signum: int, delay: float, closed: bool) -> dict:
    out = tmp / "run"
    rig = None
    if case != "report":
        rig = tmp / "rig.toml"
        rig.write_text(rig_toml_for(twins))
    proc = bench_run(tmp, case, rig, out, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        if case == "report":
            for line in proc.stdout:
                if line.startswith("run completed"):
                    break
            late = None if proc.poll() is None else f"ended ({proc.returncode}) first"
        elif case == "dwell":
            log = out / "bench.log"
            late = _wait(lambda: log.is_file() and "dwell of" in log.read_text(), proc)
        else:
            late = _wait(lambda: twins.generator.state.output_on, proc)
        if late:
            return {"ok": False, "outcome": f"the moment never came: bench {late}"}
        if closed:
            proc.stdout.close()
            proc.stderr.close()
        time.sleep(delay)
        proc.send_signal(signum)
        if closed:
            rc, err = proc.wait(timeout=180), ""
        else:
            _, err = proc.communicate(timeout=180)
            rc = proc.returncode
    finally:
        stop(proc)
    store = RunStore(out)
    events = store.events()
    offs = [e.get("confirmed") for e in events if e["event"] == "output_off"]
    status = store.metadata.get("status")
    swallowed = "exception set" in err or "Exception ignored" in err
    if case == "report":
        md = out / "report" / "report.md"
        complete = md.is_file() and "model_vs_measurement.png" in md.read_text()
        ok = rc == 130 and status == "completed" and complete and offs == [True] and not swallowed
        what = f"report {'complete' if complete else 'INCOMPLETE'}"
    else:
        with ScpiFunctionGenerator(twins.generator_url) as gen:
            outp = gen.output_enabled()
        ok = (rc == 130 and not outp and not twins.generator.state.output_on and offs == [True]
              and status == "interrupted" and not swallowed)
        what = f"OUTP? {int(outp)}"
        if case == "dwell":
            what += ", dwell " + ("cut" if not list((out / "steps").glob("*-W*.json")) else "stored first")
    return {"ok": ok, "outcome": f"rc {rc}, {what}, output_off {offs}, status {status}"
                                 + (", an exception swallowed" if swallowed else "")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=4, help="runs per case")
    ap.add_argument("--seed", type=int, default=30)
    ap.add_argument("--cases", default=",".join(PLANS), help=f"comma-separated, of {', '.join(PLANS)}")
    args = ap.parse_args()
    cases = args.cases.split(",")
    rng = random.Random(args.seed)
    tally: Counter = Counter()
    t0 = time.monotonic()
    with start_twins(SimulatedRig(RigModel(seed=3))) as twins:
        i = 0
        for case in cases:
            for _ in range(args.runs):
                signum, delay = rng.choice(SIGNALS), rng.uniform(0.0, 1.5)
                with tempfile.TemporaryDirectory() as tmp:
                    r = one(Path(tmp), twins, case, signum, delay, closed=i % 2 == 0)
                name = signal.Signals(signum).name
                tally[(case, r["ok"])] += 1
                print(f"{i:3d} {case:19s} {name:8s} +{delay:4.2f} s {'pipes closed' if i % 2 == 0 else 'pipes open  '} "
                      f"{'ok' if r['ok'] else 'FAILED'}: {r['outcome']}", flush=True)
                i += 1
    for (case, ok), n in sorted(tally.items()):
        print(f"{case:19s} {'ok' if ok else 'FAILED'}: {n}")
    print(f"{i} runs in {time.monotonic() - t0:.0f} s")


if __name__ == "__main__":
    main()
