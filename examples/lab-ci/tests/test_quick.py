"""The lab's checks of its quick plan against the simulated rig (public API and plugin only)."""

import json
import signal
import subprocess
import sys

import pytest

import bench
from bench.testing import drop_out_after, interrupt_after, with_limits, write_rig_file

PLAN = "plans/quick.toml"


def output_off(run):
    events = [json.loads(line) for line in (run.path / "events.jsonl").read_text().splitlines() if line.strip()]
    return [e for e in events if e["event"] == "output_off"]


def test_the_quick_plan_completes_with_one_row_per_step(sim_rig, tmp_path):
    plan = bench.load_plan(PLAN)
    run = bench.run(plan, sim_rig, tmp_path / "run", report=False)
    assert run.status == "completed"
    steps = run.steps()
    assert len(steps) == 6
    assert sorted(set(steps["target_force_N"])) == [0.5, 2.0]
    assert (steps["compliance_abs_m_per_N"] > 0).all()
    assert output_off(run)[-1]["confirmed"] is True


def test_ctrl_c_leaves_the_output_off_and_the_run_resumable(sim_rig, tmp_path):
    out = tmp_path / "run"
    with interrupt_after(out, 3, signal.SIGINT), pytest.raises(KeyboardInterrupt):
        bench.run(PLAN, sim_rig, out, report=False)
    run = bench.open_run(out)
    assert run.status == "interrupted"
    assert output_off(run)[-1]["confirmed"] is True
    assert len(run.resume(report=False).steps()) == 6


def test_a_force_limit_below_the_top_level_stops_the_run_safely(sim_rig, tmp_path):
    with pytest.raises(bench.BenchError, match="force"):     # refused before anything is switched on
        bench.run(PLAN, with_limits(sim_rig, force_N=1.0), tmp_path / "run", report=False)
    assert not (tmp_path / "run" / "steps").exists()


def test_a_daq_that_drops_out_ends_the_run_with_the_output_off(sim_servers, tmp_path):
    out = tmp_path / "run"
    with drop_out_after(sim_servers, out, 2, "daq"):
        run = bench.run(PLAN, sim_servers.rig, out, report=False)
    assert run.status == "instrument error"
    assert output_off(run)[-1]["confirmed"] is True


def test_the_script_runs_in_its_own_process_against_the_served_rig(sim_rig, tmp_path):
    rig_file = write_rig_file(sim_rig, tmp_path / "rig.toml")       # the servers' loopback URLs
    proc = subprocess.run([sys.executable, "scripts/run_quick.py", str(tmp_path / "run"), str(rig_file)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("completed: 6 steps")
    assert len(bench.open_run(tmp_path / "run").steps()) == 6
