"""Phase-resonance runs through the twins (procedure = "phase_resonance", decision 0044),
checked against facts the procedure does not compute: the Masing backbone by
single-harmonic balance at each point's measured amplitude (issue 27's bar), a linear
rig's analytic natural frequency and damping, and the lock-loss and exit paths."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import tomllib

import pytest

from bench.config import DEFAULTS, ConfigError, load_plan, load_rig, parse_plan, parse_rig
from bench.session import run_plan
from sim.backbone import backbone_point

BAR_LEVELS = [0.1, 0.3, 1.0, 3.0]


def backbone_plan(levels, **backbone) -> dict:
    return {"plan": {"name": "backbone", "procedure": "phase_resonance", "levels_N": levels,
                     "backbone": {"start_Hz": 80.0, **backbone},
                     "control": {"settle_cycles": 10, "measure_cycles": 10}}}


def rows(store) -> list[dict]:
    with open(store.path / "backbone.csv") as fh:
        return list(csv.DictReader(fh))


def events(store) -> list[dict]:
    return [json.loads(line) for line in (store.path / "events.jsonl").read_text().splitlines()]


@pytest.fixture(scope="module")
def bar_run(tmp_path_factory):
    plan = parse_plan(backbone_plan(BAR_LEVELS))
    rig = load_rig(DEFAULTS / "sim_rig.toml")
    store = run_plan(plan, rig, tmp_path_factory.mktemp("bb") / "run")
    assert store.metadata["status"] == "completed"
    return rig, store


def test_every_level_locks_on_the_harmonic_balance_backbone(bar_run):
    """Issue 27's bar: the feed mode at 0.1, 0.3, 1 and 3 N on the plain simulated rig, each
    point within 2 % in frequency, 5 % in force, 10 % in damping ratio of the Masing
    backbone at its measured amplitude, phase within 2 degrees of -90."""
    rig, store = bar_run
    m = dataclasses.asdict(rig.model)
    got = rows(store)
    assert [float(r["level_N"]) for r in got] == BAR_LEVELS
    for r in got:
        assert r["locked"] == "true", r
        hb = backbone_point(float(r["amplitude_m"]), m["mass_kg"], m["F_s_N"], m["x_s_m"], m["n"])
        assert float(r["frequency_Hz"]) == pytest.approx(hb.frequency_Hz, rel=0.02)
        assert float(r["force_N"]) == pytest.approx(hb.force_N, rel=0.05)
        assert float(r["damping_ratio"]) == pytest.approx(hb.damping_ratio, rel=0.10)
        assert abs(float(r["phase_deg"]) + 90.0) <= 2.0
        assert float(r["force_N"]) == pytest.approx(float(r["level_N"]), rel=0.02)   # the level held
    # the backbone of a Masing mode falls with amplitude (seed Figs. 12-13)
    f = [float(r["frequency_Hz"]) for r in got]
    assert f == sorted(f, reverse=True) and f[0] / f[-1] > 1.2


def test_points_are_steps_with_backbone_records_and_the_output_ends_off(bar_run):
    _, store = bar_run
    results = sorted(store.results(), key=lambda r: r["index"])
    assert len(results) == len(BAR_LEVELS) and all(r["backbone"]["locked"] for r in results)
    assert all(r["backbone"]["mass_kg"] == 10.0 for r in results)
    assert all(0 < r["backbone"]["periods"] < 400 for r in results)
    ev = events(store)
    assert [e["confirmed"] for e in ev if e["event"] == "output_off"] == [True]
    probe = [e for e in ev if e["event"] == "backbone_probe"]
    assert len(probe) == 1 and probe[0]["slope_deg_per_Hz"] < 0


def test_dry_run_bounds_a_phase_resonance_plans_rig_time(bar_run, tmp_path, capsys):
    """dry-run gave a phase-resonance plan no rig time (issue 32 item 3); its bound holds
    the run's rig time (decision 0063; measured: the bar's 4 levels 12.0 s of rig time, 6-8
    controller blocks each; the bound 426 s counts every level probing and spending all its
    60 blocks at the window's lowest frequency, the plan's limits)."""
    from bench.cli import main
    from bench.plan_time import backbone_time_bound_s
    from bench.storage import stored_plan
    _, store = bar_run
    res = store.results()
    last = max(res, key=lambda r: r["t0_s"])
    actual = last["t0_s"] + last["n_samples"] / last["fs_Hz"]
    bound = backbone_time_bound_s(stored_plan(store.metadata))
    assert actual <= bound, (actual, bound)
    plan_file = tmp_path / "bb.toml"
    plan_file.write_text('[plan]\nprocedure = "phase_resonance"\nlevels_N = [0.1, 0.3, 1.0, 3.0]\n'
                         '[plan.backbone]\nstart_Hz = 80.0\n[plan.control]\nsettle_cycles = 10\nmeasure_cycles = 10\n')
    assert main(["dry-run", "--plan", str(plan_file)]) == 0
    out = capsys.readouterr().out
    assert "expected rig time: at most" in out


LINEAR_K, LINEAR_C = 4.0e5, 80.0          # f_n = 31.83 Hz, zeta = 2 %


@pytest.fixture(scope="module")
def linear_rig():
    """The simulated rig with its friction made negligible (F_s 0.1 mN) and a spring and a
    viscous damper in parallel; an ideal force source."""
    data = tomllib.loads((DEFAULTS / "sim_rig.toml").read_text())
    model = data["rig"]["model"]
    for k in [k for k in model if k.startswith("shaker_")]:
        del model[k]
    model.update(F_s_N=1e-4, x_s_m=1e-2, spring_N_per_m=LINEAR_K, viscous_N_s_per_m=LINEAR_C)
    return parse_rig(data, "linear rig")


def test_a_linear_rig_has_a_flat_backbone_at_its_analytic_mode(linear_rig, tmp_path):
    plan = parse_plan(backbone_plan([0.1, 1.0], start_Hz=36.0))
    store = run_plan(plan, linear_rig, tmp_path / "run")
    assert store.metadata["status"] == "completed"
    f_n = math.sqrt(LINEAR_K / 10.0) / (2 * math.pi)
    zeta = LINEAR_C / (2 * math.sqrt(LINEAR_K * 10.0))
    for r in rows(store):
        assert r["locked"] == "true"
        assert float(r["frequency_Hz"]) == pytest.approx(f_n, rel=0.005)
        assert float(r["damping_ratio"]) == pytest.approx(zeta, rel=0.03)
        # amplitude at resonance: F / (c w)
        assert float(r["amplitude_m"]) == pytest.approx(float(r["force_N"]) / (LINEAR_C * 2 * math.pi * f_n),
                                                        rel=0.03)


def test_a_window_below_the_mode_loses_the_lock_ramps_down_and_says_why(tmp_path):
    plan = parse_plan(backbone_plan([1.0], start_Hz=40.0, max_Hz=50.0))
    store = run_plan(plan, load_rig(DEFAULTS / "sim_rig.toml"), tmp_path / "run")
    ev = events(store)
    lost = [e for e in ev if e["event"] == "lock_lost"]
    assert len(lost) == 1 and "left the window" in lost[0]["reason"]
    (row,) = rows(store)
    assert row["locked"] == "false" and "lock lost" in row["why"]
    assert [e["confirmed"] for e in ev if e["event"] == "output_off"] == [True]
    # the watch page lists it (marked bad: page.js BAD_EVENTS) with the reason
    from bench.watch.snapshot import RunReader
    shown = [e for e in RunReader(store.path).snapshot()["events"] if e["event"] == "lock_lost"]
    assert len(shown) == 1 and "left the window" in shown[0]["reason"]


def test_the_plan_is_checked():
    with pytest.raises(ConfigError, match=r"\[plan.backbone\] start_Hz: missing"):
        parse_plan({"plan": {"procedure": "phase_resonance", "levels_N": [1.0], "backbone": {}}})
    with pytest.raises(ConfigError, match="plan.frequencies.*not used"):
        parse_plan({"plan": {**backbone_plan([1.0])["plan"], "frequencies": {"list_Hz": [50.0]}}})
    with pytest.raises(ConfigError, match=r"\[plan.backbone\] phase_deg: must be > -180 and <= 0"):
        parse_plan(backbone_plan([1.0], phase_deg=90.0))
    with pytest.raises(ConfigError, match="did you mean phase_band_deg"):
        parse_plan(backbone_plan([1.0], phase_band_dg=1.0))
    with pytest.raises(ConfigError, match="window 40-30 Hz must hold start_Hz 80 Hz and its probe blocks"):
        parse_plan(backbone_plan([1.0], max_Hz=30.0))
    with pytest.raises(ConfigError, match="needs procedure"):
        parse_plan({"plan": {"levels_N": [1.0], "frequencies": {"list_Hz": [50.0]}, "backbone": {"start_Hz": 50.0}}})
    plan = parse_plan(backbone_plan([1.0]))
    b = plan.backbone
    assert (b.phase_deg, b.phase_band_deg, b.settle_periods, b.min_Hz, b.max_Hz, b.max_step_Hz) == \
        (-90.0, 1.0, 20, 40.0, 160.0, 4.0)
    assert parse_plan(backbone_plan([1.0], response="accel")).backbone.phase_deg == 90.0
    assert load_plan(DEFAULTS / "backbone_plan.toml").procedure == "phase_resonance"


def test_the_report_shows_the_backbone_over_the_model(bar_run):
    from bench.reports import write_report
    _, store = bar_run
    md = write_report(store.path).read_text()
    assert (store.path / "report" / "backbone.png").stat().st_size > 10_000
    table = [line for line in md.splitlines() if line.startswith("| ") and line.endswith(" |") and "| yes |" in line]
    assert len(table) == len(BAR_LEVELS)
    # the modes section: each locked point as the feed mode's resonance at its level (decision 0044)
    modes = md[md.index("## Modes per level"):]
    assert "Phase resonance: each level's point" in modes
    for r in rows(store):
        assert f"| feed | {float(r['level_N']):g} | ok | {float(r['frequency_Hz']):.4g} |" in modes


def test_the_report_speaks_of_phase_resonance_and_its_locked_levels(bar_run):
    """Issue 31 item 2 / issue 30 item 4 (decision 0052): the title, run table and headline
    name phase resonance and count the levels locked; no identification is claimed and the
    lock blocks are progress, not "Interruptions and aborts"."""
    from bench.reports import write_report
    _, store = bar_run
    md = write_report(store.path).read_text()
    assert md.startswith("# Phase resonance report: backbone")
    assert "Stepped-sine" not in md and "| frequencies |" not in md
    assert "| frequency | found by the loop, from 80 Hz inside the window 40-160 Hz |" in md
    overall = next(line for line in md.splitlines() if line.startswith("Overall:"))
    assert "**went well**" in overall and f"{len(BAR_LEVELS)} of {len(BAR_LEVELS)} levels locked" in overall
    assert "identified model" not in overall and "force within tolerance at every step" not in overall
    assert any(e["event"] == "lock_block" for e in events(store))
    listed = md[md.index("## Interruptions and aborts"):md.index("## Files")]
    rows = [line for line in listed.splitlines() if line.startswith("| ")]
    assert not any("lock_block" in r or "backbone_point" in r for r in rows), rows
    assert "controller blocks are progress, not interruptions" in listed


def test_export_and_modes_speak_of_locked_points_not_of_sweeps(bar_run, tmp_path, capsys, caplog):
    """`bench export` of a backbone (one point per level) writes its steps and modes and says
    why there is no frf.uff (it stopped on "internal error (Exception: Nothing to write)",
    after four "level ... has one readable step" warnings); `bench modes` names the
    energy balance at the locked point, not a single-mode fit it did not make."""
    from bench.cli import main
    _, store = bar_run
    assert main(["export", str(store.path), "--out", str(tmp_path / "x"), "--no-time"]) == 0
    assert sorted(p.name for p in (tmp_path / "x").iterdir()) == ["modes.csv", "modes.uff", "steps.csv"]
    with open(tmp_path / "x" / "steps.csv") as fh:
        assert [float(r["level"]) for r in csv.DictReader(fh)] == BAR_LEVELS
    said = [r.getMessage() for r in caplog.records]
    assert any("phase resonance: one locked point per level" in m for m in said), said
    assert not any("one readable step" in m for m in said), said
    capsys.readouterr()
    assert main(["modes", str(store.path), "--out", str(tmp_path / "m")]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if " Hz" in line]
    assert len(lines) == len(BAR_LEVELS) and all("energy balance at the locked point" in line and "single-mode" not in
                                                  line for line in lines), lines
    # issue 31's bar 3 for a backbone: the rig model's phase resonance at each level (it had none)
    with open(tmp_path / "m" / "modes.csv") as fh:
        got = list(csv.DictReader(fh))
    assert len(got) == len(BAR_LEVELS)
    for r in got:
        assert float(r["model_resonance_Hz"]) == pytest.approx(float(r["resonance_Hz"]), rel=0.005), r


def test_ctrl_c_ends_with_the_output_off_and_resume_goes_on_at_the_next_level(tmp_path, mocker):
    from bench.storage import RunStore
    from procedures.phase_resonance import PhaseLock
    from tests.bench.test_exit_paths import fail_on_call

    plan = parse_plan(backbone_plan(BAR_LEVELS))
    rig = load_rig(DEFAULTS / "sim_rig.toml")
    out = tmp_path / "run"
    fail_on_call(mocker, PhaseLock, "control", 3, KeyboardInterrupt())
    with pytest.raises(KeyboardInterrupt):
        run_plan(plan, rig, out)
    store = RunStore(out)
    assert store.metadata["status"] == "interrupted"
    assert [e["confirmed"] for e in events(store) if e["event"] == "output_off"] == [True]
    first = {p.name: p.read_bytes() for p in (out / "steps").iterdir()}
    assert len(first) == 4 and [r["level_N"] for r in rows(store)] == ["0.1", "0.3"]
    f_locked = float(rows(store)[-1]["frequency_Hz"])
    mocker.stopall()

    store = run_plan(plan, rig, out, resume=True)
    assert store.metadata["status"] == "completed"
    assert all((out / "steps" / n).read_bytes() == b for n, b in first.items())     # kept, not measured again
    got = rows(store)
    assert [float(r["level_N"]) for r in got] == BAR_LEVELS and all(r["locked"] == "true" for r in got)
    probes = [e for e in events(store) if e["event"] == "backbone_probe"]
    assert len(probes) == 2 and probes[1]["freq_Hz"] == pytest.approx(f_locked)      # from the last locked point


def test_the_pitching_mode_backbone_falls_between_its_linear_bounds(tmp_path):
    """The pitching rig's pitch mode, held at +90 degrees of the drive-point acceleration:
    its frequency falls with amplitude (seed Fig. 17) from the linearised 2-DOF pitch
    resonance with the friction's initial stiffness n/(n-1) F_s/x_s towards the one with
    no feed stiffness at all (gross rolling)."""
    from tests.bench.test_pitch_rig import two_dof

    rig = load_rig(DEFAULTS / "sim_rig_pitch.toml")
    plan = parse_plan({"plan": {"procedure": "phase_resonance", "levels_N": [0.3, 1.0, 3.0, 10.0],
                                "backbone": {"start_Hz": 200.0, "response": "accel", "mode": "pitch"}}})
    store = run_plan(plan, rig, tmp_path / "run")
    model = rig.model
    top = two_dof(model, model.n / (model.n - 1) * model.F_s_N / model.x_s_m)[1]
    bottom = two_dof(model, 0.0)[1]
    got = rows(store)
    f = [float(r["frequency_Hz"]) for r in got]
    assert all(r["locked"] == "true" and r["mode"] == "pitch" for r in got)
    assert all(abs(float(r["phase_deg"]) - 90.0) <= 2.0 for r in got)
    assert all(bottom < x < top for x in f)
    assert f == sorted(f, reverse=True) and f[0] - f[-1] > 2.0


def test_the_envelope_is_checked_at_the_low_end_of_the_window():
    """The loop may drive anywhere in min_Hz-max_Hz: 3 N at 40 Hz moves the free mass further
    than at start_Hz 80 Hz, and a displacement limit between the two refuses the plan."""
    from bench.session import EnvelopeError, check_envelope

    rig = load_rig(DEFAULTS / "sim_rig.toml")
    data = backbone_plan([3.0])
    data["plan"]["limits"] = {"disp_m": 33e-6}
    with pytest.raises(EnvelopeError, match="3 N at 40 Hz: displacement"):
        check_envelope(parse_plan(data), rig)
    data["plan"]["backbone"]["min_Hz"] = 70.0
    check_envelope(parse_plan(data), rig)


def test_bench_resume_rebuilds_the_stored_plans():
    """`bench resume` parses the plan stored in run.json back (bench.config.plan_toml)."""
    import json

    from bench.config import plan_toml
    from tests.bench.test_response_control import rc_plan

    for data in (backbone_plan([0.1, 1.0], phase_band_deg=0.5, response="accel"),
                 rc_plan([1e-6, 2e-6], [40.0, 50.0])):
        plan = parse_plan(data)
        stored = json.loads(json.dumps(plan.to_dict()))
        assert parse_plan({"plan": plan_toml(stored)}, "run.json") == plan
