"""Harmonics of periodic time records: force, acceleration and displacement of one step.

Method:
- Frequency (when not given): peak of the Hann-windowed spectrum of the force, refined by
  Gaussian interpolation of the three bins around it and then by Gauss-Newton iterations
  of a least-squares fit of the frequency, an offset and five harmonics (a distorted
  drive does not bias it), on each channel; the three are combined by inverse variance.
- The analysis window is the largest integer number of periods P in the record.  When
  the sample rate is an integer multiple of the frequency (our DAQ), the P periods are
  averaged sample by sample: the mean period holds every harmonic up to Nyquist and the
  scatter about it is the noise.  Otherwise a least-squares fit of an offset and K
  harmonics (every harmonic below Nyquist, at most ``max_harmonics``) is solved through
  its exact normal equations (sums of exponentials in closed form, projections by a
  chirp-z transform): no harmonic leaks into another whatever the sample rate.
- Noise: the residual's rms per sample, assumed white; the standard error of one
  harmonic's real or imaginary part is noise * sqrt(2 / samples).
- Periodicity: the first harmonics and the offset of each channel are estimated on the
  two halves of the window separately; their difference, in units of its standard error,
  is the ``drift_sigma`` score (a settling transient or a drifting carriage scores high,
  noise alone scores a few units at most).

Complex amplitudes follow sim.identify: C_k = A_k exp(i phi_k) for A_k sin(k w t + phi_k),
t = 0 at the first sample of the window.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.signal import CZT

log = logging.getLogger(__name__)

CHANNELS = ("force", "accel", "disp")
MAX_HARMONICS = 200
DRIFT_HARMONICS = 3
FREQ_HARMONICS = 5       # harmonics in the model that refines the frequency
# up to this many harmonics the kernel sums its fitted signal directly (Horner in e^(i step n)):
# good to 1e-13 of the signal, where the chirp-z transform's chirp loses 1e-11 on 5000 samples
DIRECT_SYNTHESIS = 8


@dataclass(frozen=True)
class ChannelHarmonics:
    harmonics: np.ndarray   # complex C_k, k = 1..K
    offset: float
    noise_rms: float        # per sample
    sigma: float            # standard error of one harmonic's real/imag part
    mean_period: np.ndarray  # one period (samples at the record's rate, or synthesized)


@dataclass(frozen=True)
class PeriodicRecords:
    freq_Hz: float
    fs_Hz: float
    periods: int
    samples: int
    channels: dict          # name -> ChannelHarmonics
    drift_sigma: float      # largest half-vs-half difference score over channels
    drift_detail: str       # which channel and harmonic gave it, in words ("accel harmonic 2"), as stored
    drift_channel: str = ""     # that channel ("" when read back from a step file, which stores the words only)
    drift_harmonic: int = -1    # that harmonic, 0 for the offset (-1: not known, as drift_channel)


def harmonic_words(harmonic: int) -> str:
    """"harmonic 2", or "offset" for harmonic 0."""
    return f"harmonic {harmonic}" if harmonic else "offset"


def drift_words(channel: str, harmonic: int) -> str:
    """The stored words of a periodicity score's origin: "accel harmonic 2", "disp offset"."""
    return f"{channel} {harmonic_words(harmonic)}"


def _coarse_frequency(x: np.ndarray, fs_Hz: float) -> float:
    """Peak of the Hann-windowed spectrum, Gaussian-interpolated between bins."""
    n = x.size
    if n < 16:
        raise ValueError(f"record too short to estimate a frequency ({n} samples)")
    spec = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(n)))
    k = int(np.argmax(spec[1:-1])) + 1
    a, b, c = np.log(spec[k - 1:k + 2] + 1e-300)
    den = a - 2 * b + c
    delta = 0.5 * (a - c) / den if den < 0 else 0.0
    return (k + float(np.clip(delta, -0.5, 0.5))) * fs_Hz / n


