"""Resonance search and `bench modes` end to end on the simulated rigs, against independent
references: the feed mode against the peak of the shooting engine's compliance_pp computed
densely (sim.frf.find_peaks); the pitching mode against a brute-force dense window of steps
(0.5 Hz apart) of the same rig.  benchmarks/bench_modes.py runs the full bars (3 levels,
wider dense runs, half-power damping)."""

from __future__ import annotations

import csv
import dataclasses
import math

import numpy as np
import pytest

from bench.cli import main
from bench.config import DEFAULTS, load_rig, parse_plan
from bench.reports import run_modes
from bench.session import run_plan
from bench.storage import RunStore
from sim.frf import find_peaks
from sim.shooting import frf_shooting


def _plan(name, levels, freqs, resonance=None):
    p = {"name": name, "levels_N": levels, "frequencies": freqs, "control": {"harmonics": 5}}
    if resonance:
        p["resonance"] = resonance
    return parse_plan({"plan": p})


@pytest.fixture(scope="module")
def feed_run(tmp_path_factory):
    """1 N on the plain rig, 12 log points 30-300 Hz, the feed peak refined."""
    plan = _plan("coarse refined", [1.0], {"start_Hz": 30.0, "stop_Hz": 300.0, "points": 12},
                 {"refine": True, "modes": ["feed"]})
    store = run_plan(plan, load_rig(DEFAULTS / "sim_rig.toml"), tmp_path_factory.mktemp("feed") / "run",
                     identify=False, labels={"rig": "plain"})
    assert store.metadata["status"] == "completed"
    return store


@pytest.fixture(scope="module")
def pitch_run(tmp_path_factory):
    """1 N on the pitching rig, 8 log points 120-300 Hz (the feed mode below the grid),
    the pitching peak refined."""
    plan = _plan("pitch refined", [1.0], {"start_Hz": 120.0, "stop_Hz": 300.0, "points": 8},
                 {"refine": True, "modes": ["pitch"]})
    store = run_plan(plan, load_rig(DEFAULTS / "sim_rig_pitch.toml"), tmp_path_factory.mktemp("pitch") / "run",
                     identify=False, labels={"lubricant": "ISO VG 32"})
    assert store.metadata["status"] == "completed"
    return store


def test_refined_feed_resonance_matches_the_engines_dense_peak(feed_run):
    keys = [r["key"] for r in feed_run.results()]
    refined = [k for k in keys if "-RF" in k]
    assert 3 <= len(refined) <= 10                       # the budget holds; the steps are ordinary steps
    assert feed_run.account().complete and not feed_run.check()
    assert feed_run.metadata["steps_total"] == len(keys)
    ws = math.sqrt(10.0 / (10e-6 * 10.0))                 # the rig file's F_s, x_s, m
    f = np.linspace(60, 75, 61)
    fr, _ = frf_shooting(2 * np.pi * f / ws, 0.1, 1.5)
    ref = find_peaks(fr)[0].beta * ws / (2 * math.pi)
    (feed,) = run_modes(feed_run.path, model=False).modes
    assert feed.ok and feed.resonance_Hz == pytest.approx(ref, rel=0.01)
    assert abs(feed.resonance_Hz / ref - 1) < 0.003       # measured: 0.06 %
    assert 0 < feed.damping_ratio_low < feed.damping_ratio < feed.damping_ratio_high < 0.3
    # never zero width (a `bench run` of this plan on main: 67.8995 Hz [67.8995, 67.8995],
    # the fitted peak pinned at the first point of a window of refinement steps, decision 0050)
    assert feed.resonance_low_Hz < feed.resonance_Hz < feed.resonance_high_Hz
    assert feed.window_Hz[0] < feed.resonance_Hz < feed.window_Hz[1]
    from bench.storage import stored_plan
    from procedures.resonance import refinement_outcomes
    assert refinement_outcomes(stored_plan(feed_run.metadata), feed_run.results()) == {(0, "feed"): "converged"}


