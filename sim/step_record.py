"""The one estimator of a measured block (decision record 0047).

    measure_block(force_N, accel_m_s2, disp_m, fs_Hz, freq_Hz, harmonics) -> BlockRecord

A stepped-sine block is analysed once, by :func:`sim.artefacts.assess_step` (artefacts
found and removed, the usable / flagged / rejected verdict, and every harmonic of the
cleaned records through :mod:`sim.records`); the step's record is made from that one
analysis: the measured fields of :class:`~sim.step_result.BlockMeasurement` (force,
compliance, accelerance, the per-channel fit summaries of the plan's harmonics with their
standard errors) and, from step format version 2, the whole analysis (``harmonics``: every
harmonic with its standard error, the noise, the periodicity score) and the verdict
(``quality``).  Every reader takes the measured numbers from there
(:func:`records_of`, :func:`quality_of`); only a version-1 step, which has neither, is
assessed again from its raw block.

A block an artefact on the raw samples rejects (clipping, a drop-out) is not cleaned: its
harmonics are those of the raw records.  A block the periodicity gate rejects keeps those
of its cleaned records.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from .artefacts import Assessment, StepQuality, assess_step
from .records import CHANNELS, ChannelHarmonics, PeriodicRecords, analyse_records, synthesized_period
from .step_result import BlockHarmonics, BlockMeasurement, ChannelRecord, FitSummary, QualityRecord

RAW = {"force": "force_N", "accel": "accel_m_s2", "disp": "disp_m"}


@dataclass(frozen=True)
class BlockRecord:
    assessment: Assessment
    records: PeriodicRecords         # the harmonics the record holds (cleaned records, or raw when rejected before)
    fields: BlockMeasurement         # the measured fields of the step result

    @property
    def quality(self) -> StepQuality:
        return self.assessment.quality

    @property
    def disp_noise_rms(self) -> float:
        return float(self.records.channels["disp"].noise_rms)


@functools.lru_cache(maxsize=16)
def _period_basis(harmonics: int) -> np.ndarray:
    """exp(i k w t) at 1024 points of a period for k = 1..harmonics (read only: shared)."""
    B = np.exp(2j * np.pi * np.outer(np.arange(1024) / 1024, np.arange(1, harmonics + 1)))
    B.flags.writeable = False
    return B


def _summary(ch: ChannelHarmonics, harmonics: int, raw: np.ndarray) -> FitSummary:
    """The channel's first ``harmonics`` harmonics as the step result keeps them (seed
    Eq. 9's peak-to-peak from the periodic part they describe, 1024 points a period)."""
    C = ch.harmonics[:harmonics]
    A = np.abs(C)
    periodic = (_period_basis(C.size) @ C).imag
    return FitSummary(amplitude=A.tolist(), phase_rad=np.angle(C).tolist(), offset=float(ch.offset),
                      thd=float(np.sqrt(np.sum(A[1:] ** 2)) / A[0]) if A.size and A[0] > 0 else math.inf,
                      noise_rms=float(ch.noise_rms), peak_to_peak=float(periodic.max() - periodic.min()),
                      raw_peak_to_peak=float(np.ptp(raw)), sigma=float(ch.sigma))


def _harmonics_record(rec: PeriodicRecords, start: int) -> BlockHarmonics:
    def channel(c: ChannelHarmonics) -> ChannelRecord:
        return ChannelRecord(re=c.harmonics.real.tolist(), im=c.harmonics.imag.tolist(), offset=float(c.offset),
                             noise_rms=float(c.noise_rms), sigma=float(c.sigma))
    return BlockHarmonics(freq_Hz=float(rec.freq_Hz), fs_Hz=float(rec.fs_Hz), periods=int(rec.periods),
                          samples=int(rec.samples), start=int(start), drift_sigma=float(rec.drift_sigma),
                          drift_detail=rec.drift_detail, force=channel(rec.channels["force"]),
                          accel=channel(rec.channels["accel"]), disp=channel(rec.channels["disp"]))


def measure_block(force_N, accel_m_s2, disp_m, fs_Hz: float, freq_Hz: float, harmonics: int = 5) -> BlockRecord:
    """The block's one analysis and the step record made from it (module doc).  Records
    that cannot be analysed at all (lengths, NaN, too short) raise ValueError."""
    a = assess_step(force_N, accel_m_s2, disp_m, fs_Hz, freq_Hz)
    rec = a.analysed if a.analysed is not None else analyse_records(force_N, accel_m_s2, disp_m, fs_Hz, freq_Hz)
    raw = {"force": np.asarray(force_N, float), "accel": np.asarray(accel_m_s2, float), "disp": np.asarray(disp_m, float)}
    fits = {ch: _summary(rec.channels[ch], harmonics, raw[ch]) for ch in CHANNELS}
    P, A, X = (rec.channels[ch].harmonics[:1] for ch in ("force", "accel", "disp"))
    F1 = complex(P[0])
    # the ratios as arrays, as sim.discrepancy.gain.frf divides them (analysis.json's numbers to the last bit)
    compliance, accelerance = complex((X / P)[0]), complex((A / P)[0])
    q = a.quality
    fields = BlockMeasurement(
        freq_Hz=float(freq_Hz), force_N=abs(F1),
        compliance_m_per_N={"re": compliance.real, "im": compliance.imag},
        compliance_abs_m_per_N=abs(compliance), compliance_phase_rad=math.atan2(compliance.imag, compliance.real),
        accelerance_abs_kg_inv=abs(accelerance), accelerance_phase_rad=math.atan2(accelerance.imag, accelerance.real),
        # seed Eq. 9 in SI: half the peak-to-peak of the steady (fitted periodic) displacement per force amplitude
        compliance_pp_m_per_N=0.5 * fits["disp"]["peak_to_peak"] / abs(F1),
        force=fits["force"], accel=fits["accel"], disp=fits["disp"],
        fs_Hz=float(fs_Hz), n_samples=int(raw["force"].size),
        quality=QualityRecord(**q.to_record()),     # type: ignore[typeddict-item]
        harmonics=_harmonics_record(rec, a.start))
    return BlockRecord(a, rec, fields)


def records_of(result) -> PeriodicRecords | None:
    """The stored analysis of a step (format version 2), as :func:`sim.records.analyse_records`
    gave it (each channel's mean period synthesized from its harmonics); None for a
    version-1 step, which has none."""
    h = result.get("harmonics")
    if not isinstance(h, dict):
        return None
    f, fs = float(h["freq_Hz"]), float(h["fs_Hz"])
    chans = {}
    for ch in CHANNELS:
        c = h[ch]
        C = np.asarray(c["re"], float) + 1j * np.asarray(c["im"], float)
        chans[ch] = ChannelHarmonics(C, float(c["offset"]), float(c["noise_rms"]), float(c["sigma"]),
                                     synthesized_period(C, float(c["offset"]), fs, f))
    return PeriodicRecords(f, fs, int(h["periods"]), int(h["samples"]), chans, float(h["drift_sigma"]),
                           str(h["drift_detail"]))


def quality_of(result) -> StepQuality | None:
    """The stored verdict of a step (format version 2); None for a version-1 step."""
    q = result.get("quality")
    return StepQuality.from_record(q) if isinstance(q, dict) else None
