"""`bench` in a process of its own, for the tests that need a real process and real
signals (and for benchmarks/bench_signals.py): start it, wait on what it writes, stop it.

The twins stay in the calling process (``rig_toml_for``), so the generator's own state
judges "off" after the process has gone.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from benchtools import REPO
from benchtools.plans import MANY_FREQS, fast_plan_toml

BENCH = [sys.executable, "-m", "bench.cli"]


def bench_process(*args: str, **popen) -> subprocess.Popen:
    """``bench ARGS`` started in the source tree (``popen``: Popen's own arguments)."""
    return subprocess.Popen([*BENCH, *args], cwd=popen.pop("cwd", REPO), **popen)


def bench_done(*args: str, **run) -> subprocess.CompletedProcess:
    """``bench ARGS`` run to its end, its output captured as text."""
    return subprocess.run([*BENCH, *args], cwd=run.pop("cwd", REPO), capture_output=True, text=True, **run)


def bench_main(*args) -> int:
    """``bench ARGS`` in this process (:func:`bench.cli.main`; paths and numbers as text): its exit code."""
    from bench.cli import main
    return main([str(a) for a in args])


def finished(proc: subprocess.Popen, timeout_s: float = 60) -> subprocess.CompletedProcess:
    """A process started with text pipes, waited for: its exit code and output."""
    out, err = proc.communicate(timeout=timeout_s)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def stop(proc: subprocess.Popen) -> None:
    """Kill a process still running (the ``finally`` of every test that starts one)."""
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def wait_for(condition, timeout_s: float, what: str, proc=None, poll_s: float = 0.01) -> None:
    """Poll ``condition`` until it holds; fail naming ``what`` on a timeout or when ``proc``
    exits first."""
    import pytest
    deadline = time.monotonic() + timeout_s
    while not condition():
        if proc is not None and proc.poll() is not None:
            pytest.fail(f"bench exited ({proc.returncode}) before {what}")
        if time.monotonic() > deadline:
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(poll_s)


def step_files(run: Path) -> list[Path]:
    return sorted((run / "steps").glob("*.json")) if (run / "steps").is_dir() else []


def driving(out: Path, twins) -> bool:
    """A step is stored and the generator's output is on."""
    return bool(step_files(out)) and twins.generator.state.output_on


def meta(out: Path) -> dict:
    return json.loads((out / "run.json").read_text())


def event_kinds(out: Path) -> list[str]:
    from bench.storage import RunStore
    return [e["event"] for e in RunStore(out).events()]


def rig_toml_for(twins) -> str:
    """A non-simulated rig whose instruments are the given twins (another process's view)."""
    return textwrap.dedent(f"""\
        [rig]
        name = "twins held by the test"
        simulated = false
        [rig.instruments]
        generator = "{twins.generator_url}"
        sensor = "{twins.sensor_url}"
        daq = "{twins.daq_bridge_url}"
        [rig.calibration]
        force_V_per_N = 0.0225
        accel_V_per_m_s2 = 0.0102
        disp_V_per_m = 8000.0
        amp_gain_N_per_V = 20.0
        [rig.limits]
        drive_V = 7.0
        force_N = 130.0
        disp_m = 0.9e-3
        accel_m_s2 = 20.0
        """)


def write_inputs(tmp: Path, twins, freqs=MANY_FREQS) -> tuple[Path, Path]:
    """plan.toml (fast steps, far more than a test gets to) and rig.toml (the twins)."""
    (tmp / "rig.toml").write_text(rig_toml_for(twins))
    (tmp / "plan.toml").write_text(fast_plan_toml(freqs))
    return tmp / "plan.toml", tmp / "rig.toml"


def bench_run(tmp: Path, twins, out: Path, **popen) -> subprocess.Popen:
    """``bench run`` of ``write_inputs``'s plan on the twins into ``out``, no report."""
    plan, rig = write_inputs(tmp, twins)
    return bench_process("run", "--plan", str(plan), "--rig", str(rig), "--out", str(out), "--no-report", **popen)
