"""Decisions are values, words are made at the edge (issue 35 item 1, decision 0059): every
function that makes the words a decision used to read is made to say something else (codes
only), and the decisions stay the same: a step's verdict, why it was rejected, what settling
longer cures, the causes of a run's artefacts, which missing steps are the run's unmeasured
tail, whether a step file was cut short.  The renderers of :mod:`bench.words` (decision 0067)
are made to say each code alone, and ``bench check`` and ``bench report`` on a damaged run
decide, exit and write the same."""

import fcntl
import importlib
import inspect
import json
import os
import pkgutil
import shutil
from dataclasses import replace

import numpy as np
import pytest

import bench.storage as storage
import bench.words
import bench.words.page as page_words
import bench.words.report as report_words
import bench.words.terminal as terminal_words
import bench.words.terminal_config as terminal_config_words
import bench.words.terminal_data as data_words
import bench.words.terminal_run as terminal_run_words
import sim.artefacts.sentences as sentences
import sim.records as records
from bench.accounting import AccountLine, AccountRefusal
from bench.analyze import AnalyzeSaid
from bench.api import ApiLine, ApiRefusal
from bench.backbone import BackboneLine
from bench.cli import CliLine, ExitCode, main
from bench.commands.results import CheckLine, ModeLine, ResultLine
from bench.commands.run import DryRunLine, ResumeLine, RunLine, RunRefusal, SequenceEndLine, WatchLine
from bench.commands.tools import ToolLine
from bench.compare import CompareSaid
from bench.config import ConfigRule, RangeNote
from bench.demo import MANIFEST, DemoLine, OutDirRefusal
from bench.durable import WriteRefusal
from bench.export import ExportSaid
from bench.export_modes import ModeId
from bench.files import FileKind, FileRefusal
from bench.frf_import import ImportProblem
from bench.frf_run import ImportLine
from bench.fundamentals import FundamentalLine
from bench.numbers import Shown
from bench.plan_time import Online, planned_step_list, rig_time_bound_s
from bench.reports._markdown import accounting_md, flagged_reasons
from bench.reports._overall import Concern, Verdict, overall
from bench.reports._run import load_run
from bench.rig_config import RigRule
from bench.rig_model import PaperRule
from bench.runlock import LOCK_NAME, LockRefusal
from bench.sequence import SequenceLine, SequenceProblem
from bench.session import EnvelopeProblem, EnvelopeRefusal, SessionLine
from bench.signals import Doing, SignalLine
from bench.sources import SourceProblem
from bench.step_files import Problem
from bench.storage import RunDirRefusal, RunStore, StoreLine
from bench.studies import StudiesSaid
from bench.studies.batch import BatchSaid
from bench.studies.cli import StudyArgs, StudyOut
from bench.studies.engine import StudySaid
from bench.studies.maps import MapRefusal
from bench.studies.montecarlo import McRefusal
from bench.testing import PluginOption, PluginRefusal
from bench.toml_tables import ConfigProblem
from bench.twin import NotInPlant, TwinNote, TwinSaid
from bench.verdict import Kept, Short
from bench.warmup import WarmupLine
from bench.watch.server import PageError, ServerLine
from bench.watch.snapshot import PageMessage, PageWarning, RunReader, SnapshotLine
from bench.watch.stop import StopLine
from procedures.stepped_sine import unsettled_in
from sim.artefacts import artefact_causes, assess_step
from sim.describing_fit import ParameterStatus, Separation
from sim.rig_friction import FrictionKey

F, FS = 37.0, 5120.0
AMPS = {"force": [5.0, 0.0, 0.3], "accel": [20.0, 0.0, 3.0], "disp": [10e-6, 0.0, 1e-6]}
NOISE = {"force": 0.003, "accel": 0.01, "disp": 2e-9}


def _step(i: int, f: float = F, periods: int = 8, fs: float = FS) -> dict:
    """One step's records (closed forms): a periodic response and noise, with per step: hum
    on the probe (0-3), a clipped force (4), a slow free vibration that leaves the record not
    periodic, with 50 Hz hum one resolution from the fundamental (5, at 53 Hz), a transient (6)."""
    t = np.arange(int(round(periods * fs / f))) / fs
    rng = np.random.default_rng(20 + i)
    sig = {ch: sum(a * np.sin(2 * np.pi * (k + 1) * f * t + 0.3 * k) for k, a in enumerate(amps))
           + NOISE[ch] * rng.standard_normal(t.size) for ch, amps in AMPS.items()}
    if i < 4:
        sig["disp"] += 12e-9 * np.sin(2 * np.pi * 50.0 * t + i)
    if i == 4:
        sig["force"] = np.clip(sig["force"], -4.0, 4.0)
    if i == 5:
        sig["disp"] += 100e-9 * np.sin(2 * np.pi * 50.0 * t) + 35e-9 * np.exp(-25.7 * t)
    if i == 6:
        sig["disp"] += 2e-6 * np.exp(-15 * t) * np.sin(2 * np.pi * 61 * t)
    return sig


STEPS = [(_step(i), F, FS) if i != 5 else (_step(i, 53.0, 10, 5120.0), 53.0, 5120.0) for i in range(7)]


def _decisions() -> tuple:
    """What the artefact check, the procedure's settle rule and the causes decide, as values."""
    out, qs = [], []
    for i, (sig, f, fs) in enumerate(STEPS):
        q = assess_step(sig["force"], sig["accel"], sig["disp"], fs, f).quality
        u = unsettled_in(q, fs, sig["force"].size)
        out.append((q.status, q.rejected_by, [(a.kind, a.channel, a.action, a.settle_cycles) for a in q.artefacts],
                    u.cycles, tuple(round(x, 6) for x in u.vibrations_Hz), u.found))
        qs.append((f"s{i}", q))
    found = [(c["id"], c["channel"], c["evidence"]["steps"], c["gain"]) for c in artefact_causes(qs)]
    return tuple(out), found, qs[5][1].reason


