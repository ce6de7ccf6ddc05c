"""Command line: `bench <command>`.  The application configures logging; libraries don't.

Exit codes (docs/reliability.md), chosen by the error's class in the tree of
sim/errors.py: 0 done; 1 runtime failure (an instrument error, a failed run, `bench check`
found problems; an unexpected exception is reported as an internal error); 2 usage or
configuration error (a bad argument, file or value: the message names it); 3 stopped by a
limit (a plan the rig's limits refuse, or a run aborted by the safety supervisor); 130
interrupted (Ctrl-C, SIGTERM, SIGHUP, SIGQUIT before the work was done: the measuring and
the report; one after it leaves the code as it was, decision record 0051).  Errors are one
line on stderr; `--debug` adds the traceback.

Here: the parser, the exit codes' mapping and :func:`main`; each command is in
:mod:`bench.commands` (``run``, ``results``, ``tools``), `bench study` in bench/studies/cli.py.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from enum import StrEnum

from sim.errors import BenchError, ConfigurationError, EnvelopeError, LimitError, RunDirectoryError

from .commands import ExitCode
from .commands.results import (
    cmd_analyze,
    cmd_check,
    cmd_compare,
    cmd_export,
    cmd_identify,
    cmd_import,
    cmd_modes,
    cmd_report,
)
from .commands.run import (
    cmd_demo,
    cmd_dry_run,
    cmd_resume,
    cmd_run,
    cmd_sequence,
    cmd_watch,
)
from .commands.tools import cmd_frf, cmd_paper, cmd_twin, cmd_twins, cmd_warmup
from .terminal import Progress, end_line, setup_logging, tolerant_streams
from .words import say, terminal_run

log = logging.getLogger(__name__)


class CliLine(StrEnum):
    """The program's own lines about a command's end (:data:`bench.words.terminal_run.CLI`)."""

    INTERRUPTED = "interrupted"             # (its reason follows: "Ctrl-C", "signal N")
    INTERNAL = "internal"                   # (the exception's type and first line follow)
    PROBLEMS = "problems"                   # count: a file's problems (their lines follow)
    LATE = "late"                           # reason: a signal after the work was done
    FAILED = "failed"                       # command (the log's line with the traceback)
    ERROR = "error"                         # before a command's one-line error (not an interruption)
    HINT_INTERNAL = "hint_internal"         # after an internal error's line: where its traceback is
    HINT_DEBUG = "hint_debug"               # after another error's line


def _said(code: CliLine, **fields) -> str:
    return say(terminal_run.CLI, code, fields)






































def _add_watch_options(s) -> None:
    s.add_argument("--watch", action="store_true", help="serve the live page of the run (URL printed)")
    s.add_argument("--watch-port", type=int, default=0, help="port of the page (default: any free one)")
    s.add_argument("--watch-host", default="127.0.0.1",
                   help="interface of the page (default 127.0.0.1; others only when given)")






































def _add_twin_parsers(sub) -> None:
    s = sub.add_parser("twin", help="write rig.toml and plan.toml of a simulated twin of the rig that measured "
                                    "SOURCE (identified friction, named causes, noise)")
    s.add_argument("source", help="run directory or UFF58 file of time records")
    s.add_argument("--analysis", help="directory (or file) of an existing analysis.json of SOURCE "
                                      "(default: analyse SOURCE into OUT/analysis)")
    s.add_argument("--out", help="output directory (default: SOURCE/twin, or <stem>_twin next to a file)")
    s.add_argument("--plain", action="store_true", help="a plain Masing twin: base F_s, x_s, n, m only")
    s.set_defaults(func=cmd_twin)

    s = sub.add_parser("compare", help="compare first-harmonic compliance and accelerance of two sources step "
                                       "by step; exit 1 when they differ by more than the tolerance or the other lacks steps "
                                       "of the reference")
    s.add_argument("reference", help="run directory or UFF58 file")
    s.add_argument("other", help="run directory or UFF58 file")
    s.add_argument("--tolerance", type=float, default=0.02,
                   help="largest rms relative difference accepted (fraction; default 0.02 = 2 %%)")
    s.add_argument("--min-coverage", type=float, default=1.0,
                   help="share of the reference's usable steps that must be matched in OTHER (fraction; default 1: "
                        "all of them; unmatched steps are named, the resonance ones as such)")
    s.add_argument("--out", help="output directory (default: OTHER/compare, or <stem>_compare next to a file)")
    s.set_defaults(func=cmd_compare)




class _Formatter(argparse.RawDescriptionHelpFormatter):
    """Every option's default shown after its help, unless it has none to show."""

    def _get_help_string(self, action):
        text = action.help or ""
        default = action.default
        if ("%(default)" in text or "default" in text or any(default is x for x in (None, False, argparse.SUPPRESS))
                or not action.option_strings or action.option_strings[0] in ("-v", "-h")):
            return text
        return f"{text} (default: %(default)s)"


