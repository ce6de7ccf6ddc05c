"""The public Python API (`import bench`) and the pytest plugin (`bench.testing`), issue 34:
what a script, a notebook and a lab's CI get, and that every safety promise of the command
line holds when the API is called from a script (decision record 0055)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

import bench
from bench.config import DEFAULTS
from benchtools.procs import bench_done, bench_process, step_files, stop, wait_for

TINY = {"name": "api test", "levels_N": [0.5, 2.0],
        "frequencies": {"list_Hz": [40.0, 80.0, 160.0], "direction": "up"},
        "control": {"settle_cycles": 6, "min_settle_s": 0.0, "measure_cycles": 6, "control_cycles": 3,
                    "ramp_s": 0.05}}


def events(out: Path) -> list[dict]:
    return [json.loads(x) for x in (out / "events.jsonl").read_text().splitlines() if x.strip()]


def output_off_confirmed(out: Path) -> bool:
    offs = [e for e in events(out) if e["event"] == "output_off"]
    return bool(offs) and offs[-1]["confirmed"] is True


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("api") / "run"
    plan = bench.plan_from_dict(TINY)
    return plan, bench.run(plan, bench.load_rig(DEFAULTS / "sim_rig.toml"), out, labels={"lubricant": "ISO VG 32"},
                           report=False)


def test_import_bench_stays_light_and_names_its_public_api():
    code = ("import sys, bench; heavy = [m for m in ('numpy', 'scipy', 'numba', 'matplotlib', 'pandas') "
            "if m in sys.modules]; print(heavy); print(sorted(bench.__all__))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.splitlines()
    assert out[0] == "[]"
    for name in ("load_rig", "load_plan", "run", "open_run", "Run", "Plan", "Rig", "BenchError"):
        assert name in out[1]
    assert callable(bench.run) and bench.Run.__module__ == "bench.api"


def test_a_run_gives_one_documented_row_per_planned_step(tiny_run):
    plan, run = tiny_run
    assert run.status == "completed"
    steps = run.steps()
    assert list(steps.columns) == list(bench.STEP_COLUMNS)
    assert len(steps) == len(plan.schedule()) == 6
    assert sorted(set(steps["target_force_N"])) == [0.5, 2.0]
    assert sorted(set(steps["freq_Hz"])) == [40.0, 80.0, 160.0]
    assert set(steps["kind"]) == {"sweep"}
    # the force the control held is the plan's level, within the plan's tolerance
    assert ((steps["force_N"] / steps["target_force_N"] - 1).abs() <= plan.force_tolerance + 1e-9).all()
    assert run.labels == {"lubricant": "ISO VG 32"}
    assert output_off_confirmed(run.path)


def test_open_run_reads_the_same_run_and_its_identification(tiny_run):
    _, run = tiny_run
    again = bench.open_run(run.path)
    assert again.steps().equals(run.steps())
    assert again.plan == run.plan
    assert again.rig.name == run.rig.name
    ident = again.identification
    assert ident is not None and set(ident["values"]) >= {"F_s_N", "x_s_m", "n", "mass_kg"}
    assert again.check() == []
    assert again.backbone().empty


def test_bad_input_is_named_and_nothing_is_written(tmp_path):
    with pytest.raises(bench.ConfigurationError, match="levels_N"):
        bench.plan_from_dict({**TINY, "levels_N": [-1.0]})
    with pytest.raises(bench.ConfigurationError, match="no_such.toml"):
        bench.load_plan(tmp_path / "no_such.toml")
    with pytest.raises(TypeError, match="plan"):
        bench.run(42, DEFAULTS / "sim_rig.toml", tmp_path / "run")
    with pytest.raises(bench.RunDirectoryError):
        bench.open_run(tmp_path)
    assert not (tmp_path / "run").exists()


SCRIPT = """\
import sys, bench
plan = bench.plan_from_dict({plan!r})
rig = bench.load_rig({rig!r})
calls = []
def progress(done, total, note):
    calls.append(done)
    if {raise_at} and done >= {raise_at}:
        raise RuntimeError("the caller's callback failed")