def refine_frequency(x: np.ndarray, fs_Hz: float, f: float) -> tuple[float, float]:
    """Gauss-Newton on x = o + sum_k s_k sin(kwt) + q_k cos(kwt) (variable projection, a
    few harmonics, so a distorted signal does not bias it).  Returns (frequency, its variance)."""
    x = np.asarray(x, float)
    n = x.size
    t = np.arange(n) / fs_Hz
    K = int(max(1, min(FREQ_HARMONICS, math.floor(0.45 * fs_Hz / f))))
    k = np.arange(1, K + 1)
    var = math.inf
    for _ in range(20):
        w = 2 * np.pi * f
        S, C = np.sin(w * np.outer(t, k)), np.cos(w * np.outer(t, k))
        A = np.column_stack([S, C, np.ones(n)])
        coef, *_ = np.linalg.lstsq(A, x, rcond=None)
        s, q = coef[:K], coef[K:2 * K]
        d = t * ((C * k) @ s - (S * k) @ q)             # d model / d w
        d -= A @ np.linalg.lstsq(A, d, rcond=None)[0]   # the part the amplitudes cannot absorb
        r = x - A @ coef
        dd = float(d @ d)
        if not dd > 0:
            break
        dw = float(d @ r / dd)
        var = float(r @ r) / max(1, n - A.shape[1] - 1) / dd / (2 * np.pi) ** 2
        f += dw / (2 * np.pi)
        if abs(dw) < 1e-12 * w:
            break
    return float(f), var


def estimate_frequency(x: np.ndarray, fs_Hz: float, *others: np.ndarray) -> float:
    """Frequency of the dominant periodic signal in ``x`` (Hz): interpolated FFT peak,
    refined by least squares on ``x`` and on the ``others`` (records of the same step),
    combined by inverse variance (the channel with the best signal-to-noise ratio, often
    the accelerometer at small force, then sets it)."""
    x = np.asarray(x, float)
    f0 = _coarse_frequency(x, fs_Hz)
    est = [refine_frequency(y, fs_Hz, f0) for y in (x, *others)]
    est = [(f, v) for f, v in est if math.isfinite(f) and f > 0 and v > 0 and abs(f / f0 - 1) < 0.01]
    if not est:
        f, v = refine_frequency(x, fs_Hz, f0)
        est = [(f, v if v > 0 else 1.0)]
    wsum = sum(1 / v for _, v in est)
    f = sum(f / v for f, v in est) / wsum
    if not (f > 0 and math.isfinite(f)):
        raise ValueError("no dominant frequency found in the record")
    return float(f)


