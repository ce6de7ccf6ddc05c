"""The terminal a technician sees: options explained with their defaults, -v/--debug after
any command, verbosity that speaks for the project only, and a progress line that fits
an 80-column terminal with log lines passing cleanly above it (checked on tmux's screen)."""

from __future__ import annotations

import argparse
import logging
import os
import shutil
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from bench.cli import build_parser
from bench.terminal import setup_logging
from benchtools import REPO
from benchtools.plans import fast_plan_toml

TMUX = shutil.which("tmux")


def all_parsers(p: argparse.ArgumentParser, name="bench"):
    yield name, p
    for a in p._actions:
        if isinstance(a, argparse._SubParsersAction):
            for sub_name, s in a.choices.items():
                yield from all_parsers(s, f"{name} {sub_name}")


def test_every_option_of_every_command_is_explained_with_its_default():
    parsers = dict(all_parsers(build_parser()))
    assert {"bench run", "bench study mc", "bench study map", "bench watch"} <= set(parsers)
    for name, p in parsers.items():
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction) or a.help == argparse.SUPPRESS:
                continue
            assert a.help, f"{name} {a.option_strings or a.dest}: no help text"
            if a.option_strings and "-v" not in a.option_strings and \
                    not any(a.default is x for x in (None, False, argparse.SUPPRESS)):
                shown = p._get_formatter()._expand_help(a)         # the text --help prints for it
                assert "default" in shown, f"{name} {a.option_strings[-1]}: default {a.default!r} not shown"
    assert "(default: 0)" in parsers["bench study mc"].format_help()            # a 0 default is shown too
    assert "developer" not in parsers["bench"].description and "libraries don't" not in parsers["bench"].description
    assert "0.1-100 N" in parsers["bench"].description and "20-1000 Hz" in parsers["bench"].description


@pytest.mark.parametrize("argv, verbose, debug", [
    (["run", "-v", "--out", "x"], 1, False),
    (["-v", "run", "--out", "x"], 1, False),
    (["run", "--out", "x", "-vv", "--debug"], 2, True),
    (["study", "mc", "--out", "x", "--debug", "-v"], 1, True),
    (["study", "map", "--out", "x", "--debug"], 0, True),
    (["--debug", "check", "x"], 0, True),
    (["check", "x"], 0, False),
])
def test_verbosity_and_debug_come_before_or_after_any_command(argv, verbose, debug):
    args = build_parser().parse_args(argv)
    assert (args.verbose, args.debug) == (verbose, debug)


def emitted(capsys, level: int, name: str, verbosity: int) -> bool:
    handler = setup_logging(verbosity)
    try:
        capsys.readouterr()
        logging.getLogger(name).log(level, "a line from %s", name)
        return f"a line from {name}" in capsys.readouterr().err
    finally:
        logging.getLogger().removeHandler(handler)


def test_verbosity_speaks_for_the_project_only(capsys):
    # default: warnings only, a third party's too
    assert not emitted(capsys, logging.INFO, "drivers._function_generator", 0)
    assert not emitted(capsys, logging.INFO, "pymodbus.logging", 0)
    assert emitted(capsys, logging.WARNING, "bench.session", 0)
    assert emitted(capsys, logging.WARNING, "pymodbus.logging", 0)
    # -v: the project's INFO lines, nobody else's
    assert emitted(capsys, logging.INFO, "drivers._function_generator", 1)
    assert not emitted(capsys, logging.INFO, "pymodbus.logging", 1)
    assert not emitted(capsys, logging.DEBUG, "bench.session", 1)
    # -vv: the project's DEBUG lines; numba's and matplotlib's are not even produced
    assert emitted(capsys, logging.DEBUG, "procedures.stepped_sine", 2)
    assert not emitted(capsys, logging.DEBUG, "numba.core.ssa", 2)
    assert not logging.getLogger("matplotlib.font_manager").isEnabledFor(logging.DEBUG)
    logging.getLogger().removeHandler(setup_logging(0))        # the project's loggers back to NOTSET


# --------------------------------------------------------------------------- 80 columns, on tmux's screen

