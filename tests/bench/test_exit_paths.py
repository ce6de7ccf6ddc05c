"""Output off on every exit path: normal end, exception, Ctrl-C, SIGTERM, instrument
error, lost connection, safety limit.  Each path runs against the real twins.

The session starts its own twins for a simulated rig; a spy on ``start_twins`` hands the
test the running Twins, whose SCPI model is the instrument's own view of its output.
Faults are injected at the instrument where the twins allow it (a corrupted CAN block, a
dropped or closed SCPI link, a DAQ that stops answering); only the errors that cannot be
provoked from outside (an exception inside the procedure, Ctrl-C at a given moment, an
instrument error reply to a valid command) are injected with pytest-mock.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

import bench.session
from bench.config import DEFAULTS, load_rig, parse_rig
from bench.session import run_plan
from bench.storage import RunStore
from benchtools.plans import FREQS, MANY_FREQS, fast_plan_toml, small_plan
from benchtools.procs import bench_process, driving, event_kinds, meta, rig_toml_for, stop, wait_for
from drivers import ScpiError, ScpiFunctionGenerator, start_twins
from procedures.safety import LimitExceeded, SupervisedGenerator, Supervisor
from procedures.stepped_sine import SteppedSine
from sim.rig import RigModel, SimulatedRig

SIM_RIG = load_rig(DEFAULTS / "sim_rig.toml")


def run(out, plan=None, rig=SIM_RIG, **kw):
    return run_plan(plan or small_plan(), rig, out, sim_seed=1, identify=False, **kw)


def the(out: Path, kind: str) -> dict:
    found = [e for e in RunStore(out).events() if e["event"] == kind]
    assert len(found) == 1, f"expected one {kind!r} event, got {event_kinds(out)}"
    return found[0]


def output_on(spy) -> bool:
    return spy.spy_return.generator.state.output_on


def fail_on_call(mocker, owner, name, n, exc, before=None):
    """Let ``owner.name`` work normally except on its n-th call, which raises ``exc``."""
    original = getattr(owner, name)
    calls = itertools.count(1)

    def side_effect(*args, **kwargs):
        if next(calls) == n:
            if before:
                before()
            raise exc
        return original(*args, **kwargs)

    return mocker.patch.object(owner, name, autospec=True, side_effect=side_effect)


def assert_ended(out: Path, status: str, steps_done: int) -> None:
    m = meta(out)
    assert m["status"] == status
    assert m["steps_done"] == steps_done and m["steps_total"] == len(FREQS)
    assert len(RunStore(out).results()) == steps_done
    last = RunStore(out).events()[-1]
    assert (last["event"], last["status"]) == ("end", status)


# --------------------------------------------------------------------------- normal end

def test_normal_end_completes_with_the_output_off(tmp_path, twins_of_run):
    on_between_steps = []
    run(tmp_path / "run", progress=lambda done, total, note: on_between_steps.append(output_on(twins_of_run)))
    assert on_between_steps[:-1] == [True] * (len(FREQS) - 1)      # it really was driving
    assert not output_on(twins_of_run)
    assert_ended(tmp_path / "run", "completed", len(FREQS))
    assert the(tmp_path / "run", "output_off")["confirmed"] is True


def test_each_run_log_holds_only_its_own_run(tmp_path, caplog, twins_of_run):
    caplog.set_level(logging.INFO)            # as the bench command sets it
    run(tmp_path / "a", plan=small_plan(freqs=(60.0,)))
    url_a = twins_of_run.spy_return.generator_url
    run(tmp_path / "b", plan=small_plan(freqs=(80.0,)))
    url_b = twins_of_run.spy_return.generator_url
    assert url_a != url_b
    log_a = (tmp_path / "a" / "bench.log").read_text()
    log_b = (tmp_path / "b" / "bench.log").read_text()
    assert url_a in log_a and url_b not in log_a
    assert url_b in log_b and url_a not in log_b


# --------------------------------------------------------------------------- exception, Ctrl-C

def test_an_exception_in_the_procedure_propagates_with_the_output_off(tmp_path, mocker, twins_of_run):
    on_at_fault = []
    fail_on_call(mocker, SteppedSine, "measure", 2, RuntimeError("injected fault"),
                 before=lambda: on_at_fault.append(output_on(twins_of_run)))
    with pytest.raises(RuntimeError, match="injected fault"):
        run(tmp_path / "run")
    assert on_at_fault == [True]
    assert not output_on(twins_of_run)
    assert_ended(tmp_path / "run", "failed", 1)
    assert "RuntimeError: injected fault" in the(tmp_path / "run", "error")["error"]
    assert the(tmp_path / "run", "output_off")["confirmed"] is True


def test_ctrl_c_is_recorded_as_interrupted_with_the_output_off(tmp_path, mocker, twins_of_run):
    on_at_fault = []
    fail_on_call(mocker, SteppedSine, "control_force", 3, KeyboardInterrupt(),
                 before=lambda: on_at_fault.append(output_on(twins_of_run)))
    with pytest.raises(KeyboardInterrupt):
        run(tmp_path / "run")
    assert on_at_fault == [True]
    assert not output_on(twins_of_run)
    assert_ended(tmp_path / "run", "interrupted", 2)
    assert the(tmp_path / "run", "interrupted")["reason"] == "Ctrl-C"


def test_ctrl_c_inside_a_generator_query_ends_with_the_output_off_confirmed(tmp_path, mocker, twins_of_run,
                                                                            caplog):
    """The interrupt lands between a query and its reply (issue 19: one in 33 random Ctrl-Cs
    left the reply stream out of step and the output-off unconfirmed).  The ramp-down and
    the off command then go over the same link, resynchronised, with no reconnection."""
    def on_and_mid_sweep():
        return output_on(twins_of_run) and len(RunStore(tmp_path / "run").results()) >= 1
    real = ScpiFunctionGenerator._read_line
    cut = []

    def read_line(self, command):
        if not cut and command == "VOLT?" and on_and_mid_sweep():
            cut.append(command)
            raise KeyboardInterrupt           # the reply to VOLT? stays in the link, unread
        return real(self, command)

    mocker.patch.object(ScpiFunctionGenerator, "_read_line", autospec=True, side_effect=read_line)
    with pytest.raises(KeyboardInterrupt):
        run(tmp_path / "run")
    assert cut == ["VOLT?"]
    assert not output_on(twins_of_run)
    assert the(tmp_path / "run", "output_off")["confirmed"] is True
    assert "ramp-down failed" not in caplog.text and "reconnecting" not in caplog.text
    assert "resynchronising" in caplog.text


def test_a_signal_python_drops_inside_a_finalizer_still_stops_the_run(tmp_path, mocker, twins_of_run,
                                                                      signal_in_a_finalizer):
    # a SIGTERM landing in numba's LLVM finalizers once let a run finish all its steps
    original, calls = SteppedSine.control_force, itertools.count(1)

    def control_force(*args, **kwargs):
        if next(calls) == 3:
            signal_in_a_finalizer(signal.SIGTERM)
        return original(*args, **kwargs)
    mocker.patch.object(SteppedSine, "control_force", autospec=True, side_effect=control_force)
    with pytest.raises(KeyboardInterrupt):
        run(tmp_path / "run")
    assert signal_in_a_finalizer.dropped == [KeyboardInterrupt]    # Python did drop it ...
    assert not output_on(twins_of_run)       # ... and the run still stopped, output off
    m = meta(tmp_path / "run")
    assert m["status"] == "interrupted" and m["steps_done"] < len(FREQS)
    assert the(tmp_path / "run", "interrupted")["reason"] == f"signal {int(signal.SIGTERM)}"


def test_a_second_ctrl_c_during_switch_off_does_not_cut_it_short(tmp_path, mocker, twins_of_run):
    real = bench.session.switch_off
    interrupted_inside = []

    def impatient(gen, url):
        os.kill(os.getpid(), signal.SIGINT)      # the technician presses Ctrl-C again
        time.sleep(0.05)
        interrupted_inside.append(True)          # reached only if the signal did not raise
        return real(gen, url)

    mocker.patch.object(bench.session, "switch_off", side_effect=impatient)
    run(tmp_path / "run")
    assert interrupted_inside == [True]
    assert not output_on(twins_of_run)
    assert the(tmp_path / "run", "output_off")["confirmed"] is True
    assert_ended(tmp_path / "run", "completed", len(FREQS))


def test_a_target_out_of_the_probe_range_stops_before_the_output_goes_on(tmp_path, twins_of_run):
    far = dataclasses.replace(SIM_RIG.model, probe_standoff_m=3.0e-3)       # beyond the 0.1-2.1 mm range
    run(tmp_path / "run", rig=dataclasses.replace(SIM_RIG, model=far))
    assert not output_on(twins_of_run)
    assert "target out of range" in the(tmp_path / "run", "abort")["reason"]
    assert_ended(tmp_path / "run", "aborted", 0)


# --------------------------------------------------------------------------- SIGTERM

@pytest.mark.timeout(120)
def test_sigterm_to_bench_run_stops_cleanly_with_the_output_off(tmp_path):
    # the twins live in this process, so their output state can be read after the kill
    with start_twins(SimulatedRig(RigModel(seed=3))) as twins:
        (tmp_path / "rig.toml").write_text(rig_toml_for(twins))
        freqs = MANY_FREQS                                  # far more steps than it will get to
        (tmp_path / "plan.toml").write_text(fast_plan_toml(freqs))
        out = tmp_path / "run"
        with open(tmp_path / "bench.out", "wb") as log:
            proc = bench_process("run", "--plan", str(tmp_path / "plan.toml"), "--rig", str(tmp_path / "rig.toml"),
                                 "--out", str(out), "--no-report", stdout=log, stderr=subprocess.STDOUT)
            try:
                wait_for(lambda: driving(out, twins), 60, "the first step with the output on", proc)
                proc.send_signal(signal.SIGTERM)
                rc = proc.wait(timeout=30)
            finally:
                stop(proc)
        output = (tmp_path / "bench.out").read_text()
        assert rc == 130, output
        assert not twins.generator.state.output_on, output
        m = meta(out)
        assert m["status"] == "interrupted"
        assert 1 <= m["steps_done"] < len(freqs)
        assert the(out, "interrupted")["reason"] == f"signal {int(signal.SIGTERM)}"
        assert the(out, "output_off")["confirmed"] is True
        assert event_kinds(out)[-1] == "end"
        assert "output off, confirmed by the generator" in output     # the terminal says so too


# --------------------------------------------------------------------------- instrument errors

def test_an_instrument_error_reply_ends_the_run_with_the_output_off(tmp_path, mocker, twins_of_run):
    # the generator refuses the second frequency change, as a real unit does when asked
    # for something it cannot do
    on_at_fault = []
    fail_on_call(mocker, ScpiFunctionGenerator, "set_frequency", 2,
                 ScpiError("FREQ 80", -222, "Data out of range"),
                 before=lambda: on_at_fault.append(output_on(twins_of_run)))
    store = run(tmp_path / "run")
    assert store.path == tmp_path / "run"
    assert on_at_fault == [True]
    assert not output_on(twins_of_run)
    assert_ended(tmp_path / "run", "instrument error", 1)
    error = the(tmp_path / "run", "instrument_error")["error"]
    assert "ScpiError" in error and "-222" in error and "FREQ 80" in error


def test_a_daq_block_that_stays_corrupt_ends_the_run_with_the_output_off(tmp_path, twins_of_run):
    def after_first_step(done, total, note):
        if done == 1:
            for _ in range(3):       # the block and both RESENDs lose their last data frame
                twins_of_run.spy_return.daq.inject_fault(lambda frames: frames[:-1])

    run(tmp_path / "run", progress=after_first_step)
    assert not output_on(twins_of_run)
    assert_ended(tmp_path / "run", "instrument error", 1)
    error = the(tmp_path / "run", "instrument_error")["error"]
    assert error.startswith("BlockIntegrityError") and "2 RESEND" in error


# --------------------------------------------------------------------------- lost connection

@pytest.mark.timeout(60)
def test_a_dropped_generator_link_ends_the_run_and_the_output_is_still_switched_off(tmp_path, twins_of_run):
    # the instrument drops its TCP connections (as on a reboot of its LAN module): the
    # session's link is dead, but the instrument is there and must end up off
    on_when_dropped = []

    def after_first_step(done, total, note):
        if done == 1:
            on_when_dropped.append(output_on(twins_of_run))
            twins_of_run.spy_return.scpi_server.drop_connections()

    run(tmp_path / "run", progress=after_first_step)
    assert on_when_dropped == [True]
    assert_ended(tmp_path / "run", "instrument error", 1)
    assert "ConnectionLost" in the(tmp_path / "run", "instrument_error")["error"]
    assert not output_on(twins_of_run)
    assert the(tmp_path / "run", "output_off")["confirmed"] is True


@pytest.mark.timeout(60)
def test_an_unreachable_generator_ends_the_run_and_says_the_output_is_unconfirmed(tmp_path, twins_of_run):
    # the instrument is gone altogether: nothing can switch it off from here, and the run
    # record must not pretend otherwise (on the real rig the amplifier interlock takes over)
    def after_first_step(done, total, note):
        if done == 1:
            twins_of_run.spy_return.scpi_server.close()

    run(tmp_path / "run", progress=after_first_step)
    assert_ended(tmp_path / "run", "instrument error", 1)
    assert "ConnectionLost" in the(tmp_path / "run", "instrument_error")["error"]
    assert output_on(twins_of_run)                      # the truth at the instrument
    assert the(tmp_path / "run", "output_off")["confirmed"] is False


@pytest.mark.timeout(60)
def test_a_silent_daq_ends_the_run_in_bounded_time_with_the_output_off(tmp_path, twins_of_run):
    def after_first_step(done, total, note):
        if done == 1:
            twins_of_run.spy_return.daq.close()          # the DAQ stops answering

    run(tmp_path / "run", progress=after_first_step)
    assert_ended(tmp_path / "run", "instrument error", 1)
    assert "InstrumentTimeout" in the(tmp_path / "run", "instrument_error")["error"]
    assert not output_on(twins_of_run)
    assert the(tmp_path / "run", "output_off")["confirmed"] is True


# --------------------------------------------------------------------------- safety limit

def test_a_force_limit_trip_aborts_with_the_output_off_and_latched(tmp_path, mocker, twins_of_run):
    # The rig file underestimates the amplifier (10 N/V; the plant has 20 N/V), so the
    # first drive of the 1 N level is twice too large and the force reaches about 2 N.
    # The plan's 1.5 N force limit passes the envelope check (1 N + 25 % margin) and
    # trips in practice.
    trips = mocker.spy(Supervisor, "trip")
    rig = parse_rig({"rig": {**_rig_dict(SIM_RIG), "calibration": {**_calibration(SIM_RIG), "amp_gain_N_per_V": 10.0}}})
    limits = {"drive_V": 7.0, "force_N": 1.5, "disp_m": 0.9e-3, "accel_m_s2": 20.0}
    run(tmp_path / "run", plan=small_plan(limits=limits), rig=rig)

    assert not output_on(twins_of_run)
    assert_ended(tmp_path / "run", "aborted", 0)
    reason = the(tmp_path / "run", "abort")["reason"]
    assert re.fullmatch(r"force [0-9.]+ N exceeds the limit 1.5 N \(force_N\)", reason), reason   # unit and key
    sup = trips.call_args.args[0]
    assert sup.trip_record.reason == "force"
    # the measured peak: above the limit, and no more than the plant can make from the
    # drive asked for (2 N) plus the impedance head's noise
    assert 1.5 < sup.trip_record.value < 2.0 + 5 * RigModel().force_noise_N

    # latched: the tripped supervisor refuses to switch any generator on again, and not
    # a single command reaches the instrument
    with start_twins(SimulatedRig()) as fresh:
        with ScpiFunctionGenerator(fresh.generator_url) as raw:
            state_before = repr(fresh.generator.state)
            with pytest.raises(LimitExceeded, match="output stays off after a trip"):
                SupervisedGenerator(raw, sup).set_output(True)
            assert repr(fresh.generator.state) == state_before
            assert not raw.output_enabled()


def _rig_dict(rig) -> dict:
    return {"name": rig.name, "simulated": True, "calibration": _calibration(rig),
            "limits": {"drive_V": rig.limits.drive_V, "force_N": rig.limits.force_N,
                       "disp_m": rig.limits.disp_m, "accel_m_s2": rig.limits.accel_m_s2},
            "model": rig.model.keys()}


def _calibration(rig) -> dict:
    return {"force_V_per_N": rig.force_V_per_N, "accel_V_per_m_s2": rig.accel_V_per_m_s2,
            "disp_V_per_m": rig.disp_V_per_m, "amp_gain_N_per_V": rig.amp_gain_N_per_V}


# --------------------------------------------------------------------------- what the terminal says

def test_a_resumed_session_stopped_before_the_generator_does_not_claim_an_earlier_sessions_output_off(
        small_run, tmp_path, mocker, capsys):
    # the run directory holds the first session's "output_off confirmed"; the resumed session is
    # interrupted before it opens the generator: the terminal must not repeat the old confirmation
    import shutil

    from bench.cli import main
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run)
    assert any(e.get("event") == "output_off" and e.get("confirmed") for e in RunStore.open(run).events())
    next(iter(sorted((run / "steps").glob("*.json")))).unlink()        # one step to measure again
    mocker.patch("bench.session.open_instruments", side_effect=KeyboardInterrupt)
    assert main(["resume", str(run), "--no-report"]) == 130
    err = capsys.readouterr().err
    assert "output not switched on by this session" in err
    assert "confirmed by the generator" not in err
