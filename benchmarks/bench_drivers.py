"""Driver figures (not pass/fail): SCPI round trip, DAQ block decode, rig vs wall clock.

Every figure runs against the real plant, ``sim.rig.SimulatedRig`` with its default model.

Run: .venv/bin/python benchmarks/bench_drivers.py
"""

from __future__ import annotations

import logging
import os
import statistics
import sys
import time
import zlib

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from drivers import CanFdDaq, Channel, ChannelSpec, ScpiFunctionGenerator, open_can_bus  # noqa: E402
from drivers import _daq_codec as codec  # noqa: E402
from drivers._daq_twin import DaqTwin  # noqa: E402
from drivers._scpi_twin_model import ScpiGeneratorModel  # noqa: E402
from drivers._scpi_twin_server import ScpiTcpServer  # noqa: E402
from sim.rig import RigModel, SimulatedRig  # noqa: E402

log = logging.getLogger(__name__)

FS_HZ = 25_600.0
N_SAMPLES = 25_600
DRIVE_VPP = 1.0          # 10 N force amplitude with the default amplifier gain
RIG_FREQS_HZ = (40.0, 1000.0)   # below and far above the friction resonance
_MODEL = RigModel()
CHANNELS = (ChannelSpec(Channel.FORCE, _MODEL.force_sens_V_per_N, "N"),
            ChannelSpec(Channel.ACCELERATION, _MODEL.accel_sens_V_per_m_s2, "m/s^2"),
            ChannelSpec(Channel.DISPLACEMENT, _MODEL.disp_sens_V_per_m, "m"))


def _driven_rig(freq_Hz: float) -> SimulatedRig:
    rig = SimulatedRig(_MODEL)
    rig.set_generator(freq_Hz=freq_Hz, amplitude_Vpp=DRIVE_VPP, output_on=True)
    return rig


def _warm_up_kernel() -> float:
    """Compile the plant's kernel once (seconds, on the first run of a process)."""
    t0 = time.perf_counter()
    _driven_rig(1000.0).run(16, FS_HZ)
    return time.perf_counter() - t0


def _percentile(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q))


def bench_scpi_round_trip(n: int = 2000) -> None:
    server = ScpiTcpServer(ScpiGeneratorModel(SimulatedRig(_MODEL)))
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


def bench_block_over_virtual_bus(repeats: int = 5, freq_Hz: float = 1000.0) -> None:
    channel = f"bench-{os.getpid()}"
    twin = DaqTwin(_driven_rig(freq_Hz), open_can_bus(f"virtual:{channel}"))
    daq = CanFdDaq(open_can_bus(f"virtual:{channel}"), CHANNELS)
    daq.configure(FS_HZ, N_SAMPLES)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        daq.acquire()
        times.append(time.perf_counter() - t0)
    daq.close()
    twin.close()
    print(f"DAQ arm+trigger+read 1 s block through the twin on a virtual bus "
          f"(plant driven at {freq_Hz:g} Hz): "
          f"median {statistics.median(times) * 1e3:.0f} ms "
          f"({1.0 / statistics.median(times):.1f}x real time)")


def bench_rig(repeats: int = 5) -> None:
    for freq_Hz in RIG_FREQS_HZ:
        rig = _driven_rig(freq_Hz)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            with rig.lock:
                rig.run(N_SAMPLES, FS_HZ)
            times.append(time.perf_counter() - t0)
        wall = statistics.median(times)
        print(f"rig generating 1 s at 25.6 kS/s, {freq_Hz:g} Hz drive, "
              f"{rig.drive_force()[0]:g} N: median {wall * 1e3:.1f} ms wall, "
              f"p95 {_percentile(times, 95) * 1e3:.1f} ms ({1.0 / wall:.0f}x real time)")


# every effect of decision 0013 on: pitching mode (~200 Hz), velocity-dependent friction,
# cubic spring, viscous damping and a linear spring (bench/defaults/sim_rig_pitch.toml + more)
ALL_EFFECTS = dict(friction_alpha=0.5, friction_v_ref_m_per_s=5e-3, pitch_inertia_kg_m2=0.3,
                   pitch_stiffness_N_m_per_rad=3e5, pitch_damping_N_m_s_per_rad=10.0,
                   drive_height_m=0.2, cg_height_m=0.1, cubic_spring_N_per_m3=1e14,
                   viscous_N_s_per_m=20.0, spring_N_per_m=1e5)


# the electrodynamic shaker of bench/defaults/sim_rig.toml (decision 0025)
SHAKER = dict(shaker_force_constant_N_per_A=15.0, shaker_resistance_ohm=1.5, shaker_inductance_H=0.2e-3,
              shaker_armature_mass_kg=0.3, shaker_suspension_N_per_m=2e4, shaker_damping_N_s_per_m=20.0)


def bench_rig_effects(repeats: int = 5, freq_Hz: float = 1000.0) -> None:
    """Rig generation per simulated second at 1 kHz: plain plant vs the shaker model vs
    every effect on."""
    walls = {}
    for name, model in (("plain", _MODEL), ("shaker", RigModel(**SHAKER)),
                        ("all effects", RigModel(**ALL_EFFECTS, **SHAKER))):
        rig = SimulatedRig(model)
        rig.set_generator(freq_Hz=freq_Hz, amplitude_Vpp=DRIVE_VPP, output_on=True)
        rig.run(16, FS_HZ)            # compile (or load the cache) outside the timing
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            rig.run(N_SAMPLES, FS_HZ)
            times.append(time.perf_counter() - t0)
        walls[name] = statistics.median(times)
    print(f"rig generation per simulated second at {freq_Hz:g} Hz, 25.6 kS/s: plain "
          f"{walls['plain'] * 1e3:.0f} ms, shaker model {walls['shaker'] * 1e3:.0f} ms "
          f"({walls['shaker'] / walls['plain']:.2f}x), pitching mode + every effect + shaker on "
          f"{walls['all effects'] * 1e3:.0f} ms ({walls['all effects'] / walls['plain']:.2f}x the plain "
          f"plant; target <= 1 s)")


def main() -> None:
    print(f"plant kernel JIT compilation (first rig.run of the process): "
          f"{_warm_up_kernel():.1f} s")
    bench_scpi_round_trip()
    bench_decode()
    bench_block_over_virtual_bus()
    bench_rig()
    bench_rig_effects()
    bench_rig_effects(freq_Hz=100.0)


if __name__ == "__main__":
    main()
