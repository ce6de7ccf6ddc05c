"""A friction model fitted to measured fundamentals across levels (issue 42 item 3, decision 0082).

The model (:mod:`sim.describing`): the carriage's mass m on the friction element's describing
function K_eq(a), with a linear structure in parallel where the data need one
(:class:`~sim.describing.Structure`; the one of least BIC).  The parameters (the model's
own, declared by :mod:`sim.friction`, then ``mass_kg``, then the structure's) are fitted by
weighted least squares (scipy's trust-region reflective) on the complex residuals of the
receptance, each real and imaginary part divided by its standard deviation; positive
quantities on their logarithms, a parameter the model fits on its value (Sakai's n) on it.

**What is identified.**  At the optimum the weighted Jacobian J (columns in relative units:
d/d ln p, or d/dp times |p| for a parameter fitted on its value) gives the covariance
(J^T J)^-1 max(1, chi2 / dof) and the 95 % intervals (1.96 standard deviations; on a log
parameter the interval is exp(+-) of that).  Its singular value decomposition J = U S V^T
gives the directions in log-parameter space the data pin down: direction k's combination
prod_i p_i^(V_ik) is known to 1.96 / S_k (times the chi-square's factor) in its logarithm.
A direction (and a parameter) is *identified* when that 95 % half-width is at most
ln 2 (a factor 2), *degenerate* otherwise; a parameter the caller holds is *fixed*.
Directions come as exponents (:class:`Direction`), the largest 1: (F_s: 1, x_s: -1) is the
stiffness F_s / x_s.

**What would separate a degenerate parameter** (:class:`Separation`): the friction's own
parameters are shaped by the loop, which the upper harmonics of time records see and the
fundamental does not (decision 0028's identification); a parameter in newtons (the friction
level: F_s, F_c) is fixed by the saturation of the loop, which a level at or above it shows;
the mass by frequencies across and above the friction resonance; a mode's parameters by
frequencies around the mode.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from .describing import POINTS, STRUCTURE_PARAMETERS, Control, Level, Structure, describing_function, receptance
from .friction import FrictionModel, friction_model

IDENTIFIED_WIDTH = math.log(2.0)   # 95 % half-width (log) at most this: identified
Z95 = 1.959963984540054
SIDE = 1e-6                        # distance kept from a value the model excludes (Sakai's n = 1)
DIFF_STEP = 1e-6                   # relative step of the forward-difference Jacobian
MAX_NFEV = 200
SATURATION_SEEN = 0.9              # loop_reach at which the data have seen the loop saturate
REACH_MIN = 0.01                   # levels below this share of the fitted friction level: its N and m extrapolated


class ParameterStatus(StrEnum):
    IDENTIFIED = "identified"      # 95 % interval within a factor 2
    DEGENERATE = "degenerate"      # the fundamentals leave it (or a combination it is in) open
    FIXED = "fixed"                # held by the caller


class Separation(StrEnum):
    """A measurement that would pin a degenerate parameter down (module doc)."""

    HARMONICS = "harmonics"                                 # time records' upper harmonics: the loop's shape
    LEVEL_AT_SATURATION = "level_at_saturation"             # a level at or above the friction level
    FREQUENCIES_ACROSS_RESONANCE = "frequencies_across_resonance"   # the mass
    FREQUENCIES_AT_MODE = "frequencies_at_mode"             # the structure's parameters


@dataclass(frozen=True)
class Estimate:
    name: str
    unit: str
    value: float
    low: float                     # 95 % interval
    high: float
    status: ParameterStatus


@dataclass(frozen=True)
class Direction:
    """A combination prod p_i^e_i of the fitted parameters (``exponents``: name -> e_i, the
    largest |e_i| = 1, entries below 0.05 dropped) and its 95 % half-width in log."""

    exponents: dict[str, float]
    half_width: float
    identified: bool


@dataclass(frozen=True)
class FundamentalFit:
    """The fit (module doc).  ``friction_values``: the model's parameters as its
    ``periodic_force`` takes them; ``bic_by_structure``: every structure tried;
    ``force_reach``: the largest force amplitude of the data over the fitted friction level
    (the model's ``friction_level``: F_s, F_c); ``loop_reach``: the friction's fundamental at
    the largest fitted amplitude over that level (below :data:`SATURATION_SEEN` the data never
    saw the loop saturate: the friction level, if identified, is the model's extrapolation of
    the pre-rolling loops, and ``separations`` names a level at saturation)."""

    model: str
    structure: Structure
    friction_values: dict[str, Any]
    mass_kg: float
    structure_values: dict[str, float]
    estimates: tuple[Estimate, ...]
    directions: tuple[Direction, ...]
    singular_values: tuple[float, ...]
    chi2: float
    dof: int
    bic: float
    bic_by_structure: dict[str, float]
    separations: tuple[Separation, ...]
    force_reach: float
    loop_reach: float
    n_points: int
    nfev: int
    seconds: float
    residuals: np.ndarray = field(repr=False)

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / max(self.dof, 1)

    def estimate(self, name: str) -> Estimate:
        return next(e for e in self.estimates if e.name == name)

    @property
    def identified(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.estimates if e.status is ParameterStatus.IDENTIFIED)

    @property
    def degenerate(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.estimates if e.status is ParameterStatus.DEGENERATE)


@dataclass(frozen=True)
class _Entry:
    name: str
    unit: str
    log: bool
    lo: float
    hi: float


class _Problem:
    """The parameter vector of one (model, structure) and its weighted residuals."""

    def __init__(self, model: FrictionModel, structure: Structure, levels: Sequence[Level],
                 start: dict[str, Any], fixed: Mapping[str, float], points: int):
        self.model, self.structure, self.levels, self.points = model, structure, levels, points
        self.n_elements = model.n_elements(start)
        entries = []
        for p in model.flat_parameters(self.n_elements):
            lo, hi = p.lo, p.hi
            v = float(_flat_value(start, p.name))
            for x in p.exclude:                      # keep to the side of the start
                if lo < x < hi:
                    lo, hi = (x + SIDE, hi) if v > x else (lo, x - SIDE)
            entries.append(_Entry(p.name, p.unit, p.log, lo, hi))
        entries.append(_Entry("mass_kg", "kg", True, 0.0, math.inf))
        entries += [_Entry(n, u, True, 0.0, math.inf) for n, u in STRUCTURE_PARAMETERS[structure]]
        self.all = entries
        self.start = {e.name: float(_flat_value(start, e.name)) for e in entries}
        self.fixed = {k: float(v) for k, v in fixed.items() if k in self.start}
        self.free = [e for e in entries if e.name not in self.fixed]
        self.H = np.concatenate([lv.receptance_m_per_N for lv in levels])
        self.sigma = np.concatenate([lv.sigma_m_per_N for lv in levels])

    def theta0(self) -> np.ndarray:
        return np.array([math.log(self.start[e.name]) if e.log else self.start[e.name] for e in self.free])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = [(math.log(e.lo) if e.lo > 0 else -np.inf) if e.log else e.lo for e in self.free]
        hi = [(math.log(e.hi) if math.isfinite(e.hi) else np.inf) if e.log else e.hi for e in self.free]
        return np.array(lo), np.array(hi)

    def flat(self, theta: np.ndarray) -> dict[str, float]:
        out = dict(self.start)
        out.update(self.fixed)
        for e, t in zip(self.free, theta):
            out[e.name] = math.exp(t) if e.log else float(t)
        return out

    def split(self, flat: Mapping[str, float]) -> tuple[dict[str, Any], float, dict[str, float]]:
        fv: dict[str, Any] = {}
        for p in self.model.parameters:
            if p.elements:
                fv[p.name] = [flat[f"{p.name}[{i}]"] for i in range(self.n_elements)]
            else:
                fv[p.name] = flat[p.name]
        sv = {n: flat[n] for n, _ in STRUCTURE_PARAMETERS[self.structure]}
        return fv, flat["mass_kg"], sv

    def model_H(self, theta: np.ndarray) -> np.ndarray:
        fv, m, sv = self.split(self.flat(theta))
        return np.concatenate([receptance(self.model, fv, m, lv, self.structure, sv, points=self.points)[0]
                               for lv in self.levels])

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        d = (self.model_H(theta) - self.H) / self.sigma
        return np.concatenate([d.real, d.imag])


def _flat_value(values: Mapping[str, Any], name: str) -> float:
    if name in values:
        return float(values[name])
    base, _, rest = name.partition("[")
    return float(np.atleast_1d(values[base])[int(rest[:-1])])


FORCE_FACTORS = (0.5, 1.0, 2.0, 5.0, 15.0, 40.0)   # friction levels tried, times the largest friction fundamental


def initial_guesses(model: FrictionModel | str, levels: Sequence[Level], *,
                    points: int = POINTS) -> list[dict[str, Any]]:
    """Starts for the fit from the data alone (the fit takes the one of least chi-square):
    the mass and a stiffness K from a straight line of Re(1/H) against w^2 at the level of
    smallest response; the friction level :data:`FORCE_FACTORS` times the largest friction
    fundamental that mass implies, |X (1/H + w^2 m)| (the fundamentals may not say where it
    is: a level well below it reaches the pre-rolling amplitudes only); the model's typical parameters, and for a parameter with an
    excluded value (Sakai's n = 1) also a value on its other side, scaled to both (newtons
    by the force's factor, metres by a length's factor that makes K_eq at the smallest
    amplitude K, N/m and N s/m by their ratio)."""
    m = friction_model(model) if isinstance(model, str) else model
    amp = [float(np.median(np.abs(lv.receptance_m_per_N) * _force(lv))) for lv in levels]
    low = levels[int(np.argmin(amp))]
    w2 = (2 * math.pi * low.frequency_Hz) ** 2
    D = (1.0 / low.receptance_m_per_N).real
    slope, K = np.polyfit(w2, D, 1) if low.frequency_Hz.size >= 2 else (0.0, D[0])
    mass = -slope if slope < 0 else float(np.median(np.abs(D) / w2))
    K = K if K > 0 else float(np.median(np.abs(D)))
    # the friction's fundamental per point, |X (1/H + w^2 m)|, at its largest
    F_top = max(float(np.max(np.abs(lv.receptance_m_per_N) * _force(lv)
                             * np.abs(1.0 / lv.receptance_m_per_N + (2 * math.pi * lv.frequency_Hz) ** 2 * mass)))
                for lv in levels)
    a_low = min(amp)
    typicals = [m.typical()]
    for p in m.parameters:
        for x in p.exclude:
            if p.lo < x < p.hi and not p.elements:
                typicals += [{**t, p.name: x - 0.8 * (t[p.name] - x)} for t in list(typicals)]
    out = []
    for typ in typicals:
        L_typ = m.friction_level(typ) / float(describing_function(m, typ, 1e-9, points=points).real)
        for factor_F in FORCE_FACTORS:
            sF = factor_F * F_top / m.friction_level(typ)

            def scaled(sL: float) -> dict[str, Any]:
                factor = {"N": sF, "m": sL, "N/m": sF / sL, "N s/m": sF / sL}
                return {k: (np.asarray(v) * factor.get(_unit(m, k), 1.0)).tolist() if isinstance(v, list)
                        else v * factor.get(_unit(m, k), 1.0) for k, v in typ.items()}

            # bisection on ln sL for K_eq(smallest amplitude) = K, from where that amplitude is
            # below the scaled model's length F / K_eq (K_eq falls with sL there; below it the
            # loop saturates)
            lo = math.log(a_low / (L_typ * sF))
            hi = lo + 30.0
            for _ in range(50):
                mid = 0.5 * (lo + hi)
                Kmid = describing_function(m, scaled(math.exp(mid)), a_low, points=points).real
                lo, hi = (lo, mid) if Kmid < K else (mid, hi)
            start = scaled(math.exp(0.5 * (lo + hi)))
            start["mass_kg"] = float(mass)
            out.append(start)
    return out


def _unit(model: FrictionModel, name: str) -> str:
    return next(p.unit for p in model.parameters if p.name == name)


def _force(level: Level) -> np.ndarray:
    return level.drive if level.control is Control.FORCE else level.drive / np.abs(level.receptance_m_per_N)


def _structure_start(structure: Structure, prob: _Problem, theta: np.ndarray, mass: float) -> dict[str, float]:
    """A start for a structure's parameters from the fit without one: the mode where the
    misfit is largest."""
    d = np.abs(prob.model_H(theta) - prob.H) / prob.sigma
    f = np.concatenate([lv.frequency_Hz for lv in prob.levels])
    H = np.concatenate([lv.receptance_m_per_N for lv in prob.levels])
    if structure is Structure.MODE:
        return {"mode_mass_kg": 0.05 * mass, "mode_frequency_Hz": float(f[int(np.argmax(d))]),
                "mode_damping_ratio": 0.02}
    k = float(np.median(np.abs(1.0 / H)))
    return {"spring_N_per_m": 0.1 * k, "dashpot_N_s_per_m": 0.02 * math.sqrt(k * mass)}


def _chi2_at(m: FrictionModel, levels: Sequence[Level], start: dict[str, Any], held: dict[str, float],
             points: int) -> float:
    prob = _Problem(m, Structure.NONE, levels, start, held, points)
    r = prob.residuals(prob.theta0())
    return float(r @ r) if np.all(np.isfinite(r)) else math.inf


def _admissible(structure: Structure, prob: _Problem, res: Any, N: int) -> bool:
    """A structure may be chosen when its parameters are what the data show: a mode inside
    the measured band with every parameter identified (a mode outside it, or one the data
    leave open, is the misfit of something else absorbed: a transient, the harmonics the
    single-harmonic balance leaves out)."""
    if structure is Structure.NONE:
        return True
    names = [n for n, _ in STRUCTURE_PARAMETERS[structure]]
    fit = _summarise(prob.model, prob, res, {structure: 0.0}, N, 0, 0.0)
    if any(fit.estimate(n).status is ParameterStatus.DEGENERATE for n in names):
        return False
    if structure is Structure.MODE:
        f = np.concatenate([lv.frequency_Hz for lv in prob.levels])
        return bool(f.min() <= fit.structure_values["mode_frequency_Hz"] <= f.max())
    return True


def fit_fundamentals(levels: Sequence[Level], model: FrictionModel | str = "masing", *,
                     structures: Sequence[Structure | str] = (Structure.NONE, Structure.MODE),
                     guess: Mapping[str, Any] | None = None, fixed: Mapping[str, float] | None = None,
                     points: int = POINTS) -> FundamentalFit:
    """Fit ``model`` (a name of :data:`sim.friction.MODELS` or the model) and the carriage's
    mass to ``levels`` with each of ``structures`` and return the fit of least BIC
    (module doc).  ``guess``: start values by name (the model's parameters, ``mass_kg``, a
    structure's; the best of :func:`initial_guesses` fills the rest); ``fixed``: values held."""
    t0 = time.perf_counter()
    m = friction_model(model) if isinstance(model, str) else model
    levels = list(levels)
    if not levels:
        raise ValueError("fit_fundamentals: no levels")
    held = dict(fixed or {})
    starts = [{**g, **(guess or {}), **held} for g in initial_guesses(m, levels, points=points)]
    if guess and all(p.name in guess for p in m.parameters) and "mass_kg" in guess:
        starts = starts[:1]
    start = min(starts, key=lambda st: _chi2_at(m, levels, st, held, points))
    wanted = [Structure(s) for s in structures]
    order = [Structure.NONE] + [s for s in wanted if s is not Structure.NONE]
    fits: dict[Structure, tuple[_Problem, Any]] = {}
    nfev = 0
    base = None
    for s in order:
        st = dict(start)
        if s is not Structure.NONE and base is not None:
            bp, br = base
            st.update(bp.flat(br.x))
            st.update({k: v for k, v in _structure_start(s, bp, br.x, bp.flat(br.x)["mass_kg"]).items()
                       if k not in (guess or {})})
        prob = _Problem(m, s, levels, st, held, points)
        lo, hi = prob.bounds()
        with np.errstate(invalid="ignore"):
            x0 = np.clip(prob.theta0(), np.where(np.isfinite(lo), lo + 1e-9 * (1 + np.abs(lo)), lo),
                         np.where(np.isfinite(hi), hi - 1e-9 * (1 + np.abs(hi)), hi))
        res = least_squares(prob.residuals, x0, bounds=(lo, hi), method="trf", x_scale="jac",
                            diff_step=DIFF_STEP, max_nfev=MAX_NFEV)
        nfev += int(res.nfev)
        if s is Structure.NONE:
            base = (prob, res)
        if s in wanted:
            fits[s] = (prob, res)
    N = int(sum(2 * lv.frequency_Hz.size for lv in levels))
    bic = {s: float(2 * r.cost + len(p.free) * math.log(N)) for s, (p, r) in fits.items()}
    best = min((s for s in bic if _admissible(s, *fits[s], N)), key=lambda s: bic[s], default=Structure.NONE)
    if best not in fits:
        fits[best] = base                                 # type: ignore[assignment]
        bic[best] = float(2 * base[1].cost + len(base[0].free) * math.log(N))  # type: ignore[index]
    prob, res = fits[best]
    return _summarise(m, prob, res, bic, N, nfev, time.perf_counter() - t0)


def _summarise(m: FrictionModel, prob: _Problem, res: Any, bic: dict[Structure, float], N: int, nfev: int,
               seconds: float) -> FundamentalFit:
    flat = prob.flat(res.x)
    k = len(prob.free)
    chi2 = float(2 * res.cost)
    dof = max(N - k, 1)
    inflate = math.sqrt(max(1.0, chi2 / dof))
    J = np.array(res.jac, dtype=np.float64)
    scale = np.array([1.0 if e.log else max(abs(flat[e.name]), 1e-300) for e in prob.free])
    Js = J / scale[None, :]                               # d r / d ln p for every column
    _, S, Vt = np.linalg.svd(Js, full_matrices=False)
    with np.errstate(divide="ignore"):
        dir_hw = np.where(S > 0, Z95 * inflate / S, np.inf)
        inv = np.where(S > 0, 1.0 / S, np.inf)
    cov = (Vt.T * inv ** 2) @ Vt if np.all(np.isfinite(inv)) else np.full((k, k), np.inf)
    hw = Z95 * inflate * np.sqrt(np.abs(np.diag(cov)))
    fv, mass, sv = prob.split(flat)
    level_N = m.friction_level(fv)
    reach = max(float(np.max(_force(lv))) for lv in prob.levels) / level_N
    friction_names = {p.name for p in m.flat_parameters(prob.n_elements)}
    # levels a hundredth of the friction level see its initial stiffness and damping only: the
    # level itself (and the slip where it is reached) is the curve's form extrapolated, not measured
    extrapolated: set[str] = set()
    if reach < REACH_MIN:
        extrapolated = {e.name for e in prob.free if e.name in friction_names and e.unit in ("N", "m")}
    estimates = []
    for e in prob.all:
        v = flat[e.name]
        if e.name in prob.fixed:
            estimates.append(Estimate(e.name, e.unit, v, v, v, ParameterStatus.FIXED))
            continue
        h = float(hw[prob.free.index(e)])
        status = ParameterStatus.IDENTIFIED if h <= IDENTIFIED_WIDTH and e.name not in extrapolated \
            else ParameterStatus.DEGENERATE
        lo, hi = (v * math.exp(-h), v * math.exp(h)) if h < 700.0 else (0.0, math.inf)
        if not e.log:
            lo, hi = v - h * abs(v), v + h * abs(v)
        estimates.append(Estimate(e.name, e.unit, v, lo, hi, status))
    directions = []
    for s_hw, vrow in zip(dir_hw, Vt):
        c = float(np.max(np.abs(vrow)))
        c = c if vrow[int(np.argmax(np.abs(vrow)))] > 0 else -c
        ex = {e.name: round(float(x / c), 3) for e, x in zip(prob.free, vrow) if abs(x / c) >= 0.05}
        directions.append(Direction(ex, float(s_hw / abs(c)), bool(s_hw / abs(c) <= IDENTIFIED_WIDTH)))
    a_max = max(float(np.max(receptance(m, fv, mass, lv, prob.structure, sv, points=prob.points)[1]))
                for lv in prob.levels)
    loop_reach = float(np.abs(describing_function(m, fv, a_max, points=prob.points))) * a_max / level_N
    open_ = {e.name for e in estimates if e.status is ParameterStatus.DEGENERATE}
    seps = []
    if open_ & friction_names:
        seps.append(Separation.HARMONICS)
    if loop_reach < SATURATION_SEEN or any(e.unit == "N" for e in prob.free if e.name in open_ & friction_names):
        seps.append(Separation.LEVEL_AT_SATURATION)
    if "mass_kg" in open_:
        seps.append(Separation.FREQUENCIES_ACROSS_RESONANCE)
    if open_ & {n for n, _ in STRUCTURE_PARAMETERS[prob.structure]}:
        seps.append(Separation.FREQUENCIES_AT_MODE)
    return FundamentalFit(m.name, prob.structure, fv, mass, sv, tuple(estimates), tuple(directions),
                          tuple(float(x) for x in S), chi2, dof, bic[prob.structure],
                          {str(s): b for s, b in bic.items()}, tuple(seps), reach, loop_reach, N // 2, nfev, seconds,
                          np.asarray(res.fun))
