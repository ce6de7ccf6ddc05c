"""The step decision of the artefact check (:mod:`sim.artefacts`): usable, flagged or
rejected, from the detectors and the cleaned records' periodicity gate."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .. import records
from ..records import CHANNELS, MAX_HARMONICS, analyse_records, checked_records, lsq_harmonics
from . import sentences
from .cleaning import _clean_channel, _motion_evidence, settle_cycles
from .detectors import HARMONIC_GUARD, find_clipping, find_dropouts
from .quality import Artefact, Assessment, StepQuality
from .sentences import MAINS_HZ, mains_line

DRIFT_LIMIT = 10.0            # periodicity gate: standard errors between the halves of a record
NOISY_RESIDUAL = 0.02         # displacement residual rms / fundamental amplitude above which a step is flagged
MIN_PERIODS = 4


def _fundamental(x: np.ndarray, fs: float, f: float) -> float:
    """Amplitude of the drive-frequency component over the whole periods of ``x``: the first
    of the kernel's harmonics (every one below Nyquist fitted, so none leaks into it)."""
    n = int(math.floor(x.size * f / fs + 1e-9) * fs / f)
    K = max(1, min(MAX_HARMONICS, int(math.floor(0.5 * fs / f - 0.5))))
    return float(abs(lsq_harmonics(x[:n], fs, f, K, noise=False)[0][0]))


def _mains_hint(f: float, periods: int, k_failed: int, lines: list[Artefact]) -> str:
    """Mains (50/60 Hz, harmonics 1-3) too close to a drive harmonic to be separated in
    ``periods`` periods: what to do, or ''.  Named only when the records make it plausible
    (decision 0037): the periodicity gate failed on that very harmonic (``failed``, the
    gate's harmonic ``k_failed``, 0 for the offset; a line within the guard of harmonic k beats with it, and the
    halves differ there, not in the offset or another harmonic), or a line at a mains
    frequency was found elsewhere in the step (``lines``)."""
    guard = HARMONIC_GUARD * f / periods
    found = [(a, line) for a in lines if a.kind == "line_interference" and (line := mains_line(a.freq_Hz))]
    for base in MAINS_HZ:
        for m in (1, 2, 3):
            fm = m * base
            k = max(1, round(fm / f))
            gap = abs(fm - k * f)
            seen = [a for a, (b, _) in found if b == base]
            if 0 < gap <= guard and (k == k_failed or seen):
                return sentences.mains_hint(fm, gap, k, f, periods, seen[0].freq_Hz if seen else math.nan,
                                            seen[0].channel if seen else "", math.ceil(HARMONIC_GUARD * f / gap))
    return ""


