"""The run report: files, plots, tables, and the simulated rig against the model engine."""

from __future__ import annotations

import json
import math
import re
import shutil

import numpy as np
import pytest

from bench.reports import (
    ID_PARAMS,
    UNSETTLED_RESIDUAL,
    identification_data,
    plot_identification,
    residual_ratio,
    write_analysis_html,
    write_report,
)
from bench.storage import RunStore
from sim.rig import RigModel
from sim.shooting import frf_shooting

PNGS = ("compliance.png", "accelerance.png", "quality.png", "modes.png", "model_vs_measurement.png",
        "identification.png")


@pytest.fixture(scope="module")
def run_dir(small_run, tmp_path_factory):
    # the report is written into the run directory: work on a copy of the shared run
    dst = tmp_path_factory.mktemp("report") / "run"
    shutil.copytree(small_run.path, dst)
    return dst


@pytest.fixture(scope="module")
def report(run_dir):
    return write_report(run_dir)


@pytest.fixture
def no_png(monkeypatch):
    """The report's figures written as empty files, not drawn (a draw is ~0.5 s each): for the
    tests that read the text and which files there are; the plots are checked on `report`."""
    from bench.reports import _figures
    monkeypatch.setattr(_figures, "save_png", lambda fig, path: (path.write_bytes(b""), path)[1])


def _copy(run_dir, tmp_path):
    dst = tmp_path / "run"
    shutil.copytree(run_dir, dst, ignore=shutil.ignore_patterns("report", "export"))
    return dst


def test_report_writes_markdown_and_every_plot(report, run_dir):
    assert report == run_dir / "report" / "report.md"
    for name in PNGS:
        assert (report.parent / name).is_file(), name
        assert f"({name})" in report.read_text(), f"report.md does not describe {name}"


@pytest.mark.parametrize("name", PNGS)
def test_plots_are_valid_non_blank_pngs(report, name):
    from matplotlib.image import imread
    path = report.parent / name
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    img = imread(path)
    assert img.ndim == 3 and img.shape[0] > 300 and img.shape[1] > 500
    ink = np.any(img[..., :3] < 0.9, axis=-1).mean()      # share of pixels that are not white
    assert 0.01 < ink < 0.6


def test_report_names_plan_rig_status_and_each_level(report, run_dir):
    text = report.read_text()
    meta = RunStore.open(run_dir).metadata
    assert "small test plan" in text and meta["rig"]["name"] in text
    assert "**completed**" in text and "20 readable / 20 planned" in text
    for part in ("TWIN000001", "numpy", "none (events.jsonl"):
        assert part in text
    for level in (1.0, 5.0):
        assert any(line.startswith(f"| {level:g} | ") for line in text.splitlines()), level


def test_report_opens_with_the_steps_used_against_the_plan_and_an_overall_line(report):
    head = report.read_text().split("## Instruments")[0]
    assert "**20 used / 20 planned**; skipped: none" in head
    assert "Overall: **went well" in head and "needs attention" not in head
    # flagged steps (used) are notes of a run that went well, counted per reason (issue 33)
    assert "with notes" not in head or "flagged by the step-quality check" in head


def _modes_rows(report):
    rows = {}
    for line in _section(report.read_text(), "Modes per level").splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) >= 9 and cells[0] in ("feed", "pitch"):
            rows[(cells[0], float(cells[1]))] = cells
    return rows


def test_modes_table_has_the_feed_mode_at_each_level_near_the_engines_peak(report):
    """The seed (Figs. 12-13): the feed resonance falls as the force rises; each level's feed
    mode is in the table, found inside the grid near the shooting engine's peak of
    compliance_pp, or said to lie at the grid's edge with no value."""
    rows = _modes_rows(report)
    assert {k for k in rows if k[0] == "feed"} == {("feed", 1.0), ("feed", 5.0)}
    for (_, level), cells in rows.items():
        if cells[2] == "ok":
            f = float(cells[3].split()[0])
            assert f == pytest.approx(float(cells[-1]), rel=0.1)     # the model's (engine) resonance: the last column
        elif cells[2].startswith("coarse"):        # 5 points: the bracket of the maximum holds the engine's peak
            lo, hi = (float(x) for x in cells[3].split("[")[1].rstrip("]").split(","))
            assert lo < float(cells[-1]) < hi and cells[4] == "-"
        else:
            assert cells[3] == "-" and ("grid" in cells[2] or "fit" in cells[2] or "found" in cells[2])
    model = [float(rows[("feed", lv)][-1]) for lv in (1.0, 5.0)]
    assert model[1] < model[0]                  # the model's peak falls with the force


