"""User mistakes give one line on stderr naming the problem, no traceback, and the
documented exit code (bench/cli.py, docs/reliability.md).

The subcommands are enumerated from the parser, so a subcommand added later is covered
without editing this file: each gets an unknown option, and each that takes a path (a
positional argument, a required option, --plan, --rig) gets one that does not exist.
Every case runs through :func:`bench.cli.main` in this process (what the command does with
a bad input: its exit code, its one line, no traceback, no warning raised while it runs).
Three of them also run as real processes (``python -m bench.cli``), all at once, each with a
time bound: the real entry point, where anything printed outside ``main`` (an import's
warning, an exception at exit) would also show.  Every case as a real process, as this test
ran until decision 0083's third addendum (19 processes, 34 s of CPU: each pays the import of
numpy, scipy and the project), is the campaign (`make bench`).
"""

from __future__ import annotations

import argparse
import subprocess
import time
import warnings
from pathlib import Path

import pytest

from bench.cli import ExitCode, build_parser, main
from benchtools.procs import bench_process

MISSING = "/nonexistent/guideway-bench/input"
PATH_OPTIONS = {"--plan", "--rig", "--spec", "--source", "--run", "--config"}
TIME_LIMIT_S = 120
# the real processes of `make test`: a positional path, the plan and rig options (the config
# loader), a bad value (decision 0083, third addendum); the campaign runs every case
IN_PROCESSES = {"resume", "dry-run", "frf"}


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


def bad_cases(tmp: Path) -> list[tuple[list[str], ExitCode]]:
    """Every subcommand given a path that does not exist, and two bad values."""
    cases = []
    for name, sub in subcommands().items():
        args = bad_path_args(name, sub, tmp)
        if args:
            cases.append((args, ExitCode.USAGE))
    return cases + [(["frf", "--gamma0", "nan"], ExitCode.USAGE), (["paper", "--out", "/dev/null/x"], ExitCode.USAGE)]


def one_line_problem(args: list[str], code: int, expected: int, err: str) -> str | None:
    lines = [line for line in err.splitlines() if line.strip()]
    if "Traceback" in err:
        return f"bench {' '.join(args)}: traceback:\n{err[-1500:]}"
    if code != expected:
        return f"bench {' '.join(args)}: exit {code}, expected {int(expected)}: {err[-500:]}"
    if len(lines) != 1 or "error:" not in lines[0]:
        return f"bench {' '.join(args)}: expected one error line, got {lines}"
    return None


def test_bad_paths_and_values_to_every_subcommand_are_one_line_without_traceback(tmp_path, capsys):
    cases = bad_cases(tmp_path)
    assert len(cases) >= 15 and {args[0] for args, _ in cases} >= IN_PROCESSES
    problems = []
    for args, expected in cases:
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            code = main(args)
        err = capsys.readouterr().err
        problem = one_line_problem(args, code, expected, err)
        if problem is None and seen:
            problem = f"bench {' '.join(args)}: warned {[str(w.message) for w in seen]}"
        if problem:
            problems.append(problem)
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("which", ["sample", pytest.param("every_case", marks=pytest.mark.campaign)])
def test_bad_inputs_to_the_real_entry_point_are_one_line_without_traceback(tmp_path, which):
    cases = [(args, code) for args, code in bad_cases(tmp_path) if which != "sample" or args[0] in IN_PROCESSES]
    assert len(cases) == (len(IN_PROCESSES) if which == "sample" else len(bad_cases(tmp_path)))
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
        problem = one_line_problem(args, proc.returncode, code, err)
        if problem:
            problems.append(problem)
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
