"""Plan and rig TOML: the shipped defaults parse; every error names the file, the key and
what is allowed; the schedule is the documented one."""

from __future__ import annotations

import math
import re
import textwrap
import tomllib
from pathlib import Path

import pytest

from bench.cli import main
from bench.config import DEFAULTS, MAX_FREQ_HZ, ConfigError, load_plan, load_rig, parse_plan

PLAN = """\
[plan]
name = "config test"
levels_N = [1.0, 3.0]

[plan.frequencies]
list_Hz = [40.0, 80.0, 160.0]
direction = "up"

[plan.control]
settle_cycles = 4
"""

RIG = """\
[rig]
name = "a real rig"
simulated = false

[rig.instruments]
generator = "socket://192.0.2.10:5025"
sensor = "modbus-tcp://192.0.2.11:502?unit=1"
daq = "tcp://192.0.2.12:29536"

[rig.calibration]
force_V_per_N = 0.0225
accel_V_per_m_s2 = 0.0102
disp_V_per_m = 8000.0
amp_gain_N_per_V = 20.0

[rig.limits]
drive_V = 7.0
force_N = 130.0
disp_m = 0.9e-3
accel_m_s2 = 20.0
"""


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def edit(text: str, old: str, new: str) -> str:
    assert old in text, f"test setup: {old!r} not in the template"
    return text.replace(old, new, 1)


# --------------------------------------------------------------------------- defaults

def test_the_demo_plan_parses_as_documented():
    plan = load_plan(DEFAULTS / "demo_plan.toml")
    assert plan.levels_N == (0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0)
    assert plan.direction == "up"
    assert len(plan.freqs_Hz) == 24
    assert plan.freqs_Hz[0] == 20.0 and plan.freqs_Hz[-1] == 1000.0
    # log spacing: a constant ratio (50 ** (1/23)) up to the 6 significant digits kept
    ratios = [b / a for a, b in zip(plan.freqs_Hz, plan.freqs_Hz[1:])]
    assert all(r == pytest.approx(50 ** (1 / 23), rel=1e-5) for r in ratios)
    # every control setting is the file's (read here with tomllib, independently)
    with open(DEFAULTS / "demo_plan.toml", "rb") as fh:
        control = tomllib.load(fh)["plan"]["control"]
    assert control and all(getattr(plan, key) == value for key, value in control.items())
    assert plan.limits is None
    assert len(plan.schedule()) == 7 * 24            # the grid; refinement steps are chosen online
    # it refines its resonances (issue 32, decision record 0063), as the file says
    assert (plan.refine, plan.refine_tolerance, plan.refine_steps, plan.refine_modes) == \
        (True, 0.002, 14, ("feed", "pitch"))


def test_the_simulated_rig_parses_as_documented():
    rig = load_rig(DEFAULTS / "sim_rig.toml")
    assert rig.simulated
    assert (rig.generator_url, rig.sensor_url, rig.daq_url) == ("", "", "")   # filled in at run time
    assert (rig.limits.drive_V, rig.limits.force_N, rig.limits.disp_m, rig.limits.accel_m_s2) == \
        (7.0, 130.0, 0.9e-3, 20.0)
    assert rig.amp_gain_N_per_V == 20.0
    assert rig.model.F_s_N == 10.0 and rig.model.n == 1.5


def test_a_non_simulated_rig_parses(tmp_path):
    rig = load_rig(write(tmp_path, "rig.toml", RIG))
    assert not rig.simulated and rig.generator_url == "socket://192.0.2.10:5025"
    assert rig.model is None


# --------------------------------------------------------------------------- plan errors