def test_refined_pitch_resonance_matches_a_dense_window_and_the_feed_is_below_the_grid(pitch_run, tmp_path):
    modes = {e.mode: e for e in run_modes(pitch_run.path, model=False).modes}
    assert modes["feed"].status == "below grid" and math.isnan(modes["feed"].resonance_Hz)
    pitch = modes["pitch"]
    assert pitch.ok and pitch.damping_ratio_low < pitch.damping_ratio < pitch.damping_ratio_high
    # brute force: 0.5 Hz steps around the estimate, the peak of their parabola
    centre = round(pitch.resonance_Hz * 2) / 2
    dense = [centre + 0.5 * k for k in range(-2, 3)]
    store = run_plan(_plan("dense", [1.0], {"list_Hz": dense}), load_rig(DEFAULTS / "sim_rig_pitch.toml"),
                     tmp_path / "dense", identify=False)
    res = sorted(store.results(), key=lambda r: r["freq_Hz"])
    acc = np.array([r["accelerance_abs_kg_inv"] for r in res])
    i = int(np.argmax(acc))
    assert 0 < i < len(dense) - 1                         # the dense window holds the peak
    a, b, _ = np.polyfit(dense[i - 1:i + 2], acc[i - 1:i + 2], 2)
    assert pitch.resonance_Hz == pytest.approx(-b / (2 * a), rel=0.005)
    assert abs(pitch.resonance_Hz / (-b / (2 * a)) - 1) < 0.001


def test_bench_modes_writes_two_runs_with_their_labels(feed_run, pitch_run, tmp_path, capsys):
    assert main(["modes", str(feed_run.path), str(pitch_run.path), "--out", str(tmp_path / "m"), "--no-model"]) == 0
    rows = list(csv.DictReader(open(tmp_path / "m" / "modes.csv")))
    need = {"run", "mode", "level_N", "resonance_Hz", "resonance_low_Hz", "resonance_high_Hz", "damping_fit_fraction",
            "damping_fit_low_fraction", "damping_fit_high_fraction", "damping_energy_balance_fraction",
            "damping_half_power_fraction", "energy_balance_mass_kg", "peak_compliance_m_per_N"}
    assert need <= set(rows[0])
    assert {(r["label"], r["mode"], r["status"]) for r in rows} == {
        ("rig=plain", "feed", "ok"), ("lubricant=ISO VG 32", "feed", "below grid"),
        ("lubricant=ISO VG 32", "pitch", "ok")}
    below = next(r for r in rows if r["status"] == "below grid")
    assert below["resonance_Hz"] == "nan"                 # said to be there, never given a value
    assert (tmp_path / "m" / "fig13_feed.png").stat().st_size > 10_000
    assert (tmp_path / "m" / "fig17_modes.png").stat().st_size > 10_000
    assert "below grid" in capsys.readouterr().out


def test_resume_continues_the_refinement_where_it_stopped(feed_run, tmp_path):
    """A run cut after its first refinement steps, resumed, chooses from the same stored
    steps the same next step as the uninterrupted run (the choice depends on the stored
    steps only) and ends the refinement.  Past that step the two may part: a re-measured
    step differs by the friction's memory and the noise (here 67.8132 Hz came out 0.02 %
    above 67.9491 Hz instead of 0.02 % below), which moves the measured maximum the line
    search brackets (decision 0063); a refinement that then spends its budget says so."""
    import shutil
    cut = tmp_path / "cut"
    shutil.copytree(feed_run.path, cut)
    refined = sorted(p for p in (cut / "steps").glob("*-RF*"))
    keep = {p.stem for p in refined[:4]}                  # R000, R001 (json + npz)
    for p in refined:
        if p.stem not in keep:
            p.unlink()
    RunStore.open(cut).update(status="interrupted")
    code = main(["resume", str(cut), "--no-report"])
    def refined_Hz(store):
        return {r["key"]: r["freq_Hz"] for r in store.results() if "-RF" in r["key"]}
    want, got = refined_Hz(feed_run), refined_Hz(RunStore.open(cut))
    first = sorted(want)[2]                               # R002: the first step the resume chose
    assert got[first] == pytest.approx(want[first], rel=1e-9)
    (end,) = [e for e in RunStore.open(cut).events() if e["event"] == "refinement_end"][-1:]
    assert (code, end["reason"]) in ((0, "converged"), (1, "budget_spent"))
    (e,) = run_modes(cut, model=False).modes
    assert e.status == ("ok" if code == 0 else "not converged")
    assert e.resonance_low_Hz < run_modes(feed_run.path, model=False).modes[0].resonance_Hz < e.resonance_high_Hz