class _Parser(argparse.ArgumentParser):
    """Usage errors in one line, naming the command, the problem and where to look; every
    (sub)command's help shows the defaults."""

    def __init__(self, *a, **k):
        k.setdefault("formatter_class", _Formatter)
        super().__init__(*a, **k)

    def error(self, message):
        self.exit(ExitCode.USAGE, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="bench", description="""\
Stepped-sine friction tests on the linear-guideway shaker rig, or on its simulated twin:
plan and run a test, watch it live, stop and resume it, then report, export and analyse
the measurements.  Start with `bench demo` (the default plan on the simulated rig), then
`bench dry-run --plan P --rig R` and `bench run --plan P --rig R --out DIR` with your own
plan and rig files (annotated examples in bench/defaults/).  Force levels 0.1-100 N,
frequencies 20-1000 Hz.  `bench COMMAND --help` explains each command.""",
                epilog="""\
exit codes: 0 done; 1 failure (an instrument error, a failed run, `bench check` found
problems); 2 usage or configuration error (the message names the file, key and allowed
values); 3 stopped by a limit (refused before the output went on, or aborted); 130
interrupted (Ctrl-C, SIGTERM, SIGHUP: the terminal closed, SIGQUIT) before the work
was done; a signal while the report is written is honoured once it is complete.  The
output is switched off on every exit.
-v, --debug and -vv may come before or after the command.""")
    _add_common(p, argparse.SUPPRESS)
    p.set_defaults(verbose=0, debug=False)
    from . import __version__
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("paper", help="redraw the seed paper's numerical figures (PNG + CSV)")
    s.add_argument("--out", default="out/paper", help="directory for the figures, their CSV and a README")
    s.add_argument("--quick", action="store_true", help="coarse grids (seconds instead of minutes)")
    s.add_argument("--rig", action="append", help="rig TOML with a pitching mode in [rig.model]: Figs. 15 and 17 "
                   "at its parameters (default: bench/defaults/sim_rig_pitch.toml's); repeat it for several "
                   "rigs, each model named by its file and drawn in the colour of the run of its position")
    s.add_argument("--runs", nargs="+", metavar="RUN", help="run directories whose measured modes are drawn over "
                                                             "Figs. 15 and 17 (legends: their --label)")
    s.set_defaults(func=cmd_paper)

    s = sub.add_parser("demo", help="the main job: the default plan on the simulated rig, with its report")
    s.add_argument("--out", default="out/demo", help="run directory (the files an earlier demo wrote there, listed in its "
                                           "demo-manifest.json, are deleted first; anything else is refused)")
    _add_watch_options(s)
    s.set_defaults(func=cmd_demo)

    for name, func, s in (("run", cmd_run, sub.add_parser("run", help="run a stepped-sine plan on a rig")),
                          ("dry-run", cmd_dry_run,
                           sub.add_parser("dry-run", help="check a plan against the rig's limits; print the envelope"))):
        s.add_argument("--plan", help="plan TOML: force levels (0.1-100 N), frequencies (20-1000 Hz), control "
                                      "(default: the demo plan, bench/defaults/demo_plan.toml)")
        s.add_argument("--rig", help="rig TOML: instrument URLs, calibration, limits "
                                     "(default: the simulated rig, bench/defaults/sim_rig.toml)")
        if name == "run":
            s.add_argument("--out", required=True, help="new run directory (bench resume continues it)")
            s.add_argument("--seed", type=int, help="noise seed of a simulated rig (default: the rig file's)")
            s.add_argument("--no-report", action="store_true", help="do not write the report at the end")
            s.add_argument("--label", action="append", metavar="KEY=VALUE",
                           help="a label kept in run.json (repeatable), used by the legends of `bench modes`, "
                                "e.g. --label lubricant=\"ISO VG 32\"")
            _add_watch_options(s)
        else:
            s.add_argument("--steps", action="store_true", help="list the steps the plan will run (key, level, "
                           "frequency or \"refined, chosen online\")")
        s.set_defaults(func=func)

    s = sub.add_parser("resume", help="continue an interrupted run without repeating completed steps")
    s.add_argument("run", help="run directory of an interrupted, aborted or failed run")
    s.add_argument("--no-report", action="store_true", help="do not write the report at the end")
    s.add_argument("--retry-skipped", action="store_true",
                   help="also measure again the steps skipped at run time because their force was unreachable "
                        "(e.g. after raising drive_V in run.json's rig); by default they stay skipped")
    _add_watch_options(s)
    s.set_defaults(func=cmd_resume)

    s = sub.add_parser("sequence", help="run a sequence file's entries (plan, rig, labels) one after the other into "
                                        "OUT/<name>/, every entry checked first; bench resume OUT goes on with it")
    s.add_argument("sequence", help="sequence file (TOML: [sequence] name, [[sequence.entry]] name, plan, rig, labels)")
    s.add_argument("--out", required=True, help="new directory for the sequence (one run directory per entry)")
    s.add_argument("--no-report", action="store_true", help="do not write each entry's report")
    s.set_defaults(func=cmd_sequence)

    s = sub.add_parser("watch", help="serve a live page of a run directory (running, resumed or finished)")
    s.add_argument("run", help="run directory (it may not exist yet: the page waits for it)")
    s.add_argument("--port", type=int, default=0, help="port (default: any free one)")
    s.add_argument("--host", default="127.0.0.1", help="interface (default 127.0.0.1; others only when given)")
    s.set_defaults(func=cmd_watch)

    s = sub.add_parser("report", help="(re)write the report of a run directory")
    s.add_argument("run", help="run directory (the report goes to RUN/report/)")
    s.add_argument("--with", dest="with_runs", action="append", metavar="OTHER",
                   help="a stepped-sine run of the same rig whose modes the backbone figure of a phase-resonance "
                        "run overlays at their peaks' amplitudes (repeatable)")
    s.set_defaults(func=cmd_report)

    s = sub.add_parser("export", help="write a run's steps as CSV and UFF 58 (FRFs and time records)")
    s.add_argument("run", help="run directory")
    s.add_argument("--out", help="output directory (default: <run>/export)")
    s.add_argument("--no-time", action="store_true", help="skip the time records (time.uff)")
    s.set_defaults(func=cmd_export)

    s = sub.add_parser("identify", help="identify F_s, x_s, n and the mass from a stored run or a UFF58 file")
    s.add_argument("source", help="run directory, or a UFF file of time records (bench export)")
    s.add_argument("--rig", help="rig TOML whose [rig.expected] values start the fit (UFF input)")
    s.set_defaults(func=cmd_identify)

    s = sub.add_parser("analyze", help="find what the Masing model gets wrong in a run or UFF58 file, "
                                       "name the cause, extend the model, measure the gain")
    s.add_argument("sources", nargs="+", metavar="source",
                   help="run directory or UFF58 file of time records; several (or an archive directory) "
                        "run as a batch with one summary table")
    s.add_argument("--rig", help="rig TOML whose [rig.expected] values start the fit")
    s.add_argument("--out", help="output directory (default: SOURCE/analysis, or next to the file; "
                                 "required for a batch)")
    from .studies.cli import add_batch_options
    add_batch_options(s)
    s.set_defaults(func=cmd_analyze)

    s = sub.add_parser("twins", help="serve the simulated rig's instruments on loopback; print their URLs")
    s.add_argument("--rig", help="simulated rig TOML (default: bench/defaults/sim_rig.toml)")
    s.add_argument("--host", default="127.0.0.1", help="interface the twins listen on")
    s.add_argument("--serial", action="store_true", help="also serve SCPI and Modbus RTU on pty pairs")
    s.set_defaults(func=cmd_twins)

    s = sub.add_parser("warmup", help="compile and cache the simulation kernels (make setup runs it)")
    s.set_defaults(func=cmd_warmup)

    s = sub.add_parser("frf", help="compliance G(beta) of the model at one force level (CSV to stdout)")
    s.add_argument("--gamma0", type=float, default=0.6, help="force ratio P0/F_s")
    s.add_argument("--n", type=float, default=1.5, help="shape factor n of the virgin curve")
    s.add_argument("--beta-min", type=float, default=0.2, help="lowest frequency ratio beta")
    s.add_argument("--beta-max", type=float, default=2.0, help="highest frequency ratio beta")
    s.add_argument("--points", type=int, default=200, help="frequency ratios, linearly spaced")
    s.add_argument("--engine", choices=("shooting", "rk4"), default="shooting",
                   help="steady state by half-period shooting (fast) or by RK4 time stepping")
    s.set_defaults(func=cmd_frf)

    s = sub.add_parser("check", help="verify a run directory: list missing, truncated, damaged and unknown steps")
    s.add_argument("run", help="run directory")
    s.add_argument("--strict", action="store_true",
                   help="also fail (exit 1) on steps skipped at run time (force unreachable), which the plan's "
                        "infeasible = \"skip\" otherwise allows")
    s.set_defaults(func=cmd_check)

    _add_twin_parsers(sub)

    s = sub.add_parser("modes", help="each mode's resonance and damping ratio per force level of one or more runs: "
                                     "modes.csv and the seed's Figs. 13 and 17 from the measurements")
    s.add_argument("runs", nargs="+", metavar="RUN", help="run directories (legends use each run's --label)")
    s.add_argument("--out", required=True, help="output directory for modes.csv and the figures")
    s.add_argument("--no-model", action="store_true", help="leave out the rig model's prediction (simulated rigs)")
    s.set_defaults(func=cmd_modes)

    s = sub.add_parser("import", help="measured frequency responses (UFF58 FRF records, CSV, MATLAB .mat) into a run "
                                      "directory that report, modes, compare and export read, recorded as imported")
    s.add_argument("source", help="a .uff/.unv file of FRF records (function type 4), a .csv or a .mat (v5/v7) file")
    s.add_argument("--out", required=True, help="new run directory")
    s.add_argument("--mapping", help="TOML file: which field is what, units, response kind, level kind, mass "
                                     "(docs/howto/measured-frfs.md)")
    s.set_defaults(func=cmd_import)

    from .studies.cli import add_parsers as add_study_parsers
    add_study_parsers(sub, Progress)
    return _with_common(p)