PLAN_ERRORS = {
    "unknown key in [plan]": (
        edit(PLAN, 'name = "config test"', 'name = "config test"\ncolour = "red"'),
        ["[plan] colour: unknown key", "allowed", "'levels_N'", "'frequencies'"]),
    "unknown key in [plan.control]": (
        edit(PLAN, "settle_cycles = 4", "setle_cycles = 4"),
        ["[plan.control] setle_cycles: unknown key; did you mean settle_cycles?"]),
    "unknown top-level table": (
        PLAN + "\n[plna]\nx = 1\n",
        ["[plna]: unknown table; did you mean [plan]?"]),
    "force level above 1000 N": (
        edit(PLAN, "levels_N = [1.0, 3.0]", "levels_N = [1.0, 2000.0]"),
        ["[plan] levels_N[1]", "must be >= 0.1 and <= 100", "got 2000"]),
    "force level zero": (
        edit(PLAN, "levels_N = [1.0, 3.0]", "levels_N = [0.0]"),
        ["[plan] levels_N[0]", "must be >= 0.1", "got 0"]),
    "force level not a number": (
        edit(PLAN, "levels_N = [1.0, 3.0]", 'levels_N = ["big"]'),
        ["[plan] levels_N[0]", "must be a number", "'big'"]),
    "no force levels": (
        edit(PLAN, "levels_N = [1.0, 3.0]", "levels_N = []"),
        ["[plan] levels_N", "non-empty list of numbers"]),
    "force levels missing": (
        edit(PLAN, "levels_N = [1.0, 3.0]", ""),
        ["[plan] levels_N", "missing (required)"]),
    "listed frequency above 1000 Hz": (
        edit(PLAN, "list_Hz = [40.0, 80.0, 160.0]", "list_Hz = [40.0, 1500.0]"),
        ["[plan.frequencies] list_Hz[1]", f"<= {MAX_FREQ_HZ:g}", "got 1500"]),
    "stop frequency above 1000 Hz": (
        edit(PLAN, "list_Hz = [40.0, 80.0, 160.0]", "start_Hz = 20.0\nstop_Hz = 1200.0\npoints = 5"),
        ["[plan.frequencies] stop_Hz", f"<= {MAX_FREQ_HZ:g}", "got 1200"]),
    "stop below start": (
        edit(PLAN, "list_Hz = [40.0, 80.0, 160.0]", "start_Hz = 100.0\nstop_Hz = 50.0\npoints = 5"),
        ["[plan.frequencies] stop_Hz", "must be >= 100", "got 50"]),
    "fractional number of points": (
        edit(PLAN, "list_Hz = [40.0, 80.0, 160.0]", "start_Hz = 20.0\nstop_Hz = 100.0\npoints = 2.5"),
        ["[plan.frequencies] points", "must be an integer", "got 2.5"]),
    "bad spacing": (
        edit(PLAN, "list_Hz = [40.0, 80.0, 160.0]",
             'start_Hz = 20.0\nstop_Hz = 100.0\npoints = 5\nspacing = "octave"'),
        ["[plan.frequencies] spacing", "['log', 'linear']", "'octave'"]),
    "list and range both given": (
        edit(PLAN, "list_Hz = [40.0, 80.0, 160.0]", "list_Hz = [40.0, 80.0]\nstart_Hz = 20.0"),
        ["[plan.frequencies]", "unknown key(s) ['start_Hz']", "'list_Hz'"]),
    "repeated frequency": (
        edit(PLAN, "list_Hz = [40.0, 80.0, 160.0]", "list_Hz = [40.0, 80.0, 40.0]"),
        ["[plan.frequencies]", "repeated frequencies"]),
    "bad direction": (
        edit(PLAN, 'direction = "up"', 'direction = "sideways"'),
        ["[plan.frequencies] direction", "['up', 'down', 'both']", "'sideways'"]),
    "force tolerance out of range": (
        edit(PLAN, "settle_cycles = 4", "force_tolerance = 0.9"),
        ["[plan.control] force_tolerance", "<= 0.5", "got 0.9"]),
    "harmonics above Nyquist at the highest frequency": (
        edit(edit(PLAN, "settle_cycles = 4", "harmonics = 20"), "160.0]", "800.0]"),
        ["[plan.control] harmonics", "must be <= 15", "Nyquist at 800 Hz", "got 20"]),
    "misspelled plan limit": (
        PLAN + "\n[plan.limits]\nforse_N = 60.0\n",
        ["[plan.limits] forse_N: unknown key; did you mean force_N?"]),
    "misspelled required key": (
        edit(PLAN, "levels_N = [1.0, 3.0]", "level_N = [1.0, 3.0]"),
        ["[plan] level_N: unknown key; did you mean levels_N?"]),
    "misspelled table": (
        edit(PLAN, "[plan.frequencies]", "[plan.frequency]"),
        ["[plan.frequency]: unknown table; did you mean [plan.frequencies]?"]),
    "level below the bench's force range": (
        edit(PLAN, "levels_N = [1.0, 3.0]", "levels_N = [0.05, 1.0]"),
        ["[plan] levels_N[0]", "must be >= 0.1 and <= 100 (the bench's force range, 0.1-100 N)", "got 0.05"]),
    "frequency below the bench's range": (
        edit(PLAN, "list_Hz = [40.0, 80.0, 160.0]", "list_Hz = [10.0, 80.0]"),
        ["[plan.frequencies] list_Hz[0]", "must be >= 20 and <= 1000 (the bench's frequency range, 20-1000 Hz)",
         "got 10"]),
    "grid start below the bench's range": (
        edit(PLAN, "list_Hz = [40.0, 80.0, 160.0]", "start_Hz = 5.0\nstop_Hz = 100.0\npoints = 5"),
        ["[plan.frequencies] start_Hz", "(the bench's frequency range, 20-1000 Hz)", "got 5"]),
    "infeasible policy": (
        edit(PLAN, 'name = "config test"', 'name = "config test"\ninfeasible = "ignore"'),
        ["[plan] infeasible", "['refuse', 'skip']", "'ignore'"]),
}


