"""Which causes the data need: greedy forward selection with two gates over the catalog and
the library of force terms together (:mod:`sim.discrepancy.effects`), and the test for
structure that none of them explains.

Each round fits every catalog effect not yet in the model (warm-started from the current
fit) and the :data:`LIBRARY_FITS` library terms that a cheap screen ranks first
(:func:`screen`: the score test of each term from the current residuals, one linear step
with the current parameters free), and scores each by

- delta BIC in quasi-likelihood form, delta chi2 / phi + delta p ln N, with phi the
  current model's reduced chi-square when above 1 (a model error the noise does not
  account for must not make every extra parameter look significant), and
- the leave-one-level-out prediction error of compliance and accelerance
  (:mod:`sim.discrepancy.gain`).

An effect is named only if delta BIC < :data:`BIC_GATE` and the held-out error falls by at
least :data:`HELDOUT_GATE` (relative); while the current model leaves misfit the noise does
not account for (reduced chi-square above :data:`CHI2_UNEXPLAINED`), it must also remove
at least :data:`MISFIT_SHARE_GATE` of that misfit (:func:`passes_bic`, decision 0079).  The best-scoring effect that passes both joins the
model and the next round starts; selection stops when none passes.

Unexplained structure (:func:`settle_final`): the final model, refitted with the noise
of its own residuals, should leave whitened residuals whose mean square, grouped by
harmonic, force level and frequency band, is near 1 in every group.  A reduced chi-square
above :data:`CHI2_UNEXPLAINED`, or a group above :data:`GROUP_UNEXPLAINED` (and far above
its own sampling spread), means the data hold something the final model does not.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace

import numpy as np

from .fit import Fit, Weights, fit, whitened
from .gain import heldout_error
from .models import CATALOG, CENTRE, CENTRED, EFFECTS, LIBRARY, Data, Path
from .rounding import percent_text

log = logging.getLogger(__name__)

BIC_GATE = -10.0
SELECT_NFEV = 50                # a candidate's fit in the selection (the chosen model is refitted in full)
HELDOUT_GATE = 0.10
MISFIT_SHARE_GATE = 0.2         # beside structured misfit, the share of it a cause must explain (decision 0079)
CHI2_UNEXPLAINED = 2.0
GROUP_UNEXPLAINED = 3.0
HELDOUT_CANDIDATES = 2          # per round, the best by BIC get the (costlier) held-out test
LIBRARY_FITS = 3                # per round, the library terms the screen ranks first get a full fit
CENTRE_POINTS = 61              # trial rest positions of the springs in the screen (centre_grid)


@dataclass
class Candidate:
    id: str
    round: int
    fit: Fit
    delta_bic: float
    heldout_before: float = math.nan
    heldout_error: float = math.nan
    named: bool = False
    screened_chi2_drop: float = math.nan     # library terms: the screen's estimate
    misfit_share: float = math.inf          # the share of the current model's excess chi-square it removes
    heldout_thetas: list = field(default_factory=list)

    @property
    def kind(self) -> str:
        return EFFECTS[self.id].kind


@dataclass
class Selection:
    base: Fit
    final: Fit
    named: list[Candidate]
    tried: list[Candidate]
    heldout_base: float
    structure: dict = field(default_factory=dict)
    final_weights: Weights | None = None
    unexplained: bool = False
    reasons: list[str] = field(default_factory=list)
    explanations: list[str] = field(default_factory=list)   # the reasons in a technician's words
    screened: list[tuple[int, str, float]] = field(default_factory=list)   # (round, term, chi2 drop)
    base_heldout_thetas: list = field(default_factory=list)
    interval_inflation: float = 1.0


def init_effect(effect: str, current: Fit, d: Data, W: Weights) -> np.ndarray:
    """Starting values of an effect's parameters (zero, or a grid search for the pitch mode)."""
    if effect != "second_mode":
        return np.zeros(1)
    # kinematic residual of the current model = h theta'' = a u + (a r) v, linear in (a, a r)
    # for a fixed mode frequency and damping: scan those, solve the rest
    _, rK = current.model.residuals(current.theta, d)
    Om = d.Omega
    m = math.exp(current.theta[3])
    wgt = 1.0 / np.sqrt(0.5 * (W.s_Kc[0] ** 2 + W.s_Kc[1] ** 2))
    best: tuple[float, tuple[float, float, float, float] | None] = (math.inf, None)
    f_lo, f_hi = d.omega.min() / (2 * math.pi), 3 * Om.max() / (2 * math.pi)
    for f_p in np.geomspace(f_lo, f_hi, 90):
        w_p = 2 * math.pi * f_p
        for zeta in (0.01, 0.03, 0.1):
            D = w_p ** 2 - Om ** 2 + 2j * zeta * w_p * Om
            u = (-Om ** 2 * d.P / D * wgt).ravel()
            v = (-m * Om ** 4 * d.X / D * wgt).ravel()
            y = (rK * wgt).ravel()
            M = np.column_stack([np.concatenate([u.real, u.imag]), np.concatenate([v.real, v.imag])])
            yy = np.concatenate([y.real, y.imag])
            coef, *_ = np.linalg.lstsq(M, yy, rcond=None)
            cost = float(np.sum((yy - M @ coef) ** 2))
            if cost < best[0] and coef[0] > 0:
                best = (cost, (f_p, zeta, coef[0], coef[1] / coef[0]))
    if best[1] is None:
        return np.array([math.log(f_hi), 0.03, 1e-6, 0.0])
    f_p, zeta, a, r = best[1]
    return np.array([math.log(f_p), zeta, a, r])


