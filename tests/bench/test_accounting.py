"""Every planned step accounted for (issue 19): `bench check`, `bench report` and `bench
resume` count a run's steps against its stored plan, not against the files that happen to
be there.  A step whose two files are both gone, or one of the pair, is missing; a step
whose files fail a check is damaged; a file no planned step owns is an orphan; each is
named by key, and `check` fails when a planned step is missing or damaged.
"""

from __future__ import annotations

import math
import shutil

import pytest

from bench.cli import ExitCode, main
from bench.storage import RunStore


def _keys(run):
    return sorted(p.stem for p in (run / "steps").glob("*.json"))


@pytest.fixture(scope="module")
def lost(small_run, tmp_path_factory):
    """A copy of the 20-step small run: one step's files both removed (the issue's case),
    one step's result removed (its raw block left), one raw block truncated, a stray file."""
    run = tmp_path_factory.mktemp("lost") / "run"
    shutil.copytree(small_run.path, run, ignore=shutil.ignore_patterns("report", "export", "analysis"))
    keys = _keys(run)
    s = run / "steps"
    gone, no_json, cut = keys[12], keys[3], keys[7]
    (s / f"{gone}.json").unlink()
    (s / f"{gone}.npz").unlink()
    (s / f"{no_json}.json").unlink()
    data = (s / f"{cut}.npz").read_bytes()
    (s / f"{cut}.npz").write_bytes(data[:len(data) // 2])
    (s / "notes.txt").write_text("a technician's note")
    return run, dict(gone=gone, no_json=no_json, cut=cut)


def test_check_counts_against_the_plan_and_names_missing_damaged_and_orphan(lost, capsys):
    run, k = lost
    acc = RunStore.open(run).account()
    assert acc.planned == 20
    assert [p.key for p in acc.missing] == sorted([k["gone"], k["no_json"]])
    assert [p.key for p in acc.damaged] == [k["cut"]]
    assert [p.path.name for p in acc.orphan] == ["notes.txt"]
    assert len(acc.intact) == 17 and not acc.complete

    assert main(["check", str(run)]) == ExitCode.FAILURE
    out = capsys.readouterr().out
    lines = out.splitlines()
    for key in (k["gone"], k["no_json"]):
        assert any(line.strip().startswith("missing") and key in line for line in lines), (key, out)
    assert any(line.strip().startswith("truncated") and k["cut"] in line for line in lines), out
    summary = lines[-1]
    assert "17 intact / 20 planned" in summary
    assert f"missing: {', '.join(sorted([k['gone'], k['no_json']]))}" in summary
    assert f"damaged: {k['cut']} (truncated)" in summary and "orphan: notes.txt" in summary


@pytest.mark.parametrize("remove", [(".json", ".npz"), (".json",)])
def test_check_fails_when_only_a_planned_step_is_missing(small_run, tmp_path, capsys, remove):
    """The issue's commands: `rm X/steps/<key>.*` or only the .json, then `bench check X`."""
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run, ignore=shutil.ignore_patterns("report", "export", "analysis"))
    key = _keys(run)[12]
    for ext in remove:
        (run / "steps" / f"{key}{ext}").unlink()
    assert main(["check", str(run)]) == ExitCode.FAILURE
    out = capsys.readouterr().out
    assert f"19 intact / 20 planned; missing: {key}; damaged: none" in out


def test_report_opens_with_steps_used_against_planned_and_why_others_were_skipped(lost):
    from bench.reports import write_report
    run, k = lost
    text = write_report(run).read_text()
    head = text.split("## Instruments")[0]
    assert "17 used / 20 planned" in head
    skipped = head.split("skipped:")[1].splitlines()[0]
    for key in k.values():
        assert key in skipped, (key, skipped)
    assert "truncated" in skipped and "missing" in skipped
    assert "**needs attention**" in head and "2 steps missing" in head and "1 step damaged" in head
    assert "20 / 20" not in head                                 # run.json's count is not the readable one
    assert "17 readable / 20 planned" in head


def test_resume_on_a_finished_intact_run_has_nothing_to_do(small_run, tmp_path, capsys, mocker):
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run, ignore=shutil.ignore_patterns("report", "export", "analysis"))
    opened = mocker.patch("bench.session.open_instruments", side_effect=AssertionError("instruments opened"))
    assert main(["resume", str(run), "--no-report"]) == ExitCode.OK
    out = capsys.readouterr().out
    assert "nothing to do" in out and "20 intact / 20 planned" in out
    assert not opened.called


