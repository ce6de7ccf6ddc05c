"""Soak test: a long plan on the simulated rig while other clients hammer the twins.

    python benchmarks/soak.py [--profile short|full] [--out /tmp/soak] [--identify]
    make soak                    # the full profile (tens of minutes to hours of wall time)

The twins (SCPI generator, Modbus sensor, CAN FD DAQ) run in this process on loopback;
the session drives them as a real rig would (``simulated = false`` with their URLs).  A
second process hammers them meanwhile: SCPI clients sending read-only queries (``*IDN?``,
``FREQ?``, ``VOLT?``, ``OUTP?``; never ``SYST:ERR?``, which would steal the driver's
errors) and several concurrent Modbus clients reading the gap.  Sampled every few
seconds: resident memory and open file descriptors of this process.

Profiles: ``full`` = 10 levels x 100 frequencies x both directions = 2000 steps, >= 2.5 s
settling and 2.5 s measuring each (about 3 h of rig time); ``short`` = 200 steps of
>= 0.3 s + 0.3 s (a few minutes of rig time), for a quick check.

Figures, no pass/fail thresholds of its own; it prints and writes ``<out>/soak.json``:
memory growth after warm-up (median of the last quarter vs the second quarter of the
samples), the open-file range, query latencies (p50/p99/max, first and second half),
answers counted wrong or missing, and whether every step is stored intact.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import shutil
import socket
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

PROFILES = {
    "full": dict(levels=10, freqs=100, min_s=2.5),
    "short": dict(levels=2, freqs=50, min_s=0.3),
}
SCPI_CLIENTS, SCPI_RATE_HZ = 2, 100.0          # per client
MODBUS_CLIENTS, MODBUS_RATE_HZ = 4, 20.0
QUERIES = [b"*IDN?", b"FREQ?", b"VOLT?", b"OUTP?"]


# ---------------------------------------------------------------------------- the hammer

def _paced(rate_Hz: float, stop: mp.Event):
    period, t_next = 1.0 / rate_Hz, time.monotonic()
    while not stop.is_set():
        yield
        t_next += period
        delay = t_next - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        else:
            t_next = time.monotonic()


def _scpi_client(host: str, port: int, stop, out: dict) -> None:
    lat, wrong, n = [], 0, 0
    sock = socket.create_connection((host, port), timeout=5.0)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    f = sock.makefile("rb")
    for _ in _paced(SCPI_RATE_HZ, stop):
        q = QUERIES[n % len(QUERIES)]
        t = time.perf_counter()
        try:
            sock.sendall(q + b"\n")
            reply = f.readline()
        except OSError:
            reply = b""
        lat.append(time.perf_counter() - t)
        n += 1
        ok = reply.endswith(b"\n") and (reply.startswith(b"Keysight") if q == b"*IDN?" else
                                        reply.strip() in (b"0", b"1") if q == b"OUTP?" else _is_float(reply))
        if not ok:
            wrong += 1
            if not reply:                 # connection gone: reconnect, count it
                sock.close()
                sock = socket.create_connection((host, port), timeout=5.0)
                f = sock.makefile("rb")
    sock.close()
    out.update(latency_s=lat, wrong=wrong, n=n)


def _is_float(b: bytes) -> bool:
    try:
        float(b)
        return True
    except ValueError:
        return False


def _modbus_client(url: str, stop, out: dict) -> None:
    from drivers import InstrumentError, ModbusEddySensor
    lat, wrong, n = [], 0, 0
    sensor = ModbusEddySensor(url, timeout_s=2.0)
    for _ in _paced(MODBUS_RATE_HZ, stop):
        t = time.perf_counter()
        try:
            ok = np.isfinite(sensor.read_gap().gap_mm)
        except InstrumentError:
            ok = False
        lat.append(time.perf_counter() - t)
        n += 1
        wrong += not ok
    sensor.close()
    out.update(latency_s=lat, wrong=wrong, n=n)


def hammer(host: str, port: int, sensor_url: str, stop, results) -> None:
    """Runs in its own process: the clients as threads until ``stop`` is set."""
    outs = {f"scpi{i}": {} for i in range(SCPI_CLIENTS)} | {f"modbus{i}": {} for i in range(MODBUS_CLIENTS)}
    threads = [threading.Thread(target=_scpi_client, args=(host, port, stop, outs[k])) for k in outs if k[0] == "s"]
    threads += [threading.Thread(target=_modbus_client, args=(sensor_url, stop, outs[k])) for k in outs if k[0] == "m"]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    results.put(outs)


# ---------------------------------------------------------------------------- monitoring

def rss_MB() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def open_files() -> int:
    return len(os.listdir("/proc/self/fd"))


class Sampler(threading.Thread):
    def __init__(self, steps_dir: Path, every_s: float):
        super().__init__(daemon=True)
        self.steps_dir, self.every_s, self.stop = steps_dir, every_s, threading.Event()
        self.samples: list[tuple[float, float, int, int]] = []      # time, RSS MB, fds, steps

    def run(self):
        t0 = time.monotonic()
        while not self.stop.wait(self.every_s):
            steps = len(list(self.steps_dir.glob("*.json"))) if self.steps_dir.is_dir() else 0
            self.samples.append((time.monotonic() - t0, rss_MB(), open_files(), steps))


def _percentiles(lat: list[float]) -> dict:
    a = np.asarray(lat) * 1e3
    if a.size == 0:
        return dict(n=0)
    return dict(n=int(a.size), p50_ms=float(np.percentile(a, 50)), p99_ms=float(np.percentile(a, 99)),
                max_ms=float(a.max()))


def soak_plan(profile: dict):
    from bench.config import parse_plan
    levels = np.geomspace(0.3, 10.0, profile["levels"]).round(3).tolist()
    return parse_plan({"plan": {
        "name": f"soak: {profile['levels']} levels x {profile['freqs']} frequencies x both",
        "levels_N": levels,
        "frequencies": {"start_Hz": 20.0, "stop_Hz": 400.0, "points": profile["freqs"], "spacing": "log",
                        "direction": "both"},
        "control": {"min_settle_s": profile["min_s"], "min_measure_s": profile["min_s"], "harmonics": 5}}},
        "soak plan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", choices=sorted(PROFILES), default="full")
    ap.add_argument("--out", default="/tmp/soak")
    ap.add_argument("--identify", action="store_true", help="online identification on (off: the drivers and storage only)")
    ap.add_argument("--sample-s", type=float, default=5.0)
    a = ap.parse_args()

    from bench.config import DEFAULTS, load_rig
    from bench.session import run_plan
    from drivers import start_twins
    from sim.rig import SimulatedRig

    out = Path(a.out)
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    plan = soak_plan(PROFILES[a.profile])
    sim_rig = load_rig(DEFAULTS / "sim_rig.toml")
    twins = start_twins(SimulatedRig(sim_rig.model))
    rig = replace(sim_rig, simulated=False, model={}, generator_url=twins.generator_url,
                  sensor_url=twins.sensor_url, daq_url=twins.daq_url)
    host, port = twins.generator_url.removeprefix("socket://").split(":")
    print(f"soak ({a.profile}): {len(plan.schedule())} steps; twins at {twins.generator_url}, {twins.sensor_url}; "
          f"{SCPI_CLIENTS} SCPI clients x {SCPI_RATE_HZ:g} q/s, {MODBUS_CLIENTS} Modbus clients x {MODBUS_RATE_HZ:g} q/s")

    ctx = mp.get_context("spawn")
    stop, results = ctx.Event(), ctx.Queue()
    proc = ctx.Process(target=hammer, args=(host, int(port), twins.sensor_url, stop, results), daemon=True)
    proc.start()
    sampler = Sampler(out / "run" / "steps", a.sample_s)
    sampler.start()
    t0 = time.perf_counter()
    try:
        store = run_plan(plan, rig, out / "run", identify=a.identify)
    except KeyboardInterrupt:             # Ctrl-C: the figures so far are still printed
        from bench.storage import RunStore
        store = RunStore.open(out / "run")
    finally:
        wall = time.perf_counter() - t0
        sampler.stop.set()
        stop.set()
        clients = results.get(timeout=120)
        proc.join(timeout=30)
        twins.close()

    res = store.results()
    last = res[-1] if res else None
    rig_time = last["t0_s"] + last["n_samples"] / last["fs_Hz"] if last else 0.0
    problems = store.check()
    s = np.array(sampler.samples) if sampler.samples else np.zeros((0, 4))
    q = len(s) // 4
    rss_2nd, rss_last = (float(np.median(s[q:2 * q, 1])), float(np.median(s[-q:, 1]))) if q else (np.nan, np.nan)
    fds = s[q:, 2] if q else s[:, 2]
    report = {
        "profile": a.profile, "identify": a.identify, "steps_planned": len(plan.schedule()),
        "steps_stored_intact": len(res), "status": store.metadata["status"], "check_problems": [str(p) for p in problems],
        "wall_s": wall, "rig_time_s": rig_time,
        "rss_MB": {"second_quarter_median": rss_2nd, "last_quarter_median": rss_last,
                   "growth_MB": rss_last - rss_2nd, "max": float(s[:, 1].max()) if len(s) else np.nan},
        "open_files": {"min_after_warmup": int(fds.min()) if len(fds) else -1,
                       "max_after_warmup": int(fds.max()) if len(fds) else -1},
        "clients": {},
        "samples": s.tolist(),
    }
    for kind in ("scpi", "modbus"):
        group = [v for k, v in clients.items() if k.startswith(kind)]
        lat = [x for v in group for x in v["latency_s"]]
        half = [v["latency_s"] for v in group]
        report["clients"][kind] = dict(
            clients=len(group), queries=sum(v["n"] for v in group), wrong_or_missing=sum(v["wrong"] for v in group),
            all=_percentiles(lat),
            first_half=_percentiles([x for h in half for x in h[:len(h) // 2]]),
            second_half=_percentiles([x for h in half for x in h[len(h) // 2:]]))
    (out / "soak.json").write_text(json.dumps(report, indent=1))

    print(f"run {report['status']}: {len(res)}/{len(plan.schedule())} steps stored intact "
          f"(bench check: {len(problems)} problems); {wall:.0f} s wall for {rig_time:.0f} s "
          f"({rig_time / 3600:.2f} h) of rig time")
    r = report["rss_MB"]
    print(f"resident memory: {r['second_quarter_median']:.1f} MB (2nd quarter) -> {r['last_quarter_median']:.1f} MB "
          f"(last quarter), growth {r['growth_MB']:+.1f} MB, max {r['max']:.1f} MB; open files "
          f"{report['open_files']['min_after_warmup']}-{report['open_files']['max_after_warmup']} after warm-up")
    for kind, c in report["clients"].items():
        print(f"{kind}: {c['clients']} clients, {c['queries']} queries, {c['wrong_or_missing']} wrong or missing; "
              f"latency p50 {c['all'].get('p50_ms', np.nan):.2f} ms, p99 {c['all'].get('p99_ms', np.nan):.2f} ms "
              f"(first half {c['first_half'].get('p99_ms', np.nan):.2f}, second half "
              f"{c['second_half'].get('p99_ms', np.nan):.2f}), max {c['all'].get('max_ms', np.nan):.1f} ms")
    print(f"figures: {out / 'soak.json'}")


if __name__ == "__main__":
    main()