bench.run(plan, rig, {out!r}, progress=progress, report=False)
"""


def script(tmp_path: Path, out: Path, raise_at: int = 0, levels=(0.5, 2.0)) -> Path:
    plan = {**TINY, "levels_N": list(levels)}
    path = tmp_path / "script.py"
    path.write_text(SCRIPT.format(plan=plan, rig=str(DEFAULTS / "sim_rig.toml"), out=str(out), raise_at=raise_at))
    return path


def wait_steps(out: Path, n: int, proc: subprocess.Popen, timeout_s: float = 180) -> None:
    wait_for(lambda: len(step_files(out)) >= n, timeout_s, f"{n} steps", proc, poll_s=0.05)


def test_ctrl_c_in_a_script_leaves_the_output_off_and_the_run_resumes_once_free(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, str(script(tmp_path, out))], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_steps(out, 2, proc)
        with pytest.raises(bench.BenchError, match="in use"):     # the lock holds across processes
            bench.open_run(out).resume(report=False)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        stop(proc)
    assert proc.returncode != 0 and "KeyboardInterrupt" in err
    run = bench.open_run(out)
    assert run.status == "interrupted"
    assert output_off_confirmed(out)
    done = len(run.steps())
    assert 2 <= done < 6
    assert len(run.resume(report=False).steps()) == 6


def test_an_exception_in_the_callers_progress_callback_leaves_the_output_off(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, str(script(tmp_path, out, raise_at=3))], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode != 0 and "the caller's callback failed" in proc.stderr
    run = bench.open_run(out)
    assert run.status == "failed"
    assert output_off_confirmed(out)
    assert len(run.steps()) == 3
    assert len(run.resume(report=False).steps()) == 6


def test_the_plugins_rig_is_served_on_loopback_and_runs_a_plan(sim_servers, tmp_path):
    rig = sim_servers.rig
    assert not rig.simulated
    for url in (rig.generator_url, rig.sensor_url, rig.daq_url):
        assert "127.0.0.1" in url
    run = bench.run(bench.plan_from_dict({**TINY, "levels_N": [1.0]}), rig, tmp_path / "run", report=False)
    assert run.status == "completed" and len(run.steps()) == 3
    # the twins served it: the generator twin saw the drive and was left off
    assert sim_servers.twins.generator.state.output_on is False


def test_the_factory_checks_model_keys_as_the_rig_file_does(sim_rig_factory):
    with pytest.raises(bench.ConfigurationError, match="viscous_N_s_per_m"):
        sim_rig_factory(viscous_N_s_per_m=-5.0)
    servers = sim_rig_factory(DEFAULTS / "sim_rig_pitch.toml", viscous_N_s_per_m=40.0)
    assert servers.model.viscous_N_s_per_m == 40.0 and servers.model.pitch_inertia_kg_m2 > 0


def test_the_plugin_is_registered_with_pytest_by_the_installed_package():
    """pytest loads it in any project that installs the package (`make examples`, run by CI,
    runs examples/lab-ci's tests with it from the wheel in a fresh virtual environment)."""
    from importlib.metadata import entry_points
    eps = {ep.name: ep.value for ep in entry_points(group="pytest11")}
    assert eps.get("guideway_bench") == "bench.testing"


def test_a_notebooks_script_can_read_every_table_of_a_phase_resonance_run(tmp_path):
    plan = bench.plan_from_dict({**_backbone_plan_dict(), "levels_N": [1.0]})
    run = bench.run(plan, DEFAULTS / "sim_rig.toml", tmp_path / "run", report=False)
    points = run.backbone()
    assert len(points) == 1 and bool(points["locked"].iloc[0])
    steps = run.steps()
    assert list(steps["kind"]) == ["backbone"]


def _backbone_plan_dict() -> dict:
    import tomllib
    return tomllib.loads((DEFAULTS / "backbone_plan.toml").read_text())["plan"]


# ---------------------------------------------------------------------------- sequences

SEQ_PLAN = """\
[plan]
name = "{name}"
levels_N = {levels}
[plan.frequencies]
list_Hz = [40.0, 80.0, 160.0]
direction = "up"
[plan.control]
settle_cycles = 6
min_settle_s = 0.0
measure_cycles = 6
control_cycles = 3
ramp_s = 0.05
"""


def write_sequence(tmp: Path, second_levels: str = "[0.5, 2.0]", extra: str = "") -> Path:
    (tmp / "plans").mkdir()
    (tmp / "plans" / "a.toml").write_text(SEQ_PLAN.format(name="a", levels="[1.0]"))
    (tmp / "plans" / "b.toml").write_text(SEQ_PLAN.format(name="b", levels=second_levels))
    (tmp / "seq.toml").write_text(f"""\
[sequence]
name = "oils overnight"
[[sequence.entry]]
name = "oil-a"
plan = "plans/a.toml"
rig = "{DEFAULTS / 'sim_rig.toml'}"
labels = {{ lubricant = "ISO VG 32" }}
[[sequence.entry]]
name = "oil-b"
plan = "plans/b.toml"
rig = "{DEFAULTS / 'sim_rig.toml'}"
labels = {{ lubricant = "ISO VG 68" }}
{extra}""")
    return tmp / "seq.toml"


def test_a_sequence_refuses_every_bad_entry_before_anything_runs(tmp_path):
    seq = write_sequence(tmp_path, second_levels="[-2.0]", extra='[[sequence.entry]]\nname = "oil-a"\nplan = "none.toml"\n')
    proc = bench_done("sequence", str(seq), "--out", str(tmp_path / "out"), timeout=120)
    assert proc.returncode == 2
    err = proc.stderr
    assert "[[sequence.entry]] 2: plan" in err and "levels_N" in err              # the bad level of entry 2
    assert "[[sequence.entry]] 3: name: 'oil-a' is used by an earlier entry" in err
    assert "[[sequence.entry]] 3: rig: the path of a rig file is needed" in err
    assert not (tmp_path / "out").exists()


def test_a_sequence_interrupted_in_its_second_entry_resumes_to_both_complete(tmp_path):
    seq, out = write_sequence(tmp_path), tmp_path / "out"
    proc = bench_process("sequence", str(seq), "--out", str(out), "--no-report", stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        wait_steps(out / "oil-b", 2, proc)
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=120)
    finally:
        stop(proc)
    assert proc.returncode == 130
    assert bench.open_run(out / "oil-a").status == "completed"
    assert bench.open_run(out / "oil-b").status == "interrupted"
    assert output_off_confirmed(out / "oil-b")
    report = (out / "report.md").read_text()
    assert "1 of 2 entries completed" in report and f"bench resume {out}" in report
    again = bench_done("resume", str(out), "--no-report", timeout=300)
    assert again.returncode == 0, again.stderr
    a, b = bench.open_run(out / "oil-a"), bench.open_run(out / "oil-b")
    assert (a.status, b.status) == ("completed", "completed")
    assert len(a.steps()) == 3 and len(b.steps()) == 6
    assert a.labels == {"lubricant": "ISO VG 32", "sequence": "oils overnight", "entry": "oil-a"}
    report = (out / "report.md").read_text()
    assert "2 of 2 entries completed." in report
    assert report.count("| completed |") == 2