def test_resume_says_what_it_measures_again(lost, tmp_path, capsys, mocker):
    """The announcement comes before anything moves (the instruments are stopped at the
    first touch: the message, not a run, is under test here; test_damage resumes for real)."""
    run = tmp_path / "run"
    shutil.copytree(lost[0], run)
    k = lost[1]
    mocker.patch("bench.session.open_instruments", side_effect=ConnectionError("no instruments in this test"))
    main(["resume", str(run), "--no-report"])
    out = capsys.readouterr().out
    line = next(line for line in out.splitlines() if "measures again" in line)
    assert line.startswith("resume: measures again 3 of 20 planned steps")
    assert f"missing: {', '.join(sorted([k['gone'], k['no_json']]))}" in line
    assert f"damaged: {k['cut']} (truncated)" in line


def test_an_adaptive_plan_is_counted_per_sweep(small_run, tmp_path, capsys):
    """adaptive_per_sweep = 3: each sweep measures 3 of its 5 frequencies, chosen online, so
    a shortfall is named by sweep, not by key."""
    import json
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run, ignore=shutil.ignore_patterns("report", "export", "analysis"))
    meta = json.loads((run / "run.json").read_text())
    meta["plan"]["adaptive_per_sweep"] = 3
    (run / "run.json").write_text(json.dumps(meta))
    by_sweep: dict[str, list[str]] = {}
    for key in _keys(run):
        by_sweep.setdefault(f"{key.split('-')[1]}-{key.split('-')[3]}", []).append(key)
    assert sorted(by_sweep) == ["L00-down", "L00-up", "L01-down", "L01-up"]
    for sweep, keys in by_sweep.items():
        for key in keys[:3 if sweep == "L00-up" else 2]:          # L00-up keeps 2 of the 3 it measures
            for ext in (".json", ".npz"):
                (run / "steps" / f"{key}{ext}").unlink()
    assert main(["check", str(run)]) == ExitCode.FAILURE
    assert "11 intact / 12 planned; missing: L00-up (1); damaged: none" in capsys.readouterr().out


SKIP_PLAN = """
[plan]
name = "run-time skip"
levels_N = [5.0, 25.0]
infeasible = "skip"
[plan.frequencies]
list_Hz = [300.0, 1000.0]
direction = "up"
[plan.limits]
drive_V = 1.6
"""
UNREACHABLE = "00003-L01-F001-up"


@pytest.fixture(scope="module")
def skip_run(tmp_path_factory):
    """A real run on the simulated rig with a step skipped at run time: 25 N at 1000 Hz.  The
    rig file's estimate (20 N/V) says 1.25 V, 1.56 V with the 1.25 margin, within the plan's
    drive limit of 1.6 V, so the dry run lets it through; the shaker really gives about 15 N/V
    at 1 kHz (the coil's pole, decision 0025), 24 N at the limit."""
    from bench.config import DEFAULTS, load_plan, load_rig
    from bench.session import run_plan
    tmp = tmp_path_factory.mktemp("skip_run")
    (tmp / "plan.toml").write_text(SKIP_PLAN)
    store = run_plan(load_plan(tmp / "plan.toml"), load_rig(DEFAULTS / "sim_rig.toml"), tmp / "run")
    assert store.metadata["status"] == "completed" and store.metadata["steps_done"] == 3
    return store.path