def test_a_misspelled_resonance_key_is_named():
    from bench.config import ConfigError
    with pytest.raises(ConfigError, match=r"\[plan.resonance\] tolerence: unknown key; did you mean tolerance"):
        parse_plan({"plan": {"levels_N": [1.0], "frequencies": {"list_Hz": [50.0, 60.0]},
                             "resonance": {"refine": True, "tolerence": 0.01}}})
    with pytest.raises(ConfigError, match="modes"):
        parse_plan({"plan": {"levels_N": [1.0], "frequencies": {"list_Hz": [50.0, 60.0]},
                             "resonance": {"modes": ["roll"]}}})


def test_dry_run_counts_the_refinement_and_its_rig_time_is_the_runs(feed_run, tmp_path, capsys):
    """dry-run names the refinement budget and an expected rig time; with the refinement
    steps the run took, the estimate is within a factor 1.5 of the simulated rig's clock."""
    import math as _m

    from bench.session import planned_steps, step_seconds
    from bench.storage import stored_plan
    plan_file = tmp_path / "p.toml"
    plan_file.write_text('[plan]\nlevels_N = [1.0]\n[plan.frequencies]\nstart_Hz = 30.0\nstop_Hz = 300.0\n'
                         'points = 12\n[plan.resonance]\nrefine = true\nmodes = ["feed"]\n')
    assert main(["dry-run", "--plan", str(plan_file)]) == 0
    out = capsys.readouterr().out
    assert "12 measured + at most 10 refinement steps" in out and "expected rig time: at most" in out and "typically about" in out
    plan = stored_plan(feed_run.metadata)
    res = feed_run.results()
    n, budget, t = planned_steps(plan)
    used = sum("-RF" in r["key"] for r in res)
    est = t - (budget - used) * step_seconds(plan, _m.sqrt(30 * 300), from_rest=True)
    last = max(res, key=lambda r: r["t0_s"])
    actual = last["t0_s"] + last["n_samples"] / last["fs_Hz"]
    assert 1 / 1.5 < est / actual < 1.5, (est, actual)


def test_the_watch_state_and_page_show_the_modes_as_found(pitch_run):
    """The live page's state holds each mode per level (the grid-edge feed mode said to lie
    below the grid, the pitching mode near the report's value) and the page shows them."""
    from bench.watch import serve
    from bench.watch.snapshot import RunReader

    from .chromium import CHROMIUM, Browser
    state = RunReader(pitch_run.path).snapshot()
    modes = {m["mode"]: m for m in state["modes"]}
    assert modes["feed"]["status"] == "below grid" and modes["feed"]["resonance_Hz"] is None
    report = {e.mode: e for e in run_modes(pitch_run.path, model=False).modes}
    assert modes["pitch"]["resonance_Hz"] == pytest.approx(report["pitch"].resonance_Hz, rel=1e-9)
    assert state["progress"]["total"] == state["progress"]["done"] == len(pitch_run.results())
    if CHROMIUM is None:
        pytest.skip("chromium not installed (make setup)")
    with serve(pitch_run.path) as server, Browser() as browser:
        browser.goto(server.url)
        text = browser.wait_for("document.getElementById('modes').textContent.includes('pitch') && "
                                "document.getElementById('modes').textContent", 30, "the modes table")
        assert "below grid: at or below 120.0 Hz" in text
        assert f"{report['pitch'].resonance_Hz:.5g}" in text
        n = len(pitch_run.results())
        browser.wait_for(f"document.getElementById('accelerance').dataset.points === '{n}'", 30, "the accelerance")
        # the phase axis is not clipped to [-180, 0]: past the pitching mode the phase goes below -180
        lowest = min(p for c in state["compliance"] for p in c["phase_deg"])
        assert lowest < -200
        assert browser.js("document.getElementById('compliance').layout.yaxis2.range[0]") < lowest