def _solve_near_diagonal(G: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve G c = rhs for a Gram matrix of nearly orthogonal columns (whole periods up to
    a fraction of a sample: off-diagonal terms below one, diagonal about N/2): Jacobi
    iterations, a dense solve if they do not settle."""
    diag = np.diag(G).copy()
    c = rhs / diag
    for _ in range(200):
        step = (rhs - G @ c) / diag
        c += step
        if np.max(np.abs(step)) <= 1e-14 * max(np.max(np.abs(c)), 1e-300):
            return c
    return np.linalg.solve(G, rhs)


@lru_cache(maxsize=32)
def _harmonic_system(N: int, step: float, K: int) -> tuple[np.ndarray, CZT, CZT]:
    """The Gram matrix of offset + K harmonics over N samples at ``step`` rad per sample, the
    chirp-z transform giving their right-hand side and the one synthesising the fitted
    signal from them: the same for every channel of a step and every pass over it, so built
    once (read only)."""
    d = np.arange(0, 2 * K + 1)
    z = np.exp(1j * d * step)
    with np.errstate(invalid="ignore", divide="ignore"):
        S = np.where(np.abs(1 - z) < 1e-12, N, (1 - z ** N) / (1 - z))
    S_full = lambda dd: np.where(dd >= 0, S[np.abs(dd)], np.conj(S[np.abs(dd)]))   # noqa: E731
    k = np.arange(0, K + 1)
    A_, B_ = np.meshgrid(k, k, indexing="ij")
    Sm, Sp = S_full(A_ - B_), S_full(A_ + B_)
    cc = 0.5 * (Sm.real + Sp.real)
    ss = 0.5 * (Sm.real - Sp.real)
    cs = 0.5 * (Sp.imag - Sm.imag)             # sum cos(a) sin(b)
    # unknowns: cos coefficients k = 0..K, sin coefficients k = 1..K
    G = np.block([[cc, cs[:, 1:]], [cs[:, 1:].T, ss[1:, 1:]]])
    G.flags.writeable = False
    return G, CZT(N, m=K + 1, w=np.exp(-1j * step), a=1.0), CZT(K + 1, m=N, w=np.exp(1j * step), a=1.0)


def _fitted(c: np.ndarray, N: int, step: float, synthesis: CZT) -> np.ndarray:
    """a_0 + sum_k a_k cos(k step n) + b_k sin(k step n) = Re(sum_k c_k e^(i k step n)), c_k = a_k - i b_k,
    n = 0..N-1: summed directly for a few harmonics, by the chirp-z transform for many."""
    if c.size - 1 > DIRECT_SYNTHESIS:
        return synthesis(c).real
    z = np.exp(1j * step * np.arange(N))
    p = np.full(N, c[-1])
    for ck in c[-2::-1]:
        p = p * z + ck
    return p.real


def noise_rms(residual: np.ndarray, params: int) -> float:
    """The per-sample noise of a record: the rms of its residual about a fitted model of
    ``params`` parameters, over ``residual.size - params`` degrees of freedom (the one noise
    estimate, decision 0066)."""
    return math.sqrt(float(np.sum(np.square(residual))) / max(1, residual.size - params))


def harmonic_sigma(noise: float, samples: int) -> float:
    """The standard error of one harmonic's real or imaginary part fitted to ``samples``
    samples of white noise of rms ``noise``: noise sqrt(2 / samples)."""
    return noise * math.sqrt(2.0 / max(samples, 1))


def lsq_harmonics(x: np.ndarray, fs: float, f: float, K: int, noise: bool = True):
    """Exact least-squares fit of offset + K harmonics of ``f`` to the ``x.size`` samples of
    ``x`` (any length: whole periods or not); returns (C_k, offset, residual rms with
    ``x.size - (2K + 1)`` degrees of freedom: :func:`noise_rms`).  The one harmonic kernel:
    every fit of harmonics to a record goes through it (procedures.analysis.fit_harmonics is
    its wrapper for the controllers).  The residual is the record minus the fitted signal
    (synthesised by a second chirp-z transform), exact on a clean record where
    x.x - coef.rhs would cancel to its last digits (decision 0066); ``noise=False`` skips it
    (the rms is then NaN) for a caller that needs the harmonics only."""
    N = x.size
    step = 2 * np.pi * f / fs
    G, transform, synthesis = _harmonic_system(N, step, K)
    Z = transform(x)
    rhs = np.concatenate([Z.real, -Z.imag[1:]])
    coef = _solve_near_diagonal(G, rhs)
    a_cos, b_sin = coef[:K + 1], coef[K + 1:]
    rms = math.nan
    if noise:
        rms = noise_rms(x - _fitted(np.concatenate([a_cos[:1], a_cos[1:] - 1j * b_sin]), N, step, synthesis), coef.size)
    # A sin(kwt + phi) = A cos(phi) sin + A sin(phi) cos -> C = b_sin + i a_cos
    return b_sin + 1j * a_cos[1:], float(a_cos[0]), rms


def analyse_channel(x: np.ndarray, fs: float, f: float, periods: int, spp: int | None,
                    max_harmonics: int, noise: bool = True) -> ChannelHarmonics:
    """Harmonics 1..``max_harmonics`` of drive frequency ``f`` in one channel's record ``x``
    (``periods`` whole periods; ``spp`` samples per period when the sample rate is a multiple
    of the drive, else None): the period-averaged waveform's harmonics, the offset, the per-sample
    noise (scatter about the mean period, or the least-squares residual) and one harmonic's
    standard error (NaN when ``noise`` is False and the least-squares fit is used: the
    harmonics only)."""
    if spp is not None:
        blocks = x[:periods * spp].reshape(periods, spp)
        mean = blocks.mean(axis=0)
        N = periods * spp
        # the mean period is the fit of every harmonic up to Nyquist: spp parameters
        rms = noise_rms(blocks - mean, spp) if periods > 1 else math.nan
        spec = np.fft.rfft(mean) * (2.0 / spp)
        K = min(max_harmonics, (spp - 1) // 2)
        C = 1j * spec[1:K + 1]
        return ChannelHarmonics(C, float(spec[0].real / 2), rms, harmonic_sigma(rms, N), mean)
    N = int(round(periods * fs / f))
    K = max(1, min(max_harmonics, int(math.floor(0.5 * fs / f - 0.5))))
    C, off, rms = lsq_harmonics(x[:N], fs, f, K, noise)
    return ChannelHarmonics(C, off, rms, harmonic_sigma(rms, N), synthesized_period(C, off, fs, f))


def synthesized_period(C: np.ndarray, offset: float, fs: float, f: float) -> np.ndarray:
    """One period of offset + sum_k Im(C_k e^(i k w t)) at the record's rate (at least 8
    samples): the mean period a record's harmonics describe."""
    K = C.size
    M = max(8, int(round(fs / f)))                       # > 2K: K <= fs / 2f - 1/2
    spec = np.zeros(max(M, K + 1), complex)
    spec[1:K + 1] = C
    return offset + (np.fft.ifft(spec) * spec.size).imag[:M]   # off + Im(sum_k C_k e^(2 pi i k m / M)), m = 0..M-1