def misfit_share(current: Fit, f: Fit) -> float:
    """The share of ``current``'s chi-square above its degrees of freedom (the misfit the
    noise does not account for) that the candidate ``f`` removes; inf when ``current``
    leaves none."""
    excess = current.chi2 - current.dof
    return (current.chi2 - f.chi2) / excess if excess > 0 else math.inf


def passes_bic(c: Candidate, phi: float) -> bool:
    """The first gate: delta BIC below :data:`BIC_GATE` and, while the current model
    leaves structured misfit (reduced chi-square ``phi`` above :data:`CHI2_UNEXPLAINED`), at
    least :data:`MISFIT_SHARE_GATE` of that misfit explained (decision 0079).

    The quasi-likelihood BIC divides by ``phi`` as if the misfit were independent noise;
    then it asks a term for only (10 + ln N) / N of the misfit (0.8 % on 90 steps).  A
    misfit with structure is not noise: any smooth term takes a few per cent of it.  On
    issue 43's second-mode case (n = 0.406, 0.1 F_s moving 1e-3 x_s, where the friction
    along a rebuilt path whose upper harmonics are noise falls to 40 % of the truth's)
    Coulomb friction took 5 % at delta BIC -114, a virgin curve 4 % at -83; every cause
    the project's cases name took 40-100 % of what its round began with."""
    return c.delta_bic < BIC_GATE and (phi <= CHI2_UNEXPLAINED or c.misfit_share >= MISFIT_SHARE_GATE)