def test_the_batch_summary_gets_mode_columns(pitch_run, tmp_path):
    from bench.studies.batch import MODE_COLUMNS, mode_columns
    cols = mode_columns(pitch_run.path)
    assert set(cols) == set(MODE_COLUMNS)
    assert cols["feed_status"] == "1:below grid" and cols["feed_resonance_Hz"] == "1:nan"
    pitch = next(e for e in run_modes(pitch_run.path, model=False).modes if e.mode == "pitch")
    assert cols["pitch_resonance_Hz"] == f"1:{pitch.resonance_Hz:.6g}" and cols["pitch_status"] == "1:ok"
    assert set(mode_columns(tmp_path).values()) == {""}          # not a run directory: empty, not an error


def test_check_of_an_interrupted_run_says_so_in_one_line(small_run, tmp_path, capsys):
    """An interrupted run's unmeasured tail is one line ('interrupted after step K; 8 not
    yet measured'), not one line per step; a step missing inside the measured part is
    still named."""
    import shutil

    from bench.cli import ExitCode
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run, ignore=shutil.ignore_patterns("report", "export", "analysis"))
    keys = sorted(p.stem for p in (run / "steps").glob("*.json"))
    for key in keys[12:] + [keys[3]]:
        for ext in (".json", ".npz"):
            (run / "steps" / f"{key}{ext}").unlink()
    RunStore.open(run).update(status="interrupted")
    assert main(["check", str(run)]) == ExitCode.FAILURE
    lines = capsys.readouterr().out.splitlines()
    assert any(f"interrupted after step {keys[11]}; 8 not yet measured" in ln for ln in lines), lines
    assert any(ln.strip().startswith("missing") and keys[3] in ln for ln in lines)
    assert not any(ln.strip().startswith("missing") and keys[15] in ln and "interrupted" not in ln for ln in lines[:-1])


def test_bench_paper_rig_needs_a_pitching_model(capsys):
    from bench.cli import ExitCode
    assert main(["paper", "--quick", "--out", "/nonexistent/never", "--rig", str(DEFAULTS / "sim_rig.toml")]) \
        == ExitCode.USAGE
    assert "no pitching mode" in capsys.readouterr().err


def test_paper_model_is_the_rig_files_without_noise_line_or_shaker():
    from bench.rig_model import paper_model
    from sim.rig import RigModel
    rig = load_rig(DEFAULTS / "sim_rig_pitch.toml")
    model = paper_model(rig, "sim_rig_pitch.toml")
    assert model.pitch_inertia_kg_m2 == rig.model.pitch_inertia_kg_m2 and model.friction_alpha == 0.5
    off = RigModel()        # the line and the shaker at their defaults (off), as if the file had none
    assert all(getattr(model, k) == getattr(off, k) for k in ("line_channel", "line_freq_Hz", "line_amplitude",
                                                             "shaker_force_constant_N_per_A", "shaker_inductance_H"))
    assert model.disp_noise_m == model.force_noise_N == model.accel_noise_m_s2 == 0.0