@pytest.mark.parametrize("text, fragments", PLAN_ERRORS.values(), ids=PLAN_ERRORS.keys())
def test_plan_errors_name_the_file_the_key_and_what_is_allowed(tmp_path, text, fragments):
    path = write(tmp_path, "my_plan.toml", text)
    with pytest.raises(ConfigError) as err:
        load_plan(path)
    message = str(err.value)
    assert message.startswith(f"{path}: ")
    for fragment in fragments:
        assert fragment in message


def test_harmonics_limit_follows_the_sample_rate_and_highest_frequency(tmp_path):
    # at 1000 Hz and 25.6 kS/s Nyquist is 12.8 kHz: harmonics up to 12 fit, 13 does not
    base = edit(PLAN, "list_Hz = [40.0, 80.0, 160.0]", "list_Hz = [40.0, 1000.0]")
    assert load_plan(write(tmp_path, "ok.toml", edit(base, "settle_cycles = 4", "harmonics = 12"))).harmonics == 12
    with pytest.raises(ConfigError, match=r"harmonics: must be <= 12 .*got 13"):
        load_plan(write(tmp_path, "bad.toml", edit(base, "settle_cycles = 4", "harmonics = 13")))


# --------------------------------------------------------------------------- rig errors

RIG_ERRORS = {
    "missing calibration key": (
        edit(RIG, "force_V_per_N = 0.0225\n", ""),
        ["[rig.calibration] force_V_per_N", "missing (required)"]),
    "model table on a real rig": (
        RIG + "\n[rig.model]\nF_s_N = 10.0\n",
        ["[rig.model]", "only allowed with simulated = true"]),
    "real rig without an instrument address": (
        edit(RIG, 'generator = "socket://192.0.2.10:5025"\n', ""),
        ["[rig.instruments] generator", "missing (required)"]),
    "unknown instrument": (
        edit(RIG, '[rig.instruments]\n', '[rig.instruments]\nscope = "socket://192.0.2.13:5025"\n'),
        ["[rig.instruments] scope: unknown key", "'daq'", "'generator'", "'sensor'"]),
    "misspelled rig limit": (
        edit(RIG, "force_N = 130.0", "forse_N = 130.0"),
        ["[rig.limits] forse_N: unknown key; did you mean force_N?"]),
    "displacement limit beyond the probe": (
        edit(RIG, "disp_m = 0.9e-3", "disp_m = 0.05"),
        ["[rig.limits] disp_m", "must be > 0 and <= 0.01", "got 0.05"]),
    "drive limit missing": (
        edit(RIG, "drive_V = 7.0\n", ""),
        ["[rig.limits] drive_V", "missing (required)"]),
    "simulated not a boolean": (
        edit(RIG, "simulated = false", 'simulated = "no"'),
        ["[rig] simulated", "must be true or false", "'no'"]),
    "unknown model parameter on a simulated rig": (
        edit(RIG, "simulated = false", "simulated = true") + "\n[rig.model]\nF_s = 10.0\n",
        ["[rig.model] F_s: unknown key; did you mean F_s_N?"]),
}