# the functions of sim.artefacts.sentences that are not words: a size's format, a decision's value
NOT_WORDS = {"si", "mains_line"}


def test_rewording_the_artefact_checks_messages_changes_no_decision(monkeypatch):
    """The verdicts, the rejection's cause, the settle advice's cycles and the causes of 7
    steps (hum, clipping, not periodic with a mains hint, a transient) are the same when every
    word-maker of the artefact check (each function of sim.artefacts.sentences) says codes only."""
    before, found, reason = _decisions()
    assert [d[0] for d in before] == ["flagged"] * 4 + ["rejected", "rejected", "flagged"]
    assert [str(d[1]) for d in before[4:6]] == ["raw_fault", "not_periodic"]
    assert before[5][5] and not before[4][5]        # settling longer may cure step 5, never step 4
    assert "mains hum" in reason and {"line_interference", "clipping", "unsettled_transient"} <= {c[0] for c in found}
    makers = [name for name, fn in vars(sentences).items() if inspect.isfunction(fn)
              and fn.__module__ == sentences.__name__ and name not in NOT_WORDS]
    assert {"artefact", "not_periodic", "mains_hint", "mains_family", "noisy"} <= set(makers)
    for name in makers:
        monkeypatch.setattr(sentences, name, (lambda n: lambda *a, **k: f"<{n}>")(name))
    monkeypatch.setattr(records, "harmonic_words", lambda k: f"H{k}")
    after, found_after, reason_after = _decisions()
    assert reason_after.startswith("<not_periodic>; <mains_hint>"), reason_after     # reworded, the hint kept
    assert after == before and found_after == found
    for name in makers:                 # no words at all: nothing decides by whether there are any
        monkeypatch.setattr(sentences, name, lambda *a, **k: "")
    assert _decisions()[:2] == (before, found)


def test_rewording_a_missing_steps_words_keeps_the_interrupted_tail_one_line(small_run, tmp_path, capsys,
                                                                              monkeypatch):
    """``bench check`` folds the plan's unmeasured tail into one line by what is missing
    (neither file), not by the words that say so."""
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run, ignore=shutil.ignore_patterns("report", "export", "analysis"))
    keys = sorted(p.stem for p in (run / "steps").glob("*.json"))
    for key in keys[12:]:
        for ext in (".json", ".npz"):
            (run / "steps" / f"{key}{ext}").unlink()
    RunStore.open(run).update(status="interrupted")
    _codes_only(monkeypatch)
    assert main(["check", str(run)]) == ExitCode.FAILURE
    lines = capsys.readouterr().out.splitlines()
    assert [ln for ln in lines if ln.startswith("  missing")] == ["  missing  <unmeasured_tail>"], lines


# every renderer of bench/words/ (a new one is reworded without editing this test)
RENDERERS = tuple(importlib.import_module(f"bench.words.{m.name}") for m in pkgutil.iter_modules(bench.words.__path__))


def test_the_renderers_are_the_three_outputs():
    assert {m.__name__ for m in RENDERERS} >= {m.__name__ for m in (terminal_words, report_words, page_words)}


def _codes_only(monkeypatch) -> None:
    """Every renderer of bench.words says a code alone: ``<code>``."""
    for module in RENDERERS:
        for name, words in vars(module).items():
            if name.isupper() and isinstance(words, dict):
                monkeypatch.setattr(module, name, {code: (lambda c: lambda **_: f"<{c}>")(code) for code in words})