def test_the_dwell_records_one_long_block_at_the_refined_resonance(tmp_path, capsys):
    """[plan.resonance] dwell_cycles: after the refinement, one step at the refined feed
    resonance whose block is dwell_cycles periods long; an ordinary step (checked, counted,
    re-measured on resume at the same frequency) that dry-run counts with its rig time."""
    import shutil

    from bench.session import planned_steps
    res = {"refine": True, "modes": ["feed"], "max_steps": 4}
    plan = _plan("dwell", [1.0], {"start_Hz": 30.0, "stop_Hz": 300.0, "points": 12}, res | {"dwell_cycles": 300})
    store = run_plan(plan, load_rig(DEFAULTS / "sim_rig.toml"), tmp_path / "run", identify=False)
    assert store.metadata["status"] == "completed"
    results = store.results()
    (dwell,) = [r for r in results if "-W" in r["key"]]
    assert dwell["key"].endswith("-WF000-up") and dwell["key"] > max(r["key"] for r in results if "-RF" in r["key"])
    assert dwell["n_samples"] / dwell["fs_Hz"] * dwell["freq_Hz"] == pytest.approx(300, abs=0.5)
    assert abs(dwell["force_error"]) <= plan.force_tolerance           # under the force control
    (feed,) = run_modes(store.path, model=False).modes
    assert dwell["freq_Hz"] == pytest.approx(feed.resonance_Hz, rel=plan.refine_tolerance)
    assert store.account().complete and not store.check()
    assert store.metadata["steps_total"] == len(results)
    # resumed without its dwell: measured again, at the same frequency
    cut = tmp_path / "cut"
    shutil.copytree(store.path, cut)
    for p in (cut / "steps").glob("*-W*"):
        p.unlink()
    RunStore.open(cut).update(status="interrupted")
    # the dwell is one more point in the fit: an interval of some width, the damping ratio
    # within a third of the fit's 95 % half-width without it (one point of n >= 5 moves an
    # estimate by about sd / sqrt(n); main: 68.1292 Hz [68.1292, 68.1292], the peak pinned at
    # the window's first point, 68.1292-71.0916 Hz)
    (without,) = run_modes(cut, model=False).modes
    assert feed.resonance_low_Hz < feed.resonance_Hz < feed.resonance_high_Hz
    half = (without.damping_ratio_high - without.damping_ratio_low) / 2
    assert abs(feed.damping_ratio - without.damping_ratio) < half / 3, (feed, without)
    from bench.verdict import promise
    spent = bool(promise(store.metadata["plan"], results, store.metadata["rig"]).short)   # budget spent: exit 1
    assert main(["resume", str(cut), "--no-report"]) == (1 if spent else 0)
    assert RunStore.open(cut).metadata["status"] == "completed"
    (again,) = [r for r in RunStore.open(cut).results() if "-W" in r["key"]]
    assert again["key"] == dwell["key"] and again["freq_Hz"] == dwell["freq_Hz"]
    # dry-run: one dwell per mode and level, with its long block in the rig time
    n, refined, t = planned_steps(plan)
    n0, refined0, t0 = planned_steps(_plan("no dwell", [1.0], {"start_Hz": 30.0, "stop_Hz": 300.0, "points": 12}, res))
    assert (n, refined) == (n0, refined0 + 1) and t - t0 > 300 / 300.0
    plan_file = tmp_path / "p.toml"
    plan_file.write_text('[plan]\nlevels_N = [1.0, 3.0]\n[plan.frequencies]\nstart_Hz = 30.0\nstop_Hz = 300.0\n'
                         'points = 12\n[plan.resonance]\nrefine = true\nmodes = ["feed"]\ndwell_cycles = 500\n')
    assert main(["dry-run", "--plan", str(plan_file)]) == 0
    assert "at most 22 refinement steps" in capsys.readouterr().out    # 2 x 10 + 2 dwells


def test_a_dwell_without_the_refinement_is_refused():
    from bench.config import ConfigError
    with pytest.raises(ConfigError, match=r"\[plan.resonance\] dwell_cycles: needs refine = true"):
        parse_plan({"plan": {"levels_N": [1.0], "frequencies": {"list_Hz": [50.0, 60.0]},
                             "resonance": {"dwell_cycles": 100}}})


