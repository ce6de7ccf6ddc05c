"""Measurement artefacts in one step's time records, found before any physics.

    assess_step(force_N, accel_m_s2, disp_m, fs_Hz, freq_Hz=None) -> Assessment

One function decides what a step is worth, for ``bench analyze`` (which steps it uses)
and for the run report (which steps it lists): the :class:`StepQuality` it returns is
``usable``, ``flagged`` (used, with notes) or ``rejected`` (with the reason, naming the
channel).  Per channel (force, accel, disp), on the raw samples:

- **clipping**: samples piled up at the record's extreme value (a flat top at the
  range); rejects the step (the harmonics of a clipped record are wrong).
- **drop-out**: a run of identical samples (held value or zeros) the signal could not have
  made: the chance that noise and quantisation put every sample of the run on the held
  value, where the periodic fit says the signal was, is below 1e-4 per record; rejects.
  Runs cluster where a quantised signal is slow (its turning points): those are its own
  (decision record 0034).

Then, on the residual of the periodic fit (offset and every harmonic of the drive below
Nyquist, :mod:`sim.records`):

- **offset drift**: a linear + quadratic trend over the record, kept when its two
  coefficients differ from zero by more than 6 standard errors together (chi-square, 2
  degrees of freedom); removed, the step is flagged.
- **interference line**: a spectral peak of the residual (Hann window) at a frequency more
  than ``HARMONIC_GUARD`` record resolutions (fs/N) from every drive harmonic (and from
  where harmonics above Nyquist fold back, when the record has content up there), above the
  noise floor by a factor that gives a false alarm probability of 1e-4 per record and
  channel; its frequency, amplitude and phase are fitted by least squares (with a decay
  rate, to tell a line from a transient), and a steady line is **removed** from the record:
  the step stays usable (flagged).  Up to ``MAX_LINES`` per channel.  A "line" the probe
  and the accelerometer see as one motion (both components above ``MOTION_Z`` standard
  errors, the accelerometer's -(2 pi f)^2 times the probe's in amplitude and phase) is a
  free vibration too slow to decay within the record, named an unsettled transient; so is
  a line on another channel at its frequency (decision record 0033).
- **unsettled transient**: a spectral peak whose fitted decay rate is positive by more
  than 6 standard errors and which loses more than 20 % of its amplitude over the record
  is a transient with its own frequency: it is **removed** like a line.  A transient the
  record cannot tell from the drive shows in the difference between consecutive periods,
  x(t + T) - x(t), where the periodic part cancels: its mean square per period falling
  (the first above the noise by more than 10 standard errors) gives the decay.
  A transient is harmless once its amplitude has fallen to ``A_tol = s sqrt(2/N)
  max(1, sigma T / 2)`` (s the noise rms, N samples, T the record length, sigma the decay
  rate): then the bias it leaves on any harmonic is below that harmonic's standard error.
  The settle cycles the plan needs are ``ceil(f ln(A_0 / A_tol) / sigma)``.  A transient
  that was not removed: when what is left after that holds at least
  ``max(MIN_PERIODS, periods / 4)`` whole periods, the first periods are dropped and the
  step is kept (flagged); otherwise the periodicity gate decides, and a rejection names
  the transient and the settle cycles it needs.

Finally the cleaned records pass the periodicity gate of :mod:`sim.records` (harmonics 1-3
and offset of each channel, first half against second, at most ``DRIFT_LIMIT`` standard
errors), and a step whose displacement residual (noise) is above ``NOISY_RESIDUAL`` of its
fundamental is flagged as noisy (used, with its noise as weight).

:func:`artefact_causes` aggregates the artefacts of many steps into ``analysis.json``
causes of ``kind: "artefact"`` (docs/analysis.md, decision record 0024).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares
from scipy.special import log_ndtr, logsumexp

from .records import CHANNELS, PeriodicRecords, analyse_channel, analyse_records, checked_records

log = logging.getLogger(__name__)

DRIFT_LIMIT = 10.0            # periodicity gate: standard errors between the halves of a record
NOISY_RESIDUAL = 0.02         # displacement residual rms / fundamental amplitude above which a step is flagged
LINE_FALSE_ALARM = 1e-4       # per record and channel
HARMONIC_GUARD = 1.5          # record resolutions (fs / N) around each drive harmonic not searched for lines
MAX_LINES = 6
TREND_Z = 6.0                 # offset drift: sqrt(chi-square, 2 dof) of the trend coefficients
DECAY_Z = 6.0                 # a line's decay rate, in standard errors, above which it is a transient
DECAY_FRACTION = 0.8          # ... and its amplitude at the end / at the start below this
ENVELOPE_Z = 10.0             # first block's residual power above the noise, in standard errors
MIN_PERIODS = 4
DROPOUT_FALSE_ALARM = 1e-4       # per record and channel
DROPOUT_MIN_SAMPLES = 4          # shortest run of identical samples examined

LABEL = {"force": "force sensor", "accel": "accelerometer", "disp": "displacement probe"}
UNIT = {"force": "N", "accel": "m/s^2", "disp": "m"}
KINDS = ("line_interference", "unsettled_transient", "clipping", "dropout", "offset_drift")


def si(value: float, unit: str) -> str:
    """'12 nm', '3.1 mN', '0.25 m/s^2': a size in the channel's unit with an SI prefix."""
    if not math.isfinite(value):
        return f"{value} {unit}"
    if unit in ("m", "N"):
        for scale, p in ((1.0, ""), (1e-3, "m"), (1e-6, "u"), (1e-9, "n"), (1e-12, "p")):
            if abs(value) >= scale or scale == 1e-12:
                return f"{value / scale:.3g} {p}{unit}"
    return f"{value:.3g} {unit}"