def checked_records(force_N, accel_m_s2, disp_m, fs_Hz: float, freq_Hz: float | None = None) -> tuple[dict, float]:
    """The three records as float arrays and the drive frequency (estimated when None);
    ValueError names what makes them unusable (lengths, NaN, rate, too few periods)."""
    sig = {"force": np.asarray(force_N, float), "accel": np.asarray(accel_m_s2, float),
           "disp": np.asarray(disp_m, float)}
    sizes = {k: v.size for k, v in sig.items()}
    if len(set(sizes.values())) != 1:
        raise ValueError(f"records of different lengths: {sizes}")
    for k, v in sig.items():
        if v.ndim != 1 or not np.all(np.isfinite(v)):
            raise ValueError(f"{k} record contains NaN or inf" if v.ndim == 1 else f"{k} record is not 1-D")
    if not (fs_Hz > 0 and math.isfinite(fs_Hz)):
        raise ValueError(f"sample rate must be finite and > 0, got {fs_Hz!r}")
    f = (estimate_frequency(sig["force"], fs_Hz, sig["accel"], sig["disp"]) if freq_Hz is None
         else float(freq_Hz))
    n = sizes["force"]
    ratio = fs_Hz / f
    periods = int(math.floor(n / ratio + 1e-9))
    if periods < 2:
        raise ValueError(f"record holds {n / ratio:.2f} periods of {f:.6g} Hz; at least 2 are needed")
    if ratio < 4:
        raise ValueError(f"{ratio:.2f} samples per period of {f:.6g} Hz: not enough to resolve a harmonic")
    return sig, f


def analyse_records(force_N, accel_m_s2, disp_m, fs_Hz: float, freq_Hz: float | None = None,
                    max_harmonics: int = MAX_HARMONICS) -> PeriodicRecords:
    """Harmonics, noise and a periodicity score of one step's three records."""
    sig, f = checked_records(force_N, accel_m_s2, disp_m, fs_Hz, freq_Hz)
    n = sig["force"].size
    ratio = fs_Hz / f
    periods = int(math.floor(n / ratio + 1e-9))
    spp = int(round(ratio)) if abs(ratio - round(ratio)) * periods < 0.02 else None
    chans = {k: analyse_channel(v, fs_Hz, f, periods, spp, max_harmonics) for k, v in sig.items()}
    # periodicity: the two halves of the window against each other
    half = periods // 2
    drift, where = 0.0, ("", -1)
    for k, v in sig.items():
        n_half = int(round(half * ratio))
        a = analyse_channel(v[:n_half], fs_Hz, f, half, spp, DRIFT_HARMONICS, False) if half >= 1 else None
        b = analyse_channel(v[n_half:2 * n_half], fs_Hz, f, half, spp, DRIFT_HARMONICS, False) if half >= 1 else None
        if a is None or b is None:
            continue
        # the noise of the whole record sets the scale (a half alone can hold too few periods)
        s_h = harmonic_sigma(chans[k].noise_rms, n_half) * math.sqrt(2.0)
        if not s_h > 0:
            continue
        # the second half's time origin is n_half samples later: refer it back to the first's
        kk = np.arange(1, b.harmonics[:DRIFT_HARMONICS].size + 1)
        hb = b.harmonics[:DRIFT_HARMONICS] * np.exp(-2j * np.pi * kk * f * n_half / fs_Hz)
        dh = np.abs(a.harmonics[:DRIFT_HARMONICS] - hb) / s_h
        do = abs(a.offset - b.offset) / (s_h / math.sqrt(2.0))
        for h, z in [(i + 1, float(v_)) for i, v_ in enumerate(dh)] + [(0, do)]:
            if z > drift:
                drift, where = z, (k, h)
    detail = drift_words(*where) if where[0] else ""
    return PeriodicRecords(f, float(fs_Hz), periods, int(round(periods * ratio)), chans, float(drift), detail,
                           *where)
