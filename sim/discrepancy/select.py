"""Which catalog effects the data need: greedy forward selection with two gates, and the
test for structure that nothing in the catalog explains.

Each round fits every effect not yet in the model (warm-started from the current fit) and
scores it by

- delta BIC in quasi-likelihood form, delta chi2 / phi + delta p ln N, with phi the
  current model's reduced chi-square when above 1 (a model error the noise does not
  account for must not make every extra parameter look significant), and
- the leave-one-level-out prediction error of compliance and accelerance
  (:mod:`sim.discrepancy.gain`).

An effect is named only if delta BIC < :data:`BIC_GATE` and the held-out error falls by at
least :data:`HELDOUT_GATE` (relative).  The best-scoring effect that passes both joins the
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
from dataclasses import dataclass, field

import numpy as np

from .fit import Fit, Weights, fit, whitened
from .gain import heldout_error
from .models import CATALOG, Data
from .rounding import percent_text

log = logging.getLogger(__name__)

BIC_GATE = -10.0
HELDOUT_GATE = 0.10
CHI2_UNEXPLAINED = 2.0
GROUP_UNEXPLAINED = 3.0
HELDOUT_CANDIDATES = 2          # per round, the best by BIC get the (costlier) held-out test


@dataclass
class Candidate:
    id: str
    round: int
    fit: Fit
    delta_bic: float
    heldout_before: float = math.nan
    heldout_error: float = math.nan
    named: bool = False


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


def structure(f: Fit, d: Data, W: Weights, freq_bands: int = 3) -> dict:
    """Mean square of the whitened residuals by harmonic, level and frequency band."""
    r = whitened(f.theta, f.model, d, W).reshape(4, d.X.shape[0], d.X.shape[1])
    sq = (r ** 2).mean(axis=0)                         # steps x K
    levels = np.unique(d.level)
    order = np.argsort(np.argsort(d.omega))
    band = np.minimum(order * freq_bands // max(1, d.omega.size), freq_bands - 1)
    return dict(
        reduced_chi2=f.reduced_chi2,
        by_harmonic=[float(x) for x in sq.mean(axis=0)],
        by_level=[float(sq[d.level == lv].mean()) for lv in levels],
        by_frequency_band=[float(sq[band == b].mean()) for b in range(freq_bands)],
        counts=dict(harmonic=int(4 * sq.shape[0]), level=[int(4 * sq[d.level == lv].size) for lv in levels],
                    band=[int(4 * sq[band == b].size) for b in range(freq_bands)]))


def _unexplained(s: dict) -> list[str]:
    reasons = []
    if s["reduced_chi2"] > CHI2_UNEXPLAINED:
        reasons.append(f"reduced chi-square {s['reduced_chi2']:.1f} (the noise alone gives about 1)")

    def check(name, values, counts):
        for i, (v, n) in enumerate(zip(values, counts)):
            if v > GROUP_UNEXPLAINED and v > 1 + 6 * math.sqrt(2.0 / max(n, 1)):
                reasons.append(f"{name} {i + 1}: mean square residual {v:.1f}")
    check("harmonic", s["by_harmonic"], [s["counts"]["harmonic"]] * len(s["by_harmonic"]))
    check("force level", s["by_level"], s["counts"]["level"])
    check("frequency band", s["by_frequency_band"], s["counts"]["band"])
    return reasons


def select(base: Fit, d: Data, W: Weights, catalog: tuple[str, ...] = CATALOG, max_causes: int = 3) -> Selection:
    current = base
    held_cur = heldout_error(base.model, base.theta, d, W)
    held_base = held_cur
    named: list[Candidate] = []
    tried: list[Candidate] = []
    for rnd in range(1, max_causes + 1):
        phi = max(1.0, current.reduced_chi2)
        cands = []
        for e in catalog:
            if e in current.model.effects:
                continue
            model, th0 = current.model.extend(current.theta, e, init_effect(e, current, d, W))
            try:
                f = fit(model, th0, d, W)
            except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
                log.warning("candidate %s did not fit: %s", e, exc)
                continue
            dbic = (f.chi2 - current.chi2) / phi + (f.model.size - current.model.size) * math.log(f.n_data)
            cands.append(Candidate(e, rnd, f, dbic))
        cands.sort(key=lambda c: c.delta_bic)
        tried.extend(cands)
        chosen = None
        for c in [c for c in cands if c.delta_bic < BIC_GATE][:HELDOUT_CANDIDATES]:
            c.heldout_before = held_cur
            c.heldout_error = heldout_error(c.fit.model, c.fit.theta, d, W)
            if c.heldout_error < (1 - HELDOUT_GATE) * held_cur:
                chosen = c
                break
        log.info("round %d: %s", rnd, ", ".join(f"{c.id} dBIC {c.delta_bic:.0f} held-out "
                                                 f"{percent_text(c.heldout_error)}" for c in cands))
        if chosen is None:
            break
        chosen.named = True
        named.append(chosen)
        current, held_cur = chosen.fit, chosen.heldout_error
    return Selection(base=base, final=current, named=named, tried=tried, heldout_base=held_base)


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
    sel.final, sel.final_weights, sel.structure, sel.unexplained, sel.reasons = final, W, s, bool(reasons), reasons
    return sel
