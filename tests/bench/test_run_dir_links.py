"""A run writes only inside its directory, and with one file mode.

A symbolic link placed in a run directory (``damaged/``, ``events.jsonl``, ``steps/``,
``bench.log``) could lead a run's writes elsewhere; each is refused with an error naming
it, and the place it points to is left untouched.  Every file a run writes has the mode
``0o666 & ~umask`` and every directory ``0o777 & ~umask`` (bench/storage.py)."""

from __future__ import annotations

import os
import shutil
import stat

import pytest

from bench.cli import main
from bench.config import DEFAULTS, load_rig
from bench.session import run_plan
from bench.storage import RunDirError, RunStore
from bench.watch.stop import request_stop
from benchtools.plans import small_plan


@pytest.fixture
def copy(small_run, tmp_path):
    dst = tmp_path / "run"
    shutil.copytree(small_run.path, dst)
    return dst


@pytest.fixture
def outside(tmp_path):
    d = tmp_path / "outside"
    d.mkdir()
    (d / "keep.txt").write_text("keep\n")
    return d


def listing(d):
    return sorted((p.relative_to(d).as_posix(), p.read_bytes()) for p in d.rglob("*") if p.is_file())


def test_damaged_as_a_link_is_refused_and_nothing_is_moved_through_it(copy, outside, capsys):
    step = sorted((copy / "steps").glob("*.json"))[3]
    step.write_text(step.read_text()[:40])           # a damaged step: resume would set it aside
    (copy / "damaged").symlink_to(outside)
    before = listing(outside)
    with pytest.raises(RunDirError, match=r"damaged: is a symbolic link"):
        RunStore(copy).set_aside_damaged()           # even past the check when opening
    assert listing(outside) == before
    assert step.exists()                              # the damaged file stays where it was
    assert main(["resume", str(copy)]) != 0
    assert "damaged: is a symbolic link" in capsys.readouterr().err
    assert listing(outside) == before


def test_events_jsonl_as_a_link_is_refused_and_its_target_untouched(copy, outside):
    target = outside / "keep.txt"
    (copy / "events.jsonl").unlink()
    (copy / "events.jsonl").symlink_to(target)
    with pytest.raises(RunDirError, match=r"events.jsonl: is a symbolic link"):
        RunStore.open(copy)
    with pytest.raises(RunDirError, match=r"events.jsonl: is a symbolic link"):
        RunStore(copy).event("resume")               # and at the write itself (O_NOFOLLOW)
    assert target.read_text() == "keep\n"


def test_steps_as_a_link_is_refused_before_a_step_is_written(tmp_path, outside):
    store = RunStore.create(tmp_path / "run", {"plan": {}})
    shutil.rmtree(store.steps_dir)
    store.steps_dir.symlink_to(outside)
    with pytest.raises(RunDirError, match=r"steps: is a symbolic link"):
        store.write_step("00000-x", {"key": "00000-x"}, {})
    assert listing(outside) == [("keep.txt", b"keep\n")]


def test_bench_log_as_a_link_stops_a_resume_before_it_writes_anything(copy, outside, capsys):
    (copy / "bench.log").unlink()
    (copy / "bench.log").symlink_to(outside / "keep.txt")
    before = listing(copy)
    assert main(["resume", str(copy)]) != 0
    assert "bench.log: is a symbolic link" in capsys.readouterr().err
    assert (outside / "keep.txt").read_text() == "keep\n"
    assert listing(copy) == before                    # run.json still says what it said


@pytest.fixture
def umask_027():
    old = os.umask(0o027)
    yield
    os.umask(old)


def test_every_file_and_directory_of_a_run_has_the_mode_the_umask_gives(tmp_path, umask_027):
    out = tmp_path / "run"
    run_plan(small_plan(freqs=(60.0, 80.0)), load_rig(DEFAULTS / "sim_rig.toml"), out, sim_seed=1)
    request_stop(out, by="the test")                  # the watch page's file too
    modes = {p.relative_to(out).as_posix(): stat.S_IMODE(p.lstat().st_mode) for p in out.rglob("*")}
    assert {"run.json", "events.jsonl", "bench.log", "identification.jsonl", "stop.request"} <= set(modes)
    assert sum(name.startswith("steps/") for name in modes) == 4
    want = {name: 0o750 if (out / name).is_dir() else 0o640 for name in modes}
    assert modes == want
