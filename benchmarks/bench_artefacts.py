"""Benchmark of the measurement-artefact detection (sim.artefacts) on generated records.

Each case is one step's three records (force, acceleration, displacement) built from a
closed form that shares no code with the detector: a periodic response with odd harmonics
falling as 1/k^2 up to the 39th (the sharp reversals of a friction loop), white noise on
every channel, a random drive frequency (15-300 Hz), sample rate (an integer multiple of
the drive or not) and record length (8-30 periods).  One artefact is hidden in it, or
none:

- ``line``: a sinusoid of 0.5-20 x the noise rms on one random channel, at mains (50/60 Hz or a
  harmonic) or a random frequency, at least 2.5 record resolutions from a drive harmonic;
- ``transient``: a decaying sinusoid (time constant 0.1-0.5 records, 20-200 x the noise)
  at a random frequency, on the displacement and the acceleration;
- ``clipping``: one channel clipped at 80-95 % of its peak;
- ``dropout``: one channel held (or zero) for 10-60 samples;
- ``drift``: a linear offset drift of 20-100 x the noise's standard error on one channel;
- ``clean``: nothing (the false-alarm check).

``--quantised N`` adds N clean steps and N drop-out steps (kinds ``clean-q`` and
``dropout-q``) quantised as an ADC does at a realistic resolution: a slow drive (3-30 Hz,
400-10000 samples per period), a 12-, 14- or 16-bit converter whose range is 1.05-3 x the
signal's peak, noise 0.05-3 quanta rms (where the old repeat-rate rule named the natural
runs at the turning points drop-outs; decision record 0034).  A held value at a turning
point that stays within one quantum of the signal is not a drop-out any test can see:
``dropout-q`` prints how far the signal moved under each missed hold.

Prints, per kind, the detection rate (the right kind on the right channel; a line's
frequency within 0.1 % and amplitude within 10 %; a transient's decay rate within 25 %),
other artefacts reported (false alarms; how many of them are drop-outs) and the time per
step.

    python benchmarks/bench_artefacts.py [--cases 60] [--first 0] [--quantised 0] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from sim.artefacts import assess_step  # noqa: E402

KINDS = ("clean", "line", "transient", "clipping", "dropout", "drift")
CHANNELS = ("force", "accel", "disp")
SCALE = {"force": 5.0, "accel": 20.0, "disp": 10e-6}
NOISE = {"force": 0.003, "accel": 0.01, "disp": 2e-9}
EXPECT = {"line": "line_interference", "transient": "unsettled_transient", "clipping": "clipping",
          "dropout": "dropout", "drift": "offset_drift"}


def make_step(seed: int, kind: str | None = None):
    """(records, fs, f, kind, truth) of one generated case (``kind`` by the seed unless given)."""
    rng = np.random.default_rng(seed)
    kind = kind or KINDS[seed % len(KINDS)]
    f = float(np.exp(rng.uniform(np.log(15), np.log(300))))
    fs = f * int(rng.integers(64, 400)) if rng.uniform() < 0.5 else float(rng.uniform(8000, 30000))
    periods = int(rng.integers(8, 31))
    n = int(periods * fs / f)
    t = np.arange(n) / fs
    k = np.arange(1, 40, 2)
    k = k[k * f < 0.45 * fs]
    sig = {}
    for ch in CHANNELS:
        amps = SCALE[ch] / k ** 2 * rng.uniform(0.5, 1.0, k.size)
        ph = rng.uniform(0, 2 * np.pi, k.size)
        sig[ch] = (np.sin(2 * np.pi * f * np.outer(t, k) + ph) @ amps) + NOISE[ch] * rng.standard_normal(n)
    truth = {}
    T = n / fs
    if kind == "line":
        ch = str(rng.choice(CHANNELS))
        res = fs / n
        while True:
            fl = float(rng.choice([50.0, 60.0, 100.0, 150.0, 180.0])) if rng.uniform() < 0.6 else \
                float(rng.uniform(5 * res, min(0.4 * fs, 2000)))
            if abs(fl - round(fl / f) * f) > 2.5 * res and fl > 4 * res:
                break
            if rng.uniform() < 0.3:              # mains next to a harmonic: take another frequency
                fl = float(rng.uniform(5 * res, min(0.4 * fs, 2000)))
                if abs(fl - round(fl / f) * f) > 2.5 * res:
                    break
        amp = NOISE[ch] * rng.uniform(0.5, 20)
        sig[ch] = sig[ch] + amp * np.sin(2 * np.pi * fl * t + rng.uniform(0, 2 * np.pi))
        truth = dict(channel=ch, freq_Hz=fl, size=amp)
    elif kind == "transient":
        sigma = 1 / (T * rng.uniform(0.1, 0.5))
        ft = f * rng.uniform(0.4, 2.5)
        amp = NOISE["disp"] * rng.uniform(20, 200)
        tr = amp * np.exp(-sigma * t) * np.sin(2 * np.pi * ft * t)
        sig["disp"] = sig["disp"] + tr
        sig["accel"] = sig["accel"] - (2 * np.pi * ft) ** 2 * tr
        truth = dict(channel="disp", decay_per_s=sigma)
    elif kind == "mode":
        # a free vibration too slow to decay measurably: time constant 1-10 records, the
        # probe 5-50 x its noise, the accelerometer its exact second derivative
        sigma = 1 / (T * rng.uniform(1, 10))
        res = fs / n
        while True:
            ft = f * rng.uniform(0.2, 3.0)
            if abs(ft - round(ft / f) * f) > 2.5 * res and ft > 4 * res and ft < 0.4 * fs:
                break
        w, amp, ph = 2 * np.pi * ft, NOISE["disp"] * rng.uniform(5, 50), rng.uniform(0, 2 * np.pi)
        e = amp * np.exp(-sigma * t)
        sig["disp"] = sig["disp"] + e * np.sin(w * t + ph)
        sig["accel"] = sig["accel"] + e * ((sigma ** 2 - w ** 2) * np.sin(w * t + ph) - 2 * sigma * w * np.cos(w * t + ph))
        truth = dict(channel="disp", freq_Hz=ft, size=amp)
    elif kind == "clipping":
        ch = str(rng.choice(CHANNELS))
        top = rng.uniform(0.8, 0.95) * sig[ch].max()
        sig[ch] = np.minimum(sig[ch], top)
        truth = dict(channel=ch)
    elif kind == "dropout":
        ch = str(rng.choice(CHANNELS))
        i0, m = int(rng.integers(0, n - 60)), int(rng.integers(10, 61))
        sig[ch][i0:i0 + m] = 0.0 if rng.uniform() < 0.5 else sig[ch][i0]
        truth = dict(channel=ch)
    elif kind == "drift":
        ch = str(rng.choice(CHANNELS))
        change = NOISE[ch] * math.sqrt(12.0 / n) * rng.uniform(20, 100)
        sig[ch] = sig[ch] + change * t / T
        truth = dict(channel=ch, size=change)
    return sig, fs, f, kind, truth


def make_quantised(seed: int, dropout: bool):
    """(records, fs, f, kind, truth) of a clean (or drop-out) step quantised at a realistic
    ADC resolution, with a slow drive: many samples per period (module doc)."""
    rng = np.random.default_rng(10_000 + seed)
    f = float(np.exp(rng.uniform(np.log(3), np.log(30))))
    fs = f * int(rng.integers(400, 10_000)) if rng.uniform() < 0.5 else float(rng.uniform(8000, 30000))
    spp = fs / f
    if not 400 <= spp <= 10_000:
        fs = f * float(np.clip(spp, 400, 10_000))
    periods = max(4, min(int(rng.integers(8, 31)), int(60_000 * f / fs)))
    n = int(periods * fs / f)
    t = np.arange(n) / fs
    k = np.arange(1, 40, 2)
    k = k[k * f < 0.45 * fs]
    sig, quantum, clean = {}, {}, {}
    for ch in CHANNELS:
        amps = SCALE[ch] / k ** 2 * rng.uniform(0.5, 1.0, k.size)
        y = np.sin(2 * np.pi * f * np.outer(t, k) + rng.uniform(0, 2 * np.pi, k.size)) @ amps
        q = 2 * rng.uniform(1.05, 3.0) * np.max(np.abs(y)) / 2 ** int(rng.choice([12, 14, 16]))
        noise = q * float(np.exp(rng.uniform(np.log(0.05), np.log(3.0))))
        sig[ch] = np.round((y + noise * rng.standard_normal(n)) / q) * q
        quantum[ch], clean[ch] = q, y
    truth: dict = {}
    if dropout:
        ch = str(rng.choice(CHANNELS))
        i0, m = int(rng.integers(0, n - 60)), int(rng.integers(10, 61))
        held = 0.0 if rng.uniform() < 0.5 else float(sig[ch][i0])
        # how far the signal itself moved under the hold, and how far it was from the held value, in quanta
        under = clean[ch][i0:i0 + m]
        truth = dict(channel=ch, start=i0, length=m, held=held, moved=float(np.ptp(under)) / quantum[ch],
                     away=float(np.max(np.abs(under - held))) / quantum[ch])
        sig[ch][i0:i0 + m] = held
    return sig, fs, f, "dropout-q" if dropout else "clean-q", truth


def run_case(seed: int, quantised: str = "") -> dict:
    sig, fs, f, kind, truth = make_quantised(seed, quantised == "dropout") if quantised else make_step(seed)
    t0 = time.perf_counter()
    q = assess_step(sig["force"], sig["accel"], sig["disp"], fs, f).quality
    dt = time.perf_counter() - t0
    want = EXPECT.get(kind.removesuffix("-q"))
    hit = False
    for a in q.artefacts:
        if a.kind != want or a.channel != truth.get("channel"):
            continue
        if kind == "line":
            hit = abs(a.freq_Hz / truth["freq_Hz"] - 1) < 1e-3 and abs(a.size / truth["size"] - 1) < 0.1
        elif kind == "transient":
            hit = abs(a.decay_per_s / truth["decay_per_s"] - 1) < 0.25
        elif kind == "drift":
            hit = abs(abs(a.size) / truth["size"] - 1) < 0.2
        else:
            hit = True
        if hit:
            break
    others = [f"{a.kind}@{a.channel}" for a in q.artefacts
              if not (a.kind == want and a.channel == truth.get("channel"))
              and not (kind == "transient" and a.kind == "unsettled_transient")]
    row = dict(seed=seed, kind=kind, detected=bool(hit), false_alarms=others, status=q.status, seconds=dt,
               periods=int(len(sig["force"]) * f / fs), spp=fs / f)
    if kind == "dropout-q" and not hit:
        row["note"] = (f"{truth['channel']} held {'at zero' if truth['held'] == 0 else ''} for {truth['length']} "
                       f"samples at phase {(truth['start'] * f / fs) % 1:.3f}: the signal moved {truth['moved']:.2f} "
                       f"quanta under it, at most {truth['away']:.2f} quanta from the held value")
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=60)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--quantised", type=int, default=0,
                    help="also this many clean-q and dropout-q steps (quantised ADC, slow drive)")
    ap.add_argument("--modes", type=int, default=0,
                    help="instead: this many slowly decaying modes (decision 0033), named a line or a vibration")
    args = ap.parse_args(argv)
    if args.modes:
        return modes(args.first, args.modes)
    rows = [run_case(s) for s in range(args.first, args.first + args.cases)]
    rows += [run_case(s, which) for s in range(args.first, args.first + args.quantised) for which in ("clean", "dropout")]
    print(f"{'kind':<10} {'cases':>5} {'detected':>9} {'with false alarms':>18} {'of them a drop-out':>19}")
    for kind in KINDS + ("clean-q", "dropout-q"):
        r = [x for x in rows if x["kind"] == kind]
        if not r:
            continue
        det = "-" if kind.startswith("clean") else f"{sum(x['detected'] for x in r)}/{len(r)}"
        fa = sum(bool(x["false_alarms"]) for x in r)
        fd = sum(any(a.startswith("dropout@") for a in x["false_alarms"]) for x in r)
        print(f"{kind:<10} {len(r):>5} {det:>9} {fa:>13}/{len(r)} {fd:>14}/{len(r)}")
    for x in rows:
        if (not x["kind"].startswith("clean") and not x["detected"]) or x["false_alarms"]:
            print(f"  seed {x['seed']} ({x['kind']}, {x['periods']} periods of {x['spp']:.0f} samples): "
                  f"detected={x['detected']} other={x['false_alarms']} {x.get('note', '')}")
    sec = [x["seconds"] for x in rows]
    print(f"time per step: median {np.median(sec):.3f} s, max {max(sec):.3f} s")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


def modes(first: int, count: int) -> int:
    """Slowly decaying modes on probe and accelerometer (x'' = a): how many are named an
    interference line (the defect of decision 0033), how many a free vibration or transient."""
    line = vib = silent = 0
    worst = []
    for seed in range(first, first + count):
        sig, fs, f, _, truth = make_step(seed, "mode")
        q = assess_step(sig["force"], sig["accel"], sig["disp"], fs, f).quality
        near = [a for a in q.artefacts if abs(a.freq_Hz - truth["freq_Hz"]) < 3 * fs / len(sig["disp"])]
        if any(a.kind == "line_interference" for a in near):
            line += 1
            worst.append(seed)
        elif near:
            vib += 1
        else:
            silent += 1
    print(f"slow modes: {count} cases; named a vibration or transient: {vib}; an interference line: {line}; "
          f"not reported: {silent}" + (f"; line seeds: {worst[:10]}" if worst else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