@dataclass(frozen=True)
class Artefact:
    """One artefact on one channel of one step.  ``size`` is in the channel's SI unit:
    a line's or a transient's amplitude (at the record start), a drift's change over the
    record, the clipping level, a drop-out's held value."""

    kind: str                        # one of KINDS
    channel: str                     # force | accel | disp
    size: float
    action: str                      # "removed" | "trimmed" | "rejected"
    freq_Hz: float = math.nan        # line / transient frequency
    time_s: float = math.nan         # clipping / drop-out: first sample, from the record start
    duration_s: float = math.nan     # drop-out length; clipping: time spent at the limit
    decay_per_s: float = math.nan    # transient: amplitude decay rate sigma (A = A_0 exp(-sigma t))
    settle_cycles: int = 0           # transient: drive cycles from the record start until harmless
    evidence: str = ""
    snr: float = math.nan            # line: amplitude over one standard error of a harmonic of the record
    decay_bound_per_s: float = math.nan   # line: upper bound of its decay rate (fit + 2 standard errors)
    settle_at_least: bool = False    # settle_cycles is a least number (from that bound)

    @property
    def unit(self) -> str:
        return UNIT[self.channel]

    def describe(self) -> str:
        where = f"on the {LABEL[self.channel]} ({self.channel})"
        if self.kind == "line_interference":
            return (f"a {self.freq_Hz:.4g} Hz line of {si(self.size, self.unit)} {where}, not locked to the drive "
                    f"({self.evidence}); removed")
        if self.kind == "unsettled_transient":
            what = f"{self.freq_Hz:.4g} Hz " if math.isfinite(self.freq_Hz) else ""
            done = {"removed": "; removed", "trimmed": "; the first periods were dropped"}.get(self.action, "")
            if not self.decay_per_s > 0:
                advice = (f"settle {'at least' if self.settle_at_least else 'about'} {self.settle_cycles} more cycles"
                          if self.settle_cycles else "settle longer")
                return (f"an unsettled {what}vibration of {si(self.size, self.unit)} {where} ({self.evidence}), "
                        f"not decaying measurably within the record: {advice}{done}")
            return (f"an unsettled {what}transient of {si(self.size, self.unit)} {where} at the record start, "
                    f"decaying at {self.decay_per_s:.3g} /s (time constant {1e3 / self.decay_per_s:.3g} ms; "
                    f"{self.evidence}): settle {self.settle_cycles} more cycles{done}")
        if self.kind == "clipping":
            return (f"clipping {where}: flat at {si(self.size, self.unit)} for {1e3 * self.duration_s:.3g} ms "
                    f"from t = {self.time_s:.4g} s ({self.evidence})")
        if self.kind == "dropout":
            return (f"a drop-out {where}: the value {si(self.size, self.unit)} held for {1e3 * self.duration_s:.3g} ms "
                    f"from t = {self.time_s:.4g} s ({self.evidence})")
        if self.kind == "offset_drift":
            return f"an offset drift {where} of {si(self.size, self.unit)} over the record ({self.evidence}); removed"
        return f"{self.kind} {where}"

    def as_dict(self) -> dict:
        f = lambda v: None if not math.isfinite(v) else float(v)      # noqa: E731
        return dict(kind=self.kind, channel=self.channel, size=float(self.size), unit=self.unit,
                    action=self.action, freq_Hz=f(self.freq_Hz), time_s=f(self.time_s),
                    duration_s=f(self.duration_s), decay_per_s=f(self.decay_per_s),
                    settle_cycles=int(self.settle_cycles), evidence=self.evidence, text=self.describe())


@dataclass
class StepQuality:
    """What a step is worth: ``usable``, ``flagged`` (used, ``notes`` say why) or
    ``rejected`` (``reason`` says why, naming the channel)."""

    status: str = "usable"
    artefacts: list[Artefact] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    reason: str = ""
    freq_Hz: float = math.nan
    level_N: float = math.nan        # force fundamental amplitude, when it could be measured
    record_s: float = math.nan       # length of the record

    @property
    def text(self) -> str:
        return self.reason if self.status == "rejected" else "; ".join(self.notes)

    def as_dict(self) -> dict:
        return dict(status=self.status, reason=self.reason, notes=list(self.notes),
                    artefacts=[a.as_dict() for a in self.artefacts])


@dataclass
class Assessment:
    quality: StepQuality
    records: PeriodicRecords | None      # of the cleaned (and possibly trimmed) records; None if rejected
    cleaned: dict | None = None          # channel -> cleaned samples
    start: int = 0                       # first sample kept


