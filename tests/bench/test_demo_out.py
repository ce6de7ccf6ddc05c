"""`bench demo --out DIR` deletes only an earlier demo run (issue 24 item 3): files it did
not write stay untouched, and the demo still starts afresh over its own earlier run.  It
deletes exactly the files its manifest lists (issue 30 item 2: a thesis in DIR/report/
was deleted with the report's own files)."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import bench.commands.run
from bench.cli import main
from bench.config import DEFAULTS, load_plan, load_rig, parse_plan
from bench.demo import MANIFEST
from benchtools import REPO

DEMO_NAME = load_plan(DEFAULTS / "demo_plan.toml").name


def snapshot(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir"
            for p in sorted(root.rglob("*"))}


@pytest.fixture
def small_demo(mocker):
    """The demo with a two-step plan under the demo's name (the real one takes minutes)."""
    plan = parse_plan({"plan": {"name": DEMO_NAME, "levels_N": [1.0],
                                "frequencies": {"list_Hz": [60.0, 80.0], "direction": "up"},
                                "control": {"settle_cycles": 4, "min_settle_s": 0.0, "measure_cycles": 4,
                                            "control_cycles": 2, "ramp_s": 0.0}}})
    return mocker.patch.object(bench.commands.run, "_load_configs", return_value=(plan, load_rig(DEFAULTS / "sim_rig.toml")))


def test_the_demo_refuses_a_directory_that_holds_other_files_and_deletes_nothing(tmp_path, small_run, capsys):
    v = tmp_path / "v"
    (v / "thesis").mkdir(parents=True)
    (v / "thesis" / "ch1.tex").write_text("x\n")
    import shutil
    shutil.copytree(small_run.path, v / "unrelated-run")
    before = snapshot(v)
    assert main(["demo", "--out", str(v)]) == 2
    assert snapshot(v) == before
    assert "holds no earlier demo run" in capsys.readouterr().err


def test_out_dot_never_wipes_the_working_directory(tmp_path, monkeypatch, capsys):
    (tmp_path / "notes.txt").write_text("mine\n")
    (tmp_path / "src").mkdir()
    monkeypatch.chdir(tmp_path)
    before = snapshot(tmp_path)
    assert main(["demo", "--out", "."]) == 2
    assert snapshot(tmp_path) == before
    assert "deletes nothing else" in capsys.readouterr().err


def test_the_demo_reruns_over_its_own_run_and_keeps_what_it_did_not_write(tmp_path, small_demo, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == 0
    first = (out / "run.json").read_text()
    assert (out / "report" / "report.md").is_file()
    assert main(["demo", "--out", str(out)]) == 0                 # twice in a row: starts afresh
    assert (out / "run.json").read_text() != first
    assert sum('"start"' in e for e in (out / "events.jsonl").read_text().splitlines()) == 1
    # a file the demo did not write, beside its run or inside its steps/: kept, nothing deleted
    for foreign, named in ((out / "export" / "frf.csv", "(export/)"), (out / "steps" / "my-notes.txt",
                                                                       "(steps/my-notes.txt)")):
        foreign.parent.mkdir(exist_ok=True)
        foreign.write_text("mine\n")
        before = snapshot(out)
        capsys.readouterr()
        assert main(["demo", "--out", str(out)]) == 2
        assert snapshot(out) == before
        assert named in capsys.readouterr().err
        os.remove(foreign)
        if foreign.parent.name == "export":
            foreign.parent.rmdir()


# `bench demo` as a process of its own, the demo's two-step plan swapped in (as small_demo does)
SMALL_DEMO = textwrap.dedent("""\
    import sys

    import bench.cli
    import bench.commands.run
    from bench.config import DEFAULTS, load_rig, parse_plan

    plan = parse_plan({"plan": {"name": %r, "levels_N": [1.0],
                                "frequencies": {"list_Hz": [60.0, 80.0], "direction": "up"},
                                "control": {"settle_cycles": 4, "min_settle_s": 0.0, "measure_cycles": 4,
                                            "control_cycles": 2, "ramp_s": 0.0}}})
    bench.commands.run._load_configs = lambda args: (plan, load_rig(DEFAULTS / "sim_rig.toml"))
    sys.argv[0] = "bench"
    sys.exit(bench.cli.main())
    """) % DEMO_NAME


def bench_demo(tmp: Path, out: Path) -> subprocess.CompletedProcess:
    script = tmp / "small_demo.py"
    script.write_text(SMALL_DEMO)
    return subprocess.run([sys.executable, str(script), "demo", "--out", str(out)], cwd=REPO, capture_output=True,
                          text=True, timeout=300)


@pytest.mark.timeout(300)
def test_a_bench_demo_process_deletes_only_the_files_its_manifest_lists(tmp_path):
    """The issue's case: a thesis chapter and notes in DIR/report/ (names the report's own
    files could have) and a file in DIR.  Refused in one line, exit 2, nothing deleted;
    also a file of the demo's that the user changed, and a demo directory with no manifest."""
    out = tmp_path / "demo"
    first = bench_demo(tmp_path, out)
    assert first.returncode == 0, first.stderr

    (out / "report" / "thesis_chapter3.md").write_text("# Chapter 3\n")
    (out / "report" / "notes.html").write_text("<p>mine</p>\n")
    for name, named in ((None, "(report/notes.html, report/thesis_chapter3.md)"),
                        ("todo.txt", "(report/notes.html, report/thesis_chapter3.md, todo.txt)")):
        if name:
            (out / name).write_text("mine\n")
        before = snapshot(out)
        again = bench_demo(tmp_path, out)
        assert again.returncode == 2, again.stderr
        assert snapshot(out) == before
        err = again.stderr.strip()
        assert len(err.splitlines()) == 1, err
        assert named in err and "deletes nothing" in err
    listed = json.loads((out / MANIFEST).read_text())["files"]
    assert {"run.json", "events.jsonl", "report/report.md", "report/compliance.png"} <= set(listed)
    assert "session.lock" not in listed and not any(n.startswith("report/thesis") for n in listed)

    for name in ("report/thesis_chapter3.md", "report/notes.html", "todo.txt"):
        (out / name).unlink()
    with open(out / "report" / "report.md", "a") as f:             # the user's remarks in the demo's report
        f.write("my remarks\n")
    before = snapshot(out)
    changed = bench_demo(tmp_path, out)
    assert changed.returncode == 2 and snapshot(out) == before
    assert "report/report.md (changed since the demo wrote it)" in changed.stderr

    (out / MANIFEST).unlink()                                      # an older bench's demo: nothing proves what it wrote
    before = snapshot(out)
    unlisted = bench_demo(tmp_path, out)
    assert unlisted.returncode == 2 and snapshot(out) == before
    assert f"no readable {MANIFEST}" in unlisted.stderr