@pytest.fixture(scope="module")
def backbone_run(tmp_path_factory):
    """Phase resonance of the plain rig's feed mode at 0.3 and 1 N (decision 0044)."""
    plan = parse_plan({"plan": {"name": "backbone", "procedure": "phase_resonance", "levels_N": [0.3, 1.0],
                                "backbone": {"start_Hz": 80.0},
                                "control": {"settle_cycles": 10, "measure_cycles": 10}}})
    store = run_plan(plan, load_rig(DEFAULTS / "sim_rig.toml"), tmp_path_factory.mktemp("bb") / "run",
                     labels={"test": "phase resonance"})
    assert store.metadata["status"] == "completed"
    return store


def test_bench_modes_reads_a_backbone_run_beside_a_stepped_sine(feed_run, backbone_run, tmp_path):
    """Each locked point is a row (its mode, level, the locked frequency, the energy
    balance's damping ratio, no interval) and is drawn in Figs. 13 and 17 with its run's
    colour as a diamond, beside the stepped sine's circles (decision 0044)."""
    from bench.reports._figures_modes import RUN_COLOURS, plot_fig13, plot_fig17
    assert main(["modes", str(feed_run.path), str(backbone_run.path), "--out", str(tmp_path / "m"),
                 "--no-model"]) == 0
    rows = [r for r in csv.DictReader(open(tmp_path / "m" / "modes.csv")) if r["label"] == "test=phase resonance"]
    points = list(csv.DictReader(open(backbone_run.path / "backbone.csv")))
    assert [(r["mode"], float(r["level_N"]), r["status"]) for r in rows] == [("feed", 0.3, "ok"), ("feed", 1.0, "ok")]
    for r, p in zip(rows, points):
        assert float(r["resonance_Hz"]) == pytest.approx(float(p["frequency_Hz"]), rel=1e-5)
        # a locked point's ratio is the energy balance's (decision 0044), named so
        assert float(r["damping_energy_balance_fraction"]) == pytest.approx(float(p["damping_ratio"]), rel=1e-5)
        assert r["resonance_low_Hz"] == r["damping_fit_fraction"] == "nan"
        assert "phase resonance" in r["note"]
    # the feed mode softens with the level: the backbone's frequency falls (seed Fig. 13)
    assert float(rows[1]["resonance_Hz"]) < float(rows[0]["resonance_Hz"])
    runs = [run_modes(feed_run.path, model=False), run_modes(backbone_run.path, model=False)]
    f = [float(p["frequency_Hz"]) for p in points]
    for fig, ax_of in ((plot_fig13(runs), lambda fig: fig.axes[0]), (plot_fig17(runs), lambda fig: fig.axes[0])):
        drawn = [ln for ln in ax_of(fig).get_lines() if ln.get_marker() == "D" and ln.get_color() == RUN_COLOURS[1]
                 and list(ln.get_ydata()) == pytest.approx(f)]
        assert drawn, "the backbone run's points are not drawn as diamonds in its colour"
        assert any(ln.get_marker() == "o" and ln.get_color() == RUN_COLOURS[0] for ln in ax_of(fig).get_lines())


