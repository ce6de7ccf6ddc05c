"""One session at a time on a run directory and on an instrument (issue 24 item 2): an
operating-system lock held for the session's life, a second session refused naming the
holder, a lock left by a dead process taken over.  Real processes throughout."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time

import pytest

from bench import runlock
from bench.storage import RunStore
from benchtools import REPO
from benchtools.procs import (
    bench_process,
    bench_run,
    driving,
    event_kinds,
    finished,
    meta,
    stop,
    wait_for,
    write_inputs,
)
from drivers import start_twins
from sim.rig import RigModel, SimulatedRig

HOLD = """
import sys, time
from pathlib import Path
from bench import runlock
with runlock.run_dir(Path(sys.argv[1])):
    print("held", flush=True)
    time.sleep(60)
"""


def bench(*args: str) -> subprocess.Popen:
    return bench_process(*args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.mark.timeout(150)
def test_a_second_session_on_a_run_directory_in_use_is_refused_and_measures_nothing(tmp_path):
    with start_twins(SimulatedRig(RigModel(seed=3))) as twins:
        out = tmp_path / "run"
        first = bench_run(tmp_path, twins, out, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            wait_for(lambda: driving(out, twins), 60, "the first step with the output on", first)
            second = bench("resume", str(out), "--no-report")
            # the same rig from another run directory: its instruments are in use
            plan, rig = write_inputs(tmp_path, twins)
            other = bench("run", "--plan", str(plan), "--rig", str(rig), "--out", str(tmp_path / "other"),
                          "--no-report")
            second, other = finished(second), finished(other)
            assert first.poll() is None                 # the first session went on meanwhile
            first.send_signal(signal.SIGINT)
            assert first.wait(timeout=30) == 130
        finally:
            stop(first)
        assert second.returncode == 1, second.stderr
        assert f"run directory {out} is in use by process {first.pid} on {socket.gethostname()} since " \
            in second.stderr
        assert "bench run" in second.stderr and "Traceback" not in second.stderr
        assert second.stdout == ""               # refused before it counted (or set aside) any step
        assert other.returncode == 1, other.stderr
        assert f"instrument {twins.generator_url} is in use by process {first.pid}" in other.stderr
        assert f"run directory {out}" in other.stderr                   # which session holds it
        assert not (tmp_path / "other" / "run.json").exists()           # nothing written, nothing measured
        # the refused sessions left no trace in the run: no resume, each step stored once
        kinds = event_kinds(out)
        assert "resume" not in kinds and kinds.count("start") == 1 and kinds.count("end") == 1
        assert meta(out)["status"] == "interrupted"
        assert len(RunStore(out).results()) == meta(out)["steps_done"] >= 1


@pytest.mark.timeout(60)
def test_a_lock_left_by_a_dead_process_is_taken_over(tmp_path):
    (tmp_path / "run").mkdir()
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(tmp_path / "run")], cwd=REPO,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(runlock.InUse, match=f"in use by process {holder.pid} on "):
            with runlock.run_dir(tmp_path / "run"):
                pass
        holder.send_signal(signal.SIGKILL)            # dies holding it: no clean release
        holder.wait(timeout=10)
    finally:
        stop(holder)
    assert str(holder.pid) in (tmp_path / "run" / runlock.LOCK_NAME).read_text()   # its information stays
    t0 = time.monotonic()
    with runlock.run_dir(tmp_path / "run"):            # ... and the lock is free
        with runlock.run_dir(tmp_path / "run"):        # re-entrant within a process
            pass
        held_by_us = (tmp_path / "run" / runlock.LOCK_NAME).read_text()
    assert time.monotonic() - t0 < 1.0
    assert f'"pid": {__import__("os").getpid()}' in held_by_us
