"""Damaged run directories lose nothing that is still good.

A completed run (the shared small run: 20 steps) is copied and damaged the ways a disk,
a copy or a hand does it: a result file truncated (the issue's case), a raw block
truncated, a bit flipped in a number of a result (still valid JSON: only the checksum
sees it), a bit flipped in a raw block, a raw block deleted, a step from another plan
dropped in.  Every reader keeps the good steps and names each damaged file; `bench check`
lists exactly those problems; `bench resume` moves the damaged files aside and measures
those steps again.
"""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest
import pyuff

from bench.cli import ExitCode, main
from bench.config import DEFAULTS, load_plan, load_rig
from bench.export import export_run
from bench.session import run_plan
from bench.storage import RunStore
from benchtools.plans import SMALL_PLAN


def _flip_digit(path: Path) -> None:
    """Change one digit of the first long number: the file stays valid JSON."""
    text = path.read_text()
    i = text.index('"compliance_abs_m_per_N": ') + len('"compliance_abs_m_per_N": ') + 3
    assert text[i].isdigit()
    path.write_text(text[:i] + str((int(text[i]) + 1) % 10) + text[i + 1:])
    json.loads(path.read_text())


def _flip_byte(path: Path, at: float = 0.6) -> None:
    data = bytearray(path.read_bytes())
    data[int(len(data) * at)] ^= 0x10
    path.write_bytes(bytes(data))


def _truncate(path: Path, keep: float) -> None:
    data = path.read_bytes()
    path.write_bytes(data[:int(len(data) * keep)])


@pytest.fixture(scope="module")
def damaged(small_run, tmp_path_factory):
    """A copy of the small run with six kinds of damage; {file name: expected kind}."""
    run = tmp_path_factory.mktemp("damaged") / "run"
    shutil.copytree(small_run.path, run)
    keys = sorted(p.stem for p in (run / "steps").glob("*.json"))
    s = run / "steps"
    _truncate(s / f"{keys[2]}.json", 0.03)      # "Unterminated string ..." as in the issue
    _truncate(s / f"{keys[4]}.npz", 0.5)
    _flip_digit(s / f"{keys[6]}.json")
    _flip_byte(s / f"{keys[8]}.npz")
    (s / f"{keys[10]}.npz").unlink()
    store = RunStore.open(run)
    good = store.results()[0]
    store.write_step("99999-L09-F009-up", dict(good, key="99999-L09-F009-up"), store.raw(good["key"]))
    expected = {f"{keys[2]}.json": "truncated", f"{keys[4]}.npz": "truncated", f"{keys[6]}.json": "checksum",
                f"{keys[8]}.npz": "checksum", f"{keys[10]}.npz": "missing", "99999-L09-F009-up.json": "unknown"}
    return run, keys, expected


def test_an_intact_run_has_no_problems_and_every_step_carries_checksums(small_run, capsys):
    assert small_run.check() == []
    for p in (small_run.path / "steps").glob("*.json"):
        integrity = json.loads(p.read_text())["integrity"]
        assert len(integrity["json_sha256"]) == 64 and len(integrity["npz_sha256"]) == 64
        assert integrity["npz_bytes"] == p.with_suffix(".npz").stat().st_size
    assert main(["check", str(small_run.path)]) == ExitCode.OK
    assert "20 intact / 20 planned; missing: none; damaged: none; orphan: none" in capsys.readouterr().out


def test_a_store_that_read_a_step_sees_it_damaged_later(small_run, tmp_path):
    """A store parses a step it already verified without checking it again only while the
    file's bytes are the same (decision 0083: a refined run reads every step after each
    refinement step); a digit flipped after the first read is a checksum problem on the next."""
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run)
    store = RunStore.open(run)
    first = store.results(warn=False)
    assert not store.problems and len(first) == len(list((run / "steps").glob("*.json")))
    assert store.results(warn=False) == first                 # the same bytes: the same results
    key = first[3]["key"]
    _flip_digit(run / "steps" / f"{key}.json")
    again = store.results(warn=False)
    assert [p.key for p in store.problems] == [key] and store.problems[0].kind == "checksum", store.problems
    assert len(again) == len(first) - 1


