"""The watch page: served on loopback, read from the run directory, refuses a stop without
the token, and its stop button stops a run in another process the way Ctrl-C does.

The end-to-end test runs ``bench run --watch`` in a subprocess against twins held by this
process (so the generator's output state is read from the instrument's own model, not from
what the run says about it), opens the page in headless Chromium and presses the button.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import threading
import urllib.error
import urllib.request
from datetime import datetime
from pathlib import Path

import pytest

import bench.session
from bench.config import DEFAULTS, load_rig
from bench.session import run_plan
from bench.storage import RunStore
from bench.watch import WatchServer, serve
from bench.watch.snapshot import RunReader
from bench.watch.stop import STOP_FILE, request_stop
from benchtools.plans import fast_plan_toml, small_plan
from benchtools.procs import bench_process, rig_toml_for, wait_for
from drivers import start_twins
from sim.rig import RigModel, SimulatedRig

from .chromium import CHROMIUM, Browser


def post_stop(server: WatchServer, token: str | None, host: str | None = None) -> tuple[int, dict]:
    headers = {} if token is None else {"X-Stop-Token": token}
    if host:
        headers["Host"] = host
    req = urllib.request.Request(server.url.split("?")[0] + "api/stop", method="POST", headers=headers)
    try:
        with urllib.request.urlopen(req, timeout=5) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def get_json(server: WatchServer, path: str, token: str | None = "") -> dict | tuple[int, dict]:
    """The JSON at ``path`` with the server's token; with ``token`` given (None: none at
    all), the HTTP status and the body."""
    query = f"?token={server.token if token == '' else token}" if token is not None else ""
    try:
        with urllib.request.urlopen(server.url.split("?")[0] + path + query, timeout=5) as r:
            body = json.loads(r.read())
            return body if token == "" else (r.status, body)
    except urllib.error.HTTPError as e:
        if token == "":
            raise
        return e.code, json.loads(e.read())


def listening_addresses(port: int) -> set[str]:
    """Local addresses of the sockets listening on ``port`` in any process (/proc/net)."""
    out = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except FileNotFoundError:
            continue
        for line in lines:
            local, state = line.split()[1], line.split()[3]
            addr, p = local.split(":")
            if state == "0A" and int(p, 16) == port:
                out.add(addr)
    return out


LOOPBACK_HEX = "0100007F"      # 127.0.0.1 as /proc/net/tcp writes it


# --------------------------------------------------------------------------- the server


def test_the_server_binds_to_loopback_by_default(small_run):
    with serve(small_run.path) as server:
        assert server.socket.getsockname()[0] == "127.0.0.1"
        assert listening_addresses(server.server_address[1]) == {LOOPBACK_HEX}
        assert server.url.startswith(f"http://127.0.0.1:{server.server_address[1]}/?token=")


def test_a_stop_without_or_with_a_wrong_token_is_refused_and_writes_nothing(tmp_path, small_run):
    run = tmp_path / "run"
    run.mkdir()
    meta = dict(small_run.metadata, status="running")      # as a running run's directory says
    (run / "run.json").write_text(json.dumps(meta))
    with serve(run) as server:
        assert post_stop(server, None)[0] == 403
        assert post_stop(server, "")[0] == 403
        assert post_stop(server, server.token[:-1] + ("x" if server.token[-1] != "x" else "y"))[0] == 403
        assert post_stop(server, server.token, host="evil.example:80")[0] == 403   # DNS rebinding
        assert not (run / STOP_FILE).exists()
        code, body = post_stop(server, server.token)
        assert code == 202
        assert json.loads((run / STOP_FILE).read_text())["by"].startswith("the watch page")


def test_a_stop_for_a_finished_run_is_refused(small_run):
    with serve(small_run.path) as server:
        code, body = post_stop(server, server.token)
    assert code == 409 and "completed" in body["error"]
    assert not (small_run.path / STOP_FILE).exists()


def test_the_state_counts_what_the_run_directory_holds(small_run):
    steps = sorted(small_run.steps_dir.glob("*.json"))
    with serve(small_run.path) as server:
        state = get_json(server, "api/state")
        js = urllib.request.urlopen(server.url.split("?")[0] + "plotly.min.js", timeout=5).read()
    assert state["status"] == "completed"
    assert state["progress"]["done"] == state["progress"]["total"] == len(steps)
    series = state["compliance"]
    assert sum(len(c["freq_Hz"]) for c in series) == len(steps)
    assert {(c["level_N"], c["direction"]) for c in series} == {(1.0, "up"), (1.0, "down"), (5.0, "up"), (5.0, "down")}
    one = json.loads(steps[0].read_text())
    c = next(c for c in series if one["key"] in c["key"])
    assert c["abs_m_per_N"][c["key"].index(one["key"])] == pytest.approx(one["compliance_abs_m_per_N"])
    assert len(state["identification"]["history"]) == len(steps)
    # one voltage convention (decision record 0029): the drive is the generator's amplitude, Vpp/2
    last = json.loads(steps[-1].read_text())
    assert state["last_step"]["drive_V"] == pytest.approx(last["drive_Vpp"] / 2)
    assert b"plotly" in js[:2000] and len(js) > 1_000_000        # the package's own bundle


def test_the_reader_waits_for_a_run_that_has_not_started_and_skips_a_torn_event_line(tmp_path, small_run):
    reader = RunReader(tmp_path / "run")
    assert reader.snapshot()["status"] == "waiting"
    run = tmp_path / "run"
    run.mkdir()
    (run / "run.json").write_text(json.dumps(dict(small_run.metadata, status="running")))
    (run / "events.jsonl").write_text('{"time": "2026-11-22T10:00:00+00:00", "event": "start"}\n{"time": "2026-1')
    state = reader.snapshot()
    assert state["status"] == "running" and [e["event"] for e in state["events"]] == ["start"]
    assert state["progress"]["done"] == 0 and state["next_step"]["key"].startswith("00000-")


def test_the_eta_is_the_time_per_step_since_the_first_step_times_the_steps_left(tmp_path, small_run):
    run = tmp_path / "run"
    (run / "steps").mkdir(parents=True)
    (run / "run.json").write_text(json.dumps(dict(small_run.metadata, status="running")))
    (run / "events.jsonl").write_text(json.dumps({"time": "2027-01-15T08:00:00+00:00", "event": "start"}) + "\n")
    t0 = datetime.fromisoformat("2027-01-15T08:00:00+00:00").timestamp()
    for k, src in enumerate(sorted(small_run.steps_dir.glob("*.json"))[:3]):
        dst = run / "steps" / src.name
        dst.write_text(src.read_text())
        os.utime(dst, (t0 + 30 + 2 * k, t0 + 30 + 2 * k))     # 30 s set-up, then 2 s per step
    p = RunReader(run).snapshot()["progress"]
    assert (p["done"], p["total"]) == (3, 20)
    assert p["per_step_s"] == pytest.approx(2.0)
    assert p["eta_s"] == pytest.approx(2.0 * 17)


def test_a_running_run_whose_process_is_gone_is_shown_stalled_and_cannot_be_stopped(tmp_path, small_run):
    gone = subprocess.Popen(["true"])
    gone.wait()                                   # its pid now names no process
    run = tmp_path / "run"
    run.mkdir()
    meta = dict(small_run.metadata, status="running", process={"pid": gone.pid, "host": socket.gethostname()})
    (run / "run.json").write_text(json.dumps(meta))
    assert RunReader(run).snapshot()["process_gone"] is True
    with serve(run) as server:
        code, body = post_stop(server, server.token)
    assert code == 409 and "process gone" in body["error"]
    meta["process"]["pid"] = os.getpid()          # alive
    (run / "run.json").write_text(json.dumps(meta))
    assert RunReader(run).snapshot()["process_gone"] is False


# --------------------------------------------------------------------------- the session's side


def test_a_stop_request_takes_the_ctrl_c_path_ramping_down_with_the_output_off(tmp_path, mocker):
    twins_spy = mocker.spy(bench.session, "start_twins")
    out = tmp_path / "run"
    amplitudes_after_request: list[str] = []

    def progress(done, total, note):
        if done == 2:
            request_stop(out, by="the test")
            model = twins_spy.spy_return.generator
            real = model.execute

            def recording(line):       # the instrument's own log of what it was told
                amplitudes_after_request.append(line)
                return real(line)
            model.execute = recording

    with pytest.raises(KeyboardInterrupt):
        run_plan(small_plan(freqs=(60.0, 80.0, 100.0, 120.0, 140.0)), load_rig(DEFAULTS / "sim_rig.toml"), out,
                 sim_seed=1, identify=False, progress=progress)
    meta = RunStore(out).metadata
    events = RunStore(out).events()
    assert meta["status"] == "interrupted" and meta["steps_done"] == 2
    assert [e for e in events if e["event"] == "interrupted"][0]["reason"] == "stop requested by the test"
    assert [e for e in events if e["event"] == "output_off"][0]["confirmed"] is True
    assert not twins_spy.spy_return.generator.state.output_on
    assert not (out / STOP_FILE).exists()                    # consumed: a resume is not stopped by it
    volts = [float(line.split()[1]) for line in amplitudes_after_request if re.match(r"VOLT [0-9.eE+-]+$", line)]
    off = next(i for i, line in enumerate(amplitudes_after_request) if line.startswith("OUTP OFF"))
    ramp = [line for line in amplitudes_after_request[:off] if line.startswith("VOLT ")]
    assert len(ramp) >= 3 and volts[:len(ramp)] == sorted(volts[:len(ramp)], reverse=True)


def test_a_stop_request_left_from_an_earlier_session_does_not_stop_a_resume(tmp_path):
    out = tmp_path / "run"
    plan, rig = small_plan(freqs=(60.0, 80.0)), load_rig(DEFAULTS / "sim_rig.toml")
    with pytest.raises(KeyboardInterrupt):
        run_plan(plan, rig, out, sim_seed=1, identify=False,
                 progress=lambda done, total, note: done == 1 and request_stop(out, by="the test"))
    request_stop(out, by="a page after the run had ended")      # stale
    store = run_plan(plan, rig, out, resume=True, sim_seed=1, identify=False)
    assert store.metadata["status"] == "completed" and store.metadata["steps_done"] == 2


# --------------------------------------------------------------------------- end to end in Chromium


def test_the_runs_data_need_the_token_and_the_refusal_says_which_link_to_open(small_run):
    with serve(small_run.path) as server:
        with urllib.request.urlopen(server.url.split("?")[0], timeout=5) as r:
            assert r.status == 200 and b"<html" in r.read()            # the page itself: no token needed
        for path in ("api/state", "api/stream"):
            code, body = get_json(server, path, token=None)
            assert code == 403 and "has no token" in body["error"] and "bench watch" in body["error"]
            code, body = get_json(server, path, token="not-" + server.token)
            assert code == 403 and "not this server's" in body["error"]
        assert get_json(server, "api/state", token=server.token)[0] == 200


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (make setup)")
def test_the_stop_button_works_only_with_the_token_and_while_the_run_runs(tmp_path, small_run):
    run = tmp_path / "run"
    run.mkdir()
    meta = dict(small_run.metadata, status="running", process={"pid": os.getpid(), "host": socket.gethostname()})
    (run / "run.json").write_text(json.dumps(meta))
    enabled = "document.getElementById('status').textContent !== 'connecting' && !document.getElementById('stop').disabled"
    access = "!document.getElementById('access').hidden && document.getElementById('access').textContent"
    with serve(run) as server, Browser() as browser:
        browser.goto(server.url.split("?")[0])                     # no token: says which link to open
        shown = browser.wait_for(access, 30, "the page to say the token is needed")
        assert "has no token" in shown and "?token=" in shown and "bench watch" in shown
        assert browser.js("document.getElementById('status').textContent") == "token needed"
        assert browser.js(enabled) is False
        assert browser.js("document.getElementById('current').textContent") == ""   # no run data shown
        browser.goto(server.url.replace("?token=", "?token=old"))  # an earlier server's link
        assert "not this server's" in browser.wait_for(access, 30, "the page to refuse a wrong token")
        browser.goto(server.url)
        browser.wait_for("document.getElementById('access').hidden", 30, "no refusal with the token")
        browser.wait_for(enabled, 30, "the stop button enabled with the token")
        (run / "run.json").write_text(json.dumps(dict(meta, status="completed")))   # the run ends
        browser.wait_for("document.getElementById('status').textContent === 'completed'", 30, "the end")
        assert browser.js(enabled) is False
    assert not (run / STOP_FILE).exists()


class PacedRig(SimulatedRig):
    """The plant holds the measured block of step ``hold_at`` (its ``SIM:STEP`` mark) until
    the test releases it: the DAQ twin reports itself busy meanwhile, which the driver
    waits for (up to its max_busy_s), so the run waits on the test, not the reverse."""

    def __init__(self, model, hold_at: int):
        super().__init__(model)
        self.hold_at, self.marks = hold_at, 0
        self.held, self.release = threading.Event(), threading.Event()

    def mark(self, line: str) -> None:
        if "SIM:STEP" in line.upper() or "SIMULATION:STEP" in line.upper():
            self.marks += 1

    def run(self, *args, **kw):
        if self.marks >= self.hold_at and not self.release.is_set():
            self.held.set()
            self.release.wait(45)            # below the driver's max_busy_s (60 s)
        return super().run(*args, **kw)


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (make setup)")
@pytest.mark.timeout(240)        # about 10 s; the waits are long for a machine under heavy load
def test_the_page_shows_a_running_test_and_its_stop_button_stops_it_safely(tmp_path):
    rig = PacedRig(RigModel(seed=5), hold_at=4)        # steps 1-3 done, step 4 held
    with start_twins(rig) as twins:
        execute = twins.generator.execute
        twins.generator.execute = lambda line: (rig.mark(line), execute(line))[1]
        (tmp_path / "rig.toml").write_text(rig_toml_for(twins))
        freqs = [40.0 + 10 * k for k in range(8)]
        (tmp_path / "plan.toml").write_text(fast_plan_toml(freqs))
        out = tmp_path / "run"
        with Browser() as browser, open(tmp_path / "bench.out", "wb") as log:
            proc = bench_process("run", "--plan", str(tmp_path / "plan.toml"), "--rig", str(tmp_path / "rig.toml"),
                                 "--out", str(out), "--no-report", "--watch", stdout=log, stderr=subprocess.STDOUT)
            try:
                def url():
                    m = re.search(rb"watch: (http://\S+)", (tmp_path / "bench.out").read_bytes())
                    return m.group(1).decode() if m else None
                wait_for(url, 60, "the watch URL", proc)
                port = int(re.search(r":(\d+)/", url()).group(1))
                assert url().startswith(f"http://127.0.0.1:{port}/?token=")
                assert listening_addresses(port) == {LOOPBACK_HEX}
                browser.goto(url())
                points = "Number(document.getElementById('compliance').dataset.points || 0)"
                browser.wait_for(f"{points} >= 1 && {points}", 60, "a first point on the compliance plot")
                wait_for(rig.held.is_set, 60, "the run to reach the held step", proc)
                assert browser.wait_for(f"{points} === 3 && {points}", 60, "the three steps done") == 3
                assert browser.js("document.getElementById('compliance').data.length") >= 2   # |x/P| and phase
                assert browser.js("document.getElementById('status').textContent") == "running"
                current = browser.js("document.getElementById('current').textContent")
                assert re.search(r"drive[0-9.]+ V amplitude", current) and "Vpp" not in current, current
                browser.wait_for("!document.getElementById('stop').disabled", 10, "the stop button")
                browser.click("#stop")
                wait_for((out / STOP_FILE).exists, 30, "the stop request from the page", proc)
                rig.release.set()                               # the held block completes
                rc = proc.wait(timeout=60)
                final = browser.wait_for("['interrupted'].includes(document.getElementById('status').textContent)"
                                         " && document.getElementById('status').textContent", 30,
                                         "the page to show the run interrupted")
                assert final == "interrupted"
                assert "stop requested by the watch page" in browser.js("document.getElementById('events').textContent")
                shown = browser.js(points)
            except BaseException:
                print((tmp_path / "bench.out").read_text()[-4000:])     # shown by pytest on failure
                raise
            finally:
                rig.release.set()
                if proc.poll() is None:
                    proc.send_signal(signal.SIGTERM)
                    proc.wait(timeout=30)
        output = (tmp_path / "bench.out").read_text()
        assert rc == 130, output                               # as Ctrl-C
        assert not twins.generator.state.output_on, output     # the instrument says so
        meta = json.loads((out / "run.json").read_text())
        events = RunStore(out).events()
        assert meta["status"] == "interrupted", output
        assert meta["steps_done"] in (3, 4)                    # the held step may still complete
        assert shown == meta["steps_done"]                     # the page kept the final state
        assert [e["reason"] for e in events if e["event"] == "interrupted"] == \
            ["stop requested by the watch page (127.0.0.1)"]
        assert [e["confirmed"] for e in events if e["event"] == "output_off"] == [True]
        assert events[-1]["event"] == "end" and events[-1]["status"] == "interrupted"


# --------------------------------------------------------------------------- bench watch, another process


@pytest.mark.timeout(120)
def test_bench_watch_follows_a_run_in_another_process_through_a_stop_and_a_resume(tmp_path):
    out = tmp_path / "run"               # not there yet: bench watch waits for the run to create it
    with open(tmp_path / "watch.out", "wb") as log:
        proc = bench_process("watch", str(out), stdout=log, stderr=subprocess.STDOUT)
    try:
        def url():
            m = re.search(rb"watch: (http://\S+)", (tmp_path / "watch.out").read_bytes())
            return m.group(1).decode() if m else None
        wait_for(url, 30, "the watch URL", proc)
        base, token = url().split("?token=")
        assert base.startswith("http://127.0.0.1:")
        assert listening_addresses(int(base.rsplit(":", 1)[1].strip("/"))) == {LOOPBACK_HEX}

        def state():
            with urllib.request.urlopen(base + f"api/state?token={token}", timeout=5) as r:
                return json.loads(r.read())
        assert state()["status"] == "waiting"
        assert f"waiting for {out} to appear ... (Ctrl-C stops)" in (tmp_path / "watch.out").read_text()

        seen = []

        def stop_from_the_page(done, total, note):
            seen.append(state()["progress"]["done"])
            if done == 2:
                req = urllib.request.Request(base + "api/stop", method="POST", headers={"X-Stop-Token": token})
                with urllib.request.urlopen(req, timeout=5) as r:
                    assert r.status == 202

        plan, rig = small_plan(freqs=(60.0, 80.0, 100.0, 120.0)), load_rig(DEFAULTS / "sim_rig.toml")
        with pytest.raises(KeyboardInterrupt):
            run_plan(plan, rig, out, sim_seed=1, identify=False, progress=stop_from_the_page)
        assert seen == [1, 2]                  # each step visible as soon as it is stored
        s = state()
        assert (s["status"], s["progress"]["done"], s["progress"]["total"]) == ("interrupted", 2, 4)
        assert sum(len(c["freq_Hz"]) for c in s["compliance"]) == 2

        run_plan(plan, rig, out, resume=True, sim_seed=1, identify=False)
        s = state()
        assert (s["status"], s["progress"]["done"]) == ("completed", 4)
        assert [e["event"] for e in s["events"]].count("resume") == 1
        assert sum(len(c["freq_Hz"]) for c in s["compliance"]) == 4
        assert proc.poll() is None             # the page outlives the runs it shows
        assert f"{out} appeared" in (tmp_path / "watch.out").read_text()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)                  # generous: CI machines are shared
    assert proc.returncode == 0