@pytest.mark.parametrize("text, fragments", RIG_ERRORS.values(), ids=RIG_ERRORS.keys())
def test_rig_errors_name_the_file_the_key_and_what_is_allowed(tmp_path, text, fragments):
    path = write(tmp_path, "my_rig.toml", text)
    with pytest.raises(ConfigError) as err:
        load_rig(path)
    message = str(err.value)
    assert message.startswith(f"{path}: ")
    for fragment in fragments:
        assert fragment in message


@pytest.mark.parametrize("loader", [load_plan, load_rig])
def test_bad_toml_syntax_names_the_file(tmp_path, loader):
    path = write(tmp_path, "broken.toml", '[plan]\nlevels_N = [1.0, 3.0\nname = "x"\n')
    with pytest.raises(ConfigError, match=rf"^{path}: not valid TOML"):
        loader(path)


@pytest.mark.parametrize("loader", [load_plan, load_rig])
def test_a_missing_file_is_named(tmp_path, loader):
    path = tmp_path / "nowhere.toml"
    with pytest.raises(ConfigError, match=rf"^{path}: file not found"):
        loader(path)


def test_the_cli_reports_a_config_error_without_a_traceback(tmp_path, capsys):
    path = write(tmp_path, "my_plan.toml", edit(PLAN, 'direction = "up"', 'direction = "sideways"'))
    assert main(["dry-run", "--plan", str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "direction" in err
    assert "Traceback" not in err


def test_three_mistakes_of_a_plan_file_are_named_in_one_run(tmp_path, capsys):
    """Independent key/value errors come together, one line each, with their usual words;
    a rule across keys waits until they are fixed (it may have seen a stand-in value)."""
    text = edit(PLAN, 'direction = "up"', 'direction = "sideways"')
    text = edit(text, "settle_cycles = 4", "settle_cycles = 4\nsettel_s = 1.0")
    text = edit(text, "levels_N = [1.0, 3.0]", "levels_N = [1.0, 300.0]")
    path = write(tmp_path, "three.toml", text)
    assert main(["dry-run", "--plan", str(path)]) == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert lines[0] == "bench dry-run: error: 3 problems:" and len(lines) == 4, lines
    wanted = [r"\[plan.frequencies\] direction: must be one of \['up', 'down', 'both'\], got 'sideways'",
              r"\[plan.control\] settel_s: unknown key; did you mean min_settle_s\?",
              r"\[plan\] levels_N\[1\]: must be >= 0.1 and <= 100 .*got 300.0"]
    for want in wanted:
        assert sum(bool(re.search(want, ln)) and str(path) in ln for ln in lines) == 1, (want, lines)
    with pytest.raises(ConfigError) as e:       # the same, as one error, for a rig file
        load_rig(write(tmp_path, "rig.toml", edit(edit(RIG, "drive_V = 7.0", "drive_V = -7.0"),
                                                  "disp_V_per_m = 8000.0", 'disp_V_per_m = "8000"')))
    assert len(str(e.value).splitlines()) == 2
    assert "[rig.limits] drive_V: must be > 0" in str(e.value) and "[rig.calibration] disp_V_per_m: must be a number" \
        in str(e.value)
    with pytest.raises(ConfigError) as e:       # one mistake: the message as it always was
        load_plan(write(tmp_path, "one.toml", edit(PLAN, 'direction = "up"', 'direction = "sideways"')))
    assert "\n" not in str(e.value) and str(e.value).endswith("got 'sideways'")


EVERY_PROBLEM = """\
[plan]
name = "every problem"
procedure = "response_controlled"
levels_N = [1.0]
levles = 3

[plan.response]
quantity = "displacement"
levels = [-1.0, nan, 0.0, 1e9]

[plan.backbone]
response = "velocity"

[plan.frequencies]
list_Hz = [40.0, 80.0]
"""


def test_one_invocation_names_every_problem_of_a_plan_file(tmp_path, capsys):
    """Issue 30 item 8: each bad element of a list, a key the procedure does not use, an
    unknown key and the bad words of two tables, all in one run, one line each; main named
    only the unknown key (the rest came one run after the other)."""
    path = write(tmp_path, "every.toml", EVERY_PROBLEM)
    assert main(["dry-run", "--plan", str(path)]) == 2
    lines = [ln.strip() for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    wanted = [r"\[plan\] levles: unknown key; did you mean levels_N\?",
              r"\[plan\] levels_N: not used with procedure = \"response_controlled\"",
              r"\[plan.response\] quantity: must be one of \['disp', 'accel'\], got 'displacement'",
              *(rf"\[plan.response\] levels\[{i}\]: must be >= 1e-09 and <= 0.001 \(m, .*got {v}$"
                for i, v in enumerate(("-1.0", "nan", "0.0", "1000000000.0"))),
              r"\[plan.backbone\] response: must be one of \['disp', 'accel'\], got 'velocity'",
              r"\[plan.backbone\] needs procedure = \"phase_resonance\""]
    assert lines[0] == f"bench dry-run: error: {len(wanted)} problems:", lines
    for want in wanted:
        assert sum(bool(re.search(want, ln)) and ln.startswith(str(path)) for ln in lines) == 1, (want, lines)
    # a force plan's list: every element named, the good ones not
    with pytest.raises(ConfigError) as e:
        load_plan(write(tmp_path, "levels.toml", edit(PLAN, "levels_N = [1.0, 3.0]",
                                                      "levels_N = [-1.0, nan, 2.0, 0.0, 1e9]")))
    named = re.findall(r"levels_N\[(\d)\]: must be >= 0.1 and <= 100", str(e.value))
    assert named == ["0", "1", "3", "4"], str(e.value)


# --------------------------------------------------------------------------- schedule

def plan_with(direction: str, levels=(1.0, 3.0), freqs=(160.0, 40.0, 80.0)):
    return parse_plan({"plan": {"levels_N": list(levels),
                                "frequencies": {"list_Hz": list(freqs), "direction": direction}}})


def test_the_frequency_list_is_sorted_ascending():
    assert plan_with("up").freqs_Hz == (40.0, 80.0, 160.0)


@pytest.mark.parametrize("direction, sweeps", [
    ("up", [("up", [40.0, 80.0, 160.0])]),
    ("down", [("down", [160.0, 80.0, 40.0])]),
    ("both", [("up", [40.0, 80.0, 160.0]), ("down", [160.0, 80.0, 40.0])]),
])
def test_schedule_runs_each_level_in_turn_through_its_sweeps(direction, sweeps):
    plan = plan_with(direction)
    expected = [(level, d, f) for level in (1.0, 3.0) for d, fs in sweeps for f in fs]
    steps = plan.schedule()
    assert [(s.force_N, s.direction, s.freq_Hz) for s in steps] == expected
    assert [s.index for s in steps] == list(range(len(expected)))
    for s in steps:
        assert plan.levels_N[s.level_index] == s.force_N
        assert plan.freqs_Hz[s.freq_index] == s.freq_Hz


def test_step_keys_are_unique_readable_and_sort_in_schedule_order():
    steps = plan_with("both", levels=[0.1, 0.2, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 100.0],
                      freqs=[20.0 * k for k in range(1, 31)]).schedule()
    keys = [s.key for s in steps]
    assert len(set(keys)) == len(keys) == 11 * 30 * 2
    # the run directory lists steps by file name: that order must be the schedule's
    assert sorted(keys) == keys
    s = steps[37]
    assert s.key == f"{37:05d}-L{s.level_index:02d}-F{s.freq_index:03d}-{s.direction}"
    assert s.key == "00037-L00-F022-down"


def test_a_log_grid_hits_its_end_points():
    plan = parse_plan({"plan": {"levels_N": [1.0], "frequencies": {
        "start_Hz": 20.0, "stop_Hz": 1000.0, "points": 7, "spacing": "log"}}})
    assert plan.freqs_Hz[0] == 20.0 and plan.freqs_Hz[-1] == 1000.0
    assert all(math.isclose(b / a, 50 ** (1 / 6), rel_tol=1e-5) for a, b in zip(plan.freqs_Hz, plan.freqs_Hz[1:]))
    lin = parse_plan({"plan": {"levels_N": [1.0], "frequencies": {
        "start_Hz": 100.0, "stop_Hz": 200.0, "points": 5, "spacing": "linear"}}})
    assert lin.freqs_Hz == (100.0, 125.0, 150.0, 175.0, 200.0)


# --------------------------------------------------------------------------- tighter plan limits

def test_one_tighter_plan_limit_on_its_own_works_and_the_rest_are_the_rigs(tmp_path, capsys):
    from bench.config import plan_toml as _plan_toml
    from procedures.safety import tightest

    text = edit(PLAN, "levels_N = [1.0, 3.0]", "levels_N = [1.0, 100.0]") + "\n[plan.limits]\nforce_N = 60\n"
    plan = load_plan(write(tmp_path, "p.toml", text))
    rig = load_rig(DEFAULTS / "sim_rig.toml")
    lim = tightest(rig.limits, plan.limits)
    assert (lim.drive_V, lim.force_N, lim.disp_m, lim.accel_m_s2) == (rig.limits.drive_V, 60.0, rig.limits.disp_m,
                                                                      rig.limits.accel_m_s2)
    assert parse_plan({"plan": _plan_toml(plan.to_dict())}) == plan       # as a resume reads run.json
    # the rig (130 N) holds a 100 N level; the plan's own 60 N does not: refused before anything moves
    assert main(["dry-run", "--plan", str(tmp_path / "p.toml")]) == 3
    assert "REFUSED" in capsys.readouterr().out
    ok = load_plan(write(tmp_path, "q.toml", edit(text, "force_N = 60", "force_N = 200")))
    assert tightest(rig.limits, ok.limits).force_N == rig.limits.force_N


def test_bench_study_mc_names_the_file_of_a_bad_plan_or_rig(tmp_path, capsys):
    bad = write(tmp_path, "mc_plan.toml", edit(PLAN, "levels_N = [1.0, 3.0]", "level_N = [1.0, 3.0]"))
    assert main(["study", "mc", "--plan", str(bad), "--out", str(tmp_path / "mc")]) == 2
    assert f"{bad}: [plan] level_N: unknown key; did you mean levels_N?" in capsys.readouterr().err
    broken = write(tmp_path, "mc_rig.toml", "[rig\n")
    assert main(["study", "mc", "--rig", str(broken), "--out", str(tmp_path / "mc")]) == 2
    assert f"{broken}: not valid TOML" in capsys.readouterr().err
    real = write(tmp_path, "real_rig.toml", RIG)
    assert main(["study", "mc", "--rig", str(real), "--out", str(tmp_path / "mc")]) == 2
    assert f"{real}: a Monte-Carlo study needs a simulated rig" in capsys.readouterr().err
    assert not (tmp_path / "mc").exists()


# --------------------------------------------------------------------------- encodings, nesting, size (issue 24)

@pytest.mark.parametrize("encoding, said", [
    ("utf-16", "saved as UTF-16; TOML files are UTF-8"),
    ("utf-16-le", "NUL bytes at offset 1: the file seems saved as UTF-16 without a byte-order mark"),
    ("latin-1", "not UTF-8: byte 0xb5 at line 1 (offset 8); the file seems saved in another encoding"),
    ("cp1252", "not UTF-8: byte 0xb5 at line 1 (offset 8)"),
])
def test_a_plan_saved_in_another_encoding_is_named_with_the_encoding_problem(tmp_path, capsys, encoding, said):
    path = tmp_path / "p.toml"
    path.write_bytes(("# force \u00b5N\n" + PLAN).encode(encoding))
    assert main(["dry-run", "--plan", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"bench dry-run: error: {path}: ") and said in err, err


def test_a_utf8_byte_order_mark_is_accepted(tmp_path):
    path = tmp_path / "p.toml"
    path.write_bytes(("# force \u00b5N\n" + PLAN).encode("utf-8-sig"))
    assert load_plan(path) == load_plan(write(tmp_path, "q.toml", PLAN))


def test_toml_nested_thousands_deep_is_named_not_a_recursion_error(tmp_path):
    for deep in ("x = " + "[" * 5000 + "]" * 5000, "x = " + "{a = " * 5000 + "1" + "}" * 5000):
        path = write(tmp_path, "deep.toml", deep + "\n")
        with pytest.raises(ConfigError, match=rf"^{path}: not a plan or rig: tables or arrays nested too deeply"):
            load_plan(path)


def test_a_plan_file_over_the_size_bound_is_refused_unread(tmp_path):
    from bench.config import MAX_FILE_BYTES
    path = write(tmp_path, "big.toml", PLAN + "#" * MAX_FILE_BYTES + "\n")
    with pytest.raises(ConfigError, match=rf"^{path}: \d+ bytes; a plan or rig file is at most {MAX_FILE_BYTES}"):
        load_plan(path)


@pytest.mark.parametrize("levels, points, direction, said", [
    ([1.0] * 1001, 10, "up", "[plan] levels_N: 1001 values; at most 1000"),
    ([1.0], 10_001, "up", "[plan.frequencies] points: must be >= 1 and <= 10000"),
    ([1.0, 2.0, 3.0, 4.0, 5.0, 6.0], 5000, "both",
     "p.toml: [plan] 6 levels x 5000 frequencies x 2 directions = 60000 steps; at most 50000"),
])
def test_plan_bounds_are_named(levels, points, direction, said):
    plan = {"plan": {"levels_N": levels, "frequencies": {"start_Hz": 20.0, "stop_Hz": 1000.0, "points": points,
                                                         "direction": direction}}}
    with pytest.raises(ConfigError) as e:
        parse_plan(plan, "p.toml")
    assert said in str(e.value)


@pytest.mark.parametrize("query, said", [
    ("unit=abc", "unit must be an integer 0-255, got 'abc'"),
    ("unit=1&unit=2", "parameter 'unit' given twice"),
    ("baud=9600", "unknown parameter 'baud' for modbus-tcp; allowed: unit"),
])
def test_a_sensor_url_query_is_checked_with_the_rig(tmp_path, query, said):
    path = write(tmp_path, "r.toml", edit(RIG, "?unit=1", f"?{query}"))
    with pytest.raises(ConfigError) as e:
        load_rig(path)
    assert f"{path}: [rig.instruments] sensor: " in str(e.value) and said in str(e.value), str(e.value)


@pytest.mark.parametrize("name", ["sim_rig.toml", "sim_rig_pitch.toml"])
def test_the_identifications_starting_guess_is_the_rig_files_expected_table(name):
    # one guess for every identification (cli, analyze, studies, online): the file's values, by name
    table = tomllib.loads((DEFAULTS / name).read_text())["rig"]["expected"]
    assert load_rig(DEFAULTS / name).guess() == {k: float(table[k]) for k in ("F_s_N", "x_s_m", "n", "mass_kg")}
