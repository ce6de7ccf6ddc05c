"""Driver figures (not pass/fail): SCPI round trip, DAQ block decode, rig vs wall clock.

Run: .venv/bin/python benchmarks/bench_drivers.py
"""

from __future__ import annotations

import importlib.util
import itertools
import logging
import os
import statistics
import sys
import threading
import time
import zlib
from dataclasses import dataclass

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from drivers import CanFdDaq, Channel, ChannelSpec, ScpiFunctionGenerator, open_can_bus  # noqa: E402
from drivers import _daq_codec as codec  # noqa: E402
from drivers._daq_twin import DaqTwin  # noqa: E402
from drivers._scpi_twin_model import ScpiGeneratorModel  # noqa: E402
from drivers._scpi_twin_server import ScpiTcpServer  # noqa: E402

log = logging.getLogger(__name__)

FS_HZ = 25_600.0
N_SAMPLES = 25_600
CHANNELS = (ChannelSpec(Channel.FORCE, 0.0225, "N"),
            ChannelSpec(Channel.ACCELERATION, 0.0102, "m/s^2"),
            ChannelSpec(Channel.DISPLACEMENT, 8000.0, "m"))


@dataclass
class _Block:
    t0_s: float
    fs_Hz: float
    force_V: np.ndarray
    accel_V: np.ndarray
    disp_V: np.ndarray


class _SineRig:
    """Minimal plant for driver figures when sim/rig.py is not there."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.t = 0.0

    def set_generator(self, **kwargs) -> None:
        pass

    def run(self, n: int, fs: float) -> _Block:
        t = self.t + np.arange(n) / fs
        self.t += n / fs
        s = np.sin(2 * np.pi * 100.0 * t)
        return _Block(t[0], fs, s, 0.5 * s, 0.1 * s)

    def gap_m(self) -> float:
        return 1e-3


def _percentile(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q))


def bench_scpi_round_trip(n: int = 2000) -> None:
    server = ScpiTcpServer(ScpiGeneratorModel(_SineRig()))
    gen = ScpiFunctionGenerator(server.url)
    for _ in range(50):
        gen.query("FREQ?")
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        gen.query("FREQ?")
        times.append(time.perf_counter() - t0)
    confirmed = []
    for i in range(200):
        t0 = time.perf_counter()
        gen.set_frequency(100.0 + i)
        confirmed.append(time.perf_counter() - t0)
    gen.close()
    server.close()
    print(f"SCPI query round trip, TCP loopback ({n}x FREQ?): "
          f"median {statistics.median(times) * 1e6:.0f} us, p95 {_percentile(times, 95) * 1e6:.0f} us")
    print(f"SCPI confirmed setting (FREQ + SYST:ERR? + FREQ?): "
          f"median {statistics.median(confirmed) * 1e6:.0f} us, "
          f"p95 {_percentile(confirmed, 95) * 1e6:.0f} us")


def bench_decode(repeats: int = 20) -> None:
    rng = np.random.default_rng(0)
    counts = rng.integers(-2**23 + 1, 2**23, size=(N_SAMPLES, 3), dtype=np.int32)
    payload = codec.pack_samples(counts)
    frames = codec.build_data_frames(payload, 1, N_SAMPLES * 3)
    header = codec.BlockHeader(1, N_SAMPLES, 7, 24, len(frames), zlib.crc32(payload),
                               int(FS_HZ * 1000), 0, 10_000)
    daq = CanFdDaq.__new__(CanFdDaq)
    daq.channels = CHANNELS
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        block = daq._to_block(header, codec.assemble_payload(header, frames), 0)
        times.append(time.perf_counter() - t0)
    assert np.array_equal(codec.volts_to_counts(block.force_V), counts[:, 0])
    best = statistics.median(times)
    print(f"DAQ decode, 3 ch x 25.6 kS/s x 1 s ({len(frames)} CAN FD frames, checks + CRC + "
          f"units): median {best * 1e3:.2f} ms = {1.0 / best:.0f}x real time")


def bench_block_over_virtual_bus(repeats: int = 5) -> None:
    channel = f"bench-{os.getpid()}"
    twin = DaqTwin(_SineRig(), open_can_bus(f"virtual:{channel}"))
    daq = CanFdDaq(open_can_bus(f"virtual:{channel}"), CHANNELS)
    daq.configure(FS_HZ, N_SAMPLES)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        daq.acquire()
        times.append(time.perf_counter() - t0)
    daq.close()
    twin.close()
    print(f"DAQ arm+trigger+read 1 s block through the twin on a virtual bus: "
          f"median {statistics.median(times) * 1e3:.0f} ms "
          f"({1.0 / statistics.median(times):.1f}x real time)")


def bench_rig() -> None:
    if importlib.util.find_spec("sim.rig") is None:
        print("rig 1 s at 25.6 kS/s vs wall: sim/rig.py not available yet, skipped")
        return
    from sim.rig import SimulatedRig
    rig = SimulatedRig()
    rig.set_generator(freq_Hz=100.0, amplitude_Vpp=1.0, output_on=True)
    times = []
    for _ in itertools.repeat(None, 3):
        t0 = time.perf_counter()
        with rig.lock:
            rig.run(N_SAMPLES, FS_HZ)
        times.append(time.perf_counter() - t0)
    wall = statistics.median(times)
    print(f"rig generating 1 s at 25.6 kS/s: median {wall * 1e3:.0f} ms wall "
          f"({1.0 / wall:.1f}x real time; first call incl. JIT {times[0] * 1e3:.0f} ms)")


def main() -> None:
    bench_scpi_round_trip()
    bench_decode()
    bench_block_over_virtual_bus()
    bench_rig()


if __name__ == "__main__":
    main()
