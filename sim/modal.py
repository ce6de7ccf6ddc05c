"""Modes per force level: each mode's resonance and damping ratio, with 95 % intervals,
from a local single-mode fit to the complex FRF around its peak (decision record 0043).

A nonlinear mode's "resonance at a fixed force" belongs to that force level and to the FRF
its peak is taken from, so each estimate names both:

- **feed**: the peak of compliance_pp = (x_max - x_min) / (2 F1), the seed's Eq. 9 and
  Fig. 13.  The fit sees compliance_pp with the phase of X1/F1 (the magnitude the seed
  reads, the phase the fundamental gives), as a receptance.
- **pitch**: the peak of the drive-point accelerance |A1/F1| (where the pitching mode is
  clearest), as an accelerance.

The local model (rational fraction, one mode plus a constant residual for everything out
of band; x = w / w0 with w0 a scale):

    receptance   H(x) = R + A / (x_r^2 - x^2 + 2 i zeta x_r x)
    accelerance  H(x) = R + A x^2 / (x_r^2 - x^2 + 2 i zeta x_r x)

A and R complex: 6 real parameters, fitted by least squares to the real and imaginary
parts of the points in a window around the peak (:func:`fit_single_mode`); the covariance
is s^2 (J^T J)^-1 with s^2 the residual variance (so a misfit of the single-mode shape,
the nonlinearity's skew included, widens the intervals); intervals are +-t(0.975, dof) sd,
plus how far the peak and zeta move between neighbouring fit windows (:func:`window_shift`;
a skewed peak's misfit is systematic, decision 0061), and a fitted peak outside the measured
maximum's neighbours is moved inside them, the interval holding both; on a flat top, points
the measured noise does not tell from the maximum make a plateau whose bracket the interval
holds (:func:`top_run`, decision 0069).
The resonance is the peak of the fitted |H| inside the window (numerically), its interval
by the delta method.  Half-power bandwidth (zeta ~ (f2 - f1) / (2 f_r), from the measured
points) is the cross-check.

A peak at the first or last frequency of the data is not a peak: the mode is said to lie
at or beyond that edge (``status`` "below grid" / "above grid"), never given a value.
Modes are tracked by identity (:func:`track_modes`): the feed mode is the compliance_pp
maximum nearest to its predicted frequency (the rig model's, else the previous level's,
else the lowest prominent maximum); the pitching mode is the accelerance maximum nearest
to its prediction (else the previous level's, else the largest one well above the feed
mode) - never simply the largest peak.
Longer than 600 lines: the fit, its intervals, the status rules and the tracking are one
estimator whose parts read each other's windows (decision 0061).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
from numpy.typing import ArrayLike
from scipy import optimize, stats

from .records import harmonic_sigma

MODES = ("feed", "pitch")
KINDS = ("receptance", "accelerance")
MIN_POINTS = 4              # 8 real equations for 6 parameters
WINDOW_LEVEL = 1 / math.sqrt(2)   # the fit's window: the peak's half-power band ...
MAX_POINTS = 15             # ... at most this many points nearest the peak
MIN_IN_BAND = 3             # a resolved peak: at least this many measured points in its half-power band
OTHER_MODE_GAP = 1.3        # a pitching peak lies at least this factor above the feed mode
PEAK_SD_FLOOR = 0.5         # the peak's sd is at least this x the pole's natural frequency's sd
MISFIT_WIDENING = True      # the shape's misfit widens the intervals (window_shift, the bracket; decision 0061)
NOISE_TIE = 2.0             # a point within this many sd (of its difference) of the maximum is tied with it (decision 0069)


@dataclass(frozen=True)
class SingleModeFit:
    """A local single-mode fit (module docstring): ``p`` = (x_r, zeta, Re A, Im A, Re R,
    Im R) in units of ``w0_rad_s`` and ``scale`` (H / scale is fitted)."""

    kind: str
    w0_rad_s: float
    scale: float
    p: np.ndarray
    cov: np.ndarray
    dof: int
    f_lo_Hz: float               # the window the fit saw
    f_hi_Hz: float
    n_points: int

    def __call__(self, f_Hz) -> np.ndarray:
        return self.scale * _model(self.p, 2 * np.pi * np.asarray(f_Hz, float) / self.w0_rad_s, self.kind)

    @property
    def t(self) -> float:
        return float(stats.t.ppf(0.975, max(self.dof, 1)))

    def natural_Hz(self) -> tuple[float, float]:
        """(f_r, standard deviation) of the pole's undamped natural frequency."""
        f0 = self.w0_rad_s / (2 * np.pi)
        return float(self.p[0] * f0), float(math.sqrt(max(self.cov[0, 0], 0.0)) * f0)

    def damping(self) -> tuple[float, float]:
        return float(self.p[1]), float(math.sqrt(max(self.cov[1, 1], 0.0)))

    def peak(self, p: np.ndarray | None = None) -> tuple[float, float]:
        """(frequency in Hz, |H|) of the fitted magnitude's maximum inside the window."""
        p = self.p if p is None else p
        f0 = self.w0_rad_s / (2 * np.pi)
        lo, hi = self.f_lo_Hz / f0, self.f_hi_Hz / f0
        grid = np.linspace(lo, hi, 401)
        mag = np.abs(_model(p, grid, self.kind))
        i = int(np.argmax(mag))
        a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
        r = optimize.minimize_scalar(lambda x: -abs(_model(p, np.array([x]), self.kind)[0]), bounds=(a, b),
                                     method="bounded", options={"xatol": 1e-10 * hi})
        return float(r.x * f0), float(-r.fun * self.scale)

    def peak_sd(self) -> tuple[float, float, float, float]:
        """(f_peak, sd, |H|_peak, sd) by the delta method (central differences)."""
        f, h = self.peak()
        g = np.zeros((2, self.p.size))
        for k in range(self.p.size):
            d = 1e-6 * max(abs(self.p[k]), 1e-3)
            up, dn = self.p.copy(), self.p.copy()
            up[k] += d
            dn[k] -= d
            (fu, hu), (fd, hd) = self.peak(up), self.peak(dn)
            g[:, k] = ((fu - fd) / (2 * d), (hu - hd) / (2 * d))
        var = np.einsum("ik,kl,il->i", g, self.cov, g)
        return f, float(math.sqrt(max(var[0], 0.0))), h, float(math.sqrt(max(var[1], 0.0)))


