"""Decisions are values, words are made at the edge (issue 35 item 1, decision 0059): every
function that makes the words a decision used to read is made to say something else (codes
only), and the decisions stay the same: a step's verdict, why it was rejected, what settling
longer cures, the causes of a run's artefacts, which missing steps are the run's unmeasured
tail, whether a step file was cut short."""

import json
import shutil

import numpy as np
import pytest

import bench.storage as storage
import sim.artefacts.causes as causes
import sim.artefacts.decision as decision
import sim.artefacts.quality as quality
from bench.cli import ExitCode, main
from bench.storage import RunStore
from procedures.stepped_sine import unsettled_in
from sim.artefacts import artefact_causes, assess_step

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
                    u.cycles, tuple(round(x, 6) for x in u.vibrations_Hz), bool(u.why)))
        qs.append((f"s{i}", q))
    found = [(c["id"], c["channel"], c["evidence"]["steps"], c["gain"]) for c in artefact_causes(qs)]
    return tuple(out), found, qs[5][1].reason


def test_rewording_the_artefact_checks_messages_changes_no_decision(monkeypatch):
    """The verdicts, the rejection's cause, the settle advice's cycles and the causes of 7
    steps (hum, clipping, not periodic with a mains hint, a transient) are the same when every
    word-maker the checks' decisions once read says codes only."""
    before, found, reason = _decisions()
    assert [d[0] for d in before] == ["flagged"] * 4 + ["rejected", "rejected", "flagged"]
    assert [str(d[1]) for d in before[4:6]] == ["raw_fault", "not_periodic"]
    assert before[5][5] and not before[4][5]        # settling longer may cure step 5, never step 4
    assert "mains hum" in reason and {"line_interference", "clipping", "unsettled_transient"} <= {c[0] for c in found}
    monkeypatch.setattr(decision, "not_periodic", lambda ch, what, score, limit: f"P:{ch}:{what}")
    monkeypatch.setattr(decision, "harmonic_words", lambda k: f"H{k}")
    monkeypatch.setattr(causes, "mains_family", lambda base: f"M{base:g}")
    monkeypatch.setattr(quality.Artefact, "describe", lambda self: f"A:{self.kind}:{self.channel}")
    after, found_after, reason_after = _decisions()
    assert reason_after.startswith("P:disp:") and "mains hum" in reason_after      # reworded, the hint kept
    assert after == before and found_after == found


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
    monkeypatch.setattr(storage, "MISSING_WORDS", {k: "|".join(k) for k in storage.MISSING_WORDS})
    assert main(["check", str(run)]) == ExitCode.FAILURE
    lines = capsys.readouterr().out.splitlines()
    assert any(f"interrupted after step {keys[11]}; {len(keys) - 12} not yet measured" in ln for ln in lines), lines
    assert not any(".json|.npz" in ln for ln in lines), lines


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
