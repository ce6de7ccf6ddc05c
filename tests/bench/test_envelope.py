"""The envelope check: `bench dry-run` and run_plan refuse a plan the rig's limits cannot
hold, name the offending level and frequency, and nothing moves.

The refused plans are infeasible by plain physics, whatever margin the estimate adds:
30 N from an amplifier of 20 N/V needs 1.5 V (> a 1 V drive limit); 30 N on a free
10 kg mass at 20 Hz moves it P/(m w^2) = 0.19 mm (> a 0.15 mm displacement limit).
"""

from __future__ import annotations

import math
import textwrap

import pytest

import bench.session
from bench.cli import main
from bench.config import DEFAULTS, load_plan, load_rig, parse_plan, parse_rig
from bench.session import EnvelopeError, run_plan
from drivers import start_twins
from sim.rig import SimulatedRig

RIG_LIMITS = dict(drive_V=7.0, force_N=130.0, disp_m=0.9e-3, accel_m_s2=20.0)   # sim_rig.toml


def plan_toml(tmp_path, levels, freqs, infeasible="refuse", **limits) -> str:
    text = textwrap.dedent(f"""\
        [plan]
        name = "envelope test"
        infeasible = "{infeasible}"
        levels_N = {list(levels)}
        [plan.frequencies]
        list_Hz = {list(freqs)}
        """)
    if limits:
        text += "[plan.limits]\n" + "".join(f"{k} = {v!r}\n" for k, v in dict(RIG_LIMITS, **limits).items())
    path = tmp_path / "plan.toml"
    path.write_text(text)
    return str(path)


def test_free_mass_figures_behind_the_refused_plans():
    # the independent facts the refusals below rest on (see the module docstring)
    rig = load_rig(DEFAULTS / "sim_rig.toml")
    assert 30.0 / rig.amp_gain_N_per_V == 1.5
    assert 30.0 / (rig.expected_mass_kg * (2 * math.pi * 20.0) ** 2) > 0.15e-3
    assert 30.0 / (rig.expected_mass_kg * (2 * math.pi * 80.0) ** 2) + 3 * rig.expected_x_s_m < 0.15e-3 / 1.25


def test_dry_run_accepts_the_default_plan_on_the_simulated_rig(capsys):
    assert main(["dry-run"]) == 0
    out = capsys.readouterr().out
    assert "7 levels x 24 frequencies" in out
    assert "envelope ok" in out and "REFUSED" not in out


def test_dry_run_refuses_a_level_beyond_the_drive_limit(tmp_path, capsys):
    plan = plan_toml(tmp_path, levels=[1.0, 30.0], freqs=[40.0, 80.0], drive_V=1.0)
    assert main(["dry-run", "--plan", plan]) == 3
    out = capsys.readouterr().out
    refused = [line for line in out.splitlines() if line.startswith("REFUSED")]
    assert len(refused) == 1
    assert "2 of 4 steps" in refused[0]
    assert "30 N at 40 Hz: drive 1.5 V x 1.25 margin = 1.88 V > drive_V 1 V" in refused[0]
    # the per-level table says the small level is fine
    level_1 = next(line for line in out.splitlines() if line.split()[:1] == ["1"])
    assert level_1.endswith("ok")


def test_dry_run_refuses_a_level_beyond_the_displacement_limit_at_low_frequency(tmp_path, capsys):
    plan = plan_toml(tmp_path, levels=[1.0, 30.0], freqs=[20.0, 80.0], disp_m=0.15e-3)
    assert main(["dry-run", "--plan", plan]) == 3
    out = capsys.readouterr().out
    refused = next(line for line in out.splitlines() if line.startswith("REFUSED"))
    assert "1 of 4 steps" in refused                  # 30 N at 80 Hz is fine
    assert "30 N at 20 Hz: displacement" in refused and "at 30 N x 1.25 margin > disp_m 0.15 mm" in refused


