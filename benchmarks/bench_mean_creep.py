"""Why a 100 N step of the demo drifts: the carriage's mean position relaxing (decision 0037).

The demo rig's plant (bench/defaults/sim_rig.toml, noise off) is driven at a force amplitude
near 100 N until steady; a short DC force (``--dc-V`` through the amplifier, 4 periods)
pushes the carriage's mean position aside, and the per-period mean of the displacement
afterwards, minus that of the same run without the pulse, is fitted with A exp(-r t) (r
scanned); "undone" is the share of the push the mean has come back by 0.3 s later (no model).  Printed beside
it: the rate the shaker suspension k_a gives against a sliding friction acting on a mean
velocity like a damper, k_a / (2 F_s/(pi V) + Bl^2/R + c_a) (V the velocity amplitude).
Rows vary k_a (2e4, 1e4, ~0) and the frequency (gross sliding at 60-154 Hz, none at 216 Hz).

    python benchmarks/bench_mean_creep.py [--dc-V 1e-4]
"""

from __future__ import annotations

import argparse
import math
import tomllib

import numpy as np

from bench.config import DEFAULTS
from sim.rig import RigModel, SimulatedRig

BASE = tomllib.loads((DEFAULTS / "sim_rig.toml").read_text())["rig"]["model"]
SPP = 200                       # samples per period: the per-period mean is exact


def _means(m: RigModel, f: float, vpp: float, dc_V: float) -> tuple[np.ndarray, float, float]:
    """Per-period mean displacement after the pulse (none when dc_V = 0), force and
    displacement amplitudes before it."""
    rig = SimulatedRig(m)
    fs = f * SPP
    rig.set_generator(freq_Hz=f, amplitude_Vpp=vpp, output_on=True)
    b = rig.run(int(0.6 * f) * SPP, fs)
    F = b.force_V[-SPP * 10:] / m.force_sens_V_per_N
    x = b.disp_V[-SPP * 10:] / m.disp_sens_V_per_m
    rig.set_generator(offset_V=dc_V)
    rig.run(4 * SPP, fs)
    rig.set_generator(offset_V=0.0)
    b = rig.run(int(0.3 * f) * SPP, fs)
    return ((b.disp_V / m.disp_sens_V_per_m).reshape(-1, SPP).mean(axis=1),
            0.5 * float(F.max() - F.min()), 0.5 * float(x.max() - x.min()))


def relax(f: float, vpp: float, k_a: float, dc_V: float) -> dict:
    """The pulse's effect on the mean position: the run with the pulse minus the same run
    (same plant, no noise) without it, so what the ramp-up left settling cancels."""
    m = RigModel.from_dict({**BASE, "shaker_suspension_N_per_m": k_a, "seed": 3, "disp_noise_m": 0.0,
                            "force_noise_N": 0.0, "accel_noise_m_s2": 0.0})
    pulsed, P, X = _means(m, f, vpp, dc_V)
    plain, _, _ = _means(m, f, vpp, 0.0)
    d = pulsed - plain
    t = (np.arange(d.size) + 0.5) / f
    best = (math.inf, 0.0)
    for r in np.linspace(1, 300, 3000):
        e = np.exp(-r * t)
        a = float(d @ e / (e @ e))
        err = float(np.sum((d - a * e) ** 2))
        if err < best[0]:
            best = (err, float(r))
    V = X * 2 * math.pi * f
    damping = 2 * m.F_s_N / (math.pi * V) + m.shaker_force_constant_N_per_A ** 2 / m.shaker_resistance_ohm \
        + m.shaker_damping_N_s_per_m
    back = 1.0 - d[-1] / d[0]                     # share of the push undone 0.3 s later
    return dict(f=f, P=P, X=X, k_a=k_a, pushed=float(d[0]), back=back, rate=best[1] if back > 0.5 else math.nan,
                predicted=k_a / damping if X > m.x_s_m else math.nan)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dc-V", type=float, default=1e-4, help="DC drive of the pulse, V (1e-4 V = 2 mN)")
    args = ap.parse_args()
    print("| drive | force | amplitude X | k_a | mean pushed | undone after 0.3 s | fitted rate | predicted (full sliding) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for f, k_a in [(154.0, 2e4), (154.0, 1e4), (154.0, 1e-3), (110.0, 2e4), (60.0, 2e4), (216.0, 2e4)]:
        d = relax(f, 11.0, k_a, args.dc_V)
        rate = f"{d['rate']:.1f} /s" if math.isfinite(d["rate"]) else "no return"
        pred = f"{d['predicted']:.1f} /s" if math.isfinite(d["predicted"]) else "- (no gross sliding)"
        print(f"| {f:g} Hz | {d['P']:.0f} N | {d['X'] * 1e6:.1f} um | {k_a:.3g} N/m | {d['pushed'] * 1e9:.3g} nm "
              f"| {100 * d['back']:.0f} % | {rate} | {pred} |")


if __name__ == "__main__":
    main()