def test_the_watch_page_shows_the_lock_of_a_phase_resonance_run(backbone_run):
    """The live page's lock panel: the latest block (its frequency, phase error, amplitude
    from the procedure's lock_block events) and each stored point; the blocks are not
    listed among the events."""
    import json

    from bench.watch import serve
    from bench.watch.snapshot import RunReader

    from .chromium import CHROMIUM, Browser
    events = [json.loads(ln) for ln in (backbone_run.path / "events.jsonl").read_text().splitlines()]
    blocks = [e for e in events if e["event"] == "lock_block"]
    points = list(csv.DictReader(open(backbone_run.path / "backbone.csv")))
    state = RunReader(backbone_run.path).snapshot()
    lock = state["lock"]
    assert lock["blocks"] == len(blocks) > 2 and lock["latest"]["freq_Hz"] == blocks[-1]["freq_Hz"]
    # the last block of a locked level is in the band, at the point's frequency
    assert abs(lock["latest"]["phase_error_deg"]) <= 1.0
    assert lock["latest"]["freq_Hz"] == pytest.approx(float(points[-1]["frequency_Hz"]), rel=1e-3)
    assert [p["frequency_Hz"] for p in lock["points"]] == pytest.approx([float(p["frequency_Hz"]) for p in points])
    assert not any(e["event"] == "lock_block" for e in state["events"])
    if CHROMIUM is None:
        pytest.skip("chromium not installed (make setup)")
    with serve(backbone_run.path) as server, Browser() as browser:
        browser.goto(server.url)
        text = browser.wait_for("!document.getElementById('lockcard').hidden && "
                                "document.getElementById('lockcard').textContent", 30, "the lock panel")
        import re
        shown = re.search(r"latest block at .*?: ([-\d.e+]+) Hz, phase error ([-\d.e+]+) deg", text)
        assert shown, text
        assert float(shown[1]) == pytest.approx(blocks[-1]["freq_Hz"], rel=1e-4)
        assert float(shown[2]) == pytest.approx(blocks[-1]["phase_error_deg"], rel=5e-3, abs=1e-3)
        cells = browser.js("Array.from(document.querySelectorAll('#lockpoints td:nth-child(2)')).map(t => t.textContent)")
        assert [float(c) for c in cells] == pytest.approx([float(p["frequency_Hz"]) for p in points], rel=1e-4)
        cells = browser.js("Array.from(document.querySelectorAll('#lockpoints td:nth-child(3)')).map(t => t.textContent)")
        assert [float(c) for c in cells] == pytest.approx([1e6 * float(p["amplitude_m"]) for p in points], rel=1e-3)
        assert text.count("yes") == len(points)


def test_the_backbone_figure_overlays_a_stepped_sines_modes_at_their_amplitudes(feed_run, backbone_run, tmp_path):
    """`bench report BACKBONE --with STEPPED`: the stepped sine's feed resonance per level is
    drawn at the amplitude of its peak (compliance_pp x level); there it lies on the Masing
    backbone of single-harmonic balance (an independent fact: sim.backbone), as the locked
    points do, within the stepped sine's skew of a friction peak (2 %)."""
    from bench.backbone import model_backbone
    from bench.reports._backbone import stepped_points
    from bench.reports._modes import run_modes

    pts = stepped_points([run_modes(feed_run.path, model=False)])
    assert [p["level_N"] for p in pts] == [1.0]
    rig = load_rig(DEFAULTS / "sim_rig.toml")
    (hb,) = model_backbone(rig, np.array([pts[0]["amplitude_m"]]))
    assert pts[0]["frequency_Hz"] == pytest.approx(hb.frequency_Hz, rel=0.02), (pts[0], hb)
    assert pts[0]["frequency_low_Hz"] <= pts[0]["frequency_Hz"] <= pts[0]["frequency_high_Hz"]
    # the amplitude is the one measured at the peak: the largest |X1| of the refined steps
    measured = max(r["compliance_abs_m_per_N"] * r["force_N"] for r in feed_run.results())
    assert pts[0]["amplitude_m"] == pytest.approx(measured, rel=0.03)
    import shutil
    bb = tmp_path / "bb"
    shutil.copytree(backbone_run.path, bb)          # the module's run stays as it was
    assert main(["report", str(bb), "--with", str(feed_run.path)]) == 0
    md = (bb / "report" / "report.md").read_text()
    assert "squares: the modes of 1 stepped-sine run (`--with`)" in md
    assert (bb / "report" / "backbone.png").stat().st_size > 10_000


