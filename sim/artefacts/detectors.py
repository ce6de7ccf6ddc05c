"""Detectors of the artefact check (:mod:`sim.artefacts`): clipping and drop-outs on the raw
samples; the periodic fit, the offset trend, the noise and the interference lines and
transients of its residual."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import leastsq
from scipy.special import log_ndtr, logsumexp

from ..records import analyse_channel
from . import sentences
from .quality import Artefact
from .sentences import UNIT

LINE_FALSE_ALARM = 1e-4       # per record and channel
HARMONIC_GUARD = 1.5          # record resolutions (fs / N) around each drive harmonic not searched for lines
MAX_LINES = 6
ALIAS_MARGIN = 10.0           # a peak near a folded harmonic is a line when above this x the largest top-tenth harmonic
_BLOCK = 128                 # samples: exp((-sigma + i w) t) as the outer product of block starts and offsets
TREND_Z = 6.0                 # offset drift: sqrt(chi-square, 2 dof) of the trend coefficients
DECAY_Z = 6.0                 # a line's decay rate, in standard errors, above which it is a transient
DECAY_FRACTION = 0.8          # ... and its amplitude at the end / at the start below this
GROWTH_LIMIT = 4.0            # a decaying fit stops where its component would grow e^4 (55) x over the record
DROPOUT_FALSE_ALARM = 1e-4       # per record and channel
DROPOUT_MIN_SAMPLES = 4          # shortest run of identical samples examined


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
                                evidence=sentences.clipped_samples(n_at, x.size, len(runs))))
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
                         evidence=sentences.one_value())]
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
    return [Artefact("dropout", ch, float(x[s0]), "rejected", time_s=s0 / fs, duration_s=n0 / fs,
                     evidence=sentences.held_runs(len(bad), total, max(L for (_, L), _, _ in bad), d0, noise, q,
                                                  UNIT[ch], lc0, DROPOUT_FALSE_ALARM / n, DROPOUT_FALSE_ALARM))]


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
    ch = analyse_channel(x[fit_from:], fs, f, periods, spp, 200, noise=False)
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


def alias_bound(C: np.ndarray, aliases: np.ndarray) -> float:
    """The largest amplitude a folded harmonic can have, times :data:`ALIAS_MARGIN`: the
    harmonics above Nyquist continue the decay of the top tenth fitted (:func:`_aliases`),
    so none exceeds the largest of those.  A component far above it at a folded
    frequency is not the fold (a free vibration of 1.4 um beside top harmonics of nm:
    decision 0088).  inf when nothing folds."""
    if not aliases.size:
        return math.inf
    m = max(3, C.size // 10)
    return ALIAS_MARGIN * float(np.max(np.abs(C)[-m:]))


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


class _Growing(Exception):
    """A decaying fit whose path has left the line for a component that grows (decision 0070)."""


def _fit_sinusoid(r: np.ndarray, fs: float, f0: float, with_decay: bool) -> _Line | None:
    """Least squares of e^(-sigma t) (a sin wt + b cos wt) + c on ``r`` from the frequency
    ``f0`` (sigma = 0 unless ``with_decay``); t from the record start.  None when it fails,
    or when the decaying fit's search reaches a component growing by more than
    e^``GROWTH_LIMIT`` over the record: not a line that decays (decision 0070)."""
    n = r.size
    scale = float(np.std(r)) or 1.0
    r = r / scale
    T = n / fs
    tt = np.arange(n) / n
    nb = -(-n // _BLOCK)
    t_in, t_of = np.arange(_BLOCK) / fs, np.arange(nb) * (_BLOCK / fs)
    w0 = 2 * np.pi * f0
    nd = 2 if with_decay else 1                # nonlinear parameters: (w - w0) T [, sigma T]

    last: list = [None, None]              # MINPACK asks for the Jacobian where it has just
    #                                        evaluated the residual: the sines are reused

    def parts(p):
        key = p.tobytes()
        if last[0] != key:
            w = w0 + p[0] / T
            sig = p[1] / T if with_decay else 0.0
            # e^((-sigma + i w) t) as the outer product of its values at the block starts and
            # within a block: the same numbers to rounding as sin, cos and exp of every sample,
            # at a fraction of their time (decision 0068)
            z = np.outer(np.exp(complex(-sig, w) * t_of), np.exp(complex(-sig, w) * t_in)).ravel()[:n]
            last[:] = key, (w, sig, z.imag, z.real)
        return last[1]

    def resid(p):
        # a line that grows by e^4 over the record is no line of the record: where MINPACK's path
        # goes there (half the decaying fits on a strong hum beside the carriage's ringing), it
        # wanders on to its 40th evaluation and ends anywhere; stopped here, it is no transient
        if with_decay and p[1] < -GROWTH_LIMIT:
            raise _Growing
        _, _, s, c = parts(p)
        return p[nd] * s + p[nd + 1] * c + p[nd + 2] - r

    def jac(p):
        _, _, s, c = parts(p)
        a, b = p[nd], p[nd + 1]
        J = np.empty((nd + 3, n))          # the Jacobian's columns as rows (col_deriv): no transposed copy
        np.multiply(tt, a * c - b * s, out=J[0])
        if with_decay:
            np.multiply(tt, -(a * s + b * c), out=J[1])
        J[nd], J[nd + 1], J[nd + 2] = s, c, 1.0
        return J

    if n < nd + 3:
        return None
    # the start: a, b, c by linear least squares at f0, from the normal equations (their sums
    # from e^(i w0 t): sin^2 and cos^2 from e^(2 i w0 t), whose sines add to n)
    _, _, s0, c0 = parts(np.zeros(nd + 3))
    z0 = c0 + 1j * s0
    sz, sz2 = complex(z0.sum()), complex(np.dot(z0, z0))
    G = np.array([[(n - sz2.real) / 2, sz2.imag / 2, sz.imag], [sz2.imag / 2, (n + sz2.real) / 2, sz.real],
                  [sz.imag, sz.real, n]])
    try:
        ab = np.linalg.solve(G, np.array([s0 @ r, c0 @ r, r.sum()]))
    except np.linalg.LinAlgError:
        return None
    p0 = np.concatenate([np.zeros(nd), ab])
    try:
        # MINPACK's lmder as least_squares(method="lm", x_scale="jac", max_nfev=40) calls it (the
        # same arguments and tolerances), without the wrappers least_squares puts around every
        # evaluation (a third of the time of a case with a strong hum on every step, issue 33)
        p, _, info, _, _ = leastsq(resid, p0, Dfun=jac, full_output=True, col_deriv=True, ftol=1e-8, xtol=1e-8,
                                   gtol=1e-8, maxfev=40)
        fun = info["fvec"]
        J = jac(p)
        cov = float(fun @ fun) / max(1, n - p0.size) * np.linalg.pinv(J @ J.T)
    except (ValueError, np.linalg.LinAlgError, _Growing):
        return None
    w, sig, s, c = parts(p)
    if not (math.isfinite(w) and w > 0):
        return None
    return _Line(freq_Hz=w / (2 * np.pi), amp=scale * float(math.hypot(p[nd], p[nd + 1])), decay=sig,
                 decay_se=math.sqrt(max(cov[1, 1], 0.0)) / T if with_decay else 0.0,
                 model=scale * (p[nd] * s + p[nd + 1] * c))


NO_FREQUENCIES = np.zeros(0)     # no aliased harmonics (read only)


def _line_search(q: np.ndarray, fs: float, f: float, skip: list[float],
                 aliases: np.ndarray = NO_FREQUENCIES, alias_amp: float = math.inf) -> list[tuple[float, float]]:
    """Candidate (frequency, peak power / noise floor) of the residual, strongest first,
    away from the drive harmonics, their ``aliases`` (unless above what a folded harmonic
    can be, ``alias_amp``: :func:`alias_bound`) and the frequencies in ``skip``."""
    n = q.size
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    S = np.abs(np.fft.rfft((q - q.mean()) * np.hanning(n), nfft)) ** 2
    freqs = np.arange(S.size) * fs / nfft
    guard = HARMONIC_GUARD * fs / n
    k = np.round(freqs / f)
    ok = (np.abs(freqs - k * f) > guard) & (freqs > guard) & (freqs < fs / 2 - guard)
    for fk in skip:
        ok &= np.abs(freqs - fk) > guard
    strong = np.zeros(S.size, bool)
    searched = ok.copy()
    if aliases.size:
        i = np.clip(np.searchsorted(aliases, freqs), 0, aliases.size - 1)
        near = np.minimum(np.abs(freqs - aliases[i]), np.abs(freqs - aliases[np.maximum(i - 1, 0)]))
        # a sinusoid of amplitude a peaks at (a sum(hann) / 2)^2 = (a n / 4)^2 in S
        strong = ok & (near <= guard) & (S > (alias_amp * n / 4) ** 2)
        ok &= near > guard
    if ok.sum() < 16 and not strong.any():
        return []
    # the floor where nothing folds; where the folds cover the band (a short record, many
    # folded harmonics), the median over it all: they are weak, a few standard errors
    floor = float(np.median(S[ok] if ok.sum() >= 16 else S[searched])) / math.log(2.0)
    thr = floor * (math.log(n / 2) - math.log(LINE_FALSE_ALARM))
    peak = (ok | strong) & (S > thr)
    peak[1:-1] &= (S[1:-1] >= S[:-2]) & (S[1:-1] >= S[2:])
    idx = np.flatnonzero(peak)
    return [(float(freqs[i]), float(S[i] / floor)) for i in idx[np.argsort(S[idx])[::-1]]]


def _find_lines(q: np.ndarray, fs: float, f: float, aliases: np.ndarray = NO_FREQUENCIES,
                alias_amp: float = math.inf) -> tuple[list[_Line], list[_Line]]:
    """Steady lines and decaying components of the residual ``q``, strongest first (near a
    folded harmonic only those above ``alias_amp``, :func:`alias_bound`)."""
    n = q.size
    guard = HARMONIC_GUARD * fs / n
    lines: list[_Line] = []
    transients: list[_Line] = []
    found = np.zeros(n)
    while len(lines) < MAX_LINES and len(transients) < 2:
        cands = _line_search(q - found, fs, f, [ln.freq_Hz for ln in lines + transients], aliases, alias_amp)
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
        if aliases.size and np.min(np.abs(aliases - ln.freq_Hz)) <= guard and not ln.amp > alias_amp:
            break                                               # onto an aliased harmonic
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
