"""Signals at the edges of a session (issue 30 items 6 and 7, decision record 0051): the
program catches the ending signals from before it parses its command line until it has
exited, and a signal while the report is written (output already off) is honoured once
the report is complete, never swallowed inside a numba kernel or a finalizer.

Each test runs `bench` as a process of its own and sends it a real signal at the named
moment: the moment the process first catches SIGHUP (read from /proc/PID/status), after
the run's `end` event, after the "run completed" line that opens the report.
"""

from __future__ import annotations

import json
import signal
import subprocess
import time
from pathlib import Path

import pytest

from bench.storage import RunStore
from benchtools.plans import fast_plan_toml
from benchtools.procs import bench_process, event_kinds, meta, rig_toml_for, wait_for
from drivers import start_twins
from sim.rig import RigModel, SimulatedRig

pytestmark = pytest.mark.skipif(not Path("/proc/self/status").is_file(), reason="reads /proc/PID/status")

PLAN = fast_plan_toml([60.0, 80.0], name="signal edges", direction="up")


def catches(pid: int, signum: int) -> bool:
    """Whether the process has a handler for ``signum`` now (SigCgt of /proc/PID/status)."""
    try:
        with open(f"/proc/{pid}/status") as f:
            mask = next(line for line in f if line.startswith("SigCgt:")).split()[1]
    except (OSError, StopIteration):
        return False
    return bool(int(mask, 16) >> (signum - 1) & 1)


def bench(*args: str, **popen) -> subprocess.Popen:
    return bench_process(*args, text=True, env={**__import__("os").environ, "PYTHONUNBUFFERED": "1"}, **popen)


def signal_when_caught(proc: subprocess.Popen, signum: int) -> None:
    """Send ``signum`` the moment the process first catches it."""
    deadline = time.monotonic() + 60
    while not catches(proc.pid, signum):
        if proc.poll() is not None:
            pytest.fail(f"bench exited ({proc.returncode}) before it caught signal {signum}")
        if time.monotonic() > deadline:
            pytest.fail(f"bench never caught signal {signum}")
    proc.send_signal(signum)


