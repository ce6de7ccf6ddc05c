"""Which friction model the data prefer: every model fitted to the same data, with the same
weights and the same held-out force levels, and the gates a rival must pass to replace
Sakai's Masing model (decision 0078).

Fitted here:

- ``masing``: the analysis's base fit (:func:`sim.discrepancy.analysis.base_fit`);
- ``dahl``: a :class:`~sim.discrepancy.models.Model` whose head is Dahl's law (F_c in the
  F_s slot, the pre-rolling length F_c / sigma in x_s's, the exponent in n's), started from
  the Masing fit (F_c ~ F_s, sigma ~ F_s / x_s, exponent 1): the same least squares, the
  same held-out refits, the catalog's effects on top of it like on Masing;
- ``masing_iwan``: N Maxwell-slip elements on a fixed grid of slip displacements
  (:func:`sim.friction.iwan.design_matrix`); force balance and kinematics are then linear in
  the stiffnesses and the mass, so the fit is one non-negative least squares
  (scipy.optimize.nnls) on the whitened harmonics, and so is each held-out refit.

- ``lugre`` and ``gms`` (rate dependent): by variable projection on a rigid carriage
  (:mod:`sim.discrepancy.rate_rivals`, decision 0086): the parameters the force is linear
  in by non-negative least squares inside, four outside; LuGre started from the Dahl fit,
  GMS's elements on the Iwan fit's grid of slip displacements.

A rival is preferred only if it passes, against the bare Masing fit *and* against Masing
with the causes the selection named on it, the selection's own gates
(:func:`sim.discrepancy.select.passes_bic`: delta BIC below -10 in the quasi-likelihood form,
beside structured misfit at least 0.2 of it; and a held-out error at least 10 % lower):
Masing with a viscous damper and a gain error can beat a bare Dahl, and bare Dahl can beat
bare Masing on such data.  Models whose BIC and held-out error are within those gates of
the preferred one are *not separable* on these data (:func:`separable`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import nnls

from ..friction import MODELS
from ..friction.iwan import design_matrix, virgin_interval
from ..identify import path_harmonics, period_paths
from . import gms_rival
from . import rate_rivals as rr
from .fit import Z95, Fit, Weights, fit
from .gain import frf, heldout_error
from .models import Data, Model
from .select import BIC_GATE, CHI2_UNEXPLAINED, HELDOUT_GATE, MISFIT_SHARE_GATE, Selection

FRICTION_MODELS = tuple(MODELS)            # masing, masing_iwan, dahl, lugre, gms
FITTED = ("masing", "masing_iwan", "dahl", "lugre", "gms")
NO_CATALOG = ("masing_iwan", "lugre", "gms")   # not heads of the Model: the catalog is not searched on top
IWAN_ELEMENTS = 160                     # a fine grid: NNLS keeps few (the issue-41 Iwan case: 12 -> rchi2 882, 64 -> 5.2, 160 -> 1.26)
DAHL_NFEV = 60
DAHL_STARTS = (1.0, 2.0)                   # exponents to start from: the second only if the first leaves misfit
ON_RIVAL_NFEV = 20                         # a catalog candidate's evaluations on top of a converged rival

# what would separate two models the data cannot (issue 41 item 4), by unordered pair
RATE = ("two drive frequencies at the same force level, or a level in gross sliding at two speeds (the rate "
        "dependence of the rate-dependent one)")
SEPARATING = {
    frozenset(("masing", "masing_iwan")): "force levels between and below the measured ones (the virgin curve's "
                                          "shape between the measured amplitudes: Sakai's curve is smooth, the "
                                          "elements' piecewise linear)",
    frozenset(("masing", "dahl")): "a reversal at a smaller amplitude inside a loop (a minor loop): after it "
                                   "Dahl's branch depends on the reversal force, Masing's does not",
    frozenset(("masing_iwan", "dahl")): "a reversal at a smaller amplitude inside a loop (a minor loop): after it "
                                        "Dahl's branch depends on the reversal force, the elements' does not",
    frozenset(("lugre", "dahl")): "two drive frequencies at the same force level, or a level in gross sliding at "
                                  "two speeds (the rate dependence: LuGre's loop changes with the speed through its "
                                  "Stribeck curve and damping, Dahl's does not)",
    frozenset(("lugre", "masing")): RATE,
    frozenset(("lugre", "masing_iwan")): RATE,
    frozenset(("gms", "masing_iwan")): "two drive frequencies at the same force level, or a level in gross sliding "
                                       "at two speeds (GMS with F_s = F_c is the Iwan model; its Stribeck curve and "
                                       "frictional lag make the loops depend on the rate)",
    frozenset(("gms", "masing")): RATE,
    frozenset(("gms", "dahl")): RATE,
    frozenset(("gms", "lugre")): "a reversal at a smaller amplitude inside a loop (a minor loop): after it LuGre's "
                                 "branch depends on the reversal force, the GMS elements' does not",
}
DEFAULT_SEPARATING = "a level above the friction level (gross sliding) at two speeds"


@dataclass
class ModelFit:
    """One friction model fitted to the data: its parameters (name -> value, low, high,
    unit; 95 %), chi-square in the analysis's base weights, parameter count, held-out
    errors (the selection's measure; compliance and accelerance apart), CPU seconds."""

    name: str
    fitted: bool = True
    parameters: dict = field(default_factory=dict)
    chi2: float = math.nan
    n_data: int = 0
    n_params: int = 0
    heldout: float = math.nan
    heldout_compliance: float = math.nan
    heldout_accelerance: float = math.nan
    seconds: float = 0.0
    fit: Fit | None = None                 # head models (masing, dahl)
    heldout_thetas: list = field(default_factory=list)
    virgin_curve: dict | None = None       # masing_iwan: the identified virgin curve with its interval
    values: dict = field(default_factory=dict)   # the model's own parameters (sim.friction names), for its force

    @property
    def dof(self) -> int:
        return max(1, self.n_data - self.n_params)

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / self.dof

    @property
    def bic(self) -> float:
        return self.chi2 + self.n_params * math.log(max(self.n_data, 1)) if self.fitted else math.nan

    def to_dict(self) -> dict:
        out: dict = dict(model=self.name, label=MODELS[self.name].label, fitted=self.fitted)
        if not self.fitted:
            return out
        out.update(parameters=self.parameters, reduced_chi2=self.reduced_chi2, bic=self.bic, n_parameters=self.n_params,
                   heldout_error=self.heldout, heldout_error_compliance=self.heldout_compliance,
                   heldout_error_accelerance=self.heldout_accelerance, seconds=self.seconds)
        if self.virgin_curve is not None:
            out["virgin_curve"] = self.virgin_curve
        return out


def delta_bic(rival: ModelFit, chi2: float, n_params: int, phi: float) -> float:
    """Quasi-likelihood delta BIC of ``rival`` against a fit of chi-square ``chi2`` with
    ``n_params`` parameters and reduced chi-square ``phi`` (as the selection scores causes)."""
    phi = max(1.0, phi)
    return (rival.chi2 - chi2) / phi + (rival.n_params - n_params) * math.log(rival.n_data)


def passes(rival: ModelFit, chi2: float, n_params: int, dof: int, heldout: float) -> bool:
    """The selection's two gates against a fit (chi-square, parameters, degrees of
    freedom, held-out error): delta BIC below :data:`BIC_GATE`, beside structured misfit at
    least :data:`MISFIT_SHARE_GATE` of it removed, and the held-out error
    :data:`HELDOUT_GATE` lower."""
    if not rival.fitted or not math.isfinite(rival.chi2):
        return False
    phi = chi2 / max(dof, 1)
    excess = chi2 - dof
    share = (chi2 - rival.chi2) / excess if excess > 0 else math.inf
    bic_ok = delta_bic(rival, chi2, n_params, phi) < BIC_GATE and (phi <= CHI2_UNEXPLAINED
                                                                     or share >= MISFIT_SHARE_GATE)
    return bic_ok and rival.heldout < (1 - HELDOUT_GATE) * heldout


def separable(best: ModelFit, other: ModelFit) -> bool:
    """Whether the data tell ``other`` from the preferred ``best``: ``other`` is worse by
    the gates (BIC by more than 10 in ``best``'s quasi-likelihood units, or a held-out
    error more than 10 % higher)."""
    if not other.fitted:
        return True
    worse_bic = delta_bic(other, best.chi2, best.n_params, best.reduced_chi2) > -BIC_GATE
    worse_held = other.heldout > best.heldout / (1 - HELDOUT_GATE)
    return worse_bic or worse_held


# ---------------------------------------------------------------- head models (masing, dahl)
def _parts(model: Model, thetas: list, d: Data) -> tuple[float, float]:
    """Held-out rms relative error of compliance and of accelerance (fractions), from the
    leave-one-level-out refits' vectors (in level order)."""
    eC, eA = [], []
    for lv, th in zip(np.unique(d.level), thetas):
        sub = d.subset(d.level == lv)
        P, A = model.predict(th, sub)
        C_pred, A_pred = frf(P, A, sub.X)
        C_meas, A_meas = frf(sub.P, sub.A, sub.X)
        eC.append(np.abs(C_pred / C_meas - 1.0))
        eA.append(np.abs(A_pred / A_meas - 1.0))
    return float(np.sqrt(np.mean(np.concatenate(eC) ** 2))), float(np.sqrt(np.mean(np.concatenate(eA) ** 2)))


def head_fit(name: str, f: Fit, d: Data, W: Weights, heldout: float | None = None,
             thetas: list | None = None, seconds: float = 0.0) -> ModelFit:
    """A :class:`ModelFit` of a head model's fit ``f`` (its held-out error measured unless given)."""
    t0 = time.process_time()
    if heldout is None or not thetas:
        thetas = []
        heldout = heldout_error(f.model, f.theta, d, W, thetas=thetas)
    hc, ha = _parts(f.model, thetas, d)
    return ModelFit(name, parameters=head_parameters(name, f), chi2=f.chi2, n_data=f.n_data, n_params=f.model.size,
                    heldout=heldout, heldout_compliance=hc, heldout_accelerance=ha,
                    seconds=seconds + time.process_time() - t0, fit=f, heldout_thetas=list(thetas),
                    values=head_values(name, f.theta))


def head_values(name: str, theta: np.ndarray) -> dict:
    """A head model's parameters by :mod:`sim.friction`'s names (what its periodic force takes)."""
    if name == "dahl":
        return dict(F_c_N=math.exp(theta[0]), sigma_N_per_m=math.exp(theta[0] - theta[1]), exponent=float(theta[2]))
    return dict(F_s_N=math.exp(theta[0]), x_s_m=math.exp(theta[1]), n=float(theta[2]))


def head_parameters(name: str, f: Fit) -> dict:
    """The head's parameters by the friction model's own names, with 95 % intervals."""
    iv = f.named_intervals()

    def q(t, unit):
        return dict(value=t[0], low=_end(min(t[1], t[2])), high=_end(max(t[1], t[2])), unit=unit)
    out = {}
    if name == "dahl":
        out["F_c_N"] = q(iv["F_s_N"], "N")
        # sigma = F_c / L: log sigma = theta0 - theta1, its variance from the covariance
        s = math.exp(f.theta[0] - f.theta[1])
        var = float(f.cov[0, 0] + f.cov[1, 1] - 2 * f.cov[0, 1])
        w = Z95 * math.sqrt(max(var, 0.0))
        out["sigma_N_per_m"] = dict(value=s, low=_end(s * math.exp(-w)), high=_end(_exp(math.log(s) + w)), unit="N/m")
        out["exponent"] = q(iv["n"], "1")
    else:
        out["F_s_N"], out["x_s_m"], out["n"] = q(iv["F_s_N"], "N"), q(iv["x_s_m"], "m"), q(iv["n"], "1")
    out["mass_kg"] = q(iv["mass_kg"], "kg")
    return out


def dahl_fit(masing: Fit, d: Data, W: Weights) -> ModelFit:
    """Dahl's model from the Masing fit's F_s, x_s, m (a few exponents to start from)."""
    t0 = time.process_time()
    best: Fit | None = None
    for i0 in DAHL_STARTS:
        th = masing.theta[:4].copy()
        th[2] = i0
        try:
            f = fit(Model((), d.X.shape[1], friction="dahl"), th, d, W, max_nfev=DAHL_NFEV)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            continue
        if best is None or f.chi2 < best.chi2:
            best = f
        if best.reduced_chi2 <= CHI2_UNEXPLAINED:
            break
    if best is None:
        return ModelFit("dahl", fitted=False)
    return head_fit("dahl", best, d, W, seconds=time.process_time() - t0)


# ---------------------------------------------------------------- Maxwell-slip (Iwan), linear
@dataclass
class _Linear:
    """Whitened residual r = b + C theta, theta = (m, k_1..k_N) >= 0, per step (rows of
    steps x 4K) so that a subset of steps is a row mask."""

    C: np.ndarray            # steps, 4K, 1 + N
    b: np.ndarray            # steps, 4K
    H: np.ndarray            # steps, K, N: the elements' force harmonics per unit stiffness
    slip: np.ndarray

    def solve(self, rows: np.ndarray) -> tuple[np.ndarray, float]:
        C = self.C[rows].reshape(-1, self.C.shape[2])
        b = self.b[rows].ravel()
        scale = np.sqrt((C ** 2).sum(axis=0))
        scale[scale == 0] = 1.0
        z, rnorm = nnls(C / scale, -b, maxiter=50 * C.shape[1])
        return z / scale, float(rnorm ** 2)


def _iwan_system(d: Data, W: Weights, slip: np.ndarray) -> _Linear:
    K = d.X.shape[1]
    m0 = Model((), K)
    x = m0._displacement({}, d)
    paths, starts = period_paths(x, m0.M)
    B = design_matrix(paths, slip)
    H = np.stack([path_harmonics(B[:, :, i], starts, K) for i in range(slip.size)], axis=-1)
    rK = d.A + d.Omega ** 2 * d.X                     # rigid carriage: A_pred = -Omega^2 X

    def vec(wF, wK):
        return np.concatenate([wF.real, wF.imag, wK.real, wK.imag], axis=1)
    b = vec(*W.whiten(d.P, rK))
    cols = [vec(*W.whiten(-d.A, np.zeros_like(d.A), bias=False))]
    cols += [vec(*W.whiten(-H[:, :, i], np.zeros_like(d.A), bias=False)) for i in range(slip.size)]
    return _Linear(np.stack(cols, axis=-1), b, H, slip)


def _iwan_errors(sys_: _Linear, z: np.ndarray, d: Data, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per step of ``rows``: relative errors of compliance, accelerance and the waveform term
    (as :func:`sim.discrepancy.gain.relative_errors`)."""
    m, k = z[0], z[1:]
    sub = d.subset(rows)
    G = sys_.H[rows] @ k
    A_pred = -sub.Omega ** 2 * sub.X
    P = m * A_pred + G
    C_pred, Acc_pred = frf(P, A_pred, sub.X)
    C_meas, Acc_meas = frf(sub.P, sub.A, sub.X)
    rF = sub.P - m * sub.A - G
    eH2 = np.sum(np.abs(rF[:, 1:]) ** 2, axis=1) / np.abs(sub.P[:, 0]) ** 2
    return np.abs(C_pred / C_meas - 1.0), np.abs(Acc_pred / Acc_meas - 1.0), eH2


def iwan_grid(masing: Fit, d: Data, elements: int) -> np.ndarray:
    """Slip displacements on a geometric grid from a quarter of the smallest step's
    amplitude to three Masing x_s (the Iwan fit's, GMS's coarse one)."""
    amp = np.abs(d.X[:, 0])
    x_s = math.exp(masing.theta[1])
    lo = max(float(amp.min()) / 4, 1e-3 * x_s)
    hi = max(3 * min(x_s, float(amp.max())), 2 * lo)
    return np.geomspace(lo, hi, elements)


def iwan_fit(masing: Fit, d: Data, W: Weights, elements: int = IWAN_ELEMENTS) -> ModelFit:
    """The Maxwell-slip / Iwan model by non-negative least squares: slip displacements on a
    geometric grid from a quarter of the smallest step's amplitude to three Masing x_s (an
    element that never slips is a spring), stiffnesses and mass linear (module doc)."""
    t0 = time.process_time()
    slip = iwan_grid(masing, d, elements)
    sys_ = _iwan_system(d, W, slip)
    every = np.ones(d.X.shape[0], bool)
    z, chi2 = sys_.solve(every)
    active = np.flatnonzero(z > 0)
    C = sys_.C.reshape(-1, sys_.C.shape[2])[:, active]
    n_data = C.shape[0]
    phi = max(1.0, chi2 / max(1, n_data - active.size))
    cov_a = np.linalg.pinv(C.T @ C) * phi
    cov = np.zeros((z.size, z.size))
    cov[np.ix_(active, active)] = cov_a
    eC, eA, eH = [], [], []
    for lv in np.unique(d.level):
        held = d.level == lv
        zt, _ = sys_.solve(~held)
        c, a, h = _iwan_errors(sys_, zt, d, held)
        eC.append(c)
        eA.append(a)
        eH.append(h)
    cc, aa, hh = (np.concatenate(e) for e in (eC, eA, eH))
    held = float(np.sqrt(np.mean(0.5 * (cc ** 2 + aa ** 2) + hh)))
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    params: dict = dict(mass_kg=dict(value=float(z[0]), low=float(z[0] - Z95 * sd[0]), high=float(z[0] + Z95 * sd[0]),
                                     unit="kg"))
    ks = [dict(value=float(z[i + 1]), low=float(max(0.0, z[i + 1] - Z95 * sd[i + 1])),
               high=float(z[i + 1] + Z95 * sd[i + 1]), unit="N/m") for i in range(slip.size) if z[i + 1] > 0]
    params["k_N_per_m"] = ks
    params["f_N"] = [dict(value=q["value"] * s, low=q["low"] * s, high=q["high"] * s, unit="N")
                     for q, s in zip(ks, slip[z[1:] > 0])]
    params["slip_m"] = [float(s) for s in slip[z[1:] > 0]]
    xv = np.linspace(0.0, float(slip.max()) * 1.2, 25)
    curve, half = virgin_interval(xv, slip, z[1:], cov[1:, 1:])
    virgin = dict(x_m=xv.tolist(), force_N=curve.tolist(), half_width_95_N=half.tolist())
    return ModelFit("masing_iwan", parameters=params, chi2=chi2, n_data=n_data, n_params=int(active.size),
                    heldout=held, heldout_compliance=float(np.sqrt(np.mean(cc ** 2))),
                    heldout_accelerance=float(np.sqrt(np.mean(aa ** 2))), seconds=time.process_time() - t0,
                    virgin_curve=virgin, values=dict(k_N_per_m=[q["value"] for q in ks], f_N=[q["value"] for q in params["f_N"]]))


def rate_fits(masing: Fit, dahl: ModelFit, d: Data, W: Weights, others: tuple = ()) -> dict[str, ModelFit]:
    """LuGre (from Dahl's F_c and sigma, or the Masing fit's F_s and F_s / x_s) and GMS (on
    the Iwan grid; ``others``: the fits so far, whose best chi-square decides GMS's fine
    grid) by :mod:`sim.discrepancy.rate_rivals`; a fit that fails is not fitted."""
    out: dict[str, ModelFit] = {}
    t0 = time.process_time()
    s = rr.setup(d, W)
    share = time.process_time() - t0
    F_s, x_s = math.exp(masing.theta[0]), math.exp(masing.theta[1])
    F_c, sigma = (dahl.values["F_c_N"], dahl.values["sigma_N_per_m"]) if dahl.fitted else (F_s, F_s / x_s)
    best = lambda: min((f.chi2 for f in (*others, *out.values()) if f.fitted), default=math.inf)  # noqa: E731
    makers = dict(lugre=lambda: rr.lugre_fit(s, F_c, sigma),
                  gms=lambda: gms_rival.gms_fit(s, iwan_grid(masing, d, gms_rival.GMS_ELEMENTS), best()))
    for name, make in makers.items():
        if name not in FITTED:
            continue
        t1 = time.process_time()
        try:
            res, values, params = make()
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            out[name] = ModelFit(name, fitted=False)
            continue
        out[name] = ModelFit(name, parameters=params, chi2=res.chi2, n_data=res.n_data, n_params=res.n_params,
                             heldout=res.heldout, heldout_compliance=res.heldout_compliance,
                             heldout_accelerance=res.heldout_accelerance,
                             seconds=share / 2 + time.process_time() - t1, values=values)
    return out


def fit_all(masing: ModelFit, d: Data, W: Weights) -> dict[str, ModelFit]:
    """Every model of :data:`FRICTION_MODELS`: the fitted ones, the others as not fitted."""
    assert masing.fit is not None
    out = {"masing": masing, "masing_iwan": iwan_fit(masing.fit, d, W), "dahl": dahl_fit(masing.fit, d, W)}
    out.update(rate_fits(masing.fit, out["dahl"], d, W, tuple(out.values())))
    for name in FRICTION_MODELS:
        out.setdefault(name, ModelFit(name, fitted=False))
    return {name: out[name] for name in FRICTION_MODELS}


def _end(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _exp(x: float) -> float:
    return math.exp(x) if x < 709.0 else math.inf


# ---------------------------------------------------------------- the choice
@dataclass
class FrictionChoice:
    """The model the data prefer (``name``), every model's fit (``fits``, by name), the
    rivals that passed the gates against bare Masing (``passed_bare``) and against Masing
    with its named causes (``passed_final``), the models the data cannot separate from the
    preferred one with the measurement that would (``not_separable``: [(name, what)]),
    and the held-out gain over bare Masing (before, after)."""

    name: str
    fits: dict[str, ModelFit]
    passed_bare: list[str] = field(default_factory=list)
    passed_final: list[str] = field(default_factory=list)
    not_separable: list[tuple[str, str]] = field(default_factory=list)
    gain: tuple[float, float] = (math.nan, math.nan)
    masing_final: tuple[float, int, int, float] = (math.nan, 0, 0, math.nan)   # chi2, params, dof, held-out

    @property
    def preferred(self) -> ModelFit:
        return self.fits[self.name]


def leaves_structure(c: FrictionChoice) -> bool:
    """A preferred rival the catalog is not searched on top of (:data:`NO_CATALOG`) whose
    own fit leaves structure (reduced chi-square above :data:`CHI2_UNEXPLAINED`): Masing's
    library forms must then compete with it (a cubic spring on Masing: GMS passed the
    catalog-only Masing at reduced chi-square 8840, decision 0086)."""
    return c.name in NO_CATALOG and c.preferred.reduced_chi2 > CHI2_UNEXPLAINED


def passed_bare(fits: dict[str, ModelFit]) -> list[str]:
    """The rivals that pass the gates against the bare Masing fit."""
    m = fits["masing"]
    return [n for n, f in fits.items() if n != "masing" and passes(f, m.chi2, m.n_params, m.dof, m.heldout)]


def choose(fits: dict[str, ModelFit], final_chi2: float, final_params: int, final_dof: int,
           final_heldout: float) -> FrictionChoice:
    """The rule of decision 0078: a rival is preferred only if it passes the gates against
    the bare Masing fit and against Masing with the causes named on it (``final_*``: that
    model's chi-square in the base weights, parameters, degrees of freedom, held-out
    error); among those the lowest BIC wins; else ``masing``."""
    m = fits["masing"]
    bare = passed_bare(fits)
    final = [n for n in bare if passes(fits[n], final_chi2, final_params, final_dof, final_heldout)]
    name = min(final, key=lambda n: fits[n].bic) if final else "masing"
    best = fits[name]
    if name == "masing":
        best = ModelFit("masing", chi2=final_chi2, n_data=m.n_data, n_params=final_params, heldout=final_heldout)
    pairs = [(n, SEPARATING.get(frozenset((name, n)), DEFAULT_SEPARATING))
             for n, f in fits.items() if n != name and f.fitted and not separable(best, f)]
    return FrictionChoice(name, fits, bare, final, pairs, (m.heldout, fits[name].heldout if name != "masing"
                                                                       else final_heldout),
                          (final_chi2, final_params, final_dof, final_heldout))


def choose_after(fits: dict[str, ModelFit], sel: Selection) -> FrictionChoice:
    """:func:`choose` against bare Masing and Masing with the causes the selection ``sel``
    named (its fits are in the base weights)."""
    held = sel.named[-1].heldout_error if sel.named else sel.heldout_base
    return choose(fits, sel.final.chi2, sel.final.model.size, sel.final.dof, held)


# ---------------------------------------------------------------- words and schema
WHY = {   # what sets the preferred model apart, in the verdict
    "dahl": "the branch after a reversal depends on the reversal force, as in Dahl's model",
    "masing_iwan": "the Masing rules hold but the virgin curve is not Sakai's: a Maxwell-slip (Iwan) distribution "
                   "of elasto-plastic elements fits it",
    "lugre": "the loops depend on the rate and the branch after a reversal on the reversal force: the LuGre "
             "bristles' Stribeck curve and damping fit them",
    "gms": "the loops follow the Masing rules at rest but depend on the rate: Maxwell-slip elements with a Stribeck "
           "curve and a frictional lag (the generalized Maxwell-slip model) fit them",
}
ON_TOP = {   # the model whose parameters stand in analysis.json's parameters when the catalog is not searched
    "masing_iwan": "the elements' model (its fit is linear",
    "lugre": "the LuGre model (its fit is a variable projection, not the Model's",
    "gms": "the generalized Maxwell-slip model (its fit is a variable projection, not the Model's",
}


def no_catalog_sentence(name: str) -> str:
    """What the verdict says when the preferred model is not a head of the Model."""
    return (f"The catalog's effects are not looked for on top of {ON_TOP[name]}; the parameters above are the "
            f"Masing model's, for reference).")


def leaves_structure_sentence(c: FrictionChoice, masing_said: list[str]) -> str:
    """What the verdict says when a preferred model the catalog is not searched on top of
    (:data:`NO_CATALOG`) leaves structure: its own misfit first, then where the Masing model
    alone misses (``masing_said``: its residuals' structure in words, for reference)."""
    best = c.preferred
    where = f" Where the Masing model alone misses, for reference: {'; '.join(masing_said[:2])}." if masing_said else ""
    return (f"Structure remains that the {MODELS[c.name].label} model does not explain: its reduced chi-square is "
            f"{best.reduced_chi2:.3g} (the noise alone gives about 1, the bar is {CHI2_UNEXPLAINED:g}) and its held-out "
            f"error {100 * best.heldout:.2f} %.{where}")


def choice_sentences(c: FrictionChoice) -> list[str]:
    """The verdict's sentences on the friction model: the preferred rival with its gain, or
    that Masing is kept; then the models the data cannot separate from it."""
    out = []
    best = c.preferred
    m = c.fits["masing"]
    if c.name != "masing":
        dbic = delta_bic(best, m.chi2, m.n_params, m.reduced_chi2)
        out.append(f"The hysteresis is not Masing: {WHY.get(c.name, MODELS[c.name].label)}; held-out error "
                   f"{100 * c.gain[0]:.1f} % -> {100 * c.gain[1]:.2f} % (reduced chi-square {m.reduced_chi2:.3g} -> "
                   f"{best.reduced_chi2:.3g}, BIC by {-dbic:.0f}).")
    elif c.passed_bare:
        out.append(f"{', '.join(MODELS[n].label for n in c.passed_bare)} fits better than the Masing model alone but "
                   f"not better than the Masing model with the causes named here: the friction model is kept as Masing.")
    for n, what in c.not_separable:
        out.append(f"{MODELS[n].label} fits these data as well within the noise (held-out error "
                   f"{100 * c.fits[n].heldout:.2f} %, reduced chi-square {c.fits[n].reduced_chi2:.3g}): the data cannot "
                   f"separate it from {MODELS[c.name].label}; {what} would.")
    return out


def choice_dict(c: FrictionChoice) -> dict:
    """analysis.json's ``friction_models`` (the table) and the reasons (docs/analysis.md)."""
    m = c.fits["masing"]
    rows = []
    for n, f in c.fits.items():
        row = f.to_dict()
        if f.fitted:
            row["delta_bic_vs_masing"] = delta_bic(f, m.chi2, m.n_params, m.reduced_chi2) if n != "masing" else 0.0
        rows.append(row)
    return dict(table=rows, preferred=c.name, passed_against_masing=list(c.passed_bare),
                passed_against_masing_with_causes=list(c.passed_final),
                not_separable=[dict(model=n, measurement=w) for n, w in c.not_separable],
                heldout_error_before=c.gain[0], heldout_error_after=c.gain[1])