def _add_common(p: argparse.ArgumentParser, default) -> None:
    p.add_argument("-v", "--verbose", action="count", default=default,
                   help="more detail on the terminal: -v the bench's INFO lines, -vv its DEBUG lines "
                        "(other libraries speak only for warnings)")
    p.add_argument("--debug", action="store_true", default=default, help="show the traceback of an error")


def _with_common(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """``-v`` and ``--debug`` after any subcommand too (every level of every subcommand,
    whoever added it): ``bench run -v`` is ``bench -v run``."""
    for action in p._actions:
        if isinstance(action, argparse._SubParsersAction):
            for s in action.choices.values():
                if "--debug" not in s._option_string_actions:
                    _add_common(s, argparse.SUPPRESS)
                _with_common(s)
    return p


# OSErrors about a path the user named (a missing file, a directory where a file goes):
# usage errors.  Any other OSError is a runtime failure (a full disk, a lost network).
_PATH_ERRORS = (FileNotFoundError, FileExistsError, IsADirectoryError, NotADirectoryError, PermissionError)


def _exit_code(e: BaseException) -> ExitCode:
    """The documented exit code of an exception, by its place in the error tree
    (sim/errors.py, decision record 0027)."""
    if isinstance(e, KeyboardInterrupt):
        return ExitCode.INTERRUPTED
    if isinstance(e, (LimitError, EnvelopeError)):
        return ExitCode.LIMIT
    if isinstance(e, (ConfigurationError, RunDirectoryError, _PATH_ERRORS)):
        return ExitCode.USAGE
    return ExitCode.FAILURE           # InstrumentError, another BenchError, a failure, a bug


def _internal(e: BaseException) -> bool:
    """A bug (or a library's error nobody translated), not an error raised on purpose."""
    return not isinstance(e, (BenchError, KeyboardInterrupt, OSError))


def _one_line(e: BaseException) -> str:
    if isinstance(e, KeyboardInterrupt):
        return f"{_said(CliLine.INTERRUPTED)}{f' ({e})' if str(e) else ''}"
    if isinstance(e, OSError) and e.strerror:
        where = " -> ".join(str(f) for f in (e.filename, e.filename2) if f is not None)
        return f"{where}: {e.strerror}" if where else e.strerror
    text = str(e).strip().splitlines()
    first = text[0] if text else ""
    named = f"{type(e).__name__}: {first}" if first else type(e).__name__
    if _internal(e):
        return f"{_said(CliLine.INTERNAL)} ({named})"
    if isinstance(e, ConfigurationError) and len(text) > 1:    # a file's problems, one line each
        return _said(CliLine.PROBLEMS, count=len(text)) + "".join(f"\n  {line}" for line in text)
    if _exit_code(e) in (ExitCode.USAGE, ExitCode.LIMIT) and first:
        return first
    return named


# the thread pools of numpy's BLAS and of OpenMP: one thread each, unless the user set them.  No
# problem of the bench is large enough to gain from more, and on cores busy with other work their
# threads spin: with OpenBLAS's two threads the frequency refinement of `bench analyze` took 16 x
# the CPU (decision 0062; the tests and benchmarks already ran with one, decision 0065)
BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def one_blas_thread() -> None:
    """One BLAS/OpenMP thread for the ``bench`` program and the processes it starts (read
    when numpy is first imported: here, before any command imports it)."""
    for name in BLAS_THREADS:
        os.environ.setdefault(name, "1")


def main(argv: list[str] | None = None) -> int:
    """`bench ARGS`.  As the program (``argv`` None: the command line) the ending signals
    are caught from here, before the heavy imports, until the process is gone: a signal
    before the command's work is done gives 130, one after it changes nothing (0051)."""
    if argv is not None:                  # inside another program (a test): its signals stay its own
        return _parse_and_run(argv)
    one_blas_thread()
    from .signals import for_process, ignore_at_exit
    latch = for_process()
    with tolerant_streams():              # these lines too may meet a terminal that is gone
        try:
            code = _parse_and_run(argv)
        except KeyboardInterrupt as e:    # before or after the command (its errors are its own)
            print(f"bench: {_one_line(e)}", file=sys.stderr)
            code = ExitCode.INTERRUPTED
        latch.finish()
        if latch.reason is not None and code == ExitCode.OK:   # a signal a finalizer dropped: never 0
            code = ExitCode.INTERRUPTED
        elif latch.late is not None:
            print(_said(CliLine.LATE, reason=latch.late), file=sys.stderr, flush=True)
    ignore_at_exit()
    return code


def _parse_and_run(argv: list[str] | None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:               # usage error or --help: argparse has printed it
        return int(e.code or 0)
    with tolerant_streams():            # a terminal that is gone changes nothing the bench does
        return _main(args)


def _main(args) -> int:
    handler = setup_logging(args.verbose)
    try:
        return int(args.func(args))
    except (Exception, KeyboardInterrupt) as e:   # one line, a documented code; --debug: traceback
        code = _exit_code(e)
        end_line()
        if args.debug:
            log.exception(_said(CliLine.FAILED, command=args.command))
        hint = (None if args.debug or code == ExitCode.INTERRUPTED else
                CliLine.HINT_INTERNAL if _internal(e) else CliLine.HINT_DEBUG)
        print(f"bench {args.command}: {_said(CliLine.ERROR) if code != ExitCode.INTERRUPTED else ''}{_one_line(e)}"
              f"{_said(hint) if hint else ''}", file=sys.stderr)
        return code
    finally:
        end_line()
        logging.getLogger().removeHandler(handler)


if __name__ == "__main__":
    sys.exit(main())
