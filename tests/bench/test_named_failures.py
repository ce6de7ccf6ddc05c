"""Instrument and storage failures are named, with the output off (issue 24 item 5): a DAQ
link lost mid-run is the bench's instrument error naming the DAQ, not an internal error;
a full disk or a deleted steps/ is a named storage error, not a traceback; a resume that
could not store a step fails before the output goes on."""

from __future__ import annotations

import errno
import shutil
import socket
import threading

import pytest

import bench.session
import bench.storage
from bench.cli import main
from bench.storage import RunStore
from benchtools.plans import FREQS, small_plan
from benchtools.procs import meta, rig_toml_for
from drivers import start_twins
from drivers._can_transport import CanTcpBridge, TcpCanBus
from sim.errors import StorageError
from sim.rig import RigModel, SimulatedRig

from .test_exit_paths import SIM_RIG, fail_on_call, output_on, run, the


def plan_toml(tmp_path):
    p = tmp_path / "plan.toml"
    p.write_text(f"""[plan]
levels_N = [1.0]
[plan.frequencies]
list_Hz = {[40.0 + 10 * k for k in range(30)]}
[plan.control]
settle_cycles = 4
min_settle_s = 0.0
measure_cycles = 4
control_cycles = 2
ramp_s = 0.0
""")
    return p


class ResetSocket:
    """The DAQ link's socket after the peer reset it (fault injection: the reset itself)."""

    def __init__(self, sock):
        self._sock = sock

    def recv(self, n):
        raise ConnectionResetError(errno.ECONNRESET, "Connection reset by peer")

    def __getattr__(self, name):
        return getattr(self._sock, name)


@pytest.mark.timeout(90)
@pytest.mark.parametrize("how", ["reset by the peer", "closed by the DAQ"])
def test_a_lost_daq_link_is_an_instrument_error_naming_the_daq(tmp_path, mocker, capsys, how):
    bridges = mocker.spy(CanTcpBridge, "__init__")
    clients = mocker.spy(TcpCanBus, "__init__")
    with start_twins(SimulatedRig(RigModel(seed=3))) as twins:
        bridge = bridges.call_args.args[0]
        (tmp_path / "rig.toml").write_text(rig_toml_for(twins))
        out = tmp_path / "run"

        def cut_after_the_first_step():
            while not (out / "steps").is_dir() or not any((out / "steps").glob("*.json")):
                if done.wait(0.01):
                    return
            if how == "reset by the peer":
                client = clients.call_args.args[0]
                client._sock = ResetSocket(client._sock)
            else:
                with bridge._lock:
                    links = list(bridge._links)
                for conn, _ in links:
                    conn.shutdown(socket.SHUT_RDWR)
        done = threading.Event()
        cutter = threading.Thread(target=cut_after_the_first_step, daemon=True)
        cutter.start()
        try:
            code = main(["run", "--plan", str(plan_toml(tmp_path)), "--rig", str(tmp_path / "rig.toml"),
                         "--out", str(out), "--no-report"])
        finally:
            done.set()
            cutter.join()
        assert not twins.generator.state.output_on
    err = capsys.readouterr().err
    assert code == 1, err
    assert meta(out)["status"] == "instrument error"
    error = the(out, "instrument_error")["error"]
    assert error.startswith("ConnectionLost: DAQ at tcp://127.0.0.1:"), error
    assert ("Connection reset by peer" if how == "reset by the peer" else "connection closed") in error
    assert the(out, "output_off")["confirmed"] is True
    assert "internal error" not in err and "Traceback" not in err
    assert "output off, confirmed by the generator" in err


def test_a_full_disk_is_a_named_storage_error_with_the_output_off(tmp_path, mocker, capsys, twins_of_run):
    on_at_fault = []
    real = bench.storage.atomic_write
    calls = []

    def atomic_write(path, write):
        if path.suffix == ".npz":
            calls.append(path)
            if len(calls) == 2:
                on_at_fault.append(output_on(twins_of_run))
                raise OSError(errno.ENOSPC, "No space left on device", str(path) + ".tmp")
        return real(path, write)
    mocker.patch.object(bench.storage, "atomic_write", side_effect=atomic_write)
    plan = tmp_path / "plan.toml"
    plan.write_text(f"""[plan]
levels_N = [1.0]
[plan.frequencies]
list_Hz = {list(FREQS)}
direction = "up"
[plan.control]
settle_cycles = 4
min_settle_s = 0.0
measure_cycles = 4
control_cycles = 2
ramp_s = 0.0
""")
    out = tmp_path / "run"
    assert main(["run", "--plan", str(plan), "--out", str(out), "--no-report"]) == 1
    err = capsys.readouterr().err
    assert on_at_fault == [True]
    assert not output_on(twins_of_run)
    assert the(out, "output_off")["confirmed"] is True
    assert f"StorageError: {calls[1]}: cannot write: No space left on device" in err
    assert "Traceback" not in err and "internal error" not in err
    assert meta(out)["status"] == "failed" and meta(out)["steps_done"] == 1
    assert "No space left on device" in the(out, "storage_error")["error"]


def test_a_steps_directory_deleted_mid_run_is_a_named_storage_error(tmp_path, twins_of_run):
    def delete_steps(done, total, note):
        if done == 1:
            shutil.rmtree(tmp_path / "run" / "steps")
    with pytest.raises(StorageError, match=r"steps: missing \(deleted while the run was using it\?\)"):
        run(tmp_path / "run", progress=delete_steps)
    assert not output_on(twins_of_run)
    assert the(tmp_path / "run", "output_off")["confirmed"] is True
    assert meta(tmp_path / "run")["status"] == "failed"


def test_resume_with_steps_deleted_fails_before_the_output_goes_on(small_run, tmp_path, mocker, capsys):
    twins = mocker.spy(bench.session, "start_twins")
    copy = tmp_path / "run"
    shutil.copytree(small_run.path, copy)
    shutil.rmtree(copy / "steps")
    events_before = len(RunStore(copy).events())
    assert main(["resume", str(copy), "--no-report"]) == 1
    err = capsys.readouterr().err
    assert twins.call_count == 0                       # no instrument opened, nothing switched on
    assert f"StorageError: {copy / 'steps'}: missing" in err and "Traceback" not in err
    assert "output not switched on by this session" in err
    new = RunStore(copy).events()[events_before:]
    assert "output_off" not in [e["event"] for e in new]
    assert meta(copy)["status"] == "failed"


def test_the_probe_of_a_full_disk_is_a_named_storage_error_and_leaves_nothing(tmp_path, mocker):
    store = RunStore.create(tmp_path / "run", {"plan": small_plan().to_dict(), "rig": SIM_RIG.to_dict()})
    fail_on_call(mocker, bench.storage.os, "write", 1, OSError(errno.ENOSPC, "No space left on device"))
    with pytest.raises(StorageError, match=r"\.probe-\d+\.tmp: cannot write: No space left on device"):
        store.check_writable()
    assert not list((tmp_path / "run" / "steps").iterdir())          # the probe file is gone