def _copy(run, tmp_path):
    shutil.copytree(run, tmp_path / "run", ignore=shutil.ignore_patterns("report"))
    return tmp_path / "run"


def test_a_step_skipped_at_run_time_is_counted_and_named_not_missing(skip_run, capsys):
    events = [e for e in RunStore.open(skip_run).events() if e["event"] == "step_skipped"]
    assert [e["key"] for e in events] == [UNREACHABLE]                # the run really skipped it, no files
    assert not (skip_run / "steps" / f"{UNREACHABLE}.json").exists()
    acc = RunStore.open(skip_run).account()
    assert acc.planned == 4 and len(acc.intact) == 3 and not acc.missing and not acc.damaged
    ((sk,),) = [acc.skipped]
    assert sk.key == UNREACHABLE and sk.reason.startswith("skipped at run time: force 25 N unreachable at 1000 Hz")
    assert main(["check", str(skip_run)]) == ExitCode.OK               # the plan allowed it: CI passes
    out = capsys.readouterr().out
    assert f"skipped  {UNREACHABLE}: skipped at run time: force 25 N unreachable" in out
    assert "3 intact / 4 planned; skipped at run time: 00003-L01-F001-up; missing: none" in out
    assert main(["check", "--strict", str(skip_run)]) == ExitCode.FAILURE
    capsys.readouterr()


def test_the_headline_says_a_truth_outside_its_interval_and_counts_flagged_steps_per_reason(skip_run, tmp_path):
    """Issue 33: the demo's headline read "went well ... the identified model fits" over a
    table marking x_s and n "truth in interval: **no**", and named 9 steps below the probe's
    resolution while 59 were flagged.  The truth check on a simulated rig is a note with
    how far out the estimate is; the flagged steps are counted per reason."""
    import json
    import re

    from bench.reports import write_report
    run = _copy(skip_run, tmp_path)
    meta = json.loads((run / "run.json").read_text())
    ident = meta["identification"]
    x_s = meta["rig"]["model"]["x_s_m"]
    # x_s 3 standard errors (log units) below the truth; the others as fitted
    se = 1e-4
    ident["values"]["x_s_m"] = x_s * math.exp(-3 * se)
    ident["low"]["x_s_m"], ident["high"]["x_s_m"] = x_s * math.exp(-3 * se - 1.959964 * se), x_s * math.exp(-3 * se + 1.959964 * se)
    (run / "run.json").write_text(json.dumps(meta))
    text = write_report(run).read_text()
    head = text.split("## Instruments")[0]
    line = next(ln for ln in head.splitlines() if ln.startswith("Overall:"))
    assert "the simulated rig's truth lies outside the 95 % interval of x_s (3 standard errors out)" in line, line
    assert "F_s (" not in line and "n (" not in line
    flagged = [ln for ln in text.splitlines() if "| flagged |" in ln]
    m = re.search(r"(\d+) steps? flagged by the step-quality check, used with their noise as weight \(([^;]*);", line)
    if flagged:
        assert m and int(m[1]) == len(flagged), line
        counts = [int(c.split()[0]) for c in m[2].split(", ")]
        assert max(counts) <= len(flagged) <= sum(counts)
    else:
        assert m is None


def test_a_run_time_skip_the_plan_does_not_allow_is_missing(skip_run, tmp_path):
    """The same events under a plan that says "refuse" (run.json edited): the step is missing."""
    import json
    run = _copy(skip_run, tmp_path)
    meta = json.loads((run / "run.json").read_text())
    meta["plan"]["infeasible"] = "refuse"
    (run / "run.json").write_text(json.dumps(meta))
    acc = RunStore.open(run).account()
    assert [p.key for p in acc.missing] == [UNREACHABLE] and not acc.skipped
    assert main(["check", str(run)]) == ExitCode.FAILURE


