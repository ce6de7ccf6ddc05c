"""Cleaning one channel of a step (:mod:`sim.artefacts`): offset drift and steady lines
removed, transients found; their settle cycles; a free vibration told from interference."""

from __future__ import annotations

import math

import numpy as np

from . import sentences
from .detectors import (
    DECAY_FRACTION,
    DECAY_Z,
    _aliases,
    _find_lines,
    _fit_sinusoid,
    _periodic_fit,
    _periodic_part,
    _quantum,
    _robust_noise,
    _trend,
    alias_bound,
    quantisation_line_bound,
)
from .quality import Artefact

TREND_Z = 6.0                 # offset drift: sqrt(chi-square, 2 dof) of the trend coefficients
SETTLED_Z = 0.5               # cleaning passes: settled when a pass moves what it removes by less (harmonic standard errors)
SLOW_PASS = 0.25              # ... not settling when a pass moves it by more than this share of the pass before
ENVELOPE_Z = 10.0             # first block's residual power above the noise, in standard errors


def _clean_channel(ch: str, x: np.ndarray, fs: float, f: float):
    """Remove offset drift and steady lines; find transients.  Returns (cleaned samples,
    artefacts removed, transients found as (A_0, sigma, freq or nan, evidence), noise rms).
    A second pass refits the drive harmonics without what the first pass found."""
    n = x.size
    zero = np.zeros(n)
    removed = zero
    # a quantiser adds at least q^2/12 of noise (Sheppard), which neighbour differences do not
    # see on a slow signal with little noise (they are mostly zero), and folds its error's
    # harmonics back as tiny steady lines: neither is the rig's (decision 0039)
    q = _quantum(x)
    floor = q / math.sqrt(12.0)
    moved = math.inf
    for _pass in range(4):        # a trend converges more slowly than lines: more passes only for it
        periodic, C = _periodic_fit(x - removed, fs, f)
        r = x - periodic
        seen = _robust_noise(r)
        noise = max(seen, floor)
        below = quantisation_line_bound(q, math.sqrt(max(seen * seen - floor * floor, 0.0)))
        aliases = _aliases(C, noise * math.sqrt(2.0 / n), f, fs)
        folded = alias_bound(C, aliases)
        lines, transients = _find_lines(r, fs, f, aliases, folded)
        lines = [ln for ln in lines if ln.amp > below]
        removed_part = sum((ln.model for ln in lines + transients), zero)
        trend, change, z = _trend(r - removed_part, noise)
        if not z > TREND_Z:
            trend, change, z = zero, 0.0, 0.0
        elif lines or transients:     # what the trend's low-frequency leakage made look like a line goes
            lines, transients = _find_lines(r - trend, fs, f, aliases, folded)
            lines = [ln for ln in lines if ln.amp > below]
            removed_part = sum((ln.model for ln in lines + transients), zero)
            trend, change, z = _trend(r - removed_part, noise)
            if not z > TREND_Z:
                trend, change, z = zero, 0.0, 0.0
        new = trend + sum((ln.model for ln in lines + transients), zero)
        if (_pass == 0 and not lines and not transients and z == 0.0) or (_pass == 1 and z == 0.0):
            break
        # what this pass changes in the part removed, at its largest frequency component, in
        # standard errors of a harmonic (decision 0065): below SETTLED_Z the passes have settled
        # (each moves it by a tenth or less of the one before: the next would move the harmonics by
        # a fraction of a standard error); by more than SLOW_PASS of the pass before, they do not
        # settle within the passes left (a strong line within the guard of a drive harmonic: they
        # move it by 50-900 standard errors, back and forth): more passes only cost time
        change_m = float(np.abs(np.fft.rfft(new - removed)).max()) * 2.0 / n
        se = noise * math.sqrt(2.0 / n)
        step = change_m / se if se > 0 else (math.inf if change_m > 0 else 0.0)
        removed = new
        if _pass >= 1 and (step < SETTLED_Z or step > SLOW_PASS * moved):
            break
        moved = step
    cleaned = x - new
    rest = (r - new)[n // 2:]          # what is left, in the second half (after any transient): the noise
    noise = max(min(float(1.4826 * np.median(np.abs(rest - np.median(rest)))) or noise, noise), floor)
    arts = []
    if z > 0:
        arts.append(Artefact("offset_drift", ch, change, "removed",
                             evidence=sentences.trend(z)))
    se = noise * math.sqrt(2.0 / n)
    for ln in lines:
        arts.append(Artefact("line_interference", ch, ln.amp, "removed", freq_Hz=ln.freq_Hz, snr=ln.amp / se,
                             decay_bound_per_s=ln.decay_bound,
                             evidence=sentences.line_found(ln.amp / se, ln.freq_Hz / f)))
    found: list[tuple] = [(ln.amp, ln.decay, ln.freq_Hz, sentences.decaying_sinusoid(ln.decay, ln.decay_se), True)
                          for ln in transients]
    if not found:
        # the periodic part of the second half (the most settled), extrapolated to the whole
        # record: what is left in the first half and not in the second is still settling
        base = x - sum((ln.model for ln in lines), zero)
        env = _envelope_transient(base, fs, f, max(_robust_noise(r), floor))
        if env is not None:
            found.append(env + (False,))
            if z > 0:                  # the trend was the transient seen over the whole record
                cleaned = base
                arts = [a for a in arts if a.kind != "offset_drift"]
    return cleaned, arts, found, noise


def _envelope_transient(x: np.ndarray, fs: float, f: float, noise: float):
    """A response still settling: the difference between consecutive drive periods,
    x(t + T) - x(t), holds no periodic part and only noise once settled; its mean square
    per period falling over the record gives the decay; ``noise`` (rms per sample, from
    sample-to-sample differences, which a slow transient barely moves) sets the settled
    level 2 noise^2.  (A_0, sigma, nan, evidence) or None."""
    n = x.size
    T = fs / f                                   # samples per period (not necessarily whole)
    P = int(math.floor(n / T + 1e-9)) - 1
    B = int(math.floor(T))
    if P < 4 or B < 8:
        return None
    j = np.arange(n - int(math.ceil(T)))
    d = np.interp(j + T, np.arange(n), x) - x[j]
    starts = (np.arange(P) * T).astype(int)
    D = np.array([np.mean(d[s:s + B] ** 2) for s in starts if s + B <= d.size])
    P = D.size
    floor = min(2 * noise ** 2, float(np.median(D[P // 2:]))) if noise > 0 else float(np.median(D[P // 2:]))
    if not floor > 0:
        return None
    sd = floor * math.sqrt(2.0 / B)
    z = (D - floor) / sd
    if z[0] < ENVELOPE_Z:
        return None
    m = 0
    while m < P and z[m] > 3:
        m += 1
    tc = (np.arange(P) + 0.5) / f
    if m >= 2:
        slope, icpt = np.polyfit(tc[:m], np.log(D[:m] - floor), 1)
        sigma = -slope / 2
        e0 = math.exp(icpt)
    else:                                        # gone after one period: a lower bound of the rate
        sigma = math.log((D[0] - floor) / (3 * sd)) / 2 * f
        e0 = (D[0] - floor) * math.exp(2 * sigma * tc[0])
    if not (sigma > 0 and math.isfinite(e0)) or math.exp(-sigma * n / fs) > DECAY_FRACTION:
        return None                              # not falling over the record: a drift or a line, not a transient
    # a transient of amplitude A e^(-sigma t) at the drive frequency differs between periods by A (1 - e^(-sigma T))
    A0 = math.sqrt(2 * e0) / max(1 - math.exp(-sigma / f), 1e-12)
    return (A0, float(sigma), math.nan, sentences.falling_differences(m, P, z[0]))


def settle_cycles(A0: float, sigma: float, noise: float, n: int, fs: float, f: float) -> int:
    """Drive cycles from the record start until the transient is harmless (module doc)."""
    T = n / fs
    tol = noise * math.sqrt(2.0 / n) * max(1.0, sigma * T / 2)
    if not (A0 > tol and sigma > 0):
        return 0
    return int(math.ceil(f * math.log(A0 / tol) / sigma))


MOTION_Z = 4.0                # a free vibration: each motion channel's component above its noise, standard errors
MOTION_TOL = 0.3              # ... and the accelerometer's within 30 % (+ 3 standard errors) of -(2 pi f)^2 x


def _motion_evidence(sig: dict, cleaned: dict, noise: dict, fs: float, f: float, fl: float) -> str:
    """Evidence that a component at ``fl`` Hz is motion of the structure, seen by the probe
    and the accelerometer as one: both show it above MOTION_Z standard errors and the
    accelerometer's complex amplitude is -(2 pi fl)^2 times the probe's within MOTION_TOL
    (and 3 combined standard errors).  A line on one sensor (mains on a cable), or on both
    in phase (crosstalk), fails.  '' when the records do not show that."""
    n = sig["disp"].size
    t = np.arange(n) / fs
    w = 2 * np.pi * fl
    M = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones(n), t - t.mean()])
    amp, se = {}, {}
    for ch in ("disp", "accel"):
        r = sig[ch] - _periodic_part(cleaned[ch], fs, f)     # the removed components + noise
        c, *_ = np.linalg.lstsq(M, r, rcond=None)
        amp[ch], se[ch] = complex(c[0], c[1]), noise[ch] * math.sqrt(2.0 / n)
        if not abs(amp[ch]) > MOTION_Z * se[ch]:
            return ""
    pred = -w * w * amp["disp"]
    tol = MOTION_TOL * abs(pred) + 3 * math.hypot(se["accel"], w * w * se["disp"])
    if not abs(amp["accel"] - pred) <= tol:
        return ""
    ratio = amp["accel"] / pred
    line = max(("disp", "accel"), key=lambda ch: abs(amp[ch]) / se[ch])
    decay = _fit_sinusoid(sig[line] - _periodic_part(cleaned[line], fs, f), fs, fl, with_decay=True)
    rate, rate_se, significant = math.nan, math.nan, False      # NaN: no decay rate fitted
    if decay is not None and decay.decay_se > 0:
        rate, rate_se, significant = decay.decay, decay.decay_se, decay.decay > DECAY_Z * decay.decay_se
    return sentences.free_vibration(abs(amp["accel"]), abs(amp["disp"]), fl, abs(ratio),
                                    math.degrees(math.atan2(ratio.imag, ratio.real)), abs(amp["accel"]) / se["accel"],
                                    abs(amp["disp"]) / se["disp"], rate, rate_se, significant, 1e3 * n / fs)
