"""Every planned step accounted for (issue 19): `bench check`, `bench report` and `bench
resume` count a run's steps against its stored plan, not against the files that happen to
be there.  A step whose two files are both gone, or one of the pair, is missing; a step
whose files fail a check is damaged; a file no planned step owns is an orphan; each is
named by key, and `check` fails when a planned step is missing or damaged.
"""

from __future__ import annotations

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
