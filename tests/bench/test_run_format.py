"""The run directory's format versions (docs/run-format.md): run.json and every step file
say which version wrote them; a file without one (written before the field existed) is
version 1 and reads as before; a newer version than this code knows is refused with a
message naming the file, never taken for damage (resume would set it aside)."""

from __future__ import annotations

import hashlib
import json
import shutil
import typing

import pytest

from bench.cli import ExitCode, main
from bench.config import DEFAULTS, load_rig, stored_rig
from bench.sources import load_source
from bench.storage import RUN_FORMAT_VERSION, RunStore
from procedures.plan import stored_model
from sim.errors import RunDirectoryError
from sim.rig import RigModel
from sim.step_result import STEP_FORMAT_VERSION, StepResult


def _rewrite_step(path, change) -> None:
    """Change a step file's content and re-seal it, as a writer of that content would have."""
    d = json.loads(path.read_text())
    integrity = d.pop("integrity")
    change(d)
    canon = json.dumps(d, sort_keys=True, separators=(",", ":")).encode()
    integrity["json_sha256"] = hashlib.sha256(canon).hexdigest()
    path.write_text(json.dumps(dict(d, integrity=integrity), indent=1))


def _rewrite_run_json(run, change) -> None:
    meta = json.loads((run / "run.json").read_text())
    change(meta)
    (run / "run.json").write_text(json.dumps(meta, indent=1))


@pytest.fixture
def run_copy(small_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run)
    return run


def test_a_run_says_its_format_versions_and_every_step_has_the_typed_fields(small_run):
    assert small_run.metadata["format_version"] == RUN_FORMAT_VERSION == 1
    fields = set(typing.get_type_hints(StepResult)) - {"format_version", "backbone", "response_control"}   # other procedures only
    for r in small_run.results():
        assert r["format_version"] == STEP_FORMAT_VERSION == 2
        assert set(r) == fields | {"format_version"}, set(r) ^ (fields | {"format_version"})
    assert len(small_run.results()) == len(small_run.step_files()) > 0


def test_files_without_a_version_are_version_1_and_read_as_before(small_run, run_copy):
    for p in sorted((run_copy / "steps").glob("*.json")):
        _rewrite_step(p, lambda d: d.pop("format_version"))
    _rewrite_run_json(run_copy, lambda m: m.pop("format_version"))
    old = RunStore.open(run_copy)
    assert old.check() == []
    want = [{k: v for k, v in r.items() if k != "format_version"} for r in small_run.results()]
    assert old.results() == want
    assert len(load_source(run_copy).steps) == len(want)
    assert main(["check", str(run_copy)]) == ExitCode.OK


# run.json's "rig" as main wrote it before decision 0058 (commit f857a23, `bench demo`): the
# [rig.model] keys its file gave, not every key
MAIN_RIG = {"name": "simulated guideway rig",
            "notes": "twins on loopback; carriage + column 10 kg, F_s 10 N, x_s 10 um, n 1.5",
            "simulated": True,
            "generator_url": "",
            "sensor_url": "",
            "daq_url": "",
            "force_V_per_N": 0.0225,
            "accel_V_per_m_s2": 0.0102,
            "disp_V_per_m": 8000.0,
            "amp_gain_N_per_V": 20.0,
            "limits": {"drive_V": 7.0, "force_N": 130.0, "disp_m": 0.0009, "accel_m_s2": 20.0},
            "expected_mass_kg": 10.0,
            "expected_x_s_m": 1e-05,
            "expected_F_s_N": 8.0,
            "expected_n": 2.0,
            "model": {"F_s_N": 10.0,
                      "x_s_m": 1e-05,
                      "n": 1.5,
                      "mass_kg": 10.0,
                      "amp_gain_N_per_V": 20.0,
                      "seed": 1,
                      "shaker_force_constant_N_per_A": 15.0,
                      "shaker_resistance_ohm": 1.5,
                      "shaker_inductance_H": 0.0002,
                      "shaker_armature_mass_kg": 0.3,
                      "shaker_suspension_N_per_m": 20000.0,
                      "shaker_damping_N_s_per_m": 20.0}}


def test_a_run_that_stored_only_its_files_model_keys_reads_the_same_model(small_run, run_copy):
    _rewrite_run_json(run_copy, lambda m: m.update(rig=MAIN_RIG))
    meta = RunStore.open(run_copy).metadata
    model = load_rig(DEFAULTS / "sim_rig.toml").model
    assert stored_model(meta["rig"]) == model and stored_rig(meta["rig"], "run.json").model == model
    assert main(["check", str(run_copy)]) == ExitCode.OK
    # a run stores every key of its model now (a Masing model without the friction key, as
    # before decision 0075), and reads back as the same model
    new = small_run.metadata["rig"]
    assert set(new["model"]) == set(typing.get_type_hints(RigModel)) - {"friction", "friction_parameters"}
    assert stored_model(new) == model


def test_a_newer_run_json_is_refused_naming_the_file_and_the_versions(run_copy, capsys):
    _rewrite_run_json(run_copy, lambda m: m.update(format_version=RUN_FORMAT_VERSION + 1))
    for cmd in ("report", "resume"):
        assert main([cmd, str(run_copy)]) == ExitCode.USAGE
        err = capsys.readouterr().err
        assert f"run.json: run format version {RUN_FORMAT_VERSION + 1}, written by a newer guideway-bench" in err
    assert not (run_copy / "damaged").exists()


def test_a_newer_step_file_is_refused_not_set_aside_as_damaged(run_copy):
    step = sorted((run_copy / "steps").glob("*.json"))[0]
    _rewrite_step(step, lambda d: d.update(format_version=STEP_FORMAT_VERSION + 1))
    store = RunStore.open(run_copy)
    with pytest.raises(RunDirectoryError, match=rf"{step.name}: step format version {STEP_FORMAT_VERSION + 1}"):
        store.results()
    with pytest.raises(RunDirectoryError):
        store.set_aside_damaged()
    assert step.exists() and not (run_copy / "damaged").exists()


def test_statuses_are_stored_as_the_strings_readers_know(small_run):
    from bench.storage import RunStatus
    # the watch page, old runs and other tools read these strings
    assert {s.value for s in RunStatus} == {"running", "completed", "aborted", "interrupted",
                                            "instrument error", "failed"}
    assert json.dumps({"status": RunStatus.INSTRUMENT_ERROR}) == '{"status": "instrument error"}'
    assert json.loads((small_run.path / "run.json").read_text())["status"] == "completed" == RunStatus.COMPLETED