def _model_pp(run_dir):
    """compliance_pp of every step from the sim/ engine, for the rig's true parameters."""
    meta = RunStore.open(run_dir).metadata
    m = RigModel.from_dict(meta["rig"]["model"])
    out = {}
    results = RunStore.open(run_dir).results()
    for level in meta["plan"]["levels_N"]:
        steps = [r for r in results if r["target_force_N"] == level]
        f = np.array(sorted({r["freq_Hz"] for r in steps}))
        fr, _ = frf_shooting(2 * math.pi * f / m.omega_s, level / m.F_s_N, m.n)
        assert fr.converged.all()
        C = dict(zip(f, fr.G * m.x_s_m / m.F_s_N))
        out.update({r["key"]: (r, C[r["freq_Hz"]]) for r in steps})
    return out


def test_simulated_rig_agrees_with_model_engine_where_the_record_is_clean(run_dir):
    """An independent check of the whole chain (plant, twins, DAQ, force control, fits):
    the rig's RK4 plant seen through noisy sensors must give the shooting engine's
    compliance.  The stored compliance_pp is the peak-to-peak of the fitted periodic
    displacement, so sensor noise biases it only through the fitted harmonics; on the
    unflagged steps it agrees within 0.1 % in this run; allow 0.5 %."""
    pairs = _model_pp(run_dir)
    clean = [(r, c) for r, c in pairs.values() if residual_ratio(r) < UNSETTLED_RESIDUAL]
    assert len(clean) >= 10
    for r, c in clean:
        assert r["compliance_pp_m_per_N"] / c - 1 == pytest.approx(0, abs=0.005), r["key"]


def test_stored_compliance_matches_model_at_every_level_flagged_steps_included(run_dir):
    """Flagged steps (displacement residual up to 80 % of the fundamental at 300 Hz, 1 N)
    still give compliance_pp within 1.5 % here, where the raw record's peak-to-peak is up to
    2x the model: the harmonic fit rejects the residual.  Median within 0.5 %, max 3 %."""
    pairs = _model_pp(run_dir)
    for level in (1.0, 5.0):
        d = [r["compliance_pp_m_per_N"] / c - 1 for r, c in pairs.values() if r["target_force_N"] == level]
        assert abs(np.median(d)) < 0.005, level
        assert max(abs(x) for x in d) < 0.03, level


def _section(text, title):
    return text.split(f"## {title}")[1].split("\n## ")[0]


def _rows(section, first_cells):
    out = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and cells[0] in first_cells:
            out[cells[0]] = cells
    return out


def test_model_table_reports_each_level_with_small_differences(report):
    rows = _rows(_section(report.read_text(), "Model vs measurement"), ("1", "5"))
    assert set(rows) == {"1", "5"}
    for row in rows.values():
        median, largest, largest_unflagged = (float(row[i].split()[0]) for i in (3, 4, 5))
        assert abs(median) < 0.5 and abs(largest) < 3 and abs(largest_unflagged) < 0.5


def test_modes_table_peak_is_near_the_largest_stored_compliance_pp(report, run_dir):
    results = RunStore.open(run_dir).results()
    for (mode, level), cells in _modes_rows(report).items():
        if mode == "feed" and cells[2] == "ok":
            best = max(r["compliance_pp_m_per_N"] for r in results if r["target_force_N"] == level)
            assert best * 0.98 <= float(cells[6].split()[0]) <= best * 1.5


def test_texts_say_where_compliance_pp_comes_from(report):
    text = report.read_text()
    assert "from the periodic displacement of the harmonic fit" in text
    assert "raw record" not in text


def test_run_stored_before_fitted_compliance_pp_is_reported_as_raw(run_dir, tmp_path, no_png):
    """Older runs have no disp.raw_peak_to_peak and their compliance_pp is the raw record's."""
    run = _copy(run_dir, tmp_path)
    for p in (run / "steps").glob("*.json"):
        r = json.loads(p.read_text())
        r.pop("integrity", None)              # they predate the checksums too
        r["disp"]["peak_to_peak"] = r["disp"].pop("raw_peak_to_peak")
        r["compliance_pp_m_per_N"] = 0.5 * r["disp"]["peak_to_peak"] / r["force_N"]
        p.write_text(json.dumps(r))
    text = write_report(run).read_text()
    assert "from the raw record (this run predates" in text
    assert "from the periodic displacement of the harmonic fit" not in text
    assert "from the raw record, is biased high" in _section(text, "Steps needing attention")
    assert (run / "report" / "compliance.png").is_file()


