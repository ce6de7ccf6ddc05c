"""bench.sources.load_source: run directories and UFF58 files as other software writes them
(contract 2), with every bad step rejected for a stated reason and nothing modified."""
import hashlib
import math
import shutil

import numpy as np
import pytest

from bench.sources import load_source
from benchtools.independent_masing import simulate_level

TRUTH = dict(F_s_N=10.0, x_s_m=10e-6, n=0.6, mass_kg=10.0)
FS = 6211.0          # not a multiple of any step frequency


def digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def uff_set(case, sdt, data, fs=FS):
    label = {13: "force", 12: "acceleration", 8: "displacement"}[sdt]
    return dict(type=58, func_type=1, func_id=1, ver_num=0, load_case_id=case, id1=f"{label}", id2="other software",
                id3="NONE", id4="NONE", id5="NONE", rsp_ent_name="carriage", rsp_node=1, rsp_dir=1,
                ref_ent_name="shaker", ref_node=1, ref_dir=1, abscissa_spacing=1, abscissa_min=0.0,
                abscissa_inc=1.0 / fs, abscissa_spec_data_type=17, abscissa_axis_lab="time",
                abscissa_axis_units_lab="s", ordinate_spec_data_type=sdt, ordinate_axis_lab=label,
                ordinate_axis_units_lab="N", orddenom_spec_data_type=0, orddenom_axis_units_lab="NONE",
                x=np.arange(len(data)) / fs, data=np.asarray(data, float))


@pytest.fixture(scope="module")
def steps():
    """Four steps (0.5 F_s, 0.6-1.5 x the friction resonance) from the independent simulator."""
    w_s = math.sqrt(TRUTH["F_s_N"] / (TRUTH["x_s_m"] * TRUTH["mass_kg"]))
    betas = [0.6, 0.9, 1.2, 1.5]
    rng = np.random.default_rng(3)
    out = []
    for (_t, u, acc, P), beta in zip(simulate_level(TRUTH["n"], 0.5, betas, 12, 8, FS / w_s), betas):
        F = P * TRUTH["F_s_N"] + 0.03 * rng.standard_normal(P.size)
        a = acc * TRUTH["F_s_N"] / TRUTH["mass_kg"]
        a = a + 0.005 * np.std(a) * rng.standard_normal(a.size)
        x = u * TRUTH["x_s_m"] + 2e-8 * rng.standard_normal(u.size)
        out.append((beta * w_s / (2 * math.pi), F, a, x))
    return out


def write(path, sets):
    import pyuff
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
    return path


def test_untagged_uff58_steps_are_read_with_frequency_and_level_from_the_data(steps, tmp_path):
    sets = [uff_set(i + 1, sdt, d) for i, (f, F, a, x) in enumerate(steps) for sdt, d in ((13, F), (12, a), (8, x))]
    path = write(tmp_path / "other.uff", sets)
    before = digest(path)
    src = load_source(path)
    assert src.kind == "uff58" and not src.rejected and len(src.steps) == 4
    # no false alarm on Masing records with sharp reversals (n < 1) and noise
    assert all(s.quality.status == "usable" and not s.quality.artefacts for s in src.steps), \
        [s.quality.notes for s in src.steps]
    for s, (f, F, a, x) in zip(src.steps, steps):
        assert s.freq_Hz == pytest.approx(f, rel=5e-5)    # ASCII UFF keeps 6 digits of 1/fs
        assert s.level_N == pytest.approx(5.0, rel=2e-3)             # measured |F_1|, not assumed
        assert s.direction == ""
        assert s.harmonics.disp.size > 20                            # every harmonic, not a guessed 5
        assert s.force_N.size == s.disp_m.size == round(FS / f)      # one averaged period
        assert np.ptp(s.disp_m) == pytest.approx(np.ptp(x), rel=0.05)
    assert digest(path) == before                                    # nothing the user gave is modified


def test_bad_steps_are_rejected_with_a_reason(steps, tmp_path):
    (f0, F0, a0, x0), (f1, F1, a1, x1), (f2, F2, a2, x2), (f3, F3, a3, x3) = steps
    marked = x2.copy()
    marked[100] = 12345.0                     # becomes "NaN" in the file (pyuff writes NaN as 0)
    sets = ([uff_set(1, 13, F0), uff_set(1, 12, a0)]                                  # no displacement
            + [uff_set(2, 13, F1), uff_set(2, 12, a1[:-7]), uff_set(2, 8, x1)]        # shorter record
            + [uff_set(3, 13, F2), uff_set(3, 12, a2), uff_set(3, 8, marked)]         # not finite
            + [uff_set(4, 13, F3), uff_set(4, 12, a3, fs=2 * FS), uff_set(4, 8, x3)]  # other rate
            + [uff_set(5, 13, F0), uff_set(5, 12, a0), uff_set(5, 8, x0)])            # good
    path = write(tmp_path / "bad.uff", sets)
    text = path.read_text()
    assert text.count("1.23450000000e+04") == 1
    path.write_text(text.replace("1.23450000000e+04", "              NaN"))
    src = load_source(path)
    reasons = {r.step: r.reason for r in src.rejected}
    assert [s.key for s in src.steps] == ["LC0005"]
    assert "missing record(s): displacement (type 8)" in reasons["LC0001"]
    assert "different lengths" in reasons["LC0002"]
    assert "non-finite values in the disp record" in reasons["LC0003"]
    assert "different sample rates" in reasons["LC0004"]