def test_every_code_has_words_in_its_renderers():
    for module in (terminal_words, report_words):
        assert set(module.PROBLEM) == {str(c) for c in Problem}, module.__name__
    assert set(page_words.WARNING) == {str(c) for c in PageWarning}
    assert set(terminal_words.REFUSAL) == {str(c) for c in (*LockRefusal, *OutDirRefusal, *RunDirRefusal,
                                                           *ConfigProblem, *ConfigRule, *RigRule, *PaperRule, *FrictionKey,
                                                           *SequenceProblem, *ApiRefusal, *PluginRefusal,
                                                           *bench._Missing, *StudyArgs)}
    assert set(terminal_words.CONFIG) == {str(c) for c in (*ConfigProblem, *ConfigRule, *RigRule, *PaperRule, *FrictionKey)}
    assert set(terminal_config_words.RULE) == {str(c) for c in (*ConfigRule, *RigRule, *PaperRule, *FrictionKey)}
    assert set(terminal_config_words.NOTE) == {str(c) for c in RangeNote}
    assert set(terminal_config_words.SEQUENCE) == {str(c) for c in SequenceProblem}
    assert set(terminal_config_words.SEQUENCE_LOG) == {str(c) for c in SequenceLine}
    assert set(terminal_config_words.PLANNED_STEP) == {str(c) for c in Online}
    assert set(terminal_config_words.API) == {str(c) for c in (*ApiRefusal, *PluginRefusal, *bench._Missing)}
    assert set(terminal_config_words.LOG) == {str(c) for c in (*ApiLine, *BackboneLine)}
    assert set(terminal_config_words.PLUGIN) == {str(c) for c in PluginOption}
    assert set(terminal_config_words.NUMBER) == {str(c) for c in Shown}
    assert set(terminal_config_words.STUDY) == {str(c) for c in StudyArgs}
    assert set(terminal_config_words.STUDY_OUT) == {str(c) for c in StudyOut}
    assert set(terminal_words.PROMISE) == {str(c) for c in (*Kept, *Short)}
    assert set(report_words.CONCERN) == {str(c) for c in (*Concern, *Kept, *Short)}
    assert set(report_words.OVERALL) == {str(c) for c in Verdict}
    assert set(terminal_words.CHECK) == {str(c) for c in CheckLine}
    assert set(terminal_words.RUN) == {str(c) for c in RunLine}
    assert set(terminal_words.MODES) == {str(c) for c in ModeLine}
    run = terminal_run_words            # a run's words before and while it runs (bench run, resume, dry-run, watch)
    for words, codes in ((run.DRY_RUN, DryRunLine), (run.RESUME, ResumeLine), (run.WATCH, WatchLine),
                         (run.SEQUENCE, SequenceEndLine), (run.ENVELOPE, EnvelopeProblem), (run.SESSION, SessionLine),
                         (run.DOING, Doing), (run.SIGNAL, SignalLine), (run.STORE, StoreLine),
                         (run.FILE_KIND, FileKind), (run.ACCOUNT, AccountLine),
                         (run.WARMUP, WarmupLine), (run.DEMO, DemoLine), (run.CLI, CliLine),
                         (run.SNAPSHOT, SnapshotLine), (run.STOP, StopLine), (run.SERVER, ServerLine),
                         (page_words.MESSAGE, PageMessage), (page_words.ERROR, PageError),
                         (run.REFUSAL, (*RunRefusal, *EnvelopeRefusal, *WriteRefusal, *FileRefusal,
                                                                  *AccountRefusal))):
        assert set(words) == {str(c) for c in codes}, codes
    data = {"SOURCE": SourceProblem, "NOT_IN_PLANT": NotInPlant, "TWIN_NOTE": TwinNote, "TWIN": TwinSaid,
            "COMPARE": CompareSaid, "EXPORT": (*ExportSaid, *ModeId), "ANALYZE": AnalyzeSaid, "TOOLS": ToolLine,
            "RESULTS": ResultLine, "STUDIES": (*StudiesSaid, *StudySaid, *MapRefusal, *McRefusal, *BatchSaid),
            "IMPORT": (*ImportProblem, *ImportLine),
            "FUNDAMENTALS": (*ParameterStatus, *Separation, *FundamentalLine)}
    for name, codes in data.items():
        assert set(getattr(data_words, name)) == {str(c) for c in codes}, name
    assert set(data) == set(data_words._MAPPINGS)       # said() finds each code in one mapping only
    every = [str(c) for codes in data.values() for c in codes]
    assert len(every) == len(set(every))


def _refusals(run, outs, capsys) -> list:
    """Each refusal's exit status, what it said on stderr and the files it left: ``bench
    resume`` of a run whose lock another session holds, ``bench demo --out`` into a file,
    a foreign directory and an earlier demo's directory with a file the demo did not write."""
    snap = lambda d: sorted((p.relative_to(d).as_posix(), p.stat().st_size) for p in d.rglob("*"))   # noqa: E731
    got = []
    fd = os.open(run / LOCK_NAME, os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)           # another open file: another session's lock
        before = snap(run)
        got.append((main(["resume", str(run), "--no-report"]), capsys.readouterr().err, snap(run) == before))
    finally:
        os.close(fd)
    for out in outs:
        before = snap(out.parent)
        got.append((main(["demo", "--out", str(out)]), capsys.readouterr().err, snap(out.parent) == before))
    for command, path in (("report", run.parent / "absent"), ("report", outs[1]), ("resume", run.parent / "newer")):
        before = snap(run.parent)
        got.append((main([command, str(path)]), capsys.readouterr().err, snap(run.parent) == before))
    return got


def test_rewording_every_refusal_changes_no_exit_status_and_no_file(small_run, tmp_path, capsys, monkeypatch):
    """A session refused because the run is in use, the demo refusing three directories, a
    report of no directory, a report of one that is not a run's, a resume of a newer format's:
    the same exit statuses, nothing written, when the terminal says codes only."""
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run, ignore=shutil.ignore_patterns("report", "export", "analysis"))
    RunStore.open(run).update(status="interrupted")
    outs = [tmp_path / d / "out" for d in ("file", "foreign", "demo")]
    for out in outs:
        out.parent.mkdir()
    outs[0].write_text("a file")
    (outs[1] / "thesis").mkdir(parents=True)
    (outs[1] / "thesis" / "ch1.tex").write_text("x")
    outs[2].mkdir()
    (outs[2] / MANIFEST).write_text(json.dumps({"files": {}, "dirs": []}))
    (outs[2] / "ch1.tex").write_text("x")
    newer = tmp_path / "newer"
    newer.mkdir()
    (newer / "run.json").write_text(json.dumps({"format_version": 99}))
    before = _refusals(run, outs, capsys)
    assert [(code, kept) for code, _, kept in before] == [(ExitCode.FAILURE, True)] + [(ExitCode.USAGE, True)] * 6
    assert f"run directory {run} is in use by another process" in before[0][1]
    _codes_only(monkeypatch)
    after = _refusals(run, outs, capsys)
    assert [(code, kept) for code, _, kept in after] == [(code, kept) for code, _, kept in before]
    said = [err for _, err, _ in after]
    for err, code in zip(said, ("in_use", "demo_not_a_dir", "demo_not_a_demo", "demo_foreign", "run_dir_missing",
                                "run_dir_no_run_json", "run_json_newer"), strict=True):
        assert f"<{code}>" in err, said