# ---------------------------------------------------------------------------- identification


def _id_table(text):
    return _rows(_section(text, "Identification of F_s, x_s, n and m"), [p.label for p in ID_PARAMS])


def test_identification_table_shows_the_final_fit_of_run_json(report, run_dir):
    final = RunStore.open(run_dir).metadata["identification"]
    rows = _id_table(report.read_text())
    assert set(rows) == {p.label for p in ID_PARAMS}
    for p in ID_PARAMS:
        row = rows[p.label]
        for col, part in ((2, "values"), (3, "low"), (4, "high")):
            assert float(row[col]) == pytest.approx(final[part][p.key] * p.scale, rel=1e-3), (p.key, part)
        assert float(row[5].split()[0]) == pytest.approx(100 * final["rel_std"][p.key], abs=0.006)


def test_identification_section_lists_times_chi2_and_warnings(report, run_dir):
    meta = RunStore.open(run_dir).metadata
    final = meta["identification"]
    section = _section(report.read_text(), "Identification of F_s, x_s, n and m")
    assert f"final fit over {final['steps_used']} steps" in section
    assert (f"median {final['update_ms_median']:.3g} ms, max {final['update_ms_max']:.3g} ms") in section
    assert f"reduced chi^2: {final['reduced_chi2']:.4g}" in section
    assert "fit warnings: none" in section and not final["warnings"]
    # this plan has no level at or above F_s and few frequencies near the resonance
    assert len(meta["identifiability_warnings"]) == 2
    for w in meta["identifiability_warnings"]:
        assert f"  - {w}" in section


def test_the_runs_log_holds_its_identifiability_warnings(run_dir):
    """They were logged before the run's bench.log was opened: the terminal showed them, the
    run directory's log did not."""
    log = (run_dir / "bench.log").read_text()
    warned = RunStore.open(run_dir).metadata["identifiability_warnings"]
    assert warned and all(f"WARNING bench.session: identifiability: {w}" in log for w in warned)


def test_simulated_rig_identification_recovers_the_true_parameters(report, run_dir):
    """The truth is the rig model's (an independent fact), not the identifier's own output.
    With 20 steps the final fit's 95 % half-widths are at most 0.5 % (x_s) and the estimates
    come out within 0.02 %: require each within 1 % of the truth and the truth inside the
    reported interval, and the report's truth and error columns to say so."""
    meta = RunStore.open(run_dir).metadata
    final, truth = meta["identification"], RigModel.from_dict(meta["rig"]["model"])
    rows = _id_table(report.read_text())
    for p in ID_PARAMS:
        t, v = getattr(truth, p.key), final["values"][p.key]
        assert v / t - 1 == pytest.approx(0, abs=0.01), p.key
        assert final["low"][p.key] <= t <= final["high"][p.key], p.key
        row = rows[p.label]
        assert float(row[6]) == pytest.approx(t * p.scale, rel=1e-3)
        assert float(row[7].split()[0]) == pytest.approx(100 * (v / t - 1), abs=0.006)
        assert row[8] == "yes"


def test_identification_plot_keeps_truth_and_final_estimate_on_scale(run_dir):
    """The first estimates are far off (the axis caps them); truth and final fit must stay visible."""
    meta = RunStore.open(run_dir).metadata
    ident = identification_data(run_dir, meta)
    assert len(ident.history) == 20 and ident.truth
    fig = plot_identification(ident, "t", [])
    for ax, p in zip(fig.axes, ID_PARAMS):
        lo, hi = ax.get_ylim()
        for v in (ident.truth[p.key], meta["identification"]["values"][p.key]):
            assert lo < v * p.scale < hi, p.key
        assert ax.get_yscale() == ("log" if p.log_y else "linear")


def test_interrupted_run_reports_the_last_online_estimate(run_dir, tmp_path, no_png):
    run = _copy(run_dir, tmp_path)
    meta = json.loads((run / "run.json").read_text())
    del meta["identification"]
    (run / "run.json").write_text(json.dumps(meta))
    lines = (run / "identification.jsonl").read_text().splitlines()[:7]
    (run / "identification.jsonl").write_text("\n".join(lines) + "\n")
    last = json.loads(lines[-1])
    text = write_report(run).read_text()
    section = _section(text, "Identification of F_s, x_s, n and m")
    assert f"last online estimate, after step {last['step']} (7 steps)" in section
    assert "no final fit" in section
    rows = _id_table(text)
    for p in ID_PARAMS:
        assert float(rows[p.label][2]) == pytest.approx(last["values"][p.key] * p.scale, rel=1e-3)
    assert (run / "report" / "identification.png").is_file()


