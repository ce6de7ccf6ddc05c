"""Every signal that ends a session goes through the safe-off path, also with the terminal
gone (issue 24): SIGHUP when the terminal closes, SIGQUIT, and the random-signal campaign
(a small seeded sample; `benchmarks/bench_signals.py` runs a bigger one).

`bench run` runs in a process of its own against twins held by the test process, so the
generator's own state (and an `OUTP?` over a new link) judges "off" after the signal.
"""

from __future__ import annotations

import os
import pty
import random
import signal
import subprocess
import time
from pathlib import Path

import pytest

import bench.session as bench_session
from bench.storage import RunStore
from benchtools import REPO
from benchtools.plans import small_plan
from benchtools.procs import BENCH, bench_run, driving, event_kinds, meta, stop, wait_for, write_inputs
from drivers import ScpiFunctionGenerator, start_twins
from sim.rig import RigModel, SimulatedRig


def assert_safe_after(out: Path, twins, reason: str) -> None:
    """Output off (the twin's state and OUTP? over a new link), confirmed in events.jsonl,
    run.json ended as interrupted by ``reason``."""
    assert not twins.generator.state.output_on
    with ScpiFunctionGenerator(twins.generator_url) as gen:
        assert gen.output_enabled() is False                      # OUTP? -> 0
    m = meta(out)
    assert m["status"] == "interrupted", m["status"]
    events = RunStore(out).events()
    offs = [e for e in events if e["event"] == "output_off"]
    assert [e["confirmed"] for e in offs] == [True]
    assert [e["reason"] for e in events if e["event"] == "interrupted"] == [reason]
    assert event_kinds(out)[-1] == "end"


@pytest.mark.timeout(120)
def test_closing_the_terminal_switches_the_output_off(tmp_path):
    """bench runs on a pseudo-terminal it holds as its controlling terminal; the test closes
    the terminal's master side, as a closed window or a lost SSH link does: the kernel sends
    SIGHUP, and every later write to the terminal fails with EIO."""
    with start_twins(SimulatedRig(RigModel(seed=3))) as twins:
        master, slave = pty.openpty()
        out = tmp_path / "run"
        plan, rig = write_inputs(tmp_path, twins)
        proc = subprocess.Popen(["setsid", "--ctty", *BENCH, "run", "--plan", str(plan),
                                 "--rig", str(rig), "--out", str(out), "--no-report"],
                                cwd=REPO, stdin=slave, stdout=slave, stderr=slave)
        os.close(slave)
        seen = bytearray()
        try:
            os.set_blocking(master, False)

            def read_terminal() -> bool:          # keep the terminal drained while waiting
                try:
                    seen.extend(os.read(master, 65536))
                except (BlockingIOError, OSError):
                    pass
                return driving(out, twins)
            wait_for(read_terminal, 60, "the first step with the output on", proc)
            assert twins.generator.state.output_on
            os.close(master)                     # the terminal is gone: SIGHUP
            rc = proc.wait(timeout=30)
        finally:
            stop(proc)
        assert b"WARNING" in seen                # it was writing to that terminal
        assert rc == 130
        assert_safe_after(out, twins, f"signal {int(signal.SIGHUP)}")