def assess_step(force_N, accel_m_s2, disp_m, fs_Hz: float, freq_Hz: float | None = None) -> Assessment:
    """Artefacts, cleaning and the usable/flagged/rejected decision for one step (module doc).
    Records that cannot be analysed at all (lengths, NaN, too short) raise ValueError."""
    sig, f = checked_records(force_N, accel_m_s2, disp_m, fs_Hz, freq_Hz)
    q = StepQuality(freq_Hz=f, level_N=_fundamental(sig["force"], fs_Hz, f), record_s=sig["force"].size / fs_Hz)
    for ch in CHANNELS:
        clip = find_clipping(ch, sig[ch], fs_Hz, f)
        q.artefacts += clip + find_dropouts(ch, sig[ch], fs_Hz, f, clip)
    if q.artefacts:
        q.status = "rejected"
        q.reason = "; ".join(a.describe() for a in q.artefacts)
        return Assessment(q, None)
    n = sig["force"].size
    cleaned, transients, noise = {}, {}, {}
    for ch in CHANNELS:
        cleaned[ch], arts, transients[ch], noise[ch] = _clean_channel(ch, sig[ch], fs_Hz, f)
        q.artefacts += arts
    start = 0
    tr_arts = []
    need = 0                         # periods to drop for transients that could not be removed
    periods = int(math.floor(n * f / fs_Hz + 1e-9))
    for ch in CHANNELS:
        for A0, sigma, ftr, ev, removed in transients[ch]:
            cyc = settle_cycles(A0, sigma, noise[ch], n, fs_Hz, f)
            if cyc == 0 and not removed:
                continue             # below one standard error of a harmonic already: harmless
            if not removed:
                need = max(need, cyc)
            tr_arts.append(Artefact("unsettled_transient", ch, A0, "removed" if removed else "kept",
                                    freq_Hz=ftr, decay_per_s=sigma, settle_cycles=cyc, evidence=ev))
    # a "line" the probe and the accelerometer both see as one motion (a = x'', the accelerometer's
    # component at the line's frequency equals -(2 pi f)^2 times the probe's, in amplitude and
    # phase) is a free vibration of the structure too slow to decay measurably within the
    # record, not interference; a line at the frequency of a transient or of such a vibration
    # on another channel is that vibration (the force sensor sees the shaker's reaction to it)
    guard = HARMONIC_GUARD * fs_Hz / n
    for i, a in enumerate(q.artefacts):
        if a.kind == "line_interference" and a.channel in ("disp", "accel") and not any(
                t.channel != a.channel and abs(t.freq_Hz - a.freq_Hz) <= guard for t in tr_arts):
            ev = _motion_evidence(sig, cleaned, noise, fs_Hz, f, a.freq_Hz)
            if ev:
                q.artefacts[i] = replace(a, kind="unsettled_transient", settle_cycles=0, evidence=ev)
    for i, a in enumerate(q.artefacts):
        if a.kind != "line_interference":
            continue
        tr = [t for t in tr_arts + [b for b in q.artefacts if b.kind == "unsettled_transient"]
              if t.channel != a.channel and abs(t.freq_Hz - a.freq_Hz) <= guard]
        if tr:
            decay = tr[0].decay_per_s
            cyc = settle_cycles(a.size, decay, noise[a.channel], n, fs_Hz, f) if decay > 0 else 0
            q.artefacts[i] = replace(a, kind="unsettled_transient", decay_per_s=decay, settle_cycles=cyc,
                                     evidence=sentences.same_vibration(decay > 0, tr[0].channel))
    if need > 0 and periods - need >= max(MIN_PERIODS, periods // 4):
        start = int(math.ceil(need * fs_Hz / f - 1e-9))
        for ch in CHANNELS:           # clean the kept part again: the fit is no longer biased by the transient
            cleaned[ch], _a, _t, noise[ch] = _clean_channel(ch, sig[ch][start:], fs_Hz, f)
        tr_arts = [a if a.action == "removed" else replace(a, action="trimmed") for a in tr_arts]
        q.notes.append(sentences.periods_dropped(need, periods))
    q.artefacts += tr_arts
    rec = analyse_records(cleaned["force"], cleaned["accel"], cleaned["disp"], fs_Hz, f)
    if rec.drift_sigma > DRIFT_LIMIT:
        q.status = "rejected"
        q.reason = sentences.not_periodic(rec.drift_channel, records.harmonic_words(rec.drift_harmonic),
                                          rec.drift_sigma, DRIFT_LIMIT)
        hint = _mains_hint(f, periods, rec.drift_harmonic, q.artefacts)
        if hint:
            q.reason += f"; {hint}"
        if tr_arts:
            worst = max(tr_arts, key=lambda a: a.settle_cycles)
            q.reason += f"; {worst.describe()}"
            q.artefacts = [replace(a, action="rejected") if a.kind == "unsettled_transient" else a
                           for a in q.artefacts]
        return Assessment(q, None, analysed=rec)
    q.notes = [a.describe() for a in q.artefacts] + q.notes
    d = rec.channels["disp"]
    a1 = abs(d.harmonics[0]) if d.harmonics.size else 0.0
    ratio = d.noise_rms / a1 if a1 > 0 else math.inf
    if ratio > NOISY_RESIDUAL:
        q.notes.append(sentences.noisy(ratio, NOISY_RESIDUAL))
    q.status = "flagged" if q.notes else "usable"
    return Assessment(q, rec, cleaned, start, rec)