def test_the_pages_warnings_are_the_renderers_words(small_run, monkeypatch):
    """The live page warns of a step whose force was not reached in the words it always
    used, made by bench.words.page; said as codes, the same warnings in the same order."""
    reader = RunReader(small_run.path)
    results = [dict(key="00003-L00-F003-up", force_converged=False, target_force_N=2.0, force_error=-0.052,
                    control_iterations=7), dict(key="00004-L00-F004-up", force_converged=True)]
    meta = {"identifiability_warnings": ["F_s: no level above it"]}
    before = reader._warnings(meta, results)
    assert before[:2] == [dict(source="plan", text="F_s: no level above it"),
                          dict(source="step", text="00003-L00-F003-up: force 2 N not reached (error -5.2 %, 7 iterations)")]
    _codes_only(monkeypatch)
    after = reader._warnings(meta, results)
    assert after[1]["text"] == "<force_not_reached>"
    assert [w["source"] for w in after] == [w["source"] for w in before]


def _damaged_run(small_run, tmp_path):
    """The small run with a step cut short, one emptied, one rewritten, a raw block cut short,
    one flipped, one gone, a stray file, and the plan's last three steps never measured."""
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run, ignore=shutil.ignore_patterns("report", "export", "analysis"))
    steps = run / "steps"
    keys = sorted(p.stem for p in steps.glob("*.json"))
    j = lambda i: steps / f"{keys[i]}.json"      # noqa: E731
    z = lambda i: steps / f"{keys[i]}.npz"       # noqa: E731
    j(1).write_bytes(j(1).read_bytes()[:200])
    j(2).write_bytes(b"")
    j(3).write_text(j(3).read_text().replace('"force_N": ', '"force_N": 1', 1))
    z(4).write_bytes(z(4).read_bytes()[:-100])
    data = bytearray(z(5).read_bytes())
    data[len(data) // 2] ^= 0xFF
    z(5).write_bytes(bytes(data))
    z(6).unlink()
    (steps / "notes.txt").write_text("a note")
    for key in keys[-3:]:
        for ext in (".json", ".npz"):
            (steps / f"{key}{ext}").unlink()
    RunStore.open(run).update(status="interrupted")
    return run


def _check_and_account(run, capsys) -> tuple:
    """``bench check``'s exit status and lines; the report's first lines (what it used and
    skipped, and why; the report's only words of a run directory's problems)."""
    code = main(["check", str(run)])
    return code, capsys.readouterr().out.splitlines(), accounting_md(load_run(run))


def test_rewording_every_storage_problem_changes_no_decision(small_run, tmp_path, capsys, monkeypatch):
    """``bench check`` and the report on a damaged run: the same exit status, the same
    problems (kind, step, file) in the same order and the same overall verdict, when the
    terminal's and the report's renderers say codes only; the words were theirs (the codes show)."""
    run = _damaged_run(small_run, tmp_path)
    before = _check_and_account(run, capsys)
    _codes_only(monkeypatch)
    after = _check_and_account(run, capsys)
    head = lambda lines: [ln.partition(": ")[0] if ln.partition(": ")[2] else ln[:11]   # noqa: E731
                          for ln in lines]          # the kind and the file, or the kind alone: what precedes the words
    assert after[0] == before[0] == ExitCode.FAILURE
    assert head(after[1]) == head(before[1]) and len(before[1]) == 9, before[1]
    assert "  missing  <unmeasured_tail>" in after[1]       # the unmeasured tail: one line
    said = [f"<{c}>" for c in ("not_json", "empty", "json_checksum", "npz_size", "npz_checksum", "missing_pair",
                               "not_a_step_file")]
    assert all(any(w in ln for ln in after[1]) for w in said), after[1]
    assert not any("<" in ln for ln in before[1]) and "<resume_measures>" in after[1][-1]
    said_overall = [ln for ln in before[2] if ln.startswith("Overall: **needs attention**: ")]
    assert said_overall and "<needs_attention>" in after[2] and not any(ln.startswith("Overall") for ln in after[2])
    assert "(damaged: <npz_size>)" in after[2][0] and "<" not in before[2][0]


@pytest.mark.parametrize("text, kind", [('{"key": "00001", "status": "ok', "truncated"),
                                        ('{"key": "00001", "status": "ok"', "truncated"),
                                        ('{"key": "00001", "status": , "x": 1}', "corrupt")])
def test_a_step_file_cut_inside_a_string_is_truncated_whatever_the_parser_says(tmp_path, text, kind):
    """A result file that ends inside a string (or at its last character) is 'truncated';
    garbled inside is 'corrupt': from where the parser stopped, not from its message."""
    p = tmp_path / "00001.json"
    p.write_text(text)
    with pytest.raises(storage.DamagedStep) as e:
        storage._read_step_json(p, "00001")
    assert e.value.problem.kind == kind
    try:
        json.loads(text)
    except json.JSONDecodeError as err:
        assert storage._json_cut(err) == (kind == "truncated")


def _verdicts(run) -> dict:
    """The small run without its two flagged steps (went well), as it is (notes: the flagged
    steps), resumed once (notes), and stopped by a limit (attention): each one's verdict, its
    reasons' and notes' codes, what the procedure kept, and the report's overall line."""
    runs = {"clean": replace(run, attention=[]), "as run": run,
            "resumed": replace(run, events=[*run.events, {"event": "interrupted", "reason": "SIGINT"}, {"event": "resume"}]),
            "tripped": replace(run, meta={**run.meta, "status": "aborted"},
                               events=[*run.events, {"event": "abort", "reason": "force limit"}])}
    out = {}
    for name, r in runs.items():
        o = overall(r, 0, flagged_reasons(r.attention))
        out[name] = ((o.verdict, [s.code for s in o.why], [s.code for s in o.notes], o.kept.kept.code),
                     [ln for ln in accounting_md(r) if ln.startswith(("Overall", "<"))])
    return out


def test_rewording_the_overall_line_changes_no_verdict(small_run, monkeypatch):
    """The report's overall line (issue 35 item 1): went well, went well with notes (a run
    resumed once), needs attention (a run stopped by a limit) are values; said as codes the
    verdicts, their reasons and notes are the same, and the line is the verdict's code."""
    run = load_run(small_run.path)
    before = _verdicts(run)
    values = {k: v for k, (v, _) in before.items()}
    assert [v[0] for v in values.values()] == [Verdict.WENT_WELL, *[Verdict.WENT_WELL_WITH_NOTES] * 2,
                                               Verdict.NEEDS_ATTENTION]
    assert values["as run"][2] == [Concern.FLAGGED] and values["resumed"][2] == [Concern.INTERRUPTED, Concern.FLAGGED]
    assert values["tripped"][1][:2] == [Concern.RUN_STATUS, Concern.LIMIT_TRIP]
    assert [ln[0].partition(": ")[2].partition(":")[0] for _, ln in before.values()] == [
        "**went well**", *["**went well, with notes**"] * 2, "**needs attention**"]
    assert "force limit" in before["tripped"][1][0] and "interrupted 1 time (SIGINT)" in before["resumed"][1][0]
    _codes_only(monkeypatch)
    after = _verdicts(run)
    assert {k: v for k, (v, _) in after.items()} == values
    assert [ln for _, ln in after.values()] == [[f"<{v[0]}>"] for v in values.values()]


BAD_PLAN = ('[plan]\nlevels_N = [1.0, -2.0]\nlevls = 0.02\n'
            '[plan.frequencies]\nstart_Hz = 20.0\nstop_Hz = 200.0\npoints = 4\n')


def test_a_plans_problems_are_codes_with_fields_and_rewording_them_changes_no_exit(tmp_path, capsys, monkeypatch):
    """A plan's problems (a misspelt key, a level out of range) are a ConfigError whose
    problems carry their codes and fields (key, value, bound); ``bench dry-run`` exits 2 with
    the same lines in the same order when the terminal says codes only; a file that is not
    TOML is one coded problem."""
    from bench.config import ConfigError, load_plan
    (tmp_path / "plan.toml").write_text(BAD_PLAN)
    (tmp_path / "bad.toml").write_text("[plan\n")
    with pytest.raises(ConfigError) as e:
        load_plan(tmp_path / "plan.toml")
    assert e.value.code is ConfigProblem.SEVERAL
    problems = [(p.code, p.fields.get("key"), p.fields.get("value"), p.fields.get("low"), p.fields.get("high"))
                for p in e.value.fields["problems"]]
    assert problems == [(ConfigProblem.UNKNOWN_KEY, "levls", None, None, None),
                        (ConfigProblem.OUT_OF_RANGE, "levels_N[1]", -2.0, 0.1, 100.0)], problems
    assert str(e.value).splitlines()[1] == (f"{tmp_path / 'plan.toml'}: [plan] levels_N[1]: must be >= 0.1 and <= 100 "
                                            "(the bench's force range, 0.1-100 N), got -2.0")
    from bench.config import DEFAULTS
    from bench.rig_config import parse_rig
    from bench.toml_tables import read_toml
    rig = read_toml(DEFAULTS / "sim_rig.toml")
    rig["rig"]["model"]["F_s_N"] = -10.0
    with pytest.raises(ConfigError) as model:
        parse_rig(rig, "rig.toml")           # a model key's unit is a field (it was words added to the line)
    assert (model.value.code, model.value.fields["key"], model.value.fields["unit"]) == (
        ConfigProblem.OUT_OF_RANGE, "F_s_N", "N")
    assert str(model.value) == "rig.toml: [rig.model] F_s_N: must be > 0 and <= 10000, got -10.0 (unit: N)"
    with pytest.raises(ConfigError) as bad:
        load_plan(tmp_path / "bad.toml")
    assert bad.value.code is ConfigProblem.NOT_TOML and bad.value.fields["path"] == tmp_path / "bad.toml"
    said = lambda: (main(["dry-run", "--plan", str(tmp_path / "plan.toml")]), capsys.readouterr().err)  # noqa: E731
    before = said()
    _codes_only(monkeypatch)
    after = said()
    assert after[0] == before[0] == ExitCode.USAGE and "levls: unknown key" in before[1]
    assert "<unknown_key>" in after[1] and "<out_of_range>" in after[1] and "levls" not in after[1]


def test_a_plans_rules_across_keys_are_codes_with_fields(monkeypatch):
    """The rules a plan breaks across its keys (bench.config.ConfigRule) and a stored plan's own
    problems are codes with fields (a dwell without the refinement, harmonics above Nyquist, a
    grid not in ascending order); said as codes, the same problems in the same order; a range's
    note is a code too (bench.config.RangeNote); a stored plan's frequency out of range keeps
    its code and names run.json's key in its fields."""
    from bench.config import FORCE_RANGE, ConfigError, parse_plan, parse_stored_plan
    plan = {"plan": {"levels_N": [1.0], "frequencies": {"list_Hz": [900.0]}, "control": {"harmonics": 30},
                     "resonance": {"dwell_cycles": 10}}}

    def problems():
        with pytest.raises(ConfigError) as e:
            parse_plan(plan, "p.toml")
        return [(p.code, dict(p.fields)) for p in e.value.fields["problems"]], str(e.value)
    before, said = problems()
    assert [c for c, _ in before] == [ConfigRule.DWELL_NEEDS_REFINE, ConfigRule.ABOVE_NYQUIST], before
    assert before[1][1] == {"source": "p.toml", "table": "plan.control", "most": 14, "top_Hz": 900.0,
                            "rate_Hz": 25600.0, "value": 30}
    assert said.splitlines() == ["p.toml: [plan.resonance] dwell_cycles: needs refine = true (the dwell is at the "
                                 "refined resonance)", "p.toml: [plan.control] harmonics: must be <= 14 (below "
                                 "Nyquist at 900 Hz with min_sample_rate_Hz = 25600), got 30"]
    assert terminal_config_words.range_note(FORCE_RANGE) == " (the bench's force range, 0.1-100 N)"

    def stored_frequency():             # run.json's key named by the fields, not by rewriting the words
        with pytest.raises(ConfigError) as e:
            parse_stored_plan({"levels_N": [1.0], "freqs_Hz": [3.0]}, "run.json")
        return e.value.code, e.value.fields["table"], e.value.fields["key"], str(e.value)
    assert stored_frequency() == (ConfigProblem.OUT_OF_RANGE, "plan", "freqs_Hz[0]", "run.json: [plan] freqs_Hz[0]: "
                                  "must be >= 20 and <= 1000 (the bench's frequency range, 20-1000 Hz), got 3.0")
    _codes_only(monkeypatch)
    assert stored_frequency() == (ConfigProblem.OUT_OF_RANGE, "plan", "freqs_Hz[0]", "<out_of_range>")
    assert problems() == (before, "<dwell_needs_refine>\n<above_nyquist>")
    with pytest.raises(ConfigError) as stored:
        parse_stored_plan({"levels_N": [1.0], "freqs_Hz": [40.0, 30.0]}, "run.json")
    assert (str(stored.value), stored.value.code, stored.value.fields["key"]) == (
        "<not_ascending>", ConfigRule.NOT_ASCENDING, "freqs_Hz")
    assert terminal_config_words.range_note(FORCE_RANGE) == "<force_range>"


def test_a_sequences_problems_are_codes_with_fields(tmp_path, capsys, monkeypatch):
    """A sequence file's problems (bench.sequence.SequenceProblem: an unknown key, an entry's
    name used twice, an entry without its files) are codes with fields, in order; said as
    codes, ``bench sequence`` refuses it with the same exit status and writes nothing."""
    from bench.sequence import load_sequence
    from sim.errors import ConfigurationError
    seq = tmp_path / "seq.toml"
    seq.write_text('[sequence]\nnme = "x"\n[[sequence.entry]]\nname = "a"\n[[sequence.entry]]\nname = "a"\n')

    def refused():
        with pytest.raises(ConfigurationError) as e:
            load_sequence(seq)
        return e.value
    e = refused()
    assert e.code is SequenceProblem.SEVERAL
    assert [(p.code, p.fields.get("entry"), p.fields.get("key", p.fields.get("name"))) for p in e.fields["problems"]] == [
        (SequenceProblem.UNKNOWN_KEY, None, "nme"), (SequenceProblem.ENTRY_NO_FILE, 1, "plan"),
        (SequenceProblem.ENTRY_NO_FILE, 1, "rig"), (SequenceProblem.ENTRY_NAME_USED, 2, "a"),
        (SequenceProblem.ENTRY_NO_FILE, 2, "plan"), (SequenceProblem.ENTRY_NO_FILE, 2, "rig")]
    assert str(e).splitlines()[3] == f"{seq}: [[sequence.entry]] 2: name: 'a' is used by an earlier entry"
    said = lambda: (main(["sequence", str(seq), "--out", str(tmp_path / "out")]), capsys.readouterr().err)  # noqa: E731
    before = said()
    _codes_only(monkeypatch)
    assert str(refused()) == "<sequence_several>"
    after = said()
    assert after[0] == before[0] == ExitCode.USAGE and "is used by an earlier entry" in before[1]
    assert "<sequence_several>" in after[1] and not (tmp_path / "out").exists()


def test_the_dry_runs_step_lines_are_made_of_values(monkeypatch):
    """``bench dry-run --steps``: what chooses a step online is a code with fields
    (bench.plan_time.Online); said as codes, the same steps, counts and rig-time bound."""
    from bench.config import parse_plan
    plan = parse_plan({"plan": {"levels_N": [1.0], "adaptive_per_sweep": 2, "frequencies": {
        "start_Hz": 40.0, "stop_Hz": 160.0, "points": 4}, "resonance": {"refine": True, "modes": ["pitch"],
                                                                         "max_steps": 3, "dwell_cycles": 100}}})

    def planned():
        steps = planned_step_list(plan)
        return [(p.key, p.count, p.online, dict(p.detail)) for p in steps], rig_time_bound_s(plan), [p.line() for p in steps]
    before = planned()
    assert [p[2] for p in before[0]] == [Online.ADAPTIVE, Online.REFINED, Online.DWELL]
    assert before[2][0] == "00000-L00F***-up                1 N           chosen online  (2 of these 4 frequencies 40-160 Hz, chosen online)"
    assert before[2][2].endswith("  (pitch mode: dwell of 100 cycles at its refined resonance (none without a peak "
                                 "inside the grid))")
    _codes_only(monkeypatch)
    after = planned()
    assert after[:2] == before[:2] and [ln.rsplit("  ", 1)[1] for ln in after[2]] == ["(<adaptive>)", "(<refined>)",
                                                                                     "(<dwell>)"]


def test_the_apis_refusals_and_a_failed_fits_number_are_codes(monkeypatch):
    """The Python API's refusals, bench's missing name and a number that is not a measurement
    are codes (their words: bench.words.terminal_config); said as codes, the same exception
    types and the same decisions (hasattr, what is named instead of printed)."""
    from bench.api import _as_plan, _checked_labels
    from bench.words.numbers import number, percent

    def said():
        out = []
        for call in (lambda: _as_plan(3), lambda: _checked_labels({"": 1}), lambda: bench.nothing_here):
            with pytest.raises(Exception) as e:
                call()
            out.append((type(e.value).__name__, getattr(e.value, "code", None), str(e.value)))
        return out, hasattr(bench, "nothing_here"), [number(v) for v in (float("nan"), -1e31, 1e-31, 1.5)], percent(1e5)
    before = said()
    assert before[0] == [("TypeError", ApiRefusal.NOT_A_PLAN, "plan: expected a bench Plan or the path of a plan "
                                                              "file, got int"),
                         ("ConfigurationError", ApiRefusal.BAD_LABEL, "labels: a key must be a non-empty string, "
                                                                      "got ''"),
                         ("AttributeError", "no_attribute", "module 'bench' has no attribute 'nothing_here'")]
    assert before[1:] == (False, ["not a number", "absurd (fit failed)", "absurd (fit failed)", "1.5"],
                          "absurd (fit failed)")
    _codes_only(monkeypatch)
    assert said() == ([(t, c, f"<{c}>") for t, c, _ in before[0]], False, ["<nan>", "<absurd>", "<absurd>", "1.5"],
                      "<absurd>")


def test_the_study_commands_refusals_and_outcome_are_codes_with_fields(tmp_path, capsys, monkeypatch):
    """What ``bench study`` and the batch mode of ``bench analyze`` refuse of their arguments (a
    grid that is not numbers, a batch without --out, a Monte-Carlo study on a real rig's file)
    and the outcome they print are codes with fields (bench.studies.cli); said as codes, the
    same exit status, nothing written, and the outcome's exit status still says whether a task
    failed."""
    from bench.studies.cli import _report
    from bench.studies.engine import Outcome

    from .test_config import RIG, write
    real = write(tmp_path, "real_rig.toml", RIG)
    outcome = Outcome(tmp_path / "s", computed=1, skipped=2, failures=[dict(task="k1", inputs={"a": 1}, error="E: x"),
                      dict(task="k2", inputs={"source": "/p/bad.uff", "pad": "x" * 300}, error="E: y")],
                      seconds=1.25, workers=2)
    commands = (["study", "map", "--n", "a,b", "--out", str(tmp_path / "m")],
                ["analyze", str(tmp_path / "x"), str(tmp_path / "y")],
                ["study", "mc", "--rig", str(real), "--out", str(tmp_path / "mc")])

    def said():
        out = []
        for args in commands:
            out.append((main(args), capsys.readouterr().err))
        return out, _report(outcome), capsys.readouterr().out
    before = said()
    assert [status for status, _ in before[0]] == [ExitCode.USAGE] * 3
    assert "expected numbers like '0.5,1.5' or 'start:stop:count', got 'a,b'" in before[0][0][1]
    assert "analysing several sources needs --out DIR" in before[0][1][1]
    assert f"{real}: a Monte-Carlo study needs a simulated rig (simulated = true, [rig.model])" in before[0][2][1]
    assert before[1:] == (1, f"1 tasks computed, 2 already done, 2 failed in 1.2 s on 2 workers; table: "
                             f"{tmp_path / 's' / 'results.parquet'}\nFAILED k1 {{'a': 1}}: E: x\n"
                             "FAILED k2 /p/bad.uff: E: y\n")
    _codes_only(monkeypatch)
    after = said()
    assert [status for status, _ in after[0]] == [ExitCode.USAGE] * 3
    assert [f"<{code}>" in err for (_, err), code in zip(after[0], (StudyArgs.NOT_NUMBERS, StudyArgs.NEEDS_OUT,
                                                                    StudyArgs.MC_RIG_NOT_SIMULATED))] == [True] * 3
    assert after[1:] == (1, f"<{StudyOut.OUTCOME}>\n<{StudyOut.FAILED}>\n<{StudyOut.FAILED}>\n")
    assert not [p for p in ("m", "mc") if (tmp_path / p).exists()]


def test_a_broken_promise_said_as_codes_still_exits_1(tmp_path, capsys, monkeypatch):
    """``bench run`` of a backbone that never locks (its window below the mode) completes and
    exits 1 because the procedure did not measure what it promised (decision 0052; in words:
    tests/bench/test_procedure_words.py); said as codes, the same exit status, its end lines
    and ``bench check``'s shortfall line the codes of bench.words.terminal."""
    from bench.config import DEFAULTS
    plan = tmp_path / "bb.toml"
    plan.write_text('[plan]\nprocedure = "phase_resonance"\nlevels_N = [1.0]\n[plan.backbone]\nstart_Hz = 40.0\n'
                    'max_Hz = 50.0\n[plan.control]\nsettle_cycles = 10\nmeasure_cycles = 10\n')
    _codes_only(monkeypatch)
    run = tmp_path / "run"
    code = main(["run", "--plan", str(plan), "--rig", str(DEFAULTS / "sim_rig.toml"), "--out", str(run), "--no-report"])
    said = capsys.readouterr()
    assert code == ExitCode.FAILURE and RunStore.open(run).metadata["status"] == "completed", said.err[-2000:]
    assert "<ended>" in said.out.splitlines() and {"<promise_broken>", "<output_off>"} <= set(said.err.splitlines())
    assert main(["check", str(run)]) == ExitCode.OK
    assert "<promise_short>" in capsys.readouterr().out.splitlines()


ENVELOPE_PLAN = """[plan]
levels_N = [1.0, 30.0]
infeasible = "{infeasible}"
[plan.frequencies]
list_Hz = [20.0, 80.0]
[plan.limits]
drive_V = 7.0
force_N = 130.0
disp_m = 0.15e-3
accel_m_s2 = 20.0
"""


def test_rewording_a_runs_words_changes_no_envelope_decision(tmp_path, capsys, monkeypatch):
    """``bench dry-run`` of a plan whose 30 N at 20 Hz moves a free 10 kg mass 0.19 mm (> 0.15
    mm): refused (exit 3) as a code, and with ``infeasible = "skip"`` the same step skipped
    (exit 0), when the terminal says codes only; the refusal keeps its code and the problem."""
    from bench.config import DEFAULTS, load_plan, load_rig
    from bench.session import EnvelopeError, check_envelope
    plans = {}
    for infeasible in ("refuse", "skip"):
        plans[infeasible] = tmp_path / f"{infeasible}.toml"
        plans[infeasible].write_text(ENVELOPE_PLAN.format(infeasible=infeasible))
    _codes_only(monkeypatch)
    assert main(["dry-run", "--plan", str(plans["refuse"])]) == ExitCode.LIMIT
    lines = capsys.readouterr().out.splitlines()
    assert lines[:3] == ["<plan>", "<levels>", "<time>"] and lines[-1] == "<refused>", lines
    assert lines[-2].split()[0] == "30" and lines[-2].endswith("20 Hz: <displacement>"), lines   # the envelope's row
    assert main(["dry-run", "--plan", str(plans["skip"])]) == ExitCode.OK
    assert "<runs_some>" in capsys.readouterr().out.splitlines()
    rig = load_rig(DEFAULTS / "sim_rig.toml")
    assert check_envelope(load_plan(plans["skip"]), rig).skip == ((1, 0),)          # 30 N at 20 Hz
    with pytest.raises(EnvelopeError) as refusal:
        check_envelope(load_plan(plans["refuse"]), rig)
    assert str(refusal.value) == "<not_held>" and refusal.value.code == EnvelopeRefusal.NOT_HELD
    bad = [p for p in refusal.value.fields["points"] if p.problems]
    assert [(p.level, p.freq_Hz, [s.code for s in p.problems]) for p in bad] == [(30.0, 20.0, ["displacement"])]
def _twin_and_source_decisions(tmp_path, capsys) -> tuple:
    """What the twin decides of three causes (not in the plant: the rig's own transient, a
    line in one step that is not mains, a cause with no plant form; a viscous damping built
    in), what the UFF58 reader decides of a step missing two records, and ``bench analyze``
    of a file that holds no dataset 58 (exit status, and its one line)."""
    from bench.config import DEFAULTS, load_rig
    from bench.sources import _uff_step
    from bench.twin import apply_causes
    model = load_rig(DEFAULTS / "sim_rig.toml").model.keys()     # the flat [rig.model] keys (decision 0075)
    causes = [dict(id="unsettled_transient"), dict(id="mystery"), dict(id="viscous_damping", parameters=dict(c=dict(value=3.0))),
              dict(id="line_interference", channel="disp", parameters=dict(frequency=dict(value=37.3), amplitude=dict(value=1e-8)),
                   evidence=dict(steps=["s1"]))]
    _, applied, missed = apply_causes(dict(model), causes, dict(mass_kg=model["mass_kg"], drive_height_m=None))
    with pytest.raises(ValueError) as e:
        _uff_step("s1", [dict(ordinate_spec_data_type=13, _record=1, data=np.zeros(8))])
    (tmp_path / "junk.uff").write_text("not a universal file\n")
    code = main(["analyze", str(tmp_path / "junk.uff")])
    return applied, missed, (e.value.code, e.value.fields, str(e.value)), code, capsys.readouterr().err.strip()


def test_rewording_the_data_commands_words_changes_no_decision(tmp_path, capsys, monkeypatch):
    """The twin's causes not in its plant, a UFF58 step's missing records and ``bench
    analyze``'s refusal of a file with no dataset 58 are codes with fields; said as codes
    (bench.words.terminal_data), the twin builds in and leaves out the same causes (a line in
    one step is the rig's own vibration by its code, no longer by whether its words are
    empty) and the command exits the same."""
    applied, missed, (code, fields, said), status, err = _twin_and_source_decisions(tmp_path, capsys)
    assert list(applied) == ["viscous_damping"] and [m["cause"] for m in missed] == ["unsettled_transient", "mystery",
                                                                                     "line_interference"]
    assert missed[2]["reason"].startswith("a 37.3 Hz line in 1 step(s) only, not mains")
    assert (code, fields) == (SourceProblem.MISSING_RECORDS, {"sdts": [12, 8]})
    assert said == "missing record(s): acceleration (type 12), displacement (type 8)"
    assert status == ExitCode.USAGE and "junk.uff: no dataset 58 in the file (dataset types: []) (" in err, err
    _codes_only(monkeypatch)
    after = _twin_and_source_decisions(tmp_path, capsys)
    assert after[0] == applied and [m["cause"] for m in after[1]] == [m["cause"] for m in missed]
    assert [m["reason"] for m in after[1]] == ["<unsettled>", "<no_form>", "<free_vibration>"]
    assert after[2] == (code, fields, "<missing_records>") and after[3] == status and "<no_dataset_58>" in after[4]
    monkeypatch.setattr(data_words, "NOT_IN_PLANT", {c: lambda **_: "" for c in data_words.NOT_IN_PLANT})
    assert _twin_and_source_decisions(tmp_path, capsys)[:2] == (applied, [dict(m, reason="") for m in missed])