def test_the_report_names_the_skipped_step_and_the_run_went_well(skip_run, tmp_path):
    from bench.reports import write_report
    run = _copy(skip_run, tmp_path)
    head = write_report(run).read_text().split("## Instruments")[0]
    assert "**3 used / 4 planned**; skipped: 00003-L01-F001-up (skipped at run time: force 25 N unreachable" in head
    assert "Overall: **went well" in head and "1 skipped at run time as the plan allows" in head
    # flagged steps (used) are notes of a run that went well, counted per reason (issue 33)
    assert "with notes" not in head or "flagged by the step-quality check" in head
    assert "missing" not in head


def test_resume_leaves_skipped_steps_alone_unless_asked(skip_run, tmp_path, capsys, mocker):
    run = _copy(skip_run, tmp_path)
    opened = mocker.patch("bench.session.open_instruments", side_effect=AssertionError("instruments opened"))
    assert main(["resume", str(run), "--no-report"]) == ExitCode.OK              # nothing to do
    assert "nothing to do" in capsys.readouterr().out and not opened.called
    mocker.stopall()
    # a step lost since: resume measures it, and only it
    lost = "00001-L00-F001-up"
    for ext in (".json", ".npz"):
        (run / "steps" / f"{lost}{ext}").unlink()
    assert main(["resume", str(run), "--no-report"]) == ExitCode.OK
    out = capsys.readouterr().out
    assert f"measures again 1 of 4 planned steps; missing: {lost}; skipped at run time, not retried" in out
    skips = [e for e in RunStore.open(run).events() if e["event"] == "step_skipped"]
    assert len(skips) == 1                                          # not tried again
    assert (run / "steps" / f"{lost}.json").exists()
    # the limit raised (run.json's plan), then retried on request: measured, and no longer skipped
    import json
    meta = json.loads((run / "run.json").read_text())
    meta["plan"]["limits"]["drive_V"] = 3.0
    (run / "run.json").write_text(json.dumps(meta))
    assert main(["resume", str(run), "--no-report", "--retry-skipped"]) == ExitCode.OK
    assert "measures again 1 of 4 planned steps; skipped at run time, retried: 00003-L01-F001-up" in \
        capsys.readouterr().out
    acc = RunStore.open(run).account()
    assert len(acc.intact) == 4 and not acc.skipped and acc.complete
    res = next(r for r in RunStore.open(run).results() if r["key"] == UNREACHABLE)
    assert res["target_force_N"] == 25.0 and res["force_converged"]


def test_a_step_the_quality_check_rejects_is_not_counted_as_used(small_run, tmp_path, capsys):
    """A step whose files are intact but whose records the step-quality check rejects (here the
    accelerometer clipped at 80 % of its peak, rewritten through the store so the files stay
    consistent) is not used by the analysis: the report's count and overall line say so,
    while `bench check`, which is about files, stays green."""
    import numpy as np

    from bench.reports import write_report
    from sim.step_record import measure_block
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run, ignore=shutil.ignore_patterns("report", "export", "analysis"))
    store = RunStore.open(run)
    key = _keys(run)[2]
    res = next(r for r in store.results() if r["key"] == key)
    raw = store.raw(key)
    raw["accel_m_s2"] = np.minimum(raw["accel_m_s2"], 0.8 * raw["accel_m_s2"].max())
    # the block as if measured so: its record made from it, as the procedure makes it (decision 0047)
    res = {**res, **measure_block(raw["force_N"], raw["accel_m_s2"], raw["disp_m"], float(raw["fs_Hz"]),
                                  res["freq_Hz"], len(res["force"]["amplitude"])).fields}
    store.write_step(key, res, raw)
    head = write_report(run).read_text().split("## Instruments")[0]
    assert "**19 used / 20 planned**" in head
    assert f"{key} (rejected by the step-quality check: clipping on the accelerometer (accel)" in head
    assert "Overall: **needs attention**: 1 step rejected by the step-quality check" in head
    assert main(["check", str(run)]) == ExitCode.OK
    assert "20 intact / 20 planned" in capsys.readouterr().out