# ---------------------------------------------------------------------------- raw-sample faults


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, length) of the runs of True."""
    if not mask.any():
        return []
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return list(zip(starts.tolist(), (ends - starts).tolist()))


def find_clipping(ch: str, x: np.ndarray, fs: float, f: float) -> list[Artefact]:
    """Samples piled up at the record's largest or smallest value (a flat top): at least 5,
    in flat runs, and 5 times more than at the next value inwards (a quantised record
    that is not clipped has about as many there); on a converter coarser than the noise,
    also a signal that would have gone beyond the level during the longest run (:func:`_beyond`)."""
    out: list[Artefact] = []
    span = float(x.max() - x.min())
    if not span > 0:
        return out
    tol = 1e-9 * span
    q = _quantum(x)
    # below a quantum of noise a slow signal dwells at its own top value for a few samples at
    # every turning point, and coherent sampling makes the counts per value lumpy: there the
    # pile-up alone does not tell a clipped top (decision 0039)
    def coarse() -> bool:
        return q > 0 and _robust_noise(x - _periodic_part(x, fs, f)) < q

    for level in (float(x.max()), float(x.min())):
        at = np.abs(x - level) <= tol
        n_at = int(at.sum())
        if n_at < 5:
            continue
        inward = level - math.copysign(q, level - float(np.median(x)))
        n_next = int((np.abs(x - inward) <= tol).sum()) if q > 10 * tol else 0
        runs = [r for r in _runs(at) if r[1] >= 2]
        if n_at >= 5 * (n_next + 1) and runs and (not coarse() or _beyond(x, max(runs, key=lambda r: r[1]), level, q)):
            out.append(Artefact("clipping", ch, level, "rejected", time_s=runs[0][0] / fs, duration_s=n_at / fs,
                                evidence=f"{n_at} samples ({100 * n_at / x.size:.2g} % of the record) flat at the "
                                         f"extreme value in {len(runs)} runs"))
    return out


def _beyond(x: np.ndarray, run: tuple[int, int], level: float, q: float) -> bool:
    """Would the signal have gone beyond ``level`` during this flat run?  A parabola through
    the samples just either side of it, carried into the run, passes the level by more than
    3 quanta and 3 standard errors of that prediction: a clipped top.  A quantised signal
    turning within its top quantum by itself gives a parabola that turns there (0039)."""
    s_, L = run
    m = max(L // 4, 8)
    idx = np.r_[max(s_ - m, 0):s_, s_ + L:min(s_ + L + m, x.size)]
    if idx.size < 6:
        return True                           # nothing to carry in from: the histogram decides
    t = (idx - (s_ + 0.5 * (L - 1))) / m
    A = np.column_stack([np.ones(idx.size), t, t * t])
    coef, *_ = np.linalg.lstsq(A, x[idx], rcond=None)
    resid = x[idx] - A @ coef
    s2 = float(resid @ resid) / (idx.size - 3) + q * q / 12.0
    tt = np.linspace(-0.5 * L / m, 0.5 * L / m, 9)
    B = np.column_stack([np.ones(tt.size), tt, tt * tt])
    inside = B @ coef
    se = np.sqrt(s2 * np.einsum("ij,jk,ik->i", B, np.linalg.inv(A.T @ A), B))
    beyond = inside - level if level >= float(np.median(x)) else level - inside
    return bool(np.any(beyond > np.maximum(3.0 * q, 3.0 * se)))


def _quantum(x: np.ndarray) -> float:
    """The smallest step between distinct values (the ADC's resolution, if quantised)."""
    u = np.unique(x)
    d = np.diff(u)
    d = d[d > 1e-12 * max(float(np.ptp(x)), 1e-300)]
    return float(d.min()) if d.size else 0.0


def find_dropouts(ch: str, x: np.ndarray, fs: float, f: float, clipped: list[Artefact]) -> list[Artefact]:
    """Runs of at least ``DROPOUT_MIN_SAMPLES`` identical samples (not at a clipping level)
    that the signal could not have made: their probability, given where the periodic fit
    puts the signal during the run, its noise and the quantum (:func:`natural_run_chance`),
    is below ``DROPOUT_FALSE_ALARM`` / samples.  One artefact per channel: the first, with
    the count.  A record holding one value throughout is a drop-out over its whole length."""
    n = x.size
    tol = 1e-9 * max(float(np.ptp(x)), 1e-300)
    runs = [(s_, r + 1) for s_, r in _runs(np.diff(x) == 0)          # r equal diffs = r + 1 equal samples
            if r + 1 >= DROPOUT_MIN_SAMPLES and not any(abs(x[s_] - a.size) <= tol for a in clipped)]
    if not runs:
        return []
    if runs[0][1] == n:
        return [Artefact("dropout", ch, float(x[0]), "rejected", time_s=0.0, duration_s=n / fs,
                         evidence="the channel holds one value over the whole record")]
    # a long hold far from the signal pulls the fitted harmonics (and the noise) with it, which
    # makes natural runs elsewhere look unlikely: the fit is made again with the runs found held
    # bridged by a straight line between the samples either side, until the runs found stop changing
    limit = math.log(DROPOUT_FALSE_ALARM / n)
    extra: np.ndarray | None = None
    for with_lines in (False, True):
        fill, found = x, None
        for _ in range(4):
            log_chance, dev, noise, q = natural_run_chance(x, fs, f, runs, fill, extra)
            held = [i for i, lc in enumerate(log_chance) if lc < limit]
            if held == found or not held:
                break
            mask = np.zeros(n, bool)
            for i in held:
                mask[runs[i][0]:runs[i][0] + runs[i][1]] = True
            if mask.all():
                break
            idx = np.arange(n)
            found, fill = held, x.copy()
            fill[mask] = np.interp(idx[mask], idx[~mask], x[~mask])
        if not held or with_lines:
            break
        # a line not locked to the drive (hum) moves the signal away from the periodic fit: on a
        # converter coarser than the noise, runs the line made itself look impossible.  Its
        # lines, fitted with the held runs bridged, join the signal and the runs are judged again
        lines, _ = _find_lines(fill - _periodic_part(fill, fs, f), fs, f)
        if not lines:
            break
        extra = np.sum([ln.model for ln in lines], axis=0)
    bad = [(runs[i], log_chance[i], dev[i]) for i in held]
    if not bad:
        return []
    (s0, n0), lc0, d0 = bad[0]
    total = sum(L for (_, L), _, _ in bad)
    chance = f"{math.exp(lc0):.1g}" if lc0 > -700 else f"1e{lc0 / math.log(10):.0f}"
    return [Artefact("dropout", ch, float(x[s0]), "rejected", time_s=s0 / fs, duration_s=n0 / fs,
                     evidence=f"{len(bad)} run(s) of identical samples, {total} samples in all, longest "
                              f"{max(L for (_, L), _, _ in bad)}; during the first the signal (periodic fit) was up "
                              f"to {si(d0, UNIT[ch])} from the held value, against a noise of {si(noise, UNIT[ch])} "
                              f"and a quantum of {si(q, UNIT[ch])}: a chance of {chance} "
                              f"(limit {DROPOUT_FALSE_ALARM / n:.1g} a run, {DROPOUT_FALSE_ALARM:g} per record)")]


def natural_run_chance(x: np.ndarray, fs: float, f: float, runs: list[tuple[int, int]],
                       fit_to: np.ndarray | None = None,
                       extra: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, float, float]:
    """For each (start, length) run of identical samples of ``x``: the log of the probability
    that the signal itself made it and how far the signal was from the held value; then the
    noise s_n and the quantum.  The signal is the periodic fit to ``fit_to`` (default ``x``)
    plus ``extra`` (lines not locked to the drive, when given).

    Sample i of a record quantised with step q (the smallest step between its values) is
    Q(m_i + e_i): m the signal, e Gaussian noise of rms s_n.  Given the first sample c of a
    run, the next ones all equal c with probability prod_i P(|m_i + e_i - c| <= q/2) (the
    noise of different samples is independent; the signal is not, which is why repeats
    cluster where it is slow).  m is the periodic fit (offset and every harmonic, as
    :mod:`sim.records` fits them), whose error s_m = s / sqrt(periods) (s the residual rms)
    is integrated over as an offset shared by the run's samples (a normal law) and also
    added to the noise sample by sample; s_n^2 = s^2 - q^2 / 12 (Sheppard: the residual
    holds the quantisation error too).  The runs themselves are left out of s.  With a whole
    number of samples per period, where the fit is within a quantum of the held value, the
    share of the other periods in which the sample had that value ((k + 1) / (P - 1 + 2)) is
    used when it is larger: the mean of quantised samples is not the signal there."""
    n = x.size
    q = _quantum(x)
    m = _periodic_part(x if fit_to is None else fit_to, fs, f)
    if extra is not None:
        m = m + extra
    keep = np.ones(n, bool)
    for s_, L in runs:
        keep[s_:s_ + L] = False
    r = (x - m)[keep]
    s_tot = math.sqrt(float(np.mean(r * r))) if r.size else 0.0
    s_n = math.sqrt(max(s_tot ** 2 - q * q / 12.0, 0.0))
    s_m = s_tot / math.sqrt(max(1, int(math.floor(n * f / fs + 1e-9))))     # the fit's error
    sig = math.hypot(s_n, s_m)
    z = np.linspace(-6.0, 6.0, 25) if s_m > 0 else np.zeros(1)
    log_w = -0.5 * z * z - logsumexp(-0.5 * z * z)
    d = np.concatenate([m[s_ + 1:s_ + L] - x[s_] for s_, L in runs])     # signal - held value, after the first
    dd = d[None, :] + s_m * z[:, None]
    if sig > 0:
        lo, hi = (-0.5 * q - dd) / sig, (0.5 * q - dd) / sig
        flip = lo + hi > 0                       # keep to the lower tail, where log_ndtr is accurate
        lo, hi = np.where(flip, -hi, lo), np.where(flip, -lo, hi)
        ln_hi = log_ndtr(hi)
        with np.errstate(divide="ignore"):
            log_p = ln_hi + np.log(-np.expm1(log_ndtr(lo) - ln_hi))
    else:
        log_p = np.where(np.abs(dd) <= 0.5 * q * (1 + 1e-9), 0.0, -np.inf)
    periods = int(math.floor(n * f / fs + 1e-9))
    spp = int(round(fs / f)) if abs(fs / f - round(fs / f)) * periods < 0.02 else 0
    if spp and periods >= 2:
        # samples at the drive's phases: where the fit (the mean period) is within a quantum of
        # the held value, the other periods show how often that sample had it (rule of
        # succession).  The mean of quantised samples is not the signal where the noise is below
        # the quantum: near a step between two levels it lies between them.
        i = np.concatenate([np.arange(s_ + 1, s_ + L) for s_, L in runs])
        c = np.concatenate([np.full(L - 1, x[s_]) for s_, L in runs])
        same = x[:periods * spp].reshape(periods, spp)[:, i % spp] == c        # (periods, samples)
        own = i // spp < periods
        count = same.sum(axis=0) - own * same[np.minimum(i // spp, periods - 1), np.arange(i.size)]
        share = np.log((count + 1.0) / (periods - own + 2.0))
        log_p = np.where(np.abs(d) < q, np.maximum(log_p, share), log_p)
    starts = np.cumsum([0] + [L - 1 for _, L in runs[:-1]])
    log_run = np.add.reduceat(log_p, starts, axis=1)                  # (nodes, runs)
    dev = np.maximum.reduceat(np.abs(d), starts)
    return logsumexp(log_w[:, None] + log_run, axis=0), dev, s_n, q


# ---------------------------------------------------------------------------- periodic part


def _periodic_part(x: np.ndarray, fs: float, f: float, fit_from: int = 0) -> np.ndarray:
    return _periodic_fit(x, fs, f, fit_from)[0]


def _periodic_fit(x: np.ndarray, fs: float, f: float, fit_from: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Offset + every harmonic below Nyquist (at most 200), fitted over the whole periods of
    ``x[fit_from:]`` as :mod:`sim.records` does, evaluated at every sample of ``x``; and
    the fitted harmonics."""
    n = x.size
    ratio = fs / f
    periods = int(math.floor((n - fit_from) / ratio + 1e-9))
    spp = int(round(ratio)) if abs(ratio - round(ratio)) * periods < 0.02 else None
    ch = analyse_channel(x[fit_from:], fs, f, periods, spp, 200)
    if spp is not None:
        return ch.mean_period[(np.arange(n) - fit_from) % spp], ch.harmonics
    M = 1 << max(12, int(math.ceil(math.log2(16 * ch.harmonics.size + 1))))
    spec = np.zeros(M // 2 + 1, complex)
    spec[1:ch.harmonics.size + 1] = -1j * ch.harmonics * (M / 2)      # C_k = A e^(i phi) of A sin(k w t + phi)
    one = np.fft.irfft(spec, M)
    phase = ((np.arange(n) - fit_from) * (f / fs)) % 1.0 * M
    return ch.offset + np.interp(phase, np.arange(M + 1), np.append(one, one[0])), ch.harmonics


def _aliases(C: np.ndarray, se: float, f: float, fs: float) -> np.ndarray:
    """Frequencies (Hz, in 0..fs/2) where drive harmonics above Nyquist fold back, when the
    fitted harmonics show the response still has content there (one of the top tenth above
    what noise alone reaches with probability 1e-3); how far up is extrapolated from their
    power-law decay (at most 8 x)."""
    K = C.size
    if K < 6 or (K + 1) * f < 0.45 * fs:          # harmonics capped below Nyquist: nothing folds
        return np.zeros(0)
    a = np.abs(C)
    m = max(3, K // 10)
    top = float(np.max(a[-m:]))
    if not top > math.sqrt(2 * math.log(m / 1e-3)) * se:     # noise alone: probability 1e-3 (Rayleigh)
        return np.zeros(0)
    k = np.arange(1, K + 1)
    upper = (k >= K // 2) & (a > 3 * se)
    b = np.polyfit(np.log(k[upper]), np.log(a[upper]), 1)[0] if upper.sum() >= 3 else 0.0
    kmax = K * min(8.0, (top / se) ** (1 / -b) if b < -0.5 else 8.0)
    kk = np.arange(K + 1, int(kmax) + 1) * f
    return np.sort(np.abs(kk - np.round(kk / fs) * fs))


def _trend(r: np.ndarray, noise: float) -> tuple[np.ndarray, float, float]:
    """Linear + quadratic trend of the residual: (trend, change over the record, z score)."""
    n = r.size
    tau = np.arange(n) / max(n - 1, 1) - 0.5
    A = np.column_stack([np.ones(n), tau, tau * tau - 1.0 / 12.0])
    coef, *_ = np.linalg.lstsq(A, r, rcond=None)
    cov = noise ** 2 * np.linalg.inv(A.T @ A)[1:, 1:]
    b = coef[1:]
    z = math.sqrt(max(float(b @ np.linalg.solve(cov, b)), 0.0)) if noise > 0 else math.inf
    trend = A[:, 1:] @ b
    return trend, float(trend[-1] - trend[0]), z


def quantisation_line_bound(q: float, noise: float) -> float:
    """The largest amplitude one spectral line of a quantiser's error can have (decision 0039).

    The error of Q(y + e) - y, a function of the signal y under Gaussian noise e (rms
    ``noise`` before quantisation), is a Fourier series in y with terms
    (q / (pi m)) exp(-2 pi^2 m^2 noise^2 / q^2) sin(2 pi m y / q) (Widrow's quantisation
    theory).  A periodic y makes each term periodic with the drive: its harmonics go far
    above Nyquist and fold back as steady "lines" at any frequency.  No such line exceeds
    the sum of the terms' amplitudes, nor 2 q / pi (the largest sinusoid in an error
    bounded by q / 2).  0 for an unquantised record."""
    if q <= 0:
        return 0.0
    m = np.arange(1, 51)
    terms = np.exp(-2.0 * (math.pi * noise / q) ** 2 * m * m) / m
    return float(min(2.0 / math.pi, terms.sum() / math.pi) * q)


def _robust_noise(r: np.ndarray) -> float:
    """Noise rms per sample from the median absolute difference of neighbours (lines,
    transients and slow trends barely move it)."""
    d = np.diff(r)
    return float(np.median(np.abs(d - np.median(d))) / 0.6745 / math.sqrt(2.0))


# ---------------------------------------------------------------------------- lines and transients


@dataclass
class _Line:
    freq_Hz: float
    amp: float
    decay: float          # sigma, 1/s (0 for a steady line)
    decay_se: float
    model: np.ndarray     # samples
    decay_bound: float = math.nan   # a steady line: its decay rate's upper bound (fit + 2 standard errors), 1/s


def _fit_sinusoid(r: np.ndarray, fs: float, f0: float, with_decay: bool) -> _Line | None:
    """Least squares of e^(-sigma t) (a sin wt + b cos wt) + c on ``r`` from the frequency
    ``f0`` (sigma = 0 unless ``with_decay``); t from the record start."""
    n = r.size
    scale = float(np.std(r)) or 1.0
    r = r / scale
    t = np.arange(n) / fs
    T = n / fs
    tt = t / T
    w0 = 2 * np.pi * f0
    nd = 2 if with_decay else 1                # nonlinear parameters: (w - w0) T [, sigma T]

    def parts(p):
        w = w0 + p[0] / T
        sig = p[1] / T if with_decay else 0.0
        e = np.exp(-sig * t)
        return w, sig, e * np.sin(w * t), e * np.cos(w * t)

    def resid(p):
        _, _, s, c = parts(p)
        return p[nd] * s + p[nd + 1] * c + p[nd + 2] - r

    def jac(p):
        _, _, s, c = parts(p)
        a, b = p[nd], p[nd + 1]
        cols = [tt * (a * c - b * s)]
        if with_decay:
            cols.append(-tt * (a * s + b * c))
        return np.column_stack(cols + [s, c, np.ones(n)])

    ab, *_ = np.linalg.lstsq(np.column_stack([np.sin(w0 * t), np.cos(w0 * t), np.ones(n)]), r, rcond=None)
    p0 = np.concatenate([np.zeros(nd), ab])
    try:
        sol = least_squares(resid, p0, jac=jac, method="lm", x_scale="jac", max_nfev=40)
        J = jac(sol.x)
        cov = float(sol.fun @ sol.fun) / max(1, n - p0.size) * np.linalg.pinv(J.T @ J)
    except (ValueError, np.linalg.LinAlgError):
        return None
    p = sol.x
    w, sig, s, c = parts(p)
    if not (math.isfinite(w) and w > 0):
        return None
    return _Line(freq_Hz=w / (2 * np.pi), amp=scale * float(math.hypot(p[nd], p[nd + 1])), decay=sig,
                 decay_se=math.sqrt(max(cov[1, 1], 0.0)) / T if with_decay else 0.0,
                 model=scale * (p[nd] * s + p[nd + 1] * c))


NO_FREQUENCIES = np.zeros(0)     # no aliased harmonics (read only)


def _line_search(q: np.ndarray, fs: float, f: float, skip: list[float],
                 aliases: np.ndarray = NO_FREQUENCIES) -> list[tuple[float, float]]:
    """Candidate (frequency, peak power / noise floor) of the residual, strongest first,
    away from the drive harmonics, their ``aliases`` and the frequencies in ``skip``."""
    n = q.size
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    S = np.abs(np.fft.rfft((q - q.mean()) * np.hanning(n), nfft)) ** 2
    freqs = np.arange(S.size) * fs / nfft
    guard = HARMONIC_GUARD * fs / n
    k = np.round(freqs / f)
    ok = (np.abs(freqs - k * f) > guard) & (freqs > guard) & (freqs < fs / 2 - guard)
    for fk in skip:
        ok &= np.abs(freqs - fk) > guard
    if aliases.size:
        i = np.clip(np.searchsorted(aliases, freqs), 0, aliases.size - 1)
        near = np.minimum(np.abs(freqs - aliases[i]), np.abs(freqs - aliases[np.maximum(i - 1, 0)]))
        ok &= near > guard
    if ok.sum() < 16:
        return []
    floor = float(np.median(S[ok])) / math.log(2.0)
    thr = floor * (math.log(n / 2) - math.log(LINE_FALSE_ALARM))
    peak = ok & (S > thr)
    peak[1:-1] &= (S[1:-1] >= S[:-2]) & (S[1:-1] >= S[2:])
    idx = np.flatnonzero(peak)
    return [(float(freqs[i]), float(S[i] / floor)) for i in idx[np.argsort(S[idx])[::-1]]]


def _find_lines(q: np.ndarray, fs: float, f: float,
                aliases: np.ndarray = NO_FREQUENCIES) -> tuple[list[_Line], list[_Line]]:
    """Steady lines and decaying components of the residual ``q``, strongest first."""
    n = q.size
    guard = HARMONIC_GUARD * fs / n
    lines: list[_Line] = []
    transients: list[_Line] = []
    found = np.zeros(n)
    while len(lines) < MAX_LINES and len(transients) < 2:
        cands = _line_search(q - found, fs, f, [ln.freq_Hz for ln in lines + transients], aliases)
        if not cands:
            break
        steady = _fit_sinusoid(q - found, fs, cands[0][0], with_decay=False)
        if steady is None:
            break
        decaying = _fit_sinusoid(q - found, fs, steady.freq_Hz, with_decay=True)
        is_transient = (decaying is not None and decaying.decay > DECAY_Z * decaying.decay_se
                        and math.exp(-decaying.decay * n / fs) < DECAY_FRACTION)
        ln = decaying if is_transient and decaying is not None else steady
        if not is_transient and decaying is not None and decaying.decay_se > 0:
            ln = replace(ln, decay_bound=max(decaying.decay, 0.0) + 2 * decaying.decay_se)
        k = round(ln.freq_Hz / f)
        if k >= 1 and abs(ln.freq_Hz - k * f) <= guard:       # moved onto a drive harmonic: not separable
            break
        if aliases.size and np.min(np.abs(aliases - ln.freq_Hz)) <= guard:    # onto an aliased harmonic
            break
        (transients if is_transient else lines).append(ln)
        found = found + ln.model
    if len(lines) + len(transients) > 1:
        # each component fitted again with the others removed: a strong neighbour within a few
        # resolutions pulls a line's frequency (a 50 Hz hum beside the carriage's 71 Hz
        # ringing was fitted at 49.4 Hz, outside the mains tolerance)
        for group, decay in ((lines, False), (transients, True)):
            for i, ln in enumerate(group):
                again = _fit_sinusoid(q - (found - ln.model), fs, ln.freq_Hz, with_decay=decay)
                if again is not None and abs(again.freq_Hz - ln.freq_Hz) <= guard:
                    found = found - ln.model + again.model
                    group[i] = again
    return lines, transients


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
    for _pass in range(4):        # a trend converges more slowly than lines: more passes only for it
        periodic, C = _periodic_fit(x - removed, fs, f)
        r = x - periodic
        seen = _robust_noise(r)
        noise = max(seen, floor)
        below = quantisation_line_bound(q, math.sqrt(max(seen * seen - floor * floor, 0.0)))
        aliases = _aliases(C, noise * math.sqrt(2.0 / n), f, fs)
        lines, transients = _find_lines(r, fs, f, aliases)
        lines = [ln for ln in lines if ln.amp > below]
        removed_part = sum((ln.model for ln in lines + transients), zero)
        trend, change, z = _trend(r - removed_part, noise)
        if not z > TREND_Z:
            trend, change, z = zero, 0.0, 0.0
        elif lines or transients:     # what the trend's low-frequency leakage made look like a line goes
            lines, transients = _find_lines(r - trend, fs, f, aliases)
            lines = [ln for ln in lines if ln.amp > below]
            removed_part = sum((ln.model for ln in lines + transients), zero)
            trend, change, z = _trend(r - removed_part, noise)
            if not z > TREND_Z:
                trend, change, z = zero, 0.0, 0.0
        new = trend + sum((ln.model for ln in lines + transients), zero)
        if (_pass == 0 and not lines and not transients and z == 0.0) or (_pass == 1 and z == 0.0):
            break
        removed = new
    cleaned = x - new
    rest = (r - new)[n // 2:]          # what is left, in the second half (after any transient): the noise
    noise = max(min(float(1.4826 * np.median(np.abs(rest - np.median(rest)))) or noise, noise), floor)
    arts = []
    if z > 0:
        arts.append(Artefact("offset_drift", ch, change, "removed",
                             evidence=f"linear + quadratic trend {z:.0f} standard errors from zero"))
    se = noise * math.sqrt(2.0 / n)
    for ln in lines:
        arts.append(Artefact("line_interference", ch, ln.amp, "removed", freq_Hz=ln.freq_Hz, snr=ln.amp / se,
                             decay_bound_per_s=ln.decay_bound,
                             evidence=f"{ln.amp / se:.0f} standard errors, {ln.freq_Hz / f:.3f} x the drive frequency"))
    found: list[tuple] = [(ln.amp, ln.decay, ln.freq_Hz, f"a decaying sinusoid fitted, decay rate {ln.decay:.3g} +- "
              f"{ln.decay_se:.2g} /s", True) for ln in transients]
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
    return (A0, float(sigma), math.nan, f"the difference between consecutive periods falls over the first {m} "
                                        f"of {P} periods (first by {z[0]:.0f} standard errors above the noise)")


# ---------------------------------------------------------------------------- one step


def _fundamental(x: np.ndarray, fs: float, f: float) -> float:
    """Amplitude of the drive-frequency component over the whole periods of ``x``."""
    n = int(math.floor(x.size * f / fs + 1e-9) * fs / f)
    t = np.arange(n) / fs
    return float(2.0 / n * abs(np.dot(x[:n] - x[:n].mean(), np.exp(-2j * np.pi * f * t))))


def _mains_hint(f: float, periods: int, failed: str, lines: list[Artefact]) -> str:
    """Mains (50/60 Hz, harmonics 1-3) too close to a drive harmonic to be separated in
    ``periods`` periods: what to do, or ''.  Named only when the records make it plausible
    (decision 0037): the periodicity gate failed on that very harmonic (``failed``, the
    gate's "harmonic k"; a line within the guard of harmonic k beats with it, and the
    halves differ there, not in the offset or another harmonic), or a line at a mains
    frequency was found elsewhere in the step (``lines``)."""
    guard = HARMONIC_GUARD * f / periods
    found = [a for a in lines if a.kind == "line_interference" and mains(a.freq_Hz)]
    k_failed = int(failed.split()[-1]) if failed.startswith("harmonic ") else 0
    for base in MAINS_HZ:
        for m in (1, 2, 3):
            fm = m * base
            k = max(1, round(fm / f))
            gap = abs(fm - k * f)
            seen = [a for a in found if mains(a.freq_Hz).startswith(f"{base:g} Hz")]
            if 0 < gap <= guard and (k == k_failed or seen):
                why = (f"a {seen[0].freq_Hz:.4g} Hz line was found on the {LABEL[seen[0].channel]}" if seen
                       else f"harmonic {k} is what changed")
                return (f"mains hum, if present, at {fm:g} Hz lies {gap:.2g} Hz from drive harmonic {k} "
                        f"({k * f:.4g} Hz) and cannot be separated from the response in {periods} periods "
                        f"({why}): measure at least {math.ceil(HARMONIC_GUARD * f / gap)} periods")
    return ""


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
    rate = ""
    if decay is not None and decay.decay_se > 0:
        rate = (f"; decay rate {decay.decay:.2g} +- {decay.decay_se:.2g} /s"
                + (", not significant" if not decay.decay > DECAY_Z * decay.decay_se else "")
                + f" in a {1e3 * n / fs:.3g} ms record")
    return (f"a free vibration of the carriage, not interference: the accelerometer's {si(abs(amp['accel']), 'm/s^2')} "
            f"at {fl:.4g} Hz is -(2 pi f)^2 times the probe's {si(abs(amp['disp']), 'm')} (ratio {abs(ratio):.2f}, "
            f"phase {math.degrees(math.atan2(ratio.imag, ratio.real)):+.0f} deg; "
            f"{abs(amp['accel']) / se['accel']:.0f} and {abs(amp['disp']) / se['disp']:.0f} standard errors){rate}")


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
            what = "transient" if decay > 0 else "free vibration"
            q.artefacts[i] = replace(a, kind="unsettled_transient", decay_per_s=decay, settle_cycles=cyc,
                                     evidence=f"at the frequency of the {what} on the {LABEL[tr[0].channel]}")
    if need > 0 and periods - need >= max(MIN_PERIODS, periods // 4):
        start = int(math.ceil(need * fs_Hz / f - 1e-9))
        for ch in CHANNELS:           # clean the kept part again: the fit is no longer biased by the transient
            cleaned[ch], _a, _t, noise[ch] = _clean_channel(ch, sig[ch][start:], fs_Hz, f)
        tr_arts = [a if a.action == "removed" else replace(a, action="trimmed") for a in tr_arts]
        q.notes.append(f"first {need} of {periods} periods dropped (unsettled transient)")
    q.artefacts += tr_arts
    rec = analyse_records(cleaned["force"], cleaned["accel"], cleaned["disp"], fs_Hz, f)
    if rec.drift_sigma > DRIFT_LIMIT:
        ch, what = rec.drift_detail.split(" ", 1)
        q.status = "rejected"
        q.reason = (f"not periodic enough on the {LABEL.get(ch, ch)} ({ch}): its {what} changes by "
                    f"{rec.drift_sigma:.0f} standard errors between the two halves of the record "
                    f"(limit {DRIFT_LIMIT:g})")
        hint = _mains_hint(f, periods, what, q.artefacts)
        if hint:
            q.reason += f"; {hint}"
        if tr_arts:
            worst = max(tr_arts, key=lambda a: a.settle_cycles)
            q.reason += f"; {worst.describe()}"
            q.artefacts = [replace(a, action="rejected") if a.kind == "unsettled_transient" else a
                           for a in q.artefacts]
        return Assessment(q, None)
    q.notes = [a.describe() for a in q.artefacts] + q.notes
    d = rec.channels["disp"]
    a1 = abs(d.harmonics[0]) if d.harmonics.size else 0.0
    ratio = d.noise_rms / a1 if a1 > 0 else math.inf
    if ratio > NOISY_RESIDUAL:
        q.notes.append(f"noisy: displacement residual {100 * ratio:.3g} % of the fundamental "
                       f"(limit {100 * NOISY_RESIDUAL:g} %; used with its noise as weight)")
    q.status = "flagged" if q.notes else "usable"
    return Assessment(q, rec, cleaned, start)


# ---------------------------------------------------------------------------- many steps


MAINS_HZ = (50.0, 60.0)
LABELS = {"line_interference": "interference line", "unsettled_transient": "unsettled transient",
          "clipping": "clipping", "dropout": "drop-outs", "offset_drift": "offset drift"}
FORMULAS = {"line_interference": "y_measured = y + a sin(2 pi f_l t + phi), f_l not a multiple of the drive",
            "unsettled_transient": "y_measured = y_periodic + A_0 exp(-sigma t) sin(2 pi f_t t + phi) at the record start",
            "clipping": "y_measured = clip(y, low, high)",
            "dropout": "y_measured = y(t_0) held (or 0) for a time",
            "offset_drift": "y_measured = y + b t + c t^2"}


def mains(freq_Hz: float) -> str:
    """'50 Hz mains' when the frequency is a harmonic 1-10 of 50 or 60 Hz (within 0.5 %), else ''."""
    for base in MAINS_HZ:
        m = round(freq_Hz / base)
        if 1 <= m <= 10 and abs(freq_Hz / (m * base) - 1) < 0.005:
            return f"{base:g} Hz mains" + (f" (harmonic {m})" if m > 1 else "")
    return ""


def _span(values, unit: str, fmt: str = ".3g") -> str:
    lo, hi = min(values), max(values)
    return f"{lo:{fmt}} {unit}" if f"{lo:{fmt}}" == f"{hi:{fmt}}" else f"{lo:{fmt}}-{hi:{fmt}} {unit}"


def _param(values, unit: str) -> dict:
    v = np.asarray(values, float)
    return dict(value=float(np.median(v)), low=float(v.min()), high=float(v.max()), unit=unit)


def _where(qs: list[StepQuality]) -> str:
    f = [q.freq_Hz for q in qs if math.isfinite(q.freq_Hz)]
    lv = [q.level_N for q in qs if math.isfinite(q.level_N)]
    parts = ([f"at {_span(f, 'Hz')}"] if f else []) + ([_span(lv, "N")] if lv else [])
    return ", ".join(parts)


# ---------------------------------------------------------------------------- many steps: whose line?

REPEAT_STEPS = 3            # a line at one frequency in at least this many steps comes from a steady source
LINE_CLUSTER_REL = 0.002    # ... one frequency: within 0.2 % (at least 0.05 Hz); a mode wanders more with level
MODE_REL = 0.1              # the rig's vibrations within 10 % of a line's frequency are the same mode


def _same_line(f1: float, f2: float) -> bool:
    return abs(f1 - f2) <= max(0.05, LINE_CLUSTER_REL * max(f1, f2))


def _vibration_Hz(a: Artefact) -> bool:
    """An unsettled transient or free vibration with a frequency of its own (the rig's mode)."""
    return a.kind == "unsettled_transient" and math.isfinite(a.freq_Hz)


def attribute_lines(quality: list[tuple[str, StepQuality]],
                    resonances_Hz: tuple[float, ...] = ()) -> list[tuple[str, StepQuality]]:
    """Whose line is it?  The steps of one source in the order they were measured, with
    every ``line_interference`` that is not interference named what it is: the rig's own
    unsettled free vibration (decision record 0045).

    One step cannot tell a weak free vibration seen by one sensor from a hum (decision
    0033); the source can.  A line at a mains frequency (50/60 Hz and harmonics,
    :func:`mains`) is interference: the fundamental, or a harmonic when the family shows in
    at least 2 steps.  Any other line is the rig's own motion when it is
    within ``MODE_REL`` of the frequency of a vibration of the step before (each frequency
    change rings the same mode, whose frequency moves a little with the level), of one
    that any step shows as the rig's (a decaying sinusoid fitted, or probe and accelerometer
    seeing one motion), or of a resonance of the source's own response (``resonances_Hz``:
    the most compliant frequency of each force level, where the rig rings); else it is interference from a steady source when it comes back at
    one frequency (within ``LINE_CLUSTER_REL``) in at least ``REPEAT_STEPS`` steps.  What is
    left, a line in one or two steps at frequencies no steady source explains, is the rig's
    own ringing too (pre-rolling friction damps little at small amplitude).  The rig's own
    becomes an ``unsettled_transient`` without a decay rate of its own, with settle advice
    from the decay rate of the source's fitted transients near its frequency (else of all
    of them), counted as :func:`settle_cycles` counts."""
    lines = [(i, a) for i, (_, q) in enumerate(quality) for a in q.artefacts if a.kind == "line_interference"]
    family: dict[str, set[int]] = {}             # mains base -> steps with a line of its family
    for i, a in lines:
        if mains(a.freq_Hz):
            family.setdefault(mains(a.freq_Hz).split(" (")[0], set()).add(i)

    def is_mains(f: float) -> bool:
        """A mains frequency whose family the source shows: the fundamental, or a harmonic
        (a window of 0.5 % that a stray line at a high frequency can fall into) seen with
        its family in at least 2 steps."""
        src = mains(f)
        return bool(src) and ("harmonic" not in src or len(family[src.split(" (")[0]]) >= 2)

    repeated = {(i, id(a)) for i, a in lines
                if len({i2 for i2, b in lines if _same_line(a.freq_Hz, b.freq_Hz)}) >= REPEAT_STEPS}
    decays = [(a.freq_Hz, a.decay_per_s) for _, q in quality for a in q.artefacts
              if _vibration_Hz(a) and a.decay_per_s > 0]
    modes = [(f"the {a.freq_Hz:.4g} Hz vibration of step {key}", a.freq_Hz)
             for key, q in quality for a in q.artefacts if _vibration_Hz(a)]
    modes += [(f"the {fr:.4g} Hz resonance of the measured response", float(fr)) for fr in resonances_Hz]
    vib: list[list[float]] = [[a.freq_Hz for a in q.artefacts if _vibration_Hz(a)] for _, q in quality]
    out = []
    for i, (key, q) in enumerate(quality):
        arts, changed = [], False
        for a in q.artefacts:
            if a.kind != "line_interference" or is_mains(a.freq_Hz):
                arts.append(a)
                continue
            near = lambda fv: abs(fv / a.freq_Hz - 1) <= MODE_REL          # noqa: E731
            before = [fv for fv in (vib[i - 1] if i else []) if near(fv)]
            mode = [(k, fv) for k, fv in modes if near(fv)]
            if before:
                why = (f"at the frequency of the vibration of the step before ({quality[i - 1][0]}, "
                       f"{before[0]:.4g} Hz): the rig's own free vibration, not interference")
            elif mode:
                why = (f"near {mode[0][0]}"
                       + (f" and {len(mode) - 1} other(s)" if len(mode) > 1 else "")
                       + ", the rig's own mode: the rig's own free vibration, not interference")
            elif (i, id(a)) in repeated:
                arts.append(a)
                continue
            else:
                why = (f"at no mains frequency and in fewer than {REPEAT_STEPS} steps at one frequency: the rig's own "
                       f"free vibration, not interference")
            arts.append(_as_vibration(a, q, why, decays))
            vib[i].append(a.freq_Hz)
            changed = True
        if not changed:
            out.append((key, q))
            continue
        old = {a.describe() for a in q.artefacts}
        notes = ([a.describe() for a in arts] + [n for n in q.notes if n not in old]) if q.notes else []
        out.append((key, replace(q, artefacts=arts, notes=notes)))
    return out


def _as_vibration(a: Artefact, q: StepQuality, why: str, decays: list[tuple[float, float]]) -> Artefact:
    """Line ``a`` of step ``q`` named an unsettled free vibration, with settle advice from
    the decay rates (frequency, rate) the source's fitted transients show."""
    near = [r for fr, r in decays if abs(fr / a.freq_Hz - 1) <= MODE_REL]
    rates = near or [r for _, r in decays]
    cycles, advice, least = 0, "", False
    if not (math.isfinite(a.snr) and math.isfinite(q.record_s) and math.isfinite(q.freq_Hz)):
        pass
    elif rates:
        sigma = float(np.median(rates))
        z = a.snr / max(1.0, sigma * q.record_s / 2)
        cycles = int(math.ceil(q.freq_Hz * math.log(z) / sigma)) if z > 1 else 0
        advice = (f"; settle advice from the decay rate {sigma:.3g} /s of the source's transients"
                  + (" near this frequency" if near else ""))
    elif a.decay_bound_per_s > 0:     # no transient to learn from: the record's own bound, so at least this many
        sigma = a.decay_bound_per_s
        z = a.snr / max(1.0, sigma * q.record_s / 2)
        cycles = int(math.ceil(q.freq_Hz * math.log(z) / sigma)) if z > 1 else 0
        advice = f"; its decay rate is below {sigma:.3g} /s (fit + 2 standard errors)"
        least = True
    return replace(a, kind="unsettled_transient", settle_cycles=cycles, settle_at_least=least,
                   evidence=f"{a.evidence}; {why}{advice}")


def artefact_causes(quality: list[tuple[str, StepQuality]], total: int | None = None) -> list[dict]:
    """``analysis.json`` causes of kind "artefact", aggregated over steps (module doc): one
    cause per family, never one per step.  Lines: the mains family of each mains frequency
    (its harmonics and channels together), and each other steady line frequency; unsettled
    transients and free vibrations: one cause; clipping, drop-outs, offset drift: one per
    channel.

    ``quality``: (step key, quality) of every step whose records were read, with the lines
    attributed (:func:`attribute_lines`); ``total``: the number of steps in the source
    (default: len(quality))."""
    total = len(quality) if total is None else total
    order = {key: i for i, (key, _) in enumerate(quality)}
    hits: dict[tuple, list[tuple[str, StepQuality, Artefact]]] = {}
    lines: list[tuple[str, StepQuality, Artefact]] = []
    for key, q in quality:
        for a in q.artefacts:
            if a.kind == "line_interference":
                lines.append((key, q, a))
            elif a.kind == "unsettled_transient":
                hits.setdefault(("unsettled_transient",), []).append((key, q, a))
            else:
                hits.setdefault((a.kind, a.channel), []).append((key, q, a))
    out = []
    families: dict[str, list] = {}
    for it in sorted(lines, key=lambda it: it[2].freq_Hz):
        src = mains(it[2].freq_Hz)
        fam = src.split(" (")[0] if src else None
        if fam is None:               # a steady line of another source: its frequency cluster
            fam = next((k for k, g in families.items() if not k.endswith("mains")
                        and _same_line(g[-1][2].freq_Hz, it[2].freq_Hz)), f"{it[2].freq_Hz:.6g} Hz")
        families.setdefault(fam, []).append(it)
    for fam, items in families.items():
        out.append(_line_cause(fam, sorted(items, key=lambda it: order[it[0]]), total))
    for (kind, *rest), items in hits.items():
        out.append(_other_cause(kind, rest[0] if rest else "", items, total))
    out.sort(key=lambda c: -len(c["evidence"]["steps"]))
    return out


def _entry(kind: str, channel: str, items, total: int, parameters: dict, sentence: str) -> dict:
    steps = list(dict.fromkeys(k for k, _, _ in items))
    rejected = list(dict.fromkeys(k for k, q, _ in items if q.status == "rejected"))
    return dict(id=kind, kind="artefact", label=LABELS[kind], formula=FORMULAS[kind], channel=channel,
                parameters=parameters, gain=dict(steps_kept=len(steps) - len(rejected), steps_rejected=len(rejected)),
                sentence=sentence,
                evidence=dict(steps=steps, steps_total=total, steps_rejected=rejected,
                              per_step=[dict(step=k, **a.as_dict()) for k, _, a in items]))


def _line_cause(family: str, items, total: int) -> dict:
    """One interference family: the mains of one frequency (any harmonic, any channel) or
    one other steady line.  Its parameters are those of its main line (the channel and
    harmonic in most steps), which a twin can rebuild; the others are in the sentence and
    the evidence."""
    base = float(family.split()[0]) if family.endswith("mains") else 0.0

    def line_of(a: Artefact) -> tuple[str, int]:
        return a.channel, (round(a.freq_Hz / base) if base else 1)

    count: dict[tuple[str, int], set] = {}
    for k, _, a in items:
        count.setdefault(line_of(a), set()).add(k)
    main = max(count, key=lambda c: len(count[c]))
    ch = main[0]
    f = [a.freq_Hz for _, _, a in items if line_of(a) == main]
    amp = [a.size for _, _, a in items if line_of(a) == main]
    n = len({k for k, _, _ in items})
    what = (f"{family} interference" if base else "interference from another source (a pump, a fan, a switching supply)")
    others = sorted(set(count) - {main})
    also = ("; also " + ", ".join((f"{m * base:g} Hz " if base else "") + f"on the {LABEL[c]} ({len(count[(c, m)])} steps)"
                                  for c, m in others)) if others else ""
    sentence = (f"a {np.median(f):.4g} Hz line of {si(float(np.median(amp)), UNIT[ch])} on the {LABEL[ch]} in {n} of "
                f"{total} steps, not locked to the drive: {what}{also}; removed before the fit")
    return _entry("line_interference", ch, items, total,
                  dict(frequency=_param(f, "Hz"), amplitude=_param(amp, UNIT[ch])), sentence)


def _other_cause(kind: str, ch: str, items, total: int) -> dict:
    qs = list({id(q): q for _, q, _ in items}.values())
    n = len(qs)
    arts = [a for _, _, a in items]
    rej = sum(q.status == "rejected" for q in qs)
    fate = (f"{n - rej} kept" if n > rej else "") + (", " if 0 < rej < n else "") + (f"{rej} rejected" if rej else "")
    where = _where(qs)
    if kind == "unsettled_transient":
        chans = sorted({a.channel for a in arts})
        worst = max(arts, key=lambda a: a.settle_cycles)
        cyc = worst.settle_cycles
        tau = [1e3 / a.decay_per_s for a in arts if a.decay_per_s > 0]
        ft = [a.freq_Hz for a in arts if math.isfinite(a.freq_Hz)]
        vib = (f"the rig's own unsettled free vibration near {np.median(ft):.3g} Hz" if ft
               else "the rig's own unsettled free vibration")
        const = f", time constant {_span(tau, 'ms')}" if tau else ""
        advice = f"settle {'at least ' if worst.settle_at_least else ''}{cyc} more cycles" if cyc else "settle longer"
        sentence = (f"steps {where} still vibrating at the record start ({vib}{const}, on the "
                    f"{' and '.join(LABEL[c] for c in chans)}) in {n} of {total} steps: {advice}; "
                    f"{fate} (transient removed or first periods dropped where the record allowed)")
        rates = [a.decay_per_s for a in arts if a.decay_per_s > 0]
        params = dict(settle_cycles_needed=_param([a.settle_cycles for a in arts], "cycles"))
        if rates:
            params["decay_rate"] = _param(rates, "1/s")
        if ft:
            params["frequency"] = _param(ft, "Hz")
        return _entry(kind, ",".join(chans), items, total, params, sentence)
    size = [abs(a.size) for a in arts]
    if kind == "clipping":
        sentence = (f"clipping on the {LABEL[ch]} in {n} of {total} steps ({where}): flat at "
                    f"{si(max(size), UNIT[ch])}, the range of the sensor or its input; {fate}: use a larger range "
                    f"or a lower level")
        params = dict(level=_param(size, UNIT[ch]), time_at_limit=_param([a.duration_s for a in arts], "s"))
    elif kind == "dropout":
        sentence = (f"drop-outs on the {LABEL[ch]} in {n} of {total} steps ({where}): the signal held for up to "
                    f"{1e3 * max(a.duration_s for a in arts):.3g} ms; {fate}: check the cable, connector and "
                    f"acquisition")
        params = dict(duration=_param([a.duration_s for a in arts], "s"))
    else:
        sentence = (f"an offset drift on the {LABEL[ch]} in {n} of {total} steps, up to {si(max(size), UNIT[ch])} "
                    f"over a record (thermal drift of the sensor, or the carriage creeping); removed before the fit")
        params = dict(change=_param(size, UNIT[ch]))
    return _entry(kind, ch, items, total, params, sentence)