def _basis(p: np.ndarray, x: np.ndarray, kind: str) -> tuple[np.ndarray, np.ndarray]:
    xr, z = p[0], p[1]
    D = xr * xr - x * x + 2j * z * xr * x
    num = x * x if kind == "accelerance" else np.ones_like(x)
    return num / D, D


def _model(p: np.ndarray, x: np.ndarray, kind: str) -> np.ndarray:
    b, _ = _basis(p, x, kind)
    return (p[4] + 1j * p[5]) + (p[2] + 1j * p[3]) * b


def _linear(xr: float, z: float, x: np.ndarray, H: np.ndarray, kind: str) -> np.ndarray:
    """A and R for fixed (x_r, zeta): linear least squares."""
    b, _ = _basis(np.array([xr, z]), x, kind)
    M = np.column_stack([b, np.ones_like(b)])
    c, *_ = np.linalg.lstsq(M, H, rcond=None)
    return np.array([xr, z, c[0].real, c[0].imag, c[1].real, c[1].imag])


def _jacobian(p: np.ndarray, x: np.ndarray, kind: str) -> np.ndarray:
    b, D = _basis(p, x, kind)
    A = p[2] + 1j * p[3]
    xr, z = p[0], p[1]
    cols = [-A * b * (2 * xr + 2j * z * x) / D, -A * b * (2j * xr * x) / D, b, 1j * b,
            np.ones_like(b), 1j * np.ones_like(b)]
    J = np.column_stack(cols)
    return np.vstack([J.real, J.imag])