def test_check_lists_every_problem_and_fails(damaged, capsys):
    run, keys, expected = damaged
    found = {p.path.name: p.kind for p in RunStore(run).check()}
    assert found == expected
    assert main(["check", str(run)]) == ExitCode.FAILURE
    out = capsys.readouterr().out.splitlines()
    for name, kind in expected.items():
        assert any(name in line and line.strip().startswith(kind) for line in out), (name, out)


def test_readers_keep_the_good_steps_and_name_each_damaged_file(damaged, caplog):
    run, keys, expected = damaged
    broken = {n.split(".")[0] for n, k in expected.items() if k != "unknown"}
    with caplog.at_level(logging.WARNING, logger="bench.storage"):
        results = RunStore.open(run).results()
    assert {r["key"] for r in results} == (set(keys) - broken) | {"99999-L09-F009-up"}
    assert all("integrity" not in r for r in results)
    for name, kind in expected.items():
        if kind != "unknown":
            assert any(name in m and "skipping" in m for m in caplog.messages), name


def test_report_export_and_identify_carry_on(damaged, tmp_path, caplog, capsys):
    run = tmp_path / "run"
    shutil.copytree(damaged[0], run)
    (run / "steps" / "99999-L09-F009-up.json").unlink()   # the plan's steps only, for the fits
    (run / "steps" / "99999-L09-F009-up.npz").unlink()
    n_good = 20 - 5
    with caplog.at_level(logging.WARNING):
        assert main(["report", str(run)]) == ExitCode.OK
        assert main(["identify", str(run)]) == ExitCode.OK
        paths = {p.name: p for p in export_run(run, tmp_path / "export")}
    assert f"{n_good} steps (5 rejected), reduced chi^2" in capsys.readouterr().out
    assert (run / "report" / "compliance.png").is_file()
    rows = paths["steps.csv"].read_text().splitlines()
    assert len(rows) == 1 + n_good
    n_time = sum(1 for s in pyuff.UFF(str(paths["time.uff"])).get_set_types())
    assert n_time == 3 * n_good
    assert sum("skipping step" in m for m in caplog.messages) >= 3 * 5


def test_resume_sets_damaged_steps_aside_and_measures_them_again(damaged, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(damaged[0], run)
    keys, expected = damaged[1], damaged[2]
    broken = sorted({n.split(".")[0] for n, k in expected.items() if k != "unknown"})
    before = {p.name: p.read_bytes() for p in (run / "steps").iterdir()}
    (tmp_path / "plan.toml").write_text(SMALL_PLAN)
    store = run_plan(load_plan(tmp_path / "plan.toml"), load_rig(DEFAULTS / "sim_rig.toml"), run,
                     resume=True, identify=False)
    assert store.metadata["status"] == "completed"
    results = {r["key"]: r for r in store.results()}
    assert set(keys) <= set(results)
    # the damaged files are kept, byte for byte, under damaged/<time>/
    aside = {p.name: p.read_bytes() for p in (run / "damaged").glob("*/*")}
    for key in broken:
        for ext in (".json", ".npz"):
            if key + ext in before:
                assert aside[key + ext] == before[key + ext]
    # the good steps were not measured again
    for key in set(keys) - set(broken):
        assert (run / "steps" / f"{key}.json").read_bytes() == before[f"{key}.json"]
    assert [p.kind for p in store.check()] == ["unknown"]       # only the foreign step is left
    events = [e for e in store.events() if e["event"] == "damaged_step"]
    assert sorted(e["step"] for e in events) == broken
    raw = store.raw(broken[0])
    assert np.all(np.isfinite(raw["disp_m"]))


@pytest.mark.parametrize("damage", ["truncated", "not an object", "missing"])
def test_a_damaged_run_json_is_one_line_naming_it(small_run, tmp_path, capsys, damage):
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run)
    p = run / "run.json"
    if damage == "truncated":
        _truncate(p, 0.5)
    elif damage == "not an object":
        p.write_text("[1, 2]")
    else:
        p.unlink()
    for cmd in ("report", "export", "identify", "resume"):
        assert main([cmd, str(run)]) == ExitCode.USAGE
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "run.json" in err[0] and "Traceback" not in err[0], err
    assert main(["check", str(run)]) == ExitCode.FAILURE
    assert "run.json" in capsys.readouterr().out