@pytest.mark.timeout(120)
def test_sighup_with_stdout_and_stderr_closed_switches_the_output_off(tmp_path):
    """The terminal's pipes are closed before the signal (every write raises BrokenPipe):
    neither the progress line nor the closing messages may cut the switch-off short.
    (SIGQUIT with the pipes closed: the campaign's sample below.)"""
    signum = signal.SIGHUP
    with start_twins(SimulatedRig(RigModel(seed=3))) as twins:
        out = tmp_path / "run"
        proc = bench_run(tmp_path, twins, out, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            wait_for(lambda: driving(out, twins), 60, "the first step with the output on", proc)
            proc.stdout.close()
            proc.stderr.close()
            time.sleep(0.3)                      # a progress line or two into the closed pipe
            proc.send_signal(signum)
            rc = proc.wait(timeout=30)
        finally:
            stop(proc)
        assert rc == 130
        assert_safe_after(out, twins, f"signal {int(signum)}")


# --------------------------------------------------------------------------- random signals

CAMPAIGN_SEED = 24


def campaign_moments(n: int, seed: int = CAMPAIGN_SEED) -> list[tuple[int, float]]:
    """(signal, delay after the output came on) of each run of the campaign."""
    rng = random.Random(seed)
    return [(rng.choice((signal.SIGHUP, signal.SIGQUIT, signal.SIGTERM, signal.SIGINT)), rng.uniform(0.0, 1.5))
            for _ in range(n)]


@pytest.mark.timeout(180)
def test_random_signals_at_random_moments_end_with_the_output_off(tmp_path):
    """A small seeded sample of the campaign: each signal at a random moment after the
    output came on, with the terminal's pipes closed on every other run (this seed: SIGINT
    at 1.26 s and SIGQUIT at 0.29 s with the pipes closed, SIGQUIT at 0.33 s)."""
    moments = campaign_moments(3)
    assert [s for s, _ in moments] == [signal.SIGINT, signal.SIGQUIT, signal.SIGQUIT]
    with start_twins(SimulatedRig(RigModel(seed=3))) as twins:
        for i, (signum, delay) in enumerate(moments):
            out = tmp_path / f"run{i}"
            closed = i % 2 == 0
            proc = bench_run(tmp_path, twins, out, stdout=subprocess.PIPE if closed else subprocess.DEVNULL,
                             stderr=subprocess.PIPE if closed else subprocess.DEVNULL)
            try:
                wait_for(lambda: twins.generator.state.output_on, 60, "the output on", proc)  # noqa: B023
                if closed:
                    proc.stdout.close()
                    proc.stderr.close()
                time.sleep(delay)
                proc.send_signal(signum)
                rc = proc.wait(timeout=30)
            finally:
                stop(proc)
            assert rc == 130, (i, signum, delay)
            assert_safe_after(out, twins, "Ctrl-C" if signum == signal.SIGINT else f"signal {int(signum)}")


@pytest.mark.parametrize("signum", [signal.SIGHUP, signal.SIGQUIT])
def test_a_signal_inside_a_generator_query_ends_with_the_output_off_confirmed(tmp_path, mocker, caplog, signum):
    """The signal itself (not an injected exception) arrives between `VOLT?` and its reply:
    the ramp-down and the off command go over the same link, resynchronised."""
    from bench.session import run_plan

    from .test_exit_paths import SIM_RIG
    twins = mocker.spy(bench_session, "start_twins")
    real = ScpiFunctionGenerator._read_line
    sent = []

    def read_line(self, command):
        if not sent and command == "VOLT?" and twins.spy_return.generator.state.output_on \
                and len(RunStore(tmp_path / "run").results()) >= 1:
            sent.append(command)
            os.kill(os.getpid(), signum)          # delivered here, before the reply is read
            for _ in range(10_000):
                pass
        return real(self, command)

    mocker.patch.object(ScpiFunctionGenerator, "_read_line", autospec=True, side_effect=read_line)
    with pytest.raises(KeyboardInterrupt):
        run_plan(small_plan(), SIM_RIG, tmp_path / "run", sim_seed=1, identify=False)
    assert sent == ["VOLT?"]
    assert not twins.spy_return.generator.state.output_on
    events = RunStore(tmp_path / "run").events()
    assert [e["confirmed"] for e in events if e["event"] == "output_off"] == [True]
    assert [e["reason"] for e in events if e["event"] == "interrupted"] == [f"signal {int(signum)}"]
    assert meta(tmp_path / "run")["status"] == "interrupted"
    assert "resynchronising" in caplog.text and "reconnecting" not in caplog.text


def test_a_signal_while_the_run_directory_is_set_up_does_not_leave_it_running(tmp_path, mocker):
    """SIGHUP just after run.json says "running" (while the session clears old stop
    requests): latched, it acts once the path that records the end is entered."""
    from bench.session import run_plan

    from .test_exit_paths import SIM_RIG
    twins = mocker.spy(bench_session, "start_twins")
    real = bench_session.stop_request.clear

    def clear(path):
        assert meta(tmp_path / "run")["status"] == "running"
        os.kill(os.getpid(), signal.SIGHUP)
        for _ in range(10_000):
            pass
        return real(path)
    mocker.patch.object(bench_session.stop_request, "clear", side_effect=clear)
    with pytest.raises(KeyboardInterrupt):
        run_plan(small_plan(), SIM_RIG, tmp_path / "run", sim_seed=1, identify=False)
    assert meta(tmp_path / "run")["status"] == "interrupted"
    assert event_kinds(tmp_path / "run") == ["start", "interrupted", "end"]
    assert twins.call_count == 0                       # stopped before any instrument was opened