def test_run_without_identification_says_so_and_has_no_plot(run_dir, tmp_path, no_png):
    run = _copy(run_dir, tmp_path)
    (run / "identification.jsonl").unlink()
    meta = json.loads((run / "run.json").read_text())
    del meta["identification"]
    (run / "run.json").write_text(json.dumps(meta))
    text = write_report(run).read_text()
    section = _section(text, "Identification of F_s, x_s, n and m")
    assert "No identification data" in section
    assert meta["identifiability_warnings"][0] in section
    assert not (run / "report" / "identification.png").exists()
    assert "identification.png" not in text


def test_unreadable_identification_entry_is_shown_not_fatal(run_dir, tmp_path, no_png):
    run = _copy(run_dir, tmp_path)
    meta = json.loads((run / "run.json").read_text())
    meta["identification"] = {"method": "something else"}
    (run / "run.json").write_text(json.dumps(meta))
    section = _section(write_report(run).read_text(), "Identification of F_s, x_s, n and m")
    assert "cannot read" in section and "something else" in section
    assert "last online estimate" in section       # the history is still there


def test_partial_run_reports_its_interruption(run_dir, tmp_path, no_png):
    run = _copy(run_dir, tmp_path)
    for p in sorted((run / "steps").glob("*.json"))[7:]:
        p.unlink()
    store = RunStore.open(run)
    store.event("interrupted", reason="Ctrl-C")
    store.update(status="interrupted", steps_done=7)
    text = write_report(run).read_text()
    assert "**interrupted**" in text and "**7 used / 20 planned**" in text
    assert "Overall: **needs attention**: the run was interrupted" in text
    assert "| interrupted | reason=Ctrl-C |" in text
    assert (run / "report" / "compliance.png").is_file()


def test_run_without_steps_gives_a_report_without_plots(run_dir, tmp_path):
    run = _copy(run_dir, tmp_path)
    for p in (run / "steps").glob("*"):
        p.unlink()
    text = write_report(run).read_text()
    assert "No step was completed" in text
    assert not (run / "report" / "compliance.png").exists()


# ---------------------------------------------------------------------------- analysis section


def test_report_has_no_analysis_section_before_bench_analyze(report):
    assert "## Analysis" not in report.read_text()


def test_report_includes_the_analysis_when_bench_analyze_wrote_it(run_dir, tmp_path, analysis_example, no_png):
    run = _copy(run_dir, tmp_path)
    (run / "analysis").mkdir()
    (run / "analysis" / "analysis.json").write_text(json.dumps(analysis_example))
    write_analysis_html(dict(analysis_example, steps=[], loops=[]), run / "analysis" / "analysis.html")
    report = write_report(run)
    section = _section(report.read_text(), "Analysis: what the model gets wrong")
    assert f"> {analysis_example['verdict']}" in section
    (cause,) = analysis_example["causes"]
    row = _rows(section, [f"{cause['label']} (`{cause['id']}`)"])[f"{cause['label']} (`{cause['id']}`)"]
    c = cause["parameters"]["c"]
    # each figure to the digit its interval supports (the interval's first or second significant digit)
    value, low, high = re.fullmatch(r"c = (\S+) N s/m \[(\S+), (\S+)\]", row[1]).groups()
    step = 10.0 ** -(len(value.split(".")[1]) if "." in value else 0)
    assert step <= (c["high"] - c["low"]) / 2 < 100 * step, (row[1], c)
    for shown, exact in zip((value, low, high), (c["value"], c["low"], c["high"])):
        assert abs(float(shown) - exact) <= step / 2 * (1 + 1e-9)
    assert float(row[2].split()[0]) == pytest.approx(100 * cause["gain"]["heldout_error_before"], rel=1e-2)
    assert float(row[3].split()[0]) == pytest.approx(100 * cause["gain"]["heldout_error_after"], rel=1e-2)
    link = "../analysis/analysis.html"
    assert f"[analysis.html]({link})" in section and (report.parent / link).is_file()
    assert f"steps used: {len(analysis_example['steps_used'])}, rejected: 1" in section