def test_a_record_that_never_settles_is_rejected_as_not_periodic(steps, tmp_path):
    f, F, a, x = steps[1]
    t = np.arange(F.size) / FS
    drifting = x * (1 + 0.2 * np.exp(-t * f / 3))                  # amplitude still growing into place
    src = load_source(write(tmp_path / "drift.uff", [uff_set(1, 13, F), uff_set(1, 12, a), uff_set(1, 8, drifting)]))
    reason = src.rejected[0].reason
    assert not src.steps and "not periodic enough on the displacement probe (disp)" in reason
    assert "unsettled transient" in reason and "settle" in reason and "more cycles" in reason
    (art,) = src.rejected[0].quality.artefacts
    assert art.kind == "unsettled_transient" and art.channel == "disp"
    assert art.decay_per_s == pytest.approx(f / 3, rel=0.15)       # the amplitude decay rate


def closed_form_step(f, fs, periods, seed, hum=0.0, clip_force=False):
    """Records of a periodic response (odd harmonics) with noise; optional 50 Hz hum on the probe."""
    t = np.arange(int(periods * fs / f)) / fs
    rng = np.random.default_rng(seed)
    wave = lambda a1, a3: a1 * np.sin(2 * np.pi * f * t) + a3 * np.sin(6 * np.pi * f * t + 0.5)   # noqa: E731
    F = wave(5.0, 0.2) + 0.003 * rng.standard_normal(t.size)
    a = wave(20.0, 2.0) + 0.01 * rng.standard_normal(t.size)
    x = wave(10e-6, 0.5e-6) + 2e-9 * rng.standard_normal(t.size) + hum * np.sin(2 * np.pi * 50.0 * t + seed)
    if clip_force:
        F = np.clip(F, -4.5, 4.5)
    return F, a, x


def test_hum_on_the_probe_in_a_foreign_file_keeps_the_steps_and_is_named_as_mains(tmp_path):
    """Written with pyuff as other software writes it; 50 Hz hum on the probe in every step
    but the last, whose force clips."""
    from sim.artefacts import artefact_causes
    fs, freqs = 8192.0, [23.0, 31.0, 71.0, 97.0]
    sets = []
    for i, f in enumerate(freqs):
        F, a, x = closed_form_step(f, fs, 16, i, hum=20e-9 if i < 3 else 0.0, clip_force=(i == 3))
        sets += [uff_set(i + 1, 13, F, fs), uff_set(i + 1, 12, a, fs), uff_set(i + 1, 8, x, fs)]
    src = load_source(write(tmp_path / "hum.uff", sets))
    assert [s.key for s in src.steps] == ["LC0001", "LC0002", "LC0003"]
    for s in src.steps:
        (line,) = s.quality.artefacts
        assert line.kind == "line_interference" and line.channel == "disp"
        assert line.freq_Hz == pytest.approx(50.0, abs=0.02) and line.size == pytest.approx(20e-9, rel=0.05)
        assert s.quality.status == "flagged"
    (rej,) = src.rejected
    assert rej.step == "LC0004" and "clipping on the force sensor (force)" in rej.reason
    causes = {c["id"]: c for c in artefact_causes(src.quality())}
    assert set(causes) == {"line_interference", "clipping"}
    assert "in 3 of 4 steps" in causes["line_interference"]["sentence"]
    assert "50 Hz mains interference" in causes["line_interference"]["sentence"]
    assert causes["clipping"]["channel"] == "force" and causes["clipping"]["evidence"]["steps_rejected"] == ["LC0004"]
    assert [(k, status) for k, status, _ in src.attention()] == [("LC0004", "rejected"), ("LC0001", "flagged"),
                                                                  ("LC0002", "flagged"), ("LC0003", "flagged")]


def test_an_unreadable_record_costs_its_step_only_and_an_unreadable_file_is_named(steps, tmp_path):
    f, F, a, x = steps[0]
    path = write(tmp_path / "broken.uff", [uff_set(1, 13, F), uff_set(1, 12, a), uff_set(1, 8, x)]
                 + [uff_set(2, 13, F), uff_set(2, 12, a), uff_set(2, 8, x)])
    lines = path.read_text().splitlines(keepends=True)
    starts = [i for i, line in enumerate(lines) if line.strip() == "-1"]
    record2 = starts[2] + 14                                           # a data line of the second record
    lines[record2] = "  garbage that is not a number\n"
    path.write_text("".join(lines))
    src = load_source(path)
    assert [s.key for s in src.steps] == ["LC0002"]
    assert [r.step for r in src.rejected] == ["LC0001"]
    assert "record 2 of the file (dataset 58) cannot be read" in src.rejected[0].reason
    junk = tmp_path / "junk.uff"
    junk.write_text("not a universal file\n")
    with pytest.raises(ValueError, match="junk.uff"):
        load_source(junk)


