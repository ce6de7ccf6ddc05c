"""The rig model's steady response per force level: every line drawn beside measurements.

One model of the rig (decision records 0042, 0054): the plant of :mod:`sim.rig` with the
rig file's [rig.model] at its values, every declared effect on (viscous damping, springs,
velocity-dependent and asymmetric friction, the pitching mode, quadratic damping, sensor
gains and delay), as the identification's model (:func:`sim.discrepancy.rigfit.rig_effects`)
declares them.  Left out: sensor noise, an interference line and the electrodynamic shaker,
so the force is an ideal sine whose *measured* fundamental is the level (the bench's force
control holds the measured fundamental; the seed's FRFs are per measured force).

Each frequency is integrated on the compiled plant kernel (through
:class:`sim.rig.SimulatedRig`, so it is the twins' plant to the bit) until the period's
fundamentals stop moving, warm-started from the steady state of the frequency before (an
upward sweep, as the bench's sweeps run).  A plant with no effect beyond the Masing
carriage (F_s, x_s, n, m) is the half-period shooting engine's exact problem: that engine
is used there (:func:`sim.shooting.frf_shooting`), it is faster by two orders.

What comes out is what the bench stores per step: compliance X1/P1, accelerance A1/P1
(drive point), compliance_pp = (x_max - x_min) / (2 |P1|) (seed Eq. 9).  Resonances use the
measurement's definitions (decision 0043): the feed mode is the peak of compliance_pp, the
pitching mode the peak of |A1/P1|; each peak is refined by golden-section search on steady
states (:func:`peak_Hz`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from . import plant_effects
from .rig import RigModel, SimulatedRig, model_keys
from .rig_friction import MASING

log = logging.getLogger(__name__)

SAMPLES_PER_PERIOD = 64        # sensor samples per drive period (the RK4 step is finer: sim.rig)
CHUNK_PERIODS, CHUNK_S = 4, 0.05   # a look at the fundamentals: at least 4 periods and 50 ms
MAX_PERIODS = 1600             # give up (not converged) after this many periods at one frequency
TOLERANCE = 2e-5               # relative change of the fundamentals' estimated remaining transient
HARMONICS = 9                  # harmonics of the periodic displacement whose peak-to-peak is compliance_pp
BEAT, BEAT_PERIODS, BEAT_CHUNKS = 2e-3, 160, 10   # a lasting beat this small is steady enough to draw
GLIDE_STEPS, GLIDE_PERIODS = 16, 2   # from one frequency to the next: 16 phase-continuous steps of 2 periods
SPLIT = 0.8                    # feed mode below, pitching mode above SPLIT x the friction-free pitch frequency
GOLDEN_TOLERANCE = 5e-4        # relative bracket width at which a peak search stops

# what the lines leave out: every key of the noise, the interference line and the shaker, off
LEFT_OUT: dict = {k: key.off for k, key in model_keys("noise", "line", "shaker").items()}
PLAIN = ("F_s_N", "x_s_m", "n", "mass_kg")


def line_model(model: RigModel | dict) -> RigModel:
    """The rig model the lines are drawn from: ``model`` without noise, interference line
    and shaker (module text)."""
    m = RigModel.from_dict(model) if isinstance(model, dict) else model
    return replace(m, **LEFT_OUT)


def plain_masing(model: RigModel) -> bool:
    """True when nothing beyond F_s, x_s, n, m acts on the measured response (the shooting
    engine's problem)."""
    return not (plant_effects.any_on(model) or model.viscous_N_s_per_m or model.spring_N_per_m
                or model.disp_delay_s or model.force_gain_error or model.accel_gain_error or model.disp_gain_error
                or model.friction != MASING)


def single_mode(model: RigModel) -> bool:
    """True when the Masing carriage with a linear spring and a viscous damper is all there is
    (what :mod:`sim.backbone`'s single-harmonic balance describes)."""
    return not (plant_effects.any_on(model) or model.disp_delay_s or model.force_gain_error
                or model.accel_gain_error or model.disp_gain_error or model.friction != MASING)


@dataclass(frozen=True)
class LevelResponse:
    """The model's steady response at one force level, per frequency."""

    level_N: float
    freq_Hz: np.ndarray
    compliance: np.ndarray          # complex X1 / P1, m/N
    accelerance: np.ndarray         # complex A1 / P1 (drive point), 1/kg
    compliance_pp: np.ndarray       # m/N, seed Eq. 9
    converged: np.ndarray           # bool: a steady state within TOLERANCE (NaN values otherwise)
    engine: str                     # "plant" | "shooting"

    def at(self, f_Hz: float) -> int:
        return int(np.argmin(np.abs(self.freq_Hz - f_Hz)))


class _Sweep:
    """One warm-started sweep of the plant: :meth:`point` moves it to a frequency."""

    def __init__(self, model: RigModel, level_N: float):
        self.model = model
        self.rig = SimulatedRig(model)
        # the bench holds the measured force's fundamental at the level
        self.true_N = level_N / (1.0 + model.force_gain_error)
        self.f: float | None = None

    def save(self) -> tuple:
        r = self.rig
        return (r.state.copy(), r.contact_state.copy(), r.pitch_rad, r.pitch_rate_rad_s, r._phase, self.f,
                r.contact_force_N, r.contact_direction)

    def restore(self, saved: tuple) -> None:
        r = self.rig
        r.pitch_rad, r.pitch_rate_rad_s, r._phase, self.f, r.contact_force_N, r.contact_direction = saved[2:]
        r.state, r.contact_state = saved[0].copy(), saved[1].copy()

    def _chunk(self, f: float) -> tuple[complex, complex, np.ndarray, int]:
        """Run one look's worth of periods (at least CHUNK_PERIODS and CHUNK_S); the force's
        and acceleration's fundamentals and the displacement's harmonics 0..HARMONICS over
        all of them (per period's worth of samples), so a free vibration at another frequency
        averages out rather than reading as a change of the steady response."""
        n = SAMPLES_PER_PERIOD
        k = max(CHUNK_PERIODS, math.ceil(f * CHUNK_S))
        blk = self.rig.run(n * k, n * f)
        m = self.model
        F = np.fft.rfft(blk.force_V / m.force_sens_V_per_N)[k] / k
        A = np.fft.rfft(blk.accel_V / m.accel_sens_V_per_m_s2)[k] / k
        X = np.fft.rfft(blk.disp_V / m.disp_sens_V_per_m)[0:k * (HARMONICS + 1):k] / k
        return F, A, X, k

    def point(self, f: float) -> tuple[complex, complex, float, bool]:
        m = self.model
        if self.f is not None and self.f != f:
            # glide from the last frequency (phase-continuous), so the jump between the two steady
            # orbits does not start a free vibration the friction then damps over thousands of periods
            n = SAMPLES_PER_PERIOD
            for g in np.geomspace(self.f, f, GLIDE_STEPS + 1)[1:-1]:
                self.rig.set_generator(freq_Hz=float(g))
                self.rig.run(n * GLIDE_PERIODS, n * float(g))
        self.f = f
        self.rig.set_generator(freq_Hz=f, amplitude_Vpp=2 * self.true_N / m.amp_gain_N_per_V, output_on=True)
        prev = None
        deltas: list[float] = []
        periods = 0
        converged = False
        while periods < MAX_PERIODS:
            F1, A1, Xk, k = self._chunk(f)
            periods += k
            cur = np.array([A1 / F1, Xk[1] / F1])
            if prev is not None:
                d = float(np.max(np.abs(cur - prev) / np.maximum(np.abs(cur), 1e-300)))
                deltas.append(d)
                # remaining transient ~ d r / (1 - r), r the ratio of successive changes (geometric decay)
                r = min(deltas[-1] / deltas[-2], 0.98) if len(deltas) >= 2 and deltas[-2] > 0 else 0.9
                if len(deltas) >= 2 and d * max(r, 0.0) / (1.0 - max(r, 0.0)) < TOLERANCE:
                    converged = True
                    break
                # a beat that does not decay: the carriage's free vibration, which the friction's small
                # loops damp very little at small amplitude; steady within BEAT once it stays that small
                if periods >= BEAT_PERIODS and max(deltas[-BEAT_CHUNKS:]) < BEAT:
                    converged = True
                    break
            prev = cur
        # compliance_pp of the periodic displacement synthesised from its first HARMONICS harmonics
        h = np.zeros(SAMPLES_PER_PERIOD // 2 + 1, complex)
        h[:HARMONICS + 1] = Xk
        x = np.fft.irfft(h, 8 * SAMPLES_PER_PERIOD) * 8
        pp = 0.5 * float(np.ptp(x)) / (2 * abs(F1) / SAMPLES_PER_PERIOD)
        return complex(Xk[1] / F1), complex(A1 / F1), pp, converged


def plant_response(model: RigModel, level_N: float, freqs_Hz) -> LevelResponse:
    """The full plant's steady response along an upward sweep through ``freqs_Hz`` (sorted)."""
    f = np.sort(np.asarray(freqs_Hz, dtype=float))
    sweep = _Sweep(model, level_N)
    C, A, pp, ok = (np.empty(f.size, complex), np.empty(f.size, complex), np.empty(f.size), np.empty(f.size, bool))
    for i, fi in enumerate(f):
        C[i], A[i], pp[i], ok[i] = sweep.point(float(fi))
    if (~ok).any():
        log.info("rig model at %g N: no steady state within %d periods at %d of %d frequencies", level_N,
                 MAX_PERIODS, int((~ok).sum()), f.size)
    return LevelResponse(level_N, f, C, A, pp, ok, "plant")


def shooting_response(model: RigModel, level_N: float, freqs_Hz) -> LevelResponse:
    """The Masing carriage's response by half-period shooting (sim.shooting), in SI units."""
    from .shooting import frf_shooting
    f = np.sort(np.asarray(freqs_Hz, dtype=float))
    ws = model.omega_s
    fr, _ = frf_shooting(2 * math.pi * f / ws, level_N / model.F_s_N, model.n)
    ok = np.asarray(fr.converged, bool)
    pp = np.where(ok, fr.G * model.x_s_m / model.F_s_N, np.nan)
    nan = np.full(f.size, complex(math.nan, math.nan))
    return LevelResponse(level_N, f, nan, nan, pp, ok, "shooting")


@lru_cache(maxsize=64)
def _cached(model: RigModel, level_N: float, freqs: tuple[float, ...]) -> LevelResponse:
    if plain_masing(model):
        return shooting_response(model, level_N, np.array(freqs))
    return plant_response(model, level_N, np.array(freqs))


def level_response(model: RigModel | dict, level_N: float, freqs_Hz) -> LevelResponse:
    """The line of one level (cached per model, level and grid: a report, its modes and
    their figures compute it once)."""
    m = line_model(model)
    return _cached(m, float(level_N), tuple(float(x) for x in np.sort(np.asarray(freqs_Hz, float))))


HELD_TOLERANCE = 1e-3          # a held response's force is solved until |R1| is this close to the level (relative)
HELD_ITERATIONS = 10           # secant steps per frequency before the point is given up (not converged)


@dataclass(frozen=True)
class HeldResponse:
    """The model's steady response with the response's fundamental held at one amplitude
    (a response-controlled run's level), per frequency: the force the level needs and what
    the bench stores per step at it, and d log|R1| / d log|F1| there (the last secant's)."""

    amplitude: float                # the held |X1| (m) or |A1| (m/s^2)
    response: str                   # "disp" or "accel"
    freq_Hz: np.ndarray
    force_N: np.ndarray             # |F1| the level needs
    compliance_pp: np.ndarray       # m/N, seed Eq. 9, at that force
    slope: np.ndarray               # d log|R1| / d log|F1|
    converged: np.ndarray           # bool: a steady state with |R1| within HELD_TOLERANCE


def one_mode_force_N(model: RigModel, X_m: float, freq_Hz: float) -> float:
    """|P1| the Masing carriage with its linear spring and viscous damper needs for a
    displacement fundamental ``X_m`` (single-harmonic balance; the held response's first guess)."""
    from .backbone import loop_coefficients
    w = 2 * math.pi * freq_Hz
    a1, b1 = loop_coefficients(X_m, model.F_s_N, model.x_s_m, model.n)
    return math.hypot(a1 + (model.spring_N_per_m - model.mass_kg * w * w) * X_m, b1 - model.viscous_N_s_per_m * w * X_m)


def _held(model: RigModel, amplitude: float, response: str, freqs: tuple[float, ...]) -> HeldResponse:
    f = np.array(freqs)
    sweep = _Sweep(model, 1.0)
    F_out, pp_out, s_out, ok_out = np.empty(f.size), np.empty(f.size), np.empty(f.size), np.zeros(f.size, bool)
    F, s = math.nan, 1.0
    for i, fi in enumerate(f):
        if not math.isfinite(F):
            w2 = (2 * math.pi * fi) ** 2
            F = one_mode_force_N(model, amplitude if response == "disp" else amplitude / w2, float(fi))
        prev: tuple[float, float] | None = None
        pp, ok = math.nan, False
        for _ in range(HELD_ITERATIONS):
            sweep.true_N = F / (1.0 + model.force_gain_error)     # the measured force's fundamental is F
            C, A, pp, steady = sweep.point(float(fi))
            R = abs(C if response == "disp" else A) * F
            if prev is not None and abs(math.log(F / prev[0])) > 1e-6 and R != prev[1]:
                s = min(max(math.log(R / prev[1]) / math.log(F / prev[0]), 0.2), 5.0)
            if steady and abs(R / amplitude - 1) <= HELD_TOLERANCE:
                ok = True
                break
            prev = (F, R)
            F *= (amplitude / R) ** (1.0 / s)
        F_out[i], pp_out[i], s_out[i], ok_out[i] = F, pp, s, ok
    if (~ok_out).any():
        log.info("rig model at a held %s of %g: not within %g at %d of %d frequencies", response, amplitude,
                 HELD_TOLERANCE, int((~ok_out).sum()), f.size)
    return HeldResponse(amplitude, response, f, F_out, np.where(ok_out, pp_out, np.nan), s_out, ok_out)


@lru_cache(maxsize=16)
def _held_cached(model: RigModel, amplitude: float, response: str, freqs: tuple[float, ...]) -> HeldResponse:
    return _held(model, amplitude, response, freqs)


def held_response(model: RigModel | dict, amplitude: float, freqs_Hz, response: str = "disp") -> HeldResponse:
    """The line of a response-controlled level from the one model of the rig (every
    declared effect, the pitching mode; :func:`line_model`): along an upward sweep of the
    compiled plant, at each frequency the force is found by a secant in log-log (started
    from the previous frequency's, or the one-mode balance) until the steady |X1| (or the
    drive point's |A1|) is within HELD_TOLERANCE of ``amplitude``."""
    m = line_model(model)
    return _held_cached(m, float(amplitude), response, tuple(float(x) for x in np.sort(np.asarray(freqs_Hz, float))))


def _golden(fun, a: float, b: float, tol: float = GOLDEN_TOLERANCE) -> tuple[float, float]:
    """(x, fun(x)) at the maximum of ``fun`` on [a, b] (unimodal there), golden-section search in log x."""
    g = (math.sqrt(5) - 1) / 2
    la, lb = math.log(a), math.log(b)
    c, d = lb - g * (lb - la), la + g * (lb - la)
    fc, fd = fun(math.exp(c)), fun(math.exp(d))
    while lb - la > tol:
        if fc >= fd:
            lb, d, fd = d, c, fc
            c = lb - g * (lb - la)
            fc = fun(math.exp(c))
        else:
            la, c, fc = c, d, fd
            d = la + g * (lb - la)
            fd = fun(math.exp(d))
    return (math.exp(c), fc) if fc >= fd else (math.exp(d), fd)


def peak_Hz(model: RigModel | dict, level_N: float, lo_Hz: float, hi_Hz: float,
            curve: str = "compliance_pp") -> tuple[float, float]:
    """(frequency, peak value) of the model's resonance between ``lo_Hz`` and ``hi_Hz`` (one
    maximum there): the peak of compliance_pp (feed mode) or of |A1/P1| (``curve = "accelerance"``, the pitching
    mode), by golden-section search on steady states, each warm-started from a steady state
    at ``lo_Hz`` approached from below."""
    m = line_model(model)
    if plain_masing(m) and curve == "compliance_pp":
        return _golden(lambda f: float(shooting_response(m, level_N, [f]).compliance_pp[0]), lo_Hz, hi_Hz)
    sweep = _Sweep(m, level_N)
    for f in np.geomspace(lo_Hz / 1.05, lo_Hz, 3):
        sweep.point(float(f))
    start = sweep.save()

    def fun(f):
        sweep.restore(start)        # from the same state each time: one branch, not the path the search took
        C, A, pp, _ = sweep.point(f)
        return pp if curve == "compliance_pp" else abs(A)
    return _golden(fun, lo_Hz, hi_Hz)


def mode_split_Hz(model: RigModel) -> float:
    """Where the feed mode's range ends and the pitching mode's begins: SPLIT x the pitching
    mode's friction-free frequency (friction only raises it; inf without a pitching mode)."""
    from .modal import pitch_band_Hz
    band = pitch_band_Hz(model)
    return SPLIT * band[0] if band else math.inf


def resonance_Hz(resp: LevelResponse, model: RigModel | dict, curve: str = "compliance_pp",
                 above_Hz: float = 0.0, below_Hz: float = math.inf) -> tuple[float, float, str]:
    """(frequency, peak value, note) of the largest maximum of ``curve`` on the level's line
    between ``above_Hz`` and ``below_Hz``, refined by :func:`peak_Hz` between its grid
    neighbours; NaN and a note when the maximum is at the grid's edge or there is none."""
    y = resp.compliance_pp if curve == "compliance_pp" else np.abs(resp.accelerance)
    f = resp.freq_Hz
    valid = np.isfinite(y) & resp.converged
    ok = valid & (f >= above_Hz) & (f <= below_Hz)
    if not ok.any():
        return math.nan, math.nan, "no model value"
    idx = [i for i in range(1, f.size - 1) if ok[i] and valid[i - 1] and valid[i + 1] and y[i] >= y[i - 1]
           and y[i] >= y[i + 1]]
    if not idx:
        i = int(np.nanargmax(np.where(ok, y, -np.inf)))
        return math.nan, math.nan, f"model peak at or beyond the edge of its grid, {f[i]:.4g} Hz"
    i = max(idx, key=lambda j: y[j])
    return (*peak_Hz(model, resp.level_N, float(f[i - 1]), float(f[i + 1]), curve), "")


@dataclass(frozen=True)
class PhasePoint:
    """One point of the model's phase-resonance backbone (decision record 0044's definitions)."""

    force_N: float
    frequency_Hz: float
    amplitude_m: float              # |X1|; for response = "accel" the drive point's |A1| / w^2
    damping_ratio: float            # |F1| sin(-phase_x) / (2 m w^2 |X1|), m the given mass
    converged: bool


PHASE_TARGET_DEG = {"disp": -90.0, "accel": 90.0}
BRACKET_STEP = 1.03             # geometric step of the search for a sign change of the phase error
BRACKET_STEPS = 60


def _phase_error(C: complex, A: complex, response: str) -> float:
    ph = math.degrees(float(np.angle(C if response == "disp" else A)))
    return (ph - PHASE_TARGET_DEG[response] + 180.0) % 360.0 - 180.0


def phase_point(model: RigModel | dict, force_N: float, start_Hz: float, *, response: str = "disp",
                mass_kg: float | None = None, lo_Hz: float = 0.0, hi_Hz: float = math.inf) -> PhasePoint:
    """Where the model's steady response at force ``force_N`` is at phase resonance: the
    response's fundamental at -90 deg from the force's (displacement) or +90 deg (drive-point
    acceleration), as the phase-resonance procedure locks it (decision 0044); found by a
    bracket from ``start_Hz`` and bisection on the phase error, each steady state from the
    same state (one branch).  NaN (``converged = False``) when no sign change lies in
    [``lo_Hz``, ``hi_Hz``]."""
    from scipy.optimize import brentq
    m = line_model(model)
    mass = m.mass_kg if mass_kg is None else mass_kg
    sweep = _Sweep(m, force_N)
    for f in np.geomspace(start_Hz / 1.05, start_Hz, 3):
        sweep.point(float(f))
    start = sweep.save()
    seen: dict[float, tuple[complex, complex, bool]] = {}

    def at(f: float) -> tuple[complex, complex, bool]:
        if f not in seen:
            sweep.restore(start)
            C, A, _, ok = sweep.point(f)
            seen[f] = (C, A, ok)
        return seen[f]

    def err(f: float) -> float:
        C, A, _ = at(f)
        return _phase_error(C, A, response)

    a = start_Hz
    ea = err(a)
    b, eb = a, ea
    for _ in range(BRACKET_STEPS):          # err falls through 0 as the frequency rises through the resonance
        b = b * BRACKET_STEP if ea > 0 else b / BRACKET_STEP
        if not lo_Hz <= b <= hi_Hz:
            break
        eb = err(b)
        if (eb > 0) != (ea > 0) and abs(eb - ea) < 180.0:
            break
        a, ea = b, eb
    else:
        b = math.nan
    if not (math.isfinite(b) and lo_Hz <= b <= hi_Hz and (eb > 0) != (ea > 0)):
        return PhasePoint(force_N, math.nan, math.nan, math.nan, False)
    f = brentq(err, min(a, b), max(a, b), xtol=1e-5 * a, rtol=1e-7)
    C, A, ok = at(f)
    w = 2 * math.pi * f
    X = C * force_N if response == "disp" else -A * force_N / (w * w)
    zeta = force_N * math.sin(-float(np.angle(X))) / (2 * mass * w * w * abs(X))
    return PhasePoint(force_N, f, abs(X), zeta, ok)


def phase_backbone(model: RigModel | dict, forces_N, start_Hz: float, *, response: str = "disp",
                   mass_kg: float | None = None, lo_Hz: float = 0.0, hi_Hz: float = math.inf) -> list[PhasePoint]:
    """The model's phase-resonance backbone at the forces ``forces_N`` (ascending), each
    point's search starting from the one before (:func:`phase_point`)."""
    out, f0 = [], start_Hz
    for P in sorted(forces_N):
        p = phase_point(model, P, f0, response=response, mass_kg=mass_kg, lo_Hz=lo_Hz, hi_Hz=hi_Hz)
        out.append(p)
        if math.isfinite(p.frequency_Hz):
            f0 = p.frequency_Hz
    return out