def test_unreadable_analysis_is_named_in_the_report_not_fatal(run_dir, tmp_path):
    run = _copy(run_dir, tmp_path)
    for p in (run / "steps").glob("*"):      # no plots: this test is about the text
        p.unlink()
    (run / "analysis").mkdir()
    (run / "analysis" / "analysis.json").write_text('{"verdict": "trunc')
    text = write_report(run).read_text()
    section = _section(text, "Analysis: what the model gets wrong")
    assert "cannot be shown" in section and "analysis.json cannot be read" in section
    assert "## Identification of F_s, x_s, n and m" in text      # the rest of the report is there


def test_every_plant_effect_the_engine_leaves_out_is_named_in_the_model_notes():
    """The shooting engine is the plain Masing model: a simulated rig with any optional effect
    on must say so next to the comparison, or a difference would read as an engine error."""
    from dataclasses import fields

    from bench.reports._model import _model_effects
    companions = {      # parameters only meaningful with a main one
        "friction_alpha": dict(friction_v_ref_m_per_s=0.01),
        "pitch_inertia_kg_m2": dict(pitch_stiffness_N_m_per_rad=1e4, pitch_damping_N_m_s_per_rad=1.0,
                                    drive_height_m=0.05, cg_height_m=0.03),
        "line_amplitude": dict(line_channel="disp", line_freq_Hz=50.0),
        "shaker_force_constant_N_per_A": dict(shaker_resistance_ohm=1.5, shaker_inductance_H=2e-4,
                                              shaker_armature_mass_kg=0.3, shaker_suspension_N_per_m=2e4,
                                              shaker_damping_N_s_per_m=20.0)}
    sub_parameters = {k for c in companions.values() for k in c}
    effects = [f.name for f in fields(RigModel) if f.default == 0.0 and f.name not in sub_parameters
               and f.name != "seed"]
    assert len(effects) >= 9
    for name in effects:
        notes = _model_effects(RigModel(**{name: 0.01}, **companions.get(name, {})))
        assert list(notes) == [name] and name in notes[name], name


def test_the_report_lists_the_same_rejected_and_flagged_steps_as_bench_analyze(run_dir, tmp_path, no_png):
    """One notion of step quality (issue 19): a step whose force clips is rejected and one
    with hum on the probe is kept with the hum removed, in the report exactly as in the
    source that `bench analyze` reads."""
    from bench.sources import load_source
    from sim.step_record import measure_block
    run = _copy(run_dir, tmp_path)
    store = RunStore.open(run)
    results = store.results()
    # hum 20 Hz from the 30 Hz drive: separable in its 10 periods (at 53 Hz it would not be)
    hummed = next(r["key"] for r in results if r["freq_Hz"] == 30.0 and r["target_force_N"] == 5.0)
    clipped = next(r["key"] for r in results if r["freq_Hz"] > 100 and r["target_force_N"] == 5.0)
    for key, edit in ((clipped, "clip"), (hummed, "hum")):
        r = next(x for x in results if x["key"] == key)
        raw = dict(store.raw(key))
        if edit == "clip":
            raw["force_N"] = np.minimum(raw["force_N"], 0.9 * raw["force_N"].max())
        else:
            t = np.arange(raw["disp_m"].size) / float(raw["fs_Hz"])
            raw["disp_m"] = raw["disp_m"] + 40e-9 * np.sin(2 * np.pi * 50.0 * t + 0.3)
        # the block as if measured so: its record made from it, as the procedure makes it (decision 0047)
        r = {**r, **measure_block(raw["force_N"], raw["accel_m_s2"], raw["disp_m"], float(raw["fs_Hz"]),
                                  r["freq_Hz"], len(r["force"]["amplitude"])).fields}
        store.write_step(key, r, raw)
    src = load_source(run)
    assert [x.step for x in src.rejected] == [clipped] and "force sensor (force)" in src.rejected[0].reason
    # one step's 50 Hz line: no source comes back over the run, so no mains cause (decision
    # 0053); the step is flagged for it all the same (the rig's own ringing, or a line)
    at50 = [a for s in src.steps if s.key == hummed for a in s.quality.artefacts
            if a.kind in ("line_interference", "unsettled_transient") and abs(a.freq_Hz - 50.0) <= 0.05]
    assert len(at50) == 1
    section = _section(write_report(run).read_text(), "Steps needing attention")
    listed = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) == 3 and cells[1] in ("rejected", "flagged"):
            listed[cells[0]] = (cells[1], cells[2])
    assert listed == {k: (status, why.replace("|", "\\|")) for k, status, why in src.attention()}
    assert listed[clipped][0] == "rejected" and "clipping" in listed[clipped][1]
    assert listed[hummed][0] == "flagged" and "50" in listed[hummed][1]