def test_the_headline_says_whether_the_refinement_converged_or_spent_its_budget(feed_run):
    """Issue 30 item 4 / issue 31 (decision 0052): a refined run is "went well" only when each
    refined peak is known within the tolerance; one whose budget ran out first is named."""
    from bench.verdict import Short, promise
    from bench.words.terminal import promised
    meta, results = feed_run.metadata, feed_run.results()
    kept = promise(meta["plan"], results, meta["rig"])
    assert kept.kept.fields["refined"]["converged"] == 1 and not kept.short
    assert "the refinement converged for 1 peak" in promised(kept.kept)
    # the same steps judged against a tolerance they do not reach, with the budget they used
    done = sum(1 for r in results if "-RF" in r["key"])
    strict = dict(meta["plan"], refine_tolerance=1e-6, refine_steps=done)
    (short,) = promise(strict, results, meta["rig"]).short
    assert short.code is Short.BUDGET_SPENT and short.fields["steps"] == done
    assert promised(short) == (f"refinement: the feed peak at 1 N not within 0.0001 % after {done} steps "
                     "(budget spent; [plan.resonance] max_steps)")
    assert not promise(strict, results, meta["rig"], completed=False).short    # an unfinished run: not judged


def test_damping_ratios_name_their_definition_and_the_energy_balance_is_the_backbones(feed_run, pitch_run, tmp_path):
    """Issue 32 item 2: modes.csv holds three named damping ratios as fractions; the feed
    mode's energy balance at resonance (from the refined step nearest it, the carriage's
    mass) is within 5 % of the single-harmonic Masing backbone's ratio at the step's
    measured amplitude (sim.backbone, independent of the modal fit); the pitching mode's
    uses the rig model's drive-point modal mass, not the carriage's 10 kg."""
    from sim.backbone import backbone_point
    assert main(["modes", str(feed_run.path), str(pitch_run.path), "--out", str(tmp_path / "m")]) == 0
    rows = {(r["label"], r["mode"]): r for r in csv.DictReader(open(tmp_path / "m" / "modes.csv"))}
    feed = rows[("rig=plain", "feed")]
    assert feed["energy_balance_mass"].startswith("carriage mass") and float(feed["energy_balance_mass_kg"]) == 10.0
    key = feed["energy_balance_step"].split()[0]
    assert "-RF" in key and "(refined," in feed["energy_balance_step"]
    step = next(r for r in feed_run.results() if r["key"] == key)
    hb = backbone_point(step["disp"]["amplitude"][0], 10.0, 10.0, 10e-6, 1.5)
    z_eb = float(feed["damping_energy_balance_fraction"])
    assert z_eb == pytest.approx(hb.damping_ratio, rel=0.05)
    assert float(feed["damping_energy_balance_low_fraction"]) < z_eb < float(feed["damping_energy_balance_high_fraction"])
    for d in ("fit", "half_power"):     # fractions, not per cent
        assert 0 < float(feed[f"damping_{d}_fraction"]) < 0.5
    hp = [float(feed[f"damping_half_power_{k}fraction"]) for k in ("low_", "", "high_")]
    assert hp[0] <= hp[1] <= hp[2]
    pitch = rows[("lubricant=ISO VG 32", "pitch")]
    assert "modal mass" in pitch["energy_balance_mass"]
    assert abs(float(pitch["energy_balance_mass_kg"]) / 10.0 - 1) > 0.2
    assert 0 < float(pitch["damping_energy_balance_fraction"]) < 0.2


def test_a_peak_not_located_has_no_half_power_ratio():
    """Issue 32 item 2: half-power "where the band is measured", each with an interval. On
    an overdamped/flat level (the demo's 10 N feed row) the estimator's half-power point
    value has no located peak to be half of; the row gave it (36.89 %) without an interval
    beside a "-" peak. Such a row now has none, a located peak keeps its value."""
    from bench.reports._damping import damping_row
    from sim.modal import ModeEstimate
    flat = ModeEstimate(mode="feed", level_N=10.0, status="overdamped/flat", curve="compliance_pp",
                        resonance_Hz=28.0, resonance_low_Hz=24.0, resonance_high_Hz=39.0, half_power_damping_ratio=0.3689)
    row = damping_row(flat)
    assert all(math.isnan(row[f"damping_half_power_{k}fraction"]) for k in ("low_", "", "high_"))
    located = dataclasses.replace(flat, status="ok")
    assert damping_row(located)["damping_half_power_fraction"] == 0.3689
