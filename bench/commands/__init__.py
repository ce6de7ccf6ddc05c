"""The commands of `bench`, one module per job; bench/cli.py parses the command line, runs
the command and maps its errors to the exit codes:

- :mod:`.run`: dry-run, run, resume, sequence, demo, watch (plan, run and watch a test);
- :mod:`.results`: report, export, identify, analyze, check, compare, modes (what a stored
  run says);
- :mod:`.tools`: paper, frf, warmup, twins, twin (the simulated rig's tools).

`bench study` and the batch mode of `bench analyze` are in bench/studies/cli.py."""

from __future__ import annotations

from enum import IntEnum


class ExitCode(IntEnum):
    OK = 0
    FAILURE = 1          # runtime failure; `bench check` found problems
    USAGE = 2            # bad argument, file or value
    LIMIT = 3            # refused or aborted by a limit
    INTERRUPTED = 130    # Ctrl-C, SIGTERM, SIGHUP (terminal closed), SIGQUIT