DEMO = """\
import logging, sys, time
from bench.terminal import Progress, end_line, setup_logging
setup_logging(0)
p = Progress("stepped sine")
note = "30 N  1000.0 Hz up   err +0.0% THD(x) 0.0% | F_s 10.1 N x_s 10.2 um n 1.49 m 10 kg"
for i in range(1, 8):
    p(i, 7, note)
    time.sleep(0.02)
    logging.getLogger("bench.session").warning("step %d: a short warning", i)
    logging.getLogger("pymodbus.logging").info("Server listening.")
q = Progress("stepped sine")       # an interrupted run: its line ends where it stood
q(2, 9, note)
end_line()
print("interrupted at 2/9", file=sys.stderr)
from bench.cli import main            # then a real run, as `bench run` (same process: one start-up)
sys.exit(main(sys.argv[1:]))
"""

PLAN = fast_plan_toml([60.0, 80.0, 100.0])


def tmux_screen(tmp_path: Path, command: str, timeout_s: float = 90) -> list[str]:
    """Run ``command`` in a detached 80x60 tmux pane and return its screen, wrapped lines
    joined (-J: a line that wrapped comes back longer than 80)."""
    sock = f"bench-test-{uuid.uuid4().hex[:8]}"
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES", "TMUX")}
    env["TERM"] = "xterm"
    script = tmp_path / "cmd.sh"
    script.write_text(f"cd {REPO}\n{command}\necho END-OF-COMMAND\nsleep 120\n")
    tmux = [TMUX, "-L", sock, "-f", "/dev/null"]
    subprocess.run(tmux + ["new-session", "-d", "-x", "80", "-y", "60", "sh", str(script)], env=env, check=True)
    try:
        deadline = time.monotonic() + timeout_s
        while True:
            screen = subprocess.run(tmux + ["capture-pane", "-p", "-J", "-S", "-"], capture_output=True,
                                    text=True, check=True).stdout
            if "END-OF-COMMAND" in screen:
                return screen.rstrip("\n").split("\n")
            assert time.monotonic() < deadline, screen
            time.sleep(0.2)
    finally:
        subprocess.run(tmux + ["kill-server"], capture_output=True)


@pytest.mark.skipif(TMUX is None, reason="tmux not installed (make setup)")
@pytest.mark.timeout(200)
def test_the_progress_line_fits_80_columns_and_log_lines_pass_above_it(tmp_path):
    (tmp_path / "demo.py").write_text(DEMO)
    (tmp_path / "plan.toml").write_text(PLAN)
    lines = tmux_screen(tmp_path, f"{sys.executable} {tmp_path / 'demo.py'} run --plan {tmp_path / 'plan.toml'} "
                                  f"--out {tmp_path / 'run'} --no-report")
    text = "\n".join(lines)
    first_run_line = next(k for k, x in enumerate(lines) if x.startswith("WARNING: identifiability"))
    demo, run = lines[:first_run_line], lines[first_run_line:]
    # the log lines, each whole on its own line, in order; the progress line once, at the end
    warnings = [x for x in demo if x.startswith("WARNING: step")]
    assert warnings == [f"WARNING: step {i}: a short warning" for i in range(1, 8)], text
    progress = [x for x in lines if "stepped sine" in x]
    assert len(progress) == 3, text                 # the demo's two and the run's final lines, nothing stale
    assert progress[0].startswith("stepped sine [") and " 7/7 " in progress[0], text
    assert progress[1].startswith("stepped sine [") and " 2/9 " in progress[1], text
    assert demo[demo.index(progress[1]) + 1] == "interrupted at 2/9", text
    assert progress[2].startswith("stepped sine [") and " 3/3 " in progress[2], text
    assert all(len(x) <= 80 for x in progress), [len(x) for x in progress]
    assert all(len(x) <= 80 for x in demo), text
    assert "Server listening" not in text and " INFO " not in text, text     # pymodbus and drivers: silent
    # a default run: its warnings, the progress line and the result, nothing else
    assert [x for x in run if not x.startswith("WARNING: identifiability")] == \
        [progress[2], "output off, confirmed by the generator", f"run completed: 3/3 steps in {tmp_path / 'run'}/",
         "END-OF-COMMAND"], text