@pytest.mark.timeout(60)
def test_the_handlers_are_in_place_before_the_command_line_is_parsed():
    """`bench resume` without its run directory is a usage error (exit 2) once argparse has
    read the command line; SIGHUP at the first moment the process catches it comes before
    that, and ends it as an interrupt: 130, one line (today's main caught it only once the
    command had started, so this process exited 2 first, and a signal in that window took
    the default action: exit -1)."""
    proc = bench("resume", stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    signal_when_caught(proc, signal.SIGHUP)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["bench: interrupted (signal 1)"]


@pytest.mark.timeout(120)
def test_a_signal_before_the_first_instrument_is_opened_ends_the_run_with_nothing_on(tmp_path):
    """`bench run` against twins held by this test: SIGHUP at the first moment the process
    catches it.  Exit 130; the generator was never switched on; no run directory was left
    `running`."""
    with start_twins(SimulatedRig(RigModel(seed=3))) as twins:
        (tmp_path / "plan.toml").write_text(PLAN)
        (tmp_path / "rig.toml").write_text(rig_toml_for(twins))
        out = tmp_path / "run"
        proc = bench("run", "--plan", str(tmp_path / "plan.toml"), "--rig", str(tmp_path / "rig.toml"),
                     "--out", str(out), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        signal_when_caught(proc, signal.SIGHUP)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, err
        assert "interrupted (signal 1)" in err
        assert not twins.generator.state.output_on
    if (out / "run.json").exists():
        assert meta(out)["status"] == "interrupted"
        assert "output_off" not in event_kinds(out)


@pytest.mark.timeout(180)
def test_signals_after_the_end_event_change_nothing(tmp_path):
    """The issue's case: two signals (SIGHUP, then SIGTERM) after the `end` event of a
    completed run with --no-report.  The run's work is done, so the exit code is the run's
    (0), and what the process says of the signals is that they came after it; today's main
    ended on them with the default action (exit -1, -15)."""
    (tmp_path / "plan.toml").write_text(PLAN)
    out = tmp_path / "run"
    proc = bench("run", "--plan", str(tmp_path / "plan.toml"), "--out", str(out), "--no-report",
                 stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        wait_for(lambda: (out / "events.jsonl").is_file() and '"end"' in (out / "events.jsonl").read_text(),
                 150, "the end event", proc)
        proc.send_signal(signal.SIGHUP)
        time.sleep(0.02)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert meta(out)["status"] == "completed"
    said = [line for line in err.splitlines() if "signal 1" in line or "signal 15" in line]
    assert said == [] or said[-1].startswith("bench: signal") and said[-1].endswith(   # or none: ignored at exit
        "after the work was done: nothing left to stop"), said
    assert "interrupted" not in err


@pytest.mark.timeout(240)
def test_a_signal_while_the_report_is_written_is_honoured_once_it_is_complete(tmp_path):
    """Two SIGHUPs just after "run completed" (the report, the rig model's curve computed by
    the numba RK4 kernel first, is being written): exit 130 and a complete report, model
    curve included; no exception swallowed in a kernel or a finalizer.  Today's main: a
    report cut short (or, 3 times in 9, exit 0 with the model curve missing)."""
    (tmp_path / "plan.toml").write_text(PLAN)
    out = tmp_path / "run"
    proc = bench("run", "--plan", str(tmp_path / "plan.toml"), "--out", str(out),
                 stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        for line in proc.stdout:
            if line.startswith("run completed"):
                break
        proc.send_signal(signal.SIGHUP)
        time.sleep(0.05)
        proc.send_signal(signal.SIGHUP)
        rest = proc.stdout.read()         # the same buffered reader: nothing it holds is lost
        err = proc.stderr.read()
        proc.wait(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "(complete; then signal 1)" in rest, (rest, err)
    assert "signal 1 while the report is written (the output is off): finishing it first" in err
    report = (out / "report" / "report.md").read_text()
    figures = [name for name in ("compliance.png", "accelerance.png", "quality.png", "model_vs_measurement.png")
               if f"]({name})" in report or f"({name})" in report]
    assert "model_vs_measurement.png" in figures, report[:2000]
    assert all((out / "report" / name).stat().st_size > 0 for name in figures)
    assert "exception set" not in err and "Exception ignored" not in err, err
    assert meta(out)["status"] == "completed"
    assert json.loads((out / "run.json").read_text())["steps_done"] == 2
    assert [e["event"] for e in RunStore(out).events()][-1] == "end"


def test_a_signal_during_a_completed_runs_switch_off_stops_the_report_from_beginning(tmp_path, mocker, capsys):
    """SIGHUP while a completed run records its end (the switch-off's hold-off is in place,
    the measuring over): the run stays completed, the report is not begun (it is work the
    signal came before), exit 130, and the message says how to write it.  The real signal
    is sent from inside RunStore.finish (pytest-mock as the injector of the moment)."""
    import os

    from bench.cli import main
    from bench.storage import RunStore as Store

    real = Store.finish

    def finish(self, *a, **k):
        os.kill(os.getpid(), signal.SIGHUP)
        for _ in range(10_000):            # the handler runs between bytecodes
            pass
        return real(self, *a, **k)

    mocker.patch.object(Store, "finish", autospec=True, side_effect=finish)
    (tmp_path / "plan.toml").write_text(PLAN)
    out = tmp_path / "run"
    assert main(["run", "--plan", str(tmp_path / "plan.toml"), "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert "signal 1 while switching the output off: finishing that first" in err
    assert f"report not written: signal 1 before it began; `bench report {out}` writes it" in err
    assert meta(out)["status"] == "completed"
    assert not (out / "report").exists()