@pytest.mark.parametrize("sample", ["3.00000000000e+300", "3.0e+300", "NaN", "inf", "-inf"])
def test_one_damaged_sample_costs_its_step_only_not_the_file(steps, tmp_path, capsys, sample):
    """Issue 24, item 9: a file of 8 steps written by pyuff (as other software writes it)
    with one sample of step 4's force record damaged: the 7 others are kept, step 4 is
    listed with the reason (as a damaged step of a run directory is)."""
    sets = [uff_set(case, sdt, d) for case in range(1, 9)
            for sdt, d in ((13, steps[(case - 1) % 4][1]), (12, steps[(case - 1) % 4][2]), (8, steps[(case - 1) % 4][3]))]
    path = write(tmp_path / "eight.uff", sets)
    lines = path.read_text().splitlines(keepends=True)
    starts = [i for i, line in enumerate(lines) if line.strip() == "-1"]
    data = starts[2 * 9] + 13 + 5                        # a data line of record 10: step 4's force
    head, first = lines[data][:3], lines[data][3:23]
    assert float(first) == pytest.approx(steps[3][1][20], rel=1e-9)  # the 21st sample (4 per line)
    lines[data] = head + sample.rjust(len(first)) + lines[data][23:]
    path.write_text("".join(lines))
    src = load_source(path)
    assert [s.key for s in src.steps] == [f"LC{c:04d}" for c in (1, 2, 3, 5, 6, 7, 8)]
    assert [r.step for r in src.rejected] == ["LC0004"]
    said = src.rejected[0].reason
    assert said.startswith(("record 10 of the file (dataset 58) cannot be read",      # pyuff cannot parse it
                            "non-finite values in the force record")), said              # or it reads inf/NaN
    if sample == "3.00000000000e+300":        # the command (a fit: seconds) once
        from bench.cli import main
        assert main(["identify", str(path)]) == 0
        out = capsys.readouterr().out
        assert "step LC0004 rejected: record 10 of the file" in out and "7 steps (1 rejected)" in out


def test_a_run_directory_gives_every_step_and_rejects_a_damaged_block(small_run, tmp_path):
    src = load_source(small_run.path)
    results = small_run.results()
    assert src.kind == "run" and not src.rejected and len(src.steps) == len(results)
    for s, r in zip(src.steps, results):
        assert s.key == r["key"] and s.freq_Hz == r["freq_Hz"] and s.level_N == r["target_force_N"]
        assert s.direction == r["direction"]
        X1 = r["disp"]["amplitude"][0]
        # the source fits the block again after the step-quality check (sim.artefacts: trend and
        # line removal, its own noise estimate), not the stored fit: equal to its noise, not to 1e-12
        assert abs(s.harmonics.disp[0]) == pytest.approx(X1, rel=5e-3)
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run)
    victim = results[3]["key"]
    (run / "steps" / f"{victim}.npz").write_bytes(b"not a zip")
    before = {p.name: digest(p) for p in (run / "steps").iterdir()}
    src = load_source(run)
    assert [r.step for r in src.rejected] == [victim]
    assert "damaged" in src.rejected[0].reason and f"{victim}.npz" in src.rejected[0].reason
    assert len(src.steps) == len(results) - 1
    assert {p.name: digest(p) for p in (run / "steps").iterdir()} == before


def test_the_simulated_rig_has_no_interference_line_and_its_free_vibration_is_settled(small_run):
    """The default simulated rig puts no line on any sensor (no `line_channel` in
    bench/defaults/sim_rig.toml), so no step of a run on it may carry a line_interference.
    What its records carried before decision 0037 is the carriage's pre-rolling mode, which
    the ramp and each frequency change excite (decision 0033); the procedure now settles
    until the step-quality check finds none, so no step keeps it (its frequency and decay
    rate are checked on records taken without the re-settle, tests/procedures/test_settle.py),
    and no step was recorded unsettled."""
    from bench.config import DEFAULTS, load_rig
    assert load_rig(DEFAULTS / "sim_rig.toml").model.line_channel == ""
    src = load_source(small_run.path)
    arts = [(s.key, a) for s in src.steps for a in s.quality.artefacts]
    assert not [(k, a.describe()) for k, a in arts if a.kind in ("line_interference", "unsettled_transient")]
    results = small_run.results()
    assert not [r["unsettled"] for r in results if r["unsettled"]]
    assert sum(r["settle_extra_blocks"] for r in results) > 0          # there was something to settle