def test_run_plan_refuses_before_any_twin_starts(tmp_path, mocker):
    spy = mocker.spy(bench.session, "start_twins")
    plan = load_plan(plan_toml(tmp_path, levels=[30.0], freqs=[20.0, 80.0], disp_m=0.15e-3))
    out = tmp_path / "run"
    with pytest.raises(EnvelopeError, match=r"30 N at 20 Hz: displacement"):
        run_plan(plan, load_rig(DEFAULTS / "sim_rig.toml"), out, identify=False)
    assert spy.call_count == 0
    assert not out.exists()


def test_run_plan_refuses_without_touching_a_real_rigs_generator(tmp_path):
    # a non-simulated rig whose instruments are twins this test holds: the refused plan
    # must not even connect (the driver's first act would be OUTP OFF / OUTP:LOAD INF)
    with start_twins(SimulatedRig()) as twins:
        state_before = repr(twins.generator.state)
        rig = parse_rig({"rig": {
            "simulated": False,
            "instruments": {"generator": twins.generator_url, "sensor": twins.sensor_url,
                            "daq": twins.daq_bridge_url},
            "calibration": {"force_V_per_N": 0.0225, "accel_V_per_m_s2": 0.0102,
                            "disp_V_per_m": 8000.0, "amp_gain_N_per_V": 20.0},
            "limits": dict(RIG_LIMITS, drive_V=1.0)}})
        plan = parse_plan({"plan": {"levels_N": [1.0, 30.0], "frequencies": {"list_Hz": [40.0]}}})
        with pytest.raises(EnvelopeError, match=r"30 N at 40 Hz: drive 1.5 V x 1.25 margin = 1.88 V > drive_V 1 V"):
            run_plan(plan, rig, tmp_path / "run", identify=False)
        assert repr(twins.generator.state) == state_before
        assert not twins.generator.state.output_on
        assert twins.daq.frames_sent == 0
        assert not (tmp_path / "run").exists()


def test_a_plan_that_asks_to_skip_infeasible_steps_runs_the_rest(tmp_path, capsys):
    path = plan_toml(tmp_path, levels=[1.0, 30.0], freqs=[20.0, 80.0], infeasible="skip", disp_m=0.15e-3)
    assert main(["dry-run", "--plan", path]) == 0
    assert "3 steps run, 1 skipped" in capsys.readouterr().out
    plan = bench.session.check_envelope(load_plan(path), load_rig(DEFAULTS / "sim_rig.toml"))
    assert plan.skip == ((1, 0),)                   # 30 N at 20 Hz
    steps = plan.schedule()
    assert [(s.force_N, s.freq_Hz) for s in steps] == [(1.0, 20.0), (1.0, 80.0), (30.0, 80.0)]
    assert steps[-1].key == "00003-L01-F001-up"      # keys keep their place in the full schedule


def test_the_refusal_names_the_force_margin_and_the_limit_key(tmp_path, capsys):
    """Issue 19: 120 N against force_N = 130 N was refused as "force 150 N > 130 N", the
    1.25 control-overshoot margin applied but never named (levels now end at 100 N)."""
    plan = plan_toml(tmp_path, levels=[100.0], freqs=[200.0], force_N=120.0)
    assert main(["dry-run", "--plan", plan]) == 3
    refused = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("REFUSED"))
    assert "100 N x 1.25 margin = 125 N > force_N 120 N" in refused
    assert "drive" not in refused                      # 100 N x 1.25 / 20 N/V = 6.25 V < drive_V 7 V


def test_the_drive_column_is_the_generator_amplitude_at_the_level(tmp_path, capsys):
    """One voltage convention (decision record 0029): a sine's amplitude (= Vpp/2), the
    unit of drive_V and of the amplifier gain.  50 N through 20 N/V is 2.5 V, whatever the
    margin of the limit check (which the refusal names instead)."""
    plan = plan_toml(tmp_path, levels=[1.0, 50.0], freqs=[200.0], drive_V=3.0)
    assert main(["dry-run", "--plan", plan]) == 3
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.split()[:1] == ["50"])
    assert row.split()[1] == "2.5"
    assert "the generator's amplitude, V = Vpp/2, at the level" in out
    refused = next(line for line in out.splitlines() if line.startswith("REFUSED"))
    assert "drive 2.5 V x 1.25 margin = 3.12 V > drive_V 3 V" in refused