def fit_single_mode(f_Hz: ArrayLike, H: ArrayLike, kind: str = "receptance",
                    guess_Hz: float | None = None, guess_zeta: float = 0.05) -> SingleModeFit:
    """Fit the single-mode model (module docstring) to the complex FRF values ``H`` at
    ``f_Hz`` (every point given is used; choose the window before).  Raises ValueError
    with fewer than MIN_POINTS points."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    f = np.asarray(f_Hz, float)
    Hc = np.asarray(H, complex)
    if f.size < MIN_POINTS:
        raise ValueError(f"a single-mode fit needs at least {MIN_POINTS} points, got {f.size}")
    if guess_Hz is None:
        guess_Hz = float(f[np.argmax(np.abs(Hc))])
    w0 = 2 * np.pi * guess_Hz
    scale = float(np.max(np.abs(Hc)))
    x, y = 2 * np.pi * f / w0, Hc / scale

    def res(p):
        r = _model(p, x, kind) - y
        return np.concatenate([r.real, r.imag])

    best = None
    for z0 in sorted({guess_zeta, 0.01, 0.05, 0.2}):   # a few starts: the cost is not convex in zeta
        p0 = _linear(1.0, z0, x, y, kind)
        r = optimize.least_squares(res, p0, jac=lambda p: _jacobian(p, x, kind), method="lm", x_scale="jac",
                                   max_nfev=2000)
        if best is None or r.cost < best.cost:
            best = r
    assert best is not None
    p = best.x.copy()
    if p[1] < 0:                # the sign of zeta is not identified by the magnitude alone: keep the physical one
        p[1] = -p[1]
        p = _linear(p[0], p[1], x, y, kind)
    J = _jacobian(p, x, kind)
    dof = 2 * f.size - p.size
    s2 = float(np.sum(res(p) ** 2) / dof) if dof > 0 else math.inf
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((p.size, p.size), math.inf)
    return SingleModeFit(kind, w0, scale, p, cov, dof, float(f.min()), float(f.max()), int(f.size))


def half_power_zeta(f_Hz: ArrayLike, mag: ArrayLike, f_peak: float, peak: float) -> float:
    """zeta ~ (f2 - f1) / (2 f_r) from the measured points where ``mag`` crosses
    peak / sqrt(2) either side of ``f_peak`` (linear interpolation); NaN when the data do
    not reach the half-power level on both sides."""
    f, m = np.asarray(f_Hz, float), np.asarray(mag, float)
    o = np.argsort(f)
    f, m = f[o], m[o]
    level = peak / math.sqrt(2.0)
    i = int(np.searchsorted(f, f_peak))
    f1 = f2 = math.nan
    for j in range(min(i, f.size - 1), 0, -1):          # downwards
        if m[j - 1] <= level <= m[j] or (f[j] > f_peak and m[j] <= level):
            if m[j - 1] <= level <= m[j]:
                f1 = float(f[j - 1] + (level - m[j - 1]) * (f[j] - f[j - 1]) / (m[j] - m[j - 1]))
            break
    for j in range(max(i, 1), f.size):                  # upwards
        if m[j] <= level <= m[j - 1]:
            f2 = float(f[j - 1] + (m[j - 1] - level) * (f[j] - f[j - 1]) / (m[j - 1] - m[j]))
            break
    return (f2 - f1) / (2 * f_peak) if math.isfinite(f1) and math.isfinite(f2) else math.nan


@dataclass
class ModeEstimate:
    """One mode at one force level.  ``status``: "ok", "below grid" / "above grid" (the
    peak lies at or beyond the data's edge ``edge_Hz``: no value given), "not found" (no
    maximum of this mode in the data) or "no fit" (too few points, or the fit's peak left
    its window), "coarse" (fewer than MIN_IN_BAND points in the half-power band: the
    resonance's interval is the bracket of the measured maximum, no damping ratio).  ``peak``
    is the fitted peak of the curve the resonance is read from
    (compliance_pp in m/N for the feed mode, |A1/F1| in 1/kg for the pitching mode)."""

    mode: str
    level_N: float
    status: str
    curve: str                              # which FRF the peak is taken from
    resonance_Hz: float = math.nan
    resonance_low_Hz: float = math.nan
    resonance_high_Hz: float = math.nan
    damping_ratio: float = math.nan
    damping_ratio_low: float = math.nan
    damping_ratio_high: float = math.nan
    peak: float = math.nan
    peak_low: float = math.nan
    peak_high: float = math.nan
    half_power_damping_ratio: float = math.nan
    natural_Hz: float = math.nan            # the fitted pole's undamped frequency
    n_points: int = 0
    edge_Hz: float = math.nan
    note: str = ""
    window_Hz: tuple[float, float] = (math.nan, math.nan)
    extra: dict = field(default_factory=dict)
    phase_resonance: bool = False           # one point of a phase-resonance run, not a fit to a curve (decision 0044)

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def as_dict(self) -> dict:
        return asdict(self)


def local_maxima(f: np.ndarray, mag: np.ndarray, min_prominence: float = 0.02) -> list[int]:
    """Indices of the maxima of ``mag`` (sorted by ``f``), edges included (an edge
    maximum means the curve rises beyond the data), that stand out by ``min_prominence``
    (relative to themselves): the topographic prominence, the drop to the higher of the
    lowest points between the maximum and the nearest higher point on either side (or
    the data's end); an edge maximum counts its one side."""
    out = []
    n = mag.size
    for i in range(n):
        left = mag[i - 1] if i > 0 else -math.inf
        right = mag[i + 1] if i < n - 1 else -math.inf
        if not (mag[i] > left and mag[i] >= right):
            continue
        bases = []
        for side in (range(i - 1, -1, -1), range(i + 1, n)):
            low, higher = math.inf, False
            for j in side:
                if mag[j] > mag[i]:
                    higher = True
                    break
                low = min(low, mag[j])
            if math.isfinite(low):
                bases.append(low if higher or i in (0, n - 1) else low)
        base = max(bases) if i not in (0, n - 1) else (bases[0] if bases else -math.inf)
        if mag[i] - base >= min_prominence * mag[i]:
            out.append(i)
    return out


def top_run(mag: np.ndarray, sd: np.ndarray | None, ip: int) -> tuple[int, int]:
    """(first, last) index of the contiguous run of points about the maximum ``ip`` (of
    ``mag``, sorted by frequency) that the measured noise does not tell from it: each
    within NOISE_TIE standard deviations of the difference (``sd``: each point's absolute
    sd; None: the maximum alone).  On a flat, noisy top the peak's location is known only
    to this plateau and its outer neighbours, whichever point noise made the largest
    (decision record 0069)."""
    lo = hi = ip
    if sd is None:
        return lo, hi

    def tied(j: int) -> bool:
        return bool(mag[ip] - mag[j] <= NOISE_TIE * math.hypot(sd[ip], sd[j]))
    while lo > 0 and tied(lo - 1):
        lo -= 1
    while hi < mag.size - 1 and tied(hi + 1):
        hi += 1
    return lo, hi


def _window(f: np.ndarray, mag: np.ndarray, ip: int) -> np.ndarray:
    """The fit's points: the contiguous run around the peak ``ip`` above WINDOW_LEVEL of
    it (the half-power band: there the single-mode shape holds best on a nonlinear
    mode's skewed peak), widened when fewer than MIN_POINTS + 1: first by the point
    beyond the band on each side (both flanks: points crowded near the peak, refinement
    steps and a dwell, must not push a flank out and leave the fit one-sided, decision
    0050), then to the MIN_POINTS + 1 nearest; never across a point where the curve
    rises again (another mode), at most MAX_POINTS nearest."""
    lo = hi = ip
    top, level = mag[ip], WINDOW_LEVEL * mag[ip]
    while lo > 0 and level <= mag[lo - 1] <= top:
        lo -= 1
    while hi < f.size - 1 and level <= mag[hi + 1] <= top:
        hi += 1
    if hi - lo + 1 < MIN_POINTS + 1:          # both flanks, where the curve keeps falling
        if lo > 0 and mag[lo - 1] < min(mag[lo], level):
            lo -= 1
        if hi < f.size - 1 and mag[hi + 1] < min(mag[hi], level):
            hi += 1
    while hi - lo + 1 < MIN_POINTS + 1:       # below the half-power level: while the curve keeps falling
        can_lo = lo > 0 and mag[lo - 1] < min(mag[lo], level)
        can_hi = hi < f.size - 1 and mag[hi + 1] < min(mag[hi], level)
        if not (can_lo or can_hi):
            break
        if can_lo and (not can_hi or math.log(f[ip] / f[lo - 1]) <= math.log(f[hi + 1] / f[ip])):
            lo -= 1
        else:
            hi += 1
    sel = np.arange(lo, hi + 1)
    if sel.size > MAX_POINTS:
        sel = np.sort(np.array(sorted(sel, key=lambda i: abs(math.log(f[i] / f[ip])))[:MAX_POINTS]))
    return sel


def window_shift(f: np.ndarray, H: np.ndarray, mag: np.ndarray, sel: np.ndarray, kind: str, guess_Hz: float,
                 guess_zeta: float, f_peak: float, zeta: float) -> tuple[float, float]:
    """How far the fitted peak and damping ratio move when the fit's window loses its
    lowest or its highest point (windows of at least MIN_POINTS + 1 points) or gains the
    next point on either side (while the curve keeps falling there): (largest |shift| of
    the peak in Hz, of zeta).  A single-mode shape that fits moves by its noise; on a
    skewed nonlinear peak its misfit is systematic, and the shift measures it (decision
    0061).  Refits whose peak is pinned at their window's edge are not counted."""
    windows = []
    if sel.size >= MIN_POINTS + 2:
        windows += [sel[1:], sel[:-1]]
    if sel[0] > 0 and mag[sel[0] - 1] < mag[sel[0]]:
        windows.append(np.concatenate([[sel[0] - 1], sel]))
    if sel[-1] < f.size - 1 and mag[sel[-1] + 1] < mag[sel[-1]]:
        windows.append(np.concatenate([sel, [sel[-1] + 1]]))
    df = dz = 0.0
    for w in windows:
        try:
            fit = fit_single_mode(f[w], H[w], kind, guess_Hz, guess_zeta)
            fpk = fit.peak()[0]
        except (ValueError, np.linalg.LinAlgError):
            continue
        cell = (f[w[-1]] - f[w[0]]) / 400
        if not f[w[0]] + cell < fpk < f[w[-1]] - cell:
            continue
        df, dz = max(df, abs(fpk - f_peak)), max(dz, abs(fit.damping()[0] - zeta))
    return df, dz


def _nearest(f: np.ndarray, idx: list[int], target: float) -> int:
    return min(idx, key=lambda i: abs(math.log(f[i] / target)))


def estimate_mode(f_Hz: ArrayLike, H: ArrayLike, *, mode: str, kind: str, level_N: float = math.nan,
                  curve: ArrayLike | None = None, curve_name: str = "", peak_index: int | None = None,
                  guess_zeta: float = 0.05, sd: ArrayLike | None = None) -> ModeEstimate:
    """The mode whose maximum of ``curve`` (default |H|) is at ``peak_index`` (default the
    curve's largest value), from the complex FRF ``H`` at ``f_Hz`` (any order; one value
    per frequency).  The fit sees ``curve`` with the phase of ``H`` (module docstring); a
    peak at the first or last frequency is reported as lying beyond the edge.  ``sd``: the
    measured noise (standard deviation) of each point of the curve; points the noise does
    not tell from the maximum make a plateau (:func:`top_run`) whose bracket the interval
    holds (decision record 0069)."""
    f = np.asarray(f_Hz, float)
    Hc = np.asarray(H, complex)
    mag = np.abs(Hc) if curve is None else np.asarray(curve, float)
    o = np.argsort(f)
    f, Hc, mag = f[o], Hc[o], mag[o]
    sdv = None if sd is None else np.asarray(sd, float)[o]
    name = curve_name or ("|A1/F1|" if kind == "accelerance" else "|X1/F1|")
    est = ModeEstimate(mode, float(level_N), "ok", name)
    if f.size == 0:
        est.status, est.note = "not found", "no data"
        return est
    ip = int(np.argmax(mag)) if peak_index is None else int(np.nonzero(o == peak_index)[0][0])
    if ip == 0 or ip == f.size - 1:
        est.status = "below grid" if ip == 0 else "above grid"
        est.edge_Hz = float(f[ip])
        est.note = (f"the largest {name} is at the {'lowest' if ip == 0 else 'highest'} frequency measured, "
                    f"{f[ip]:.4g} Hz: the resonance lies at or beyond it")
        return est
    Hfit = mag * np.exp(1j * np.angle(Hc))
    fp = float(f[ip])
    sel = _window(f, mag, ip)
    if sel.size < MIN_POINTS:
        est.status, est.note = "no fit", f"{sel.size} points around the peak at {fp:.4g} Hz; a fit needs {MIN_POINTS}"
        return est
    while True:
        try:
            fit = fit_single_mode(f[sel], Hfit[sel], kind, fp, guess_zeta)
        except (ValueError, np.linalg.LinAlgError) as e:
            est.status, est.note = "no fit", f"single-mode fit failed: {e}"
            return est
        fpk, sd_f, hpk, sd_h = fit.peak_sd()
        # a fitted peak pinned at the window's edge (its search grid's first or last cell:
        # the delta method then gives sd 0) is not placed by the data: one more point on
        # that side, while the curve keeps falling there (decision 0050)
        cell = (f[sel[-1]] - f[sel[0]]) / 400
        low, high = fpk <= f[sel[0]] + cell, fpk >= f[sel[-1]] - cell
        if low and sel[0] > 0 and mag[sel[0] - 1] < mag[sel[0]]:
            sel = np.concatenate([[sel[0] - 1], sel])
        elif high and sel[-1] < f.size - 1 and mag[sel[-1] + 1] < mag[sel[-1]]:
            sel = np.concatenate([sel, [sel[-1] + 1]])
        else:
            break
    est.n_points = int(sel.size)
    est.window_Hz = (float(f[sel[0]]), float(f[sel[-1]]))
    t = fit.t
    # the peak cannot be placed better than its pole: at least half the natural
    # frequency's sd (the delta method's is 0.54-1.0 of it on 99 % of linear fits,
    # decision 0050; 0 when the peak is pinned at the window's edge)
    sd_f = max(sd_f, PEAK_SD_FLOOR * fit.natural_Hz()[1])
    if low or high:
        est.status = "no fit"
        est.note = f"the fitted peak {fpk:.4g} Hz lies at the edge of its window {f[sel[0]]:.4g}-{f[sel[-1]]:.4g} Hz"
        return est
    z, sd_z = fit.damping()
    # the bracket of the measured maximum: its neighbours (a bracket that holds for any
    # single peak of noise-free data), or those of the plateau of points the measured
    # noise does not tell from it (decision 0069)
    ra, rb = top_run(mag, sdv, ip)
    lo_b, hi_b = float(f[max(ra - 1, 0)]), float(f[min(rb + 1, f.size - 1)])
    in_band = int(np.sum(mag >= hpk / math.sqrt(2)))
    if in_band < MIN_IN_BAND:
        # the grid does not resolve the peak: the fit extrapolates from its flanks, and its
        # covariance knows nothing of the shape it did not see.  The peak lies in the
        # measured maximum's bracket; no damping ratio.
        est.status = "coarse"
        est.resonance_Hz = min(max(fpk, lo_b), hi_b)
        est.resonance_low_Hz, est.resonance_high_Hz = lo_b, hi_b
        est.peak, est.n_points, est.window_Hz = float(mag[ip]), int(sel.size), (float(f[sel[0]]), float(f[sel[-1]]))
        est.note = (f"{in_band} measured point(s) in the peak's half-power band: the grid does not resolve it; "
                    f"the interval is the bracket of the measured maximum (refine: [plan.resonance])")
        return est
    shift_f, shift_z = window_shift(f, Hfit, mag, sel, kind, fp, guess_zeta, fpk, z) if MISFIT_WIDENING else (0, 0)
    hw_f, hw_z = t * sd_f + shift_f, t * sd_z + shift_z
    est.extra["window_shift_Hz"] = shift_f
    est.resonance_Hz, est.resonance_low_Hz, est.resonance_high_Hz = fpk, fpk - hw_f, fpk + hw_f
    if MISFIT_WIDENING and not lo_b <= fpk <= hi_b:
        # the fitted peak lies outside the bracket of the measured maximum: the shape does not
        # fit the peak (a skewed nonlinear peak; decision 0061).  The estimate stays inside
        # the bracket, the interval holds both.
        est.resonance_Hz = min(max(fpk, lo_b), hi_b)
        est.resonance_low_Hz, est.resonance_high_Hz = min(fpk - hw_f, lo_b), max(fpk + hw_f, hi_b)
        est.note = (f"the single-mode fit's peak {fpk:.4g} Hz lies outside the measured maximum's neighbours "
                    f"{lo_b:.4g}-{hi_b:.4g} Hz: the shape misfits the peak; the interval holds both")
    if rb > ra:
        # a flat top: the noise does not tell these points from the maximum, so the peak is
        # known only to their plateau and its outer neighbours, never to a point (decision 0069)
        est.resonance_low_Hz, est.resonance_high_Hz = min(est.resonance_low_Hz, lo_b), max(est.resonance_high_Hz, hi_b)
        est.extra["plateau_Hz"] = (lo_b, hi_b)
        est.note = "; ".join(x for x in (
            f"flat top: the measured noise does not tell {rb - ra + 1} points {f[ra]:.5g}-{f[rb]:.5g} Hz from "
            f"the maximum ({NOISE_TIE:g} sd); the interval holds their plateau {lo_b:.5g}-{hi_b:.5g} Hz", est.note) if x)
    est.damping_ratio, est.damping_ratio_low, est.damping_ratio_high = z, max(z - hw_z, 0.0), z + hw_z
    est.peak, est.peak_low, est.peak_high = hpk, hpk - t * sd_h, hpk + t * sd_h
    est.natural_Hz = fit.natural_Hz()[0]
    est.half_power_damping_ratio = half_power_zeta(f, mag, fpk, hpk)
    if not all(map(math.isfinite, (sd_f, sd_z))):
        est.note = "no residual degrees of freedom: no interval"
    return est


@dataclass(frozen=True)
class LevelData:
    """One force level's steps: frequency, complex compliance X1/F1 and accelerance A1/F1,
    compliance_pp (seed Eq. 9); the measured noise (standard deviation) of compliance_pp
    and of |A1/F1| at each frequency, None where the steps do not say (decision 0069)."""

    level_N: float
    f_Hz: np.ndarray
    compliance: np.ndarray
    accelerance: np.ndarray
    compliance_pp: np.ndarray
    compliance_pp_sd: np.ndarray | None = None
    accelerance_sd: np.ndarray | None = None

    @classmethod
    def from_steps(cls, level_N: float, steps: Sequence[dict]) -> LevelData:
        """From stored step results (one per frequency: a frequency measured twice, in an
        up and a down sweep, keeps its mean, its noise divided by sqrt(2))."""
        by_f: dict[float, list[dict]] = {}
        for s in steps:
            by_f.setdefault(float(s["freq_Hz"]), []).append(s)
        f = np.array(sorted(by_f))

        def mean(key):
            return np.array([np.mean([key(s) for s in by_f[x]]) for x in f])
        X = mean(lambda s: complex(s["compliance_m_per_N"]["re"], s["compliance_m_per_N"]["im"]))
        A = mean(lambda s: s["accelerance_abs_kg_inv"] * np.exp(1j * s["accelerance_phase_rad"]))
        pp = mean(lambda s: s["compliance_pp_m_per_N"])
        try:
            sd = [[_step_sd(s) for s in by_f[x]] for x in f]
        except (KeyError, IndexError, TypeError, ValueError):
            return cls(float(level_N), f, X, A, pp)
        pp_sd = np.array([math.sqrt(sum(v[0] ** 2 for v in g)) / len(g) for g in sd])
        a_sd = np.array([math.sqrt(sum(v[1] ** 2 for v in g)) / len(g) for g in sd])
        return cls(float(level_N), f, X, A, pp, pp_sd, a_sd)


def _step_sd(s: dict) -> tuple[float, float]:
    """(sd of compliance_pp, sd of |A1/F1|) of one stored step, from its record's noise: each
    harmonic's standard error (sim.records.harmonic_sigma of the channel's noise rms over
    the record's samples) relative to the fundamentals it divides, in quadrature."""
    n = int(s["n_samples"])
    F1 = float(s["force"]["amplitude"][0])
    A1 = float(s["accel"]["amplitude"][0])
    sf = harmonic_sigma(float(s["force"]["noise_rms"]), n) / F1
    sa = harmonic_sigma(float(s["accel"]["noise_rms"]), n) / A1
    pp = float(s["compliance_pp_m_per_N"])
    sx = harmonic_sigma(float(s["disp"]["noise_rms"]), n) / (pp * F1)    # pp / 2 = compliance_pp F1
    return pp * math.hypot(sx, sf), float(s["accelerance_abs_kg_inv"]) * math.hypot(sa, sf)


def find_feed(d: LevelData, predicted_Hz: float | None = None) -> int | None:
    """Index (into d.f_Hz) of the feed mode's compliance_pp maximum: the one nearest to
    ``predicted_Hz``, else the lowest-frequency prominent maximum."""
    idx = local_maxima(d.f_Hz, d.compliance_pp)
    if not idx:
        return None
    if predicted_Hz and math.isfinite(predicted_Hz):
        return _nearest(d.f_Hz, idx, predicted_Hz)
    return min(idx)


def find_pitch(d: LevelData, predicted_Hz: float | None = None, band_Hz: tuple[float, float] | None = None,
               feed_Hz: float | None = None) -> int | None:
    """Index of the pitching mode's accelerance maximum: among the maxima inside ``band_Hz``
    (the rig model's bounds, when known) the one nearest ``predicted_Hz`` (else the
    largest); without a band, the maxima above OTHER_MODE_GAP x the feed mode."""
    mag = np.abs(d.accelerance)
    idx = local_maxima(d.f_Hz, mag, 0.02 if band_Hz is not None else 0.1)
    if band_Hz is not None:
        lo, hi = band_Hz
        idx = [i for i in idx if lo / 1.1 <= d.f_Hz[i] <= hi * 1.1]
    elif feed_Hz and math.isfinite(feed_Hz):
        idx = [i for i in idx if d.f_Hz[i] >= OTHER_MODE_GAP * feed_Hz]
    else:
        idx = [i for i in idx if i > 0]       # the lowest frequency is the feed mode's side
    if not idx:
        return None
    if predicted_Hz and math.isfinite(predicted_Hz):
        return _nearest(d.f_Hz, idx, predicted_Hz)
    return max(idx, key=lambda i: mag[i])


def level_modes(d: LevelData, *, feed_predicted_Hz: float | None = None, pitch: bool = False,
                pitch_predicted_Hz: float | None = None, pitch_band_Hz: tuple[float, float] | None = None
                ) -> list[ModeEstimate]:
    """The feed mode (and the pitching mode when ``pitch``) of one level."""
    out = []
    i = find_feed(d, feed_predicted_Hz)
    if i is None:
        feed = ModeEstimate("feed", d.level_N, "not found", "compliance_pp", note="no compliance_pp maximum")
    else:
        feed = estimate_mode(d.f_Hz, d.compliance, mode="feed", kind="receptance", level_N=d.level_N,
                             curve=d.compliance_pp, curve_name="compliance_pp", peak_index=i, sd=d.compliance_pp_sd)
    out.append(feed)
    if pitch:
        # the feed mode's frequency: its estimate (a coarse one too), its edge, else its
        # measured maximum (a feed peak without a fit is still no pitching mode)
        fh = feed.resonance_Hz if math.isfinite(feed.resonance_Hz) else (
            feed.edge_Hz if math.isfinite(feed.edge_Hz) else None if i is None else float(d.f_Hz[i]))
        j = find_pitch(d, pitch_predicted_Hz, pitch_band_Hz, fh)
        if j is None:
            out.append(ModeEstimate("pitch", d.level_N, "not found", "|A1/F1|",
                                    note="no accelerance maximum where the pitching mode can be"))
        else:
            est = estimate_mode(d.f_Hz, d.accelerance, mode="pitch", kind="accelerance", level_N=d.level_N,
                                peak_index=j, guess_zeta=0.02, sd=d.accelerance_sd)
            if est.ok:
                est.extra["compliance_pp"] = float(np.interp(est.resonance_Hz, d.f_Hz, d.compliance_pp))
            out.append(est)
    if feed.ok:
        feed.extra["accelerance"] = float(np.interp(feed.resonance_Hz, d.f_Hz, np.abs(d.accelerance)))
    return out


def track_modes(levels: Sequence[LevelData], *, feed_predicted_Hz: dict[float, float] | None = None,
                pitch: bool = False, pitch_band_Hz: tuple[float, float] | None = None) -> list[ModeEstimate]:
    """Every level's modes, in the order of ``levels``, tracked by identity: the feed
    prediction is the rig model's at that level (``feed_predicted_Hz``: level -> Hz) or
    the previous level's estimate; the pitching mode's is the previous level's estimate
    inside the model's band (or above the feed mode)."""
    out: list[ModeEstimate] = []
    prev_feed = prev_pitch = None
    for d in sorted(levels, key=lambda d: d.level_N):
        fp = (feed_predicted_Hz or {}).get(d.level_N)
        if fp is None or not math.isfinite(fp):
            fp = prev_feed
        ests = level_modes(d, feed_predicted_Hz=fp, pitch=pitch, pitch_predicted_Hz=prev_pitch,
                           pitch_band_Hz=pitch_band_Hz)
        for e in ests:
            if e.ok and e.mode == "feed":
                prev_feed = e.resonance_Hz
            if e.ok and e.mode == "pitch":
                prev_pitch = e.resonance_Hz
        out += ests
    return out


def pitch_band_Hz(model) -> tuple[float, float] | None:
    """Where a rig model's pitching mode can be (its ``pitch_*`` fields; None when off):
    above the 2-DOF's upper undamped frequency with the friction free (k_x = the rig's
    linear spring only), the large-force limit; friction stiffens the feed direction and
    acts on the pitching mode as an additional spring (seed, section 4), which raises it
    without a bound the model can state (the upper end is inf)."""
    if not getattr(model, "pitch_inertia_kg_m2", 0):
        return None
    m, e, J, kth = model.mass_kg, model.cg_height_m, model.pitch_inertia_kg_m2, model.pitch_stiffness_N_m_per_rad
    M = np.array([[m, m * e], [m * e, J]])
    w2 = np.linalg.eigvals(np.linalg.solve(M, np.diag([model.spring_N_per_m, kth]))).real
    return float(math.sqrt(max(w2)) / (2 * math.pi)), math.inf


def next_refinement_Hz(f_Hz: ArrayLike, mag: ArrayLike, peak_index: int, estimate_Hz: float,
                       zeta: float, tolerance: float, f_min: float, f_max: float,
                       last_Hz: float | None = None, sd: ArrayLike | None = None) -> float | None:
    """The next frequency to measure to know a peak within ``tolerance`` (relative), or
    None when it is known: the measured maximum (``peak_index`` into ``f_Hz``, the maximum
    of the curve ``mag``) has measured neighbours within ``tolerance`` on both sides (the
    peak lies between them).  With the points' measured noise ``sd``, the "maximum" is the
    plateau of points the noise does not tell from it (:func:`top_run`, decision record
    0069): converged when the plateau's outer neighbours are within the tolerance of its
    ends, whichever of its points noise made the largest.  A safeguarded line search on
    that bracket, like Brent's (decision record 0063); a gap beside the maximum (the
    plateau) wider than the tolerance is "open":

    1. a half-power point (vertex x (1 -+ zeta), the fit's window), when no point lies
       between vertex x (1 -+ zeta/2) and vertex x (1 -+ 2 zeta) on its side (a zeta
       that shrinks as the points come in does not ask again);
    2. a tolerance step beside the maximum, towards its wider open gap, when the model's
       vertex (``estimate_Hz``: the fit's, else a parabola's) is at the maximum (within
       tolerance/2) or in no open gap; not when the maximum is the last refinement step
       (``last_Hz``) and already has a neighbour within the tolerance (it was such a step
       and came out higher: the vertex lags the data, and tolerance steps would crawl),
       nor beside a plateau (tolerance steps would crawl along it);
    3. the vertex, when it lies inside an open gap, tolerance/2 or more from its ends and,
       once the last step became the maximum, at least a fifth of the gap (log) from either
       end (the gap shrinks to at most 0.8 of itself);
    4. else the wider open gap, halved.

    Every step lands inside an open gap, so the bracket shrinks whatever the vertex says: a
    skewed peak whose fitted vertex drifts with every point no longer spends the budget
    re-measuring it."""
    f = np.asarray(f_Hz, float)
    o = np.argsort(f)
    f = f[o]
    ip = int(np.nonzero(o == peak_index)[0][0])
    fp = f[ip]
    if ip in (0, f.size - 1):
        return None                       # not a peak inside the grid (the caller's case)
    ra, rb = top_run(np.asarray(mag, float)[o], None if sd is None else np.asarray(sd, float)[o], ip)
    fa, fb = float(f[ra]), float(f[rb])   # the plateau's ends (the maximum itself without noise)
    lo, hi = float(f[max(ra - 1, 0)]), float(f[min(rb + 1, f.size - 1)])
    v = estimate_Hz if math.isfinite(estimate_Hz) and lo < estimate_Hz < hi else fp
    z = zeta if math.isfinite(zeta) and 2 * tolerance < zeta < 0.3 else None
    if z is not None:
        for x, side in ((v * (1 - z), -1.0), (v * (1 + z), 1.0)):
            r = side * np.log(f / v)                  # how far out on that side, log
            if f_min <= x <= f_max and not np.any((r >= math.log1p(z / 2)) & (r <= math.log1p(2 * z))):
                return float(x)
    # a gap is closed within the tolerance or, on a flat top, within what the noise resolves:
    # half the measured plateau's span, or the half-width over which a single mode of the
    # fit's zeta stays within the noise of its peak (|H| falls by (df/f)^2 / (2 zeta^2));
    # closer points would be ordered by the noise, not the curve (decision 0069)
    step = max(math.log1p(tolerance), 0.5 * math.log(fb / fa))
    if sd is not None and z is not None:
        rel = float(np.asarray(sd, float)[o][ip] / np.asarray(mag, float)[o][ip])
        step = max(step, z * math.sqrt(2 * NOISE_TIE * math.sqrt(2) * rel))
    # the gaps beside the tied points and between them (two tied points either side of a
    # sharp peak are no plateau: the peak may lie between them, higher)
    pts = f[max(ra - 1, 0):min(rb + 1, f.size - 1) + 1]
    gaps = [(g, float(a), float(b)) for g, a, b in zip(np.log(pts[1:] / pts[:-1]), pts[:-1], pts[1:])
            if g > 1.01 * step]
    if not gaps:
        return None
    _, a, b = max(gaps)
    beside = float(fa * math.exp(-step) if b <= fa else fb * math.exp(step))
    margin = math.log1p(tolerance / 2)
    if ra < rb or step > 1.0001 * math.log1p(tolerance):
        # a plateau: its vertex when that lies in an open gap, else the widest open gap halved
        # when it lies between tied points, else a step beside the plateau by the closing
        # distance (tied: the plateau grows; not: that gap is closed)
        for g, a_v, b_v in gaps:
            if a_v < v < b_v and min(math.log(v / a_v), math.log(b_v / v)) >= margin:
                return float(v)
        return float(math.sqrt(a * b)) if fa <= a and b <= fb else beside
    # the last step became the maximum (or joined the points tied with it)
    moved = last_Hz is not None and any(abs(last_Hz / x - 1) < 1e-9 for x in f[ra:rb + 1])
    crawl = moved and min(fa / lo, hi / fb) - 1 <= 1.01 * tolerance
    if (abs(v / fp - 1) <= tolerance / 2 or not any(a_v < v < b_v for _, a_v, b_v in gaps)) and not crawl:
        return beside
    for g, a_v, b_v in gaps:
        if a_v < v < b_v and min(math.log(v / a_v), math.log(b_v / v)) >= margin \
                and (not moved or 0.2 <= math.log(v / a_v) / g <= 0.8):
            return float(v)
    return float(math.sqrt(a * b))
