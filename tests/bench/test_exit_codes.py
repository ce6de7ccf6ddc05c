"""Exit codes come from the error tree (sim/errors.py, decision record 0027), by isinstance:
an error raised on purpose gets its documented code and one line naming the problem; an
unexpected exception (a bug, a library error nobody translated) exits 1 as an internal
error and says to rerun with --debug.  Each case below goes through ``bench``'s real
``main`` with the command's function made to raise (fault injection)."""

from __future__ import annotations

import pytest

import drivers
from bench import config, storage
from bench.cli import ExitCode, main
from procedures.safety import LimitExceeded
from sim import errors
from sim.errors import BenchError, ConfigurationError, EnvelopeError, InstrumentError, LimitError, RunDirectoryError

CASES = [
    # (exception, exit code, expected line after "bench report: ", internal?)
    (ConfigurationError("plan.toml: [plan] levels_N: must be > 0"), ExitCode.USAGE,
     "error: plan.toml: [plan] levels_N: must be > 0", False),
    (config.ConfigError("rig.toml: [rig] name: missing"), ExitCode.USAGE, "error: rig.toml: [rig] name: missing", False),
    (RunDirectoryError("runs/a: not a run directory"), ExitCode.USAGE, "error: runs/a: not a run directory", False),
    (EnvelopeError("the rig's limits cannot hold 3 of 9 steps"), ExitCode.LIMIT,
     "error: the rig's limits cannot hold 3 of 9 steps", False),
    (LimitExceeded("force 40 exceeds the limit 35"), ExitCode.LIMIT, "error: force 40 exceeds the limit 35", False),
    (drivers.ConnectionLost("socket://127.0.0.1:5025: reset"), ExitCode.FAILURE,
     "error: ConnectionLost: socket://127.0.0.1:5025: reset", False),
    (drivers.ScpiError("FREQ 1e9", -222, "Data out of range"), ExitCode.FAILURE, "error: ScpiError: ", False),
    (BenchError("something else went wrong"), ExitCode.FAILURE, "error: BenchError: something else went wrong", False),
    (FileNotFoundError(2, "No such file or directory", "plan.toml"), ExitCode.USAGE,
     "error: plan.toml: No such file or directory", False),
    (OSError(28, "No space left on device", "runs/a/steps"), ExitCode.FAILURE,
     "error: runs/a/steps: No space left on device", False),
    (ValueError("operands could not be broadcast together"), ExitCode.FAILURE,
     "error: internal error (ValueError: operands could not be broadcast together)", True),
    (KeyError("compliance_abs_m_per_N"), ExitCode.FAILURE, "error: internal error (KeyError: ", True),
    (ZeroDivisionError("float division by zero"), ExitCode.FAILURE, "error: internal error (ZeroDivisionError", True),
    (KeyboardInterrupt("signal 15"), ExitCode.INTERRUPTED, "interrupted (signal 15)", False),
]


@pytest.mark.parametrize("exc, code, line, internal", CASES, ids=[type(c[0]).__name__ + str(i) for i, c in enumerate(CASES)])
def test_each_error_has_its_exit_code_and_one_line(mocker, capsys, exc, code, line, internal):
    mocker.patch("bench.cli.cmd_report", side_effect=exc)
    assert main(["report", "/tmp"]) == code
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0], err
    assert err[0].startswith(f"bench report: {line}"), err[0]
    assert ("internal error" in err[0] and "rerun with --debug" in err[0]) == internal, err[0]


def test_an_internal_error_with_debug_logs_the_traceback(mocker, capsys, caplog):
    mocker.patch("bench.cli.cmd_report", side_effect=ValueError("a numpy bug"))
    assert main(["report", "/tmp", "--debug"]) == ExitCode.FAILURE
    err = capsys.readouterr().err
    assert "internal error (ValueError: a numpy bug)" in err and "rerun with --debug" not in err
    assert any(r.exc_info and r.exc_info[0] is ValueError for r in caplog.records)


def test_one_tree_that_every_layer_raises_from():
    for cls in (ConfigurationError, EnvelopeError, LimitError, InstrumentError, RunDirectoryError):
        assert issubclass(cls, BenchError)
    # the drivers' tree is part of it, not a second root
    assert drivers.InstrumentError is InstrumentError
    for name in ("ConnectionLost", "InstrumentTimeout", "ScpiError", "ProtocolError", "SafetyInterlock",
                 "ModbusError", "FrameError", "BlockIntegrityError"):
        assert issubclass(getattr(drivers, name), InstrumentError), name
    assert issubclass(LimitExceeded, LimitError)
    assert config.ConfigError is ConfigurationError
    assert storage.RunDirError is RunDirectoryError and issubclass(storage.DamagedStep, RunDirectoryError)
    # a user's bad value stays a ValueError for code that catches that
    assert issubclass(ConfigurationError, ValueError) and issubclass(RunDirectoryError, ValueError)
    assert errors.__doc__ and "BenchError" in errors.__doc__
