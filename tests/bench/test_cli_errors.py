"""User mistakes give one line on stderr naming the problem, no traceback, and the
documented exit code (bench/cli.py, docs/reliability.md).

The subcommands are enumerated from the parser, so a subcommand added later is covered
without editing this file: each gets an unknown option, and each that takes a path (a
positional argument, a required option, --plan, --rig) gets one that does not exist.
The commands run as real processes, all at once (they are independent), each with a
time bound.
"""

from __future__ import annotations

import argparse
import subprocess
import time
from pathlib import Path

import pytest

from bench.cli import ExitCode, build_parser, main
from benchtools.procs import bench_process

MISSING = "/nonexistent/guideway-bench/input"
PATH_OPTIONS = {"--plan", "--rig", "--spec", "--source", "--run", "--config"}
TIME_LIMIT_S = 120


def subcommands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    raise AssertionError("no subcommands")


def bad_path_args(name: str, sub: argparse.ArgumentParser, tmp: Path) -> list[str] | None:
    """Arguments giving ``name`` a path that does not exist; None if it takes no path."""
    args, bad = [name], False
    for a in sub._actions:
        if not a.option_strings and a.nargs != 0:              # positional
            args += [MISSING] if a.nargs in (None, 1, "?", "+") else [MISSING]
            bad = True
        elif a.required:
            value = str(tmp / f"new-{name}") if a.dest == "out" else MISSING
            args += [a.option_strings[-1], value]
            bad = bad or value == MISSING
        elif set(a.option_strings) & PATH_OPTIONS:
            args += [a.option_strings[-1], MISSING + ".toml"]
            bad = True
    return args if bad else None


def test_every_subcommand_is_enumerated():
    assert {"run", "resume", "report", "export", "identify", "check", "dry-run"} <= set(subcommands())


def test_unknown_options_to_every_subcommand_are_one_usage_line(capsys):
    for args in [["--no-such-option"], ["no-such-command"], []] + \
            [[name, "--no-such-option"] for name in subcommands()]:
        assert main(args) == ExitCode.USAGE, args
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "error:" in err[0] and "Traceback" not in err[0], (args, err)


def test_bad_paths_and_values_to_every_subcommand_are_one_line_without_traceback(tmp_path):
    cases = []
    for name, sub in subcommands().items():
        args = bad_path_args(name, sub, tmp_path)
        if args:
            cases.append((args, ExitCode.USAGE))
    cases += [(["frf", "--gamma0", "nan"], ExitCode.USAGE), (["paper", "--out", "/dev/null/x"], ExitCode.USAGE)]
    procs = [(args, code, bench_process(*args, text=True, stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE))
             for args, code in cases]
    deadline = time.monotonic() + TIME_LIMIT_S
    problems = []
    for args, code, proc in procs:
        try:
            out, err = proc.communicate(timeout=max(1.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            problems.append(f"bench {' '.join(args)}: no answer within {TIME_LIMIT_S} s")
            continue
        lines = [line for line in err.splitlines() if line.strip()]
        if "Traceback" in err:
            problems.append(f"bench {' '.join(args)}: traceback:\n{err[-1500:]}")
        elif proc.returncode != code:
            problems.append(f"bench {' '.join(args)}: exit {proc.returncode}, expected {int(code)}: {err[-500:]}")
        elif len(lines) != 1 or "error:" not in lines[0]:
            problems.append(f"bench {' '.join(args)}: expected one error line, got {lines}")
    assert not problems, "\n".join(problems)


def test_the_messages_name_the_value_and_what_was_expected(capsys):
    assert main(["resume", "/tmp/nonexistent"]) == ExitCode.USAGE
    assert "/tmp/nonexistent: no such directory (expected a run directory" in capsys.readouterr().err
    assert main(["report", "/tmp"]) == ExitCode.USAGE
    assert "/tmp: not a run directory (no run.json" in capsys.readouterr().err
    assert main(["frf", "--points", "-3"]) == ExitCode.USAGE
    assert "--points must be >= 1, got -3" in capsys.readouterr().err
    assert main(["dry-run", "--plan", MISSING]) == ExitCode.USAGE
    assert f"{MISSING}: file not found" in capsys.readouterr().err


def test_debug_shows_the_traceback(capsys, caplog):
    assert main(["report", "/tmp", "--debug"]) == ExitCode.USAGE
    err = capsys.readouterr().err
    assert "(--debug shows the traceback)" not in err and "not a run directory" in err
    assert any(r.exc_info for r in caplog.records), "no traceback logged with --debug"
    caplog.clear()
    assert main(["--debug", "report", "/tmp"]) == ExitCode.USAGE
    assert any(r.exc_info for r in caplog.records)


@pytest.mark.parametrize("exc, code", [
    (KeyboardInterrupt("signal 15"), ExitCode.INTERRUPTED),
    (RuntimeError("a bug"), ExitCode.FAILURE),
    (PermissionError(13, "Permission denied", "/x/run.json"), ExitCode.USAGE),
])
def test_unexpected_errors_and_interruptions_have_their_codes(mocker, capsys, exc, code):
    # fault injection: errors the command line cannot provoke on demand
    mocker.patch("bench.cli.cmd_report", side_effect=exc)   # build_parser() binds it at call time
    assert main(["report", "/tmp"]) == code
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0]
    if isinstance(exc, PermissionError):
        assert "/x/run.json: Permission denied" in err[0]


@pytest.mark.parametrize("given, blas", [(None, "1"), ("2", "2")])
def test_the_bench_program_gives_numpy_one_blas_thread_unless_the_user_chose(given, blas):
    """Decisions 0062, 0065: OpenBLAS's default threads spin on busy cores (16 x the CPU in
    `bench analyze`'s frequency refinement); the program sets one BLAS and OpenMP thread before
    any command imports numpy, and a number the user set stays."""
    import os
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    if given:
        env["OPENBLAS_NUM_THREADS"] = given
    code = ("import os, sys\nimport bench.cli as cli\nbefore = 'numpy' in sys.modules\nsys.argv = ['bench', 'dry-run', '--help']\n"
            "cli.main()\nprint(before, os.environ['OPENBLAS_NUM_THREADS'], os.environ['OMP_NUM_THREADS'])")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert out.stdout.split()[-3:] == ["False", blas, "1"], out.stdout[-300:] + out.stderr[-300:]