def structure(f: Fit, d: Data, W: Weights, freq_bands: int = 3) -> dict:
    """Mean square of the whitened residuals by harmonic (both residuals, and the force
    balance and the kinematics apart), force level and frequency band."""
    r = whitened(f.theta, f.model, d, W).reshape(4, d.X.shape[0], d.X.shape[1])
    sq = (r ** 2).mean(axis=0)                         # steps x K
    sqF, sqK = (r[:2] ** 2).mean(axis=0), (r[2:] ** 2).mean(axis=0)
    levels = np.unique(d.level)
    order = np.argsort(np.argsort(d.omega))
    band = np.minimum(order * freq_bands // max(1, d.omega.size), freq_bands - 1)
    f_Hz = d.omega / (2 * math.pi)
    return dict(
        reduced_chi2=f.reduced_chi2,
        by_harmonic=[float(x) for x in sq.mean(axis=0)],
        by_harmonic_force_balance=[float(x) for x in sqF.mean(axis=0)],
        by_harmonic_kinematics=[float(x) for x in sqK.mean(axis=0)],
        by_level=[float(sq[d.level == lv].mean()) for lv in levels],
        by_frequency_band=[float(sq[band == b].mean()) for b in range(freq_bands)],
        levels_N=[float(np.median(np.abs(d.P[d.level == lv, 0]))) for lv in levels],
        bands_Hz=[[float(f_Hz[band == b].min()), float(f_Hz[band == b].max())] for b in range(freq_bands)],
        counts=dict(harmonic=int(4 * sq.shape[0]), level=[int(4 * sq[d.level == lv].size) for lv in levels],
                    band=[int(4 * sq[band == b].size) for b in range(freq_bands)]))


def _flagged(values, counts) -> list[int]:
    return [i for i, (v, n) in enumerate(zip(values, counts))
            if v > GROUP_UNEXPLAINED and v > 1 + 6 * math.sqrt(2.0 / max(n, 1))]


def _unexplained(s: dict) -> list[str]:
    reasons = []
    if s["reduced_chi2"] > CHI2_UNEXPLAINED:
        reasons.append(f"reduced chi-square {s['reduced_chi2']:.1f} (the noise alone gives about 1)")
    for name, values, counts in (("harmonic", s["by_harmonic"], [s["counts"]["harmonic"]] * len(s["by_harmonic"])),
                                 ("force level", s["by_level"], s["counts"]["level"]),
                                 ("frequency band", s["by_frequency_band"], s["counts"]["band"])):
        reasons += [f"{name} {i + 1}: mean square residual {values[i]:.1f}" for i in _flagged(values, counts)]
    return reasons


def explain(s: dict) -> list[str]:
    """What remains, in a technician's words: which residual (force balance or the two
    motion channels), which harmonic, level or band, and what that usually means."""
    out = []
    n_h = s["counts"]["harmonic"] // 2
    for h in _flagged(s.get("by_harmonic_force_balance", []), [n_h] * 99):
        v = s["by_harmonic_force_balance"][h]
        where = f"the force balance (force minus mass x acceleration minus friction) at harmonic {h + 1}"
        size = f"{math.sqrt(v):.1f} times the noise"
        if h == 0:
            out.append(f"{where}, the drive frequency, misses by {size}: a linear term is missing or wrong "
                       f"(stiffness, damping or mass), or the response had not settled")
        elif (h + 1) % 2 == 0:
            out.append(f"{where} ({h + 1} x the drive frequency) misses by {size}: even harmonics mean the force "
                       f"differs between the two directions of motion (asymmetric friction, a preload, a "
                       f"one-sided spring or stop)")
        else:
            out.append(f"{where} ({h + 1} x the drive frequency) misses by {size}: odd harmonics mean a symmetric "
                       f"nonlinearity the model lacks (a spring stiffening with amplitude, damping growing faster "
                       f"than the speed, a friction curve of another shape)")
    for h in _flagged(s.get("by_harmonic_kinematics", []), [n_h] * 99):
        v = s["by_harmonic_kinematics"][h]
        out.append(f"the accelerometer and the displacement probe disagree at harmonic {h + 1} by "
                   f"{math.sqrt(v):.1f} times the noise: a sensor error (gain, delay, mounting) or a mode of the "
                   f"carriage that one of them sees and the other does not")
    levels = s.get("levels_N", [])
    for i in _flagged(s["by_level"], s["counts"]["level"]):
        at = f" ({levels[i]:.3g} N)" if i < len(levels) else ""
        pos = "the highest" if i == len(s["by_level"]) - 1 else "the lowest" if i == 0 else "a middle"
        out.append(f"force level {i + 1} of {len(s['by_level'])}{at}, {pos}, is fitted worse than the others: an "
                   f"effect that grows or fades with the amplitude")
    bands = s.get("bands_Hz", [])
    flagged = _flagged(s["by_frequency_band"], s["counts"]["band"])
    if flagged and len(flagged) < len(s["by_frequency_band"]):
        for b in flagged:
            rng = f" ({bands[b][0]:.3g} to {bands[b][1]:.3g} Hz)" if b < len(bands) else ""
            out.append(f"the misfit sits in one frequency band{rng}: structure only near one frequency usually "
                       f"means a resonance (a mode) of the rig, the carriage or the fixture")
    if not out and s["reduced_chi2"] > CHI2_UNEXPLAINED:
        out.append(f"the residual is {math.sqrt(s['reduced_chi2']):.1f} times the noise overall, spread over "
                   f"harmonics, levels and frequencies: the noise may be underestimated, or the records were "
                   f"disturbed")
    return out


def _score(ctx: Path, Q: np.ndarray, r: np.ndarray, W: Weights, t: str) -> tuple[float, float]:
    """(chi-square fall, coefficient) of one linear step in term ``t``'s coefficient from the
    residual ``r``, with the current parameters free (``Q``: their Jacobian's basis)."""
    e = EFFECTS[t]
    assert e.force is not None, t
    dG = e.force(ctx, np.array([e.step])) / e.step
    wF, wK = W.whiten(-dG, np.zeros_like(dG), bias=False)
    b = np.concatenate([wF.real.ravel(), wF.imag.ravel(), wK.real.ravel(), wK.imag.ravel()])
    b = b - Q @ (Q.T @ b)
    bb = float(b @ b)
    if not (bb > 1e-300 and np.isfinite(bb)):
        return 0.0, 0.0
    return float((b @ r) ** 2 / bb), float(-(b @ r) / bb)


def centre_grid(ctx: Path, points: int = CENTRE_POINTS) -> np.ndarray:
    """Trial rest positions (m, on the scale of the steps' mean displacements x0): the
    steps' span of x0 widened by three of the largest amplitudes either way."""
    x0 = ctx.x0 if ctx.x0 is not None else np.zeros(1)
    amp = float(0.5 * (ctx.x.max(axis=1) - ctx.x.min(axis=1)).max())
    return np.linspace(float(x0.min()) - 3 * amp, float(x0.max()) + 3 * amp, points)


def screen(current: Fit, d: Data, W: Weights, terms: tuple[str, ...],
           centres: dict | None = None) -> list[tuple[str, float]]:
    """Each library term's estimated fall of chi-square if it joined ``current`` (the score
    test: the term's whitened force at a unit coefficient, projected off the current
    Jacobian, against the current whitened residual), largest first.  Exact for a term
    linear in its coefficient when the rest of the model is linear near the fit; it costs
    one evaluation of the term, not a fit.

    A stiffness term that would bring the springs' rest position x_c with it (the model has
    none yet) is scored at every x_c of :func:`centre_grid` and keeps the best; ``centres``
    (if given) receives ``{term: (x_c in m, coefficient)}`` there, the fit's start."""
    if current.jac is None or current.resid is None:
        raise ValueError("screening needs the current fit's Jacobian")
    ctx = current.model.context(current.theta, d)
    Q, _ = np.linalg.qr(current.jac)
    r = current.resid
    out = []
    for t in terms:
        if t in CENTRED and CENTRE not in current.model.effects:
            best = (-1.0, 0.0, 0.0)
            for x_c in centre_grid(ctx):
                trial = replace(ctx, centre=float(x_c), cache=lambda key, make: make())    # not memoised
                drop, coef = _score(trial, Q, r, W, t)
                if drop > best[0]:
                    best = (drop, float(x_c), coef)
            if centres is not None:
                centres[t] = best[1:]
            out.append((t, best[0]))
        else:
            out.append((t, _score(ctx, Q, r, W, t)[0]))
    return sorted(out, key=lambda x: -x[1])


def term_scale(current: Fit, d: Data, term: str) -> float:
    """A library coefficient whose force is of the order of the drive force: the fit's unit
    for it (nonlinear terms keep 1)."""
    e = EFFECTS[term]
    if e.step != 1.0:
        return 1.0
    assert e.force is not None, e.id
    dG = e.force(current.model.context(current.theta, d), np.ones(1))
    size = float(np.sqrt(np.mean(np.abs(dG[:, 0]) ** 2)))
    ref = float(np.sqrt(np.mean(np.abs(d.P[:, 0]) ** 2)))
    return ref / size if size > 0 and np.isfinite(size) else 1.0


def select(base: Fit, d: Data, W: Weights, catalog: tuple[str, ...] = CATALOG, max_causes: int = 3,
           library: tuple[str, ...] = LIBRARY, library_fits: int = LIBRARY_FITS,
           restart: np.ndarray | None = None, nfev: int = SELECT_NFEV,
           heldout: tuple[float, list] | None = None) -> Selection:
    """``restart``: log F_s, log x_s, n, log m to start the candidates from while the
    current model's F_s or x_s is unbounded (gross sliding beside a spring: the Masing
    model alone runs off to F_s, x_s ~ 1e30 and a candidate warm-started there stays
    stuck, chi-square 1.6e5 where the truth gives 1).  ``nfev``: a candidate's evaluations;
    ``heldout``: the base fit's held-out error and refits when already measured."""
    current = base
    base_thetas: list = [] if heldout is None else list(heldout[1])
    held_cur = (heldout_error(base.model, base.theta, d, W, thetas=base_thetas) if heldout is None
                else heldout[0])
    held_base = held_cur
    named: list[Candidate] = []
    tried: list[Candidate] = []
    screened: list[tuple[int, str, float]] = []
    for rnd in range(1, max_causes + 1):
        phi = max(1.0, current.reduced_chi2)
        cands = []
        lib = tuple(t for t in library if t not in current.model.effects)
        centres: dict = {}
        scores = screen(current, d, W, lib, centres) if lib else []
        screened.extend((rnd, t, x) for t, x in scores)
        gate = -BIC_GATE + math.log(current.n_data)            # a term must at least be able to pass
        picks = [t for t, x in scores[:library_fits] if x / phi > gate]
        screen_of = dict(scores)
        scale_of = {t: term_scale(current, d, t) for t in picks}
        for e in tuple(catalog) + tuple(picks):
            if e in current.model.effects:
                continue
            init = init_effect(e, current, d, W)
            if e in centres:           # a stiffness term with its rest position: the screen's best start
                x_c, coef = centres[e]
                init = np.array([coef / scale_of.get(e, 1.0), x_c / math.exp(current.theta[1])])
            start = current.theta
            if restart is not None and {"F_s_N", "x_s_m"} & set(current.unbounded()):
                start = np.concatenate([restart, current.theta[4:]])
            model, th0 = current.model.extend(start, e, init, scale_of.get(e, 1.0))
            try:
                f = fit(model, th0, d, W, max_nfev=nfev)
            except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
                log.warning("candidate %s did not fit: %s", e, exc)
                continue
            dbic = (f.chi2 - current.chi2) / phi + (f.model.size - current.model.size) * math.log(f.n_data)
            cands.append(Candidate(e, rnd, f, dbic, screened_chi2_drop=screen_of.get(e, math.nan),
                                   misfit_share=misfit_share(current, f)))
        cands.sort(key=lambda c: c.delta_bic)
        tried.extend(cands)
        chosen = None
        for c in [c for c in cands if passes_bic(c, phi)][:HELDOUT_CANDIDATES]:
            c.heldout_before = held_cur
            c.heldout_error = heldout_error(c.fit.model, c.fit.theta, d, W, thetas=c.heldout_thetas)
            if c.heldout_error < (1 - HELDOUT_GATE) * held_cur:
                chosen = c
                break
        log.info("round %d (reduced chi2 %.3g): %s", rnd, phi, ", ".join(
            f"{c.id} dBIC {c.delta_bic:.0f} misfit share {c.misfit_share:.3g} held-out {percent_text(c.heldout_error)}"
            for c in cands))
        if chosen is None:
            break
        chosen.named = True
        named.append(chosen)
        # the selection's fits stop early; the next round starts from a converged model, and
        # what the next candidate must beat is that model's own held-out error: measured from
        # the early-stopped fit it was higher, and a form added beside the cause "improved" on
        # the cause's unconverged fit, not on the cause (issue 33: coulomb_friction and
        # virgin_curve_family beside a second mode that was the only effect)
        chosen.fit = fit(chosen.fit.model, chosen.fit.theta, d, W, max_nfev=100)
        converged: list = []
        held = heldout_error(chosen.fit.model, chosen.fit.theta, d, W, thetas=converged)
        if held < chosen.heldout_error:
            chosen.heldout_error, chosen.heldout_thetas = held, converged
        current, held_cur = chosen.fit, chosen.heldout_error
    return Selection(base=base, final=current, named=named, tried=tried, heldout_base=held_base,
                     screened=screened, base_heldout_thetas=base_thetas)


def settle_final(sel: Selection, d: Data, seed: int = 0) -> Selection:
    """Refit the selected model with the noise of its own residuals
    (:meth:`Weights.propagated`) and test what remains for structure.

    Selection compares candidates in the base model's noise units; the verdict on the
    final model (its intervals, reduced chi-square and the unexplained test) must use the
    noise that actually reaches its residuals."""
    W = Weights.propagated(sel.final.model, sel.final.theta, d, seed=seed)
    final = fit(sel.final.model, sel.final.theta, d, W, max_nfev=100)
    s = structure(final, d, W)
    reasons = _unexplained(s)
    if reasons:
        final, sel.interval_inflation = widen(final, s, sel.named[-1].heldout_thetas if sel.named
                                              else sel.base_heldout_thetas)
    sel.final, sel.final_weights, sel.structure, sel.unexplained, sel.reasons = final, W, s, bool(reasons), reasons
    sel.explanations = explain(s) if reasons else []
    return sel


def widen(f: Fit, s: dict, thetas: list) -> tuple[Fit, float]:
    """Intervals of a model that still leaves structure: the covariance (already scaled by
    the reduced chi-square) is scaled up to the worst group's mean square (harmonic, level,
    band), and no standard error is smaller than the spread of the leave-one-level-out
    refits (a jackknife over force levels: a model error that depends on the level moves
    the parameters with the levels used).  Returns the fit and the largest factor applied
    to a standard error."""
    worst = max([s["reduced_chi2"]] + s["by_harmonic"] + s["by_level"] + s["by_frequency_band"])
    factor = math.sqrt(max(1.0, worst / max(1.0, s["reduced_chi2"])))
    jack = None
    if len(thetas) >= 2:
        T = np.array(thetas)
        L = T.shape[0]
        jack = np.sqrt((L - 1) / L * ((T - T.mean(axis=0)) ** 2).sum(axis=0))

    def widened(cov: np.ndarray) -> tuple[np.ndarray, float]:
        sd = np.sqrt(np.maximum(np.diag(cov), 0.0)) * factor
        if jack is not None:
            sd = np.maximum(sd, jack)
        D = sd / np.sqrt(np.maximum(np.diag(cov), 1e-300))
        return cov * np.outer(D, D), float(D.max())
    cov, inflation = widened(f.cov)
    cov_j = None if f.cov_jacobian is None else widened(f.cov_jacobian)[0]
    cov_m = None if f.cov_noise_model is None else widened(f.cov_noise_model)[0]
    return replace(f, cov=cov, cov_jacobian=cov_j, cov_noise_model=cov_m), inflation
