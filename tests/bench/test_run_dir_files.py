"""A run directory's files are read only as regular files, within a bound (issue 24, items
4, 6, 7, 8; decision record 0041).

A step file linked to /dev/zero drove `bench check` to 17 GB; a FIFO in a step file's
place hung check, report and resume forever.  Now every reader goes through
``bench.files.read_file``: no link followed, no FIFO waited on, at most the bound of the
file's kind.  The commands run in their own process here (a regression would hang or eat
the machine), with a 2 GiB address-space limit and a timeout, and their time and peak
memory are measured.  The plan stored in run.json is checked by the plan file's validator
in check, report and resume alike.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bench.cli import ExitCode, main
from bench.config import MAX_FREQUENCIES, MAX_STEPS
from bench.files import MAX_BYTES, UnreadableFile, read_file
from bench.storage import RunStore
from benchtools import REPO

ADDRESS_SPACE = 2 * 2**30


def _limit_memory():
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


# bench's main in a process of its own that reports its peak resident memory on stderr.
# VmHWM, not getrusage's ru_maxrss: Linux carries ru_maxrss across exec, so after a fork
# it is at least the forking pytest worker's resident size (532 MB on CI), not bench's.
CHILD = ("import sys\nfrom bench.cli import main\ntry:\n    code = main(sys.argv[1:])\nfinally:\n"
         "    hwm = [line.split()[1] for line in open('/proc/self/status') if line.startswith('VmHWM:')]\n"
         "    print(f'peak-kB {hwm[0]}', file=sys.stderr)\n"
         "sys.exit(code)\n")


def bench(*args, timeout=60.0):
    """``bench ARGS`` in a process of its own: (exit code, stdout, stderr, seconds, peak MB)."""
    t = time.monotonic()
    try:
        p = subprocess.run([sys.executable, "-c", CHILD, *args], cwd=REPO, text=True, capture_output=True,
                           preexec_fn=_limit_memory, timeout=timeout)
    except subprocess.TimeoutExpired as e:
        pytest.fail(f"bench {' '.join(args)} still running after {timeout:.0f} s (a FIFO waited on?)\n{e.stderr}")
    peak = [int(line.split()[1]) / 1024 for line in p.stderr.splitlines() if line.startswith("peak-kB ")]
    assert peak, p.stderr[-2000:]
    return p.returncode, p.stdout, p.stderr, time.monotonic() - t, peak[0]


@pytest.fixture
def copy(small_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run)
    shutil.rmtree(run / "report", ignore_errors=True)
    return run


def _keys(run: Path) -> list[str]:
    return sorted(p.stem for p in (run / "steps").glob("*.json"))


def test_check_names_a_step_linked_to_dev_zero_and_a_fifo_within_seconds_and_bounded_memory(copy):
    keys = _keys(copy)
    (copy / "steps" / f"{keys[1]}.json").unlink()
    (copy / "steps" / f"{keys[1]}.json").symlink_to("/dev/zero")
    (copy / "steps" / f"{keys[3]}.npz").unlink()
    (copy / "steps" / f"{keys[3]}.npz").symlink_to("/dev/zero")
    (copy / "steps" / f"{keys[5]}.json").unlink()
    os.mkfifo(copy / "steps" / f"{keys[5]}.json")
    (copy / "steps" / f"{keys[7]}.npz").unlink()
    os.mkfifo(copy / "steps" / f"{keys[7]}.npz")
    code, out, err, seconds, peak_mb = bench("check", str(copy))
    assert code == ExitCode.FAILURE, err
    assert f"steps/{keys[1]}.json: is a symbolic link" in out
    assert f"steps/{keys[3]}.npz: is a symbolic link" in out
    assert f"steps/{keys[5]}.json: not a regular file (a FIFO)" in out
    assert f"steps/{keys[7]}.npz: not a regular file (a FIFO)" in out
    assert "16 intact / 20 planned" in out
    assert seconds < 30 and peak_mb < 400, (seconds, peak_mb)


def test_report_and_resume_get_past_fifos_and_links_naming_them(copy, capsys):
    keys = _keys(copy)
    (copy / "steps" / f"{keys[2]}.json").unlink()
    os.mkfifo(copy / "steps" / f"{keys[2]}.json")
    (copy / "steps" / f"{keys[4]}.npz").unlink()
    (copy / "steps" / f"{keys[4]}.npz").symlink_to("/dev/zero")
    (copy / "identification.jsonl").rename(copy / "identification.kept")
    os.mkfifo(copy / "identification.jsonl")
    assert main(["report", str(copy)]) == ExitCode.OK    # in this process: a regression hangs until the timeout
    err = capsys.readouterr().err
    assert f"{keys[2]}.json: not a regular file (a FIFO)" in err and f"{keys[4]}.npz: is a symbolic link" in err
    assert "identification.jsonl: not a regular file (a FIFO)" in err
    report = (copy / "report" / "report.md").read_text()
    assert "18 used / 20 planned" in report and keys[2] in report and keys[4] in report
    # a session writes to identification.jsonl: a FIFO there is refused before anything is opened
    assert main(["resume", str(copy), "--no-report"]) == ExitCode.USAGE
    assert "identification.jsonl: not a regular file (a FIFO); a run writes only regular files" in capsys.readouterr().err
    (copy / "identification.jsonl").unlink()
    (copy / "identification.kept").rename(copy / "identification.jsonl")
    assert main(["resume", str(copy), "--no-report"]) == ExitCode.OK
    out = capsys.readouterr().out
    assert f"measures again 2 of 20 planned steps; damaged: {keys[2]} (corrupt), {keys[4]} (corrupt)" in out
    moved = {p.name for p in (copy / "damaged").glob("*/*")}
    assert {f"{keys[2]}.json", f"{keys[4]}.npz"} <= moved            # the FIFO and the link set aside, not read
    assert RunStore(copy).account().complete


def test_the_reader_refuses_links_special_files_and_oversize_files_by_name(tmp_path):
    big = tmp_path / "x.json"
    big.write_bytes(b" " * (MAX_BYTES[".json"] + 1))
    with pytest.raises(UnreadableFile, match=rf"{big}: {MAX_BYTES['.json'] + 1} bytes, more than"):
        read_file(big)
    assert read_file(big, MAX_BYTES[".json"] + 1) == b" " * (MAX_BYTES[".json"] + 1)
    (tmp_path / "link.json").symlink_to(big)
    with pytest.raises(UnreadableFile, match="link.json: is a symbolic link"):
        read_file(tmp_path / "link.json")
    with pytest.raises(UnreadableFile, match="dev: not a regular file .a directory."):
        read_file(Path("/dev"))
    with pytest.raises(UnreadableFile, match="null: not a regular file .a character device."):
        read_file(Path("/dev/null"))
    with pytest.raises(FileNotFoundError):
        read_file(tmp_path / "absent.json")


def test_steps_directory_as_a_link_is_not_read_through(copy, tmp_path):
    outside = tmp_path / "elsewhere"
    shutil.move(copy / "steps", outside)
    (copy / "steps").symlink_to(outside)
    assert main(["check", str(copy)]) == ExitCode.FAILURE
    assert RunStore(copy).results() == []


# ---------------------------------------------------------------------------- the stored plan (item 6)


def _edit_meta(run: Path, change) -> None:
    meta = json.loads((run / "run.json").read_text())
    change(meta)
    (run / "run.json").write_text(json.dumps(meta))


@pytest.mark.parametrize("change, said", [
    (lambda m: m.pop("plan"), "no plan stored"),
    (lambda m: m["plan"].update(levels_N="abc"), "[plan] levels_N: must be a non-empty list of numbers, got 'abc'"),
    (lambda m: m["plan"].update(levels_N=[float("nan"), 5.0]), "[plan] levels_N[0]: must be >= 0.1"),
    (lambda m: m["plan"].update(freqs_Hz=[]), "[plan] freqs_Hz: must be a non-empty list of numbers, got []"),
    (lambda m: m["plan"].update(freqs_Hz=[20 + i / 100 for i in range(100_000)]),
     f"[plan] freqs_Hz: 100000 values; at most {MAX_FREQUENCIES}"),
    (lambda m: m["plan"].update(freqs_Hz=[300.0, 30.0]), "[plan] freqs_Hz: not in ascending order"),
    (lambda m: m["plan"].update(harmonics=500), "[plan.control] harmonics: must be >= 1 and <= 50"),
    (lambda m: m["plan"].update(skip=[[0, 99]]), "[plan] skip: must be a list of [level index, frequency index]"),
], ids=["no plan", "levels abc", "nan level", "no frequencies", "100000 frequencies", "unsorted", "harmonics",
        "skip"])
def test_check_report_and_resume_name_the_same_problem_of_the_stored_plan(copy, capsys, change, said):
    _edit_meta(copy, change)
    t = time.monotonic()
    assert main(["check", str(copy)]) == ExitCode.FAILURE
    out = capsys.readouterr().out
    assert f"corrupt  {copy}/run.json: " in out and said in out and "cannot be counted against the plan" in out
    for command in ("report", "resume"):
        assert main([command, str(copy)]) == ExitCode.USAGE
        err = capsys.readouterr().err
        assert err.startswith(f"bench {command}: error: {copy}/run.json: ") and said in err, err
    assert time.monotonic() - t < 20
    assert not (copy / "report").exists()


def test_a_newer_run_format_is_refused_by_check_as_by_report_and_resume(copy, capsys):
    _edit_meta(copy, lambda m: m.update(format_version=2))
    for command in ("check", "report", "resume"):
        assert main([command, str(copy)]) == ExitCode.USAGE
        assert "run format version 2, written by a newer guideway-bench" in capsys.readouterr().err


def test_run_json_nested_thousands_deep_is_named(copy, capsys):
    (copy / "run.json").write_text('{"a": ' * 50_000 + "1" + "}" * 50_000)
    with (copy / "events.jsonl").open("a") as fh:
        fh.write("[" * 50_000 + "]" * 50_000 + "\n")
    assert main(["check", str(copy)]) == ExitCode.FAILURE
    assert "run.json: damaged (nested too deeply" in capsys.readouterr().out
    assert main(["report", str(copy)]) == ExitCode.USAGE
    assert "run.json: damaged (nested too deeply" in capsys.readouterr().err


def test_a_step_file_named_in_bytes_that_are_not_utf8_is_an_orphan_printed_escaped(copy, capsys):
    (copy / "steps" / os.fsdecode(b"caf\xe9.json")).write_bytes(b"{}")
    assert main(["check", str(copy)]) == ExitCode.FAILURE
    out = capsys.readouterr().out
    assert "steps/caf\\xe9.json: not a step file (its name is not UTF-8)" in out
    assert main(["report", str(copy)]) == ExitCode.OK
    assert "caf\\xe9.json" in (copy / "report" / "report.md").read_text()


CRAFTED = [
    (lambda d: d.update(freq_Hz="abc"), "freq_Hz: float expected, found str 'abc'"),
    (lambda d: d.update(force=5), "force is not an object"),
    (lambda d: d.update(target_force_N=None), "target_force_N: float expected, found NoneType"),
    (lambda d: d["disp"].update(amplitude=[1.0, "x"]), "disp.amplitude[1]: float expected, found str"),
    (lambda d: [d.pop(k) for k in ("level_index", "direction")], "lacks level_index, direction"),
    (lambda d: d.update(direction="sideways"), "direction: 'up' or 'down' expected"),
]


def test_crafted_steps_of_the_format_before_checksums_are_damaged_not_an_internal_error(copy, capsys):
    """Steps without checksums (the first format) are read with structural checks: one
    crafted each way (a field of the wrong type, a channel fit that is not an object, fields
    gone) was an internal error in report and export."""
    keys = _keys(copy)
    for (change, _), key in zip(CRAFTED, keys[1::3]):
        p = copy / "steps" / f"{key}.json"
        d = json.loads(p.read_text())
        d.pop("integrity")
        d.pop("format_version")
        change(d)
        p.write_text(json.dumps(d))
    assert main(["check", str(copy)]) == ExitCode.FAILURE
    out = capsys.readouterr().out
    for (_, said), key in zip(CRAFTED, keys[1::3]):
        assert f"corrupt  {copy}/steps/{key}.json: not a step result: {said}" in out
    assert "14 intact / 20 planned" in out
    assert main(["report", str(copy)]) == ExitCode.OK
    assert main(["export", str(copy), "--no-time"]) == ExitCode.OK
    assert "14 used / 20 planned" in (copy / "report" / "report.md").read_text()


# ---------------------------------------------------------------------------- plan size (item 8)


def test_a_ten_million_step_plan_is_refused_before_it_is_expanded(tmp_path, capsys):
    plan = tmp_path / "many.toml"
    plan.write_text("[plan]\nlevels_N = [" + ", ".join(["1.0"] * 1000) + "]\n[plan.frequencies]\n"
                    "start_Hz = 20.0\nstop_Hz = 1000.0\npoints = 5000\ndirection = \"both\"\n")
    t = time.monotonic()
    assert main(["dry-run", "--plan", str(plan)]) == ExitCode.USAGE
    assert time.monotonic() - t < 2
    assert (f"{plan}: [plan] 1000 levels x 5000 frequencies x 2 directions = 10000000 steps; at most {MAX_STEPS}"
            in capsys.readouterr().err)
