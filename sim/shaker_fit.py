"""The electrodynamic shaker's least-squares fit (decision records 0025, 0032): the
amplifier and shaker parameters a run's measured force per drive volt determines, with
their intervals, or the ideal amplifier when one constant gain explains the steps.

System identification, beside sim/identify.py; `bench twin` (bench/twin.py) calls it with
the documented defaults of bench/defaults/sim_rig.toml (moved from bench/twin.py, decision
record 0057).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

# The plant (sim/_plant_kernel.py) and every measured quantity depend on the shaker's six
# keys and the amplifier gain only through A = amp_gain_N_per_V (blocked force per volt at
# DC), tau = L/R, c_e = Bl^2/R (back-EMF damping), m_a, k_a, c_a: the coil's state is
# q = Bl i / F_s with tau q' = A V/F_s - q - c_e x_d'/F_s.  R is therefore fixed at the
# documented default and Bl = sqrt(c_e R), L = tau R.  The damping is fitted as its total
# c_t = c_a + c_e and the back-EMF's share s = c_e / c_t: the two differ only through the
# coil's pole (c_e / (1 + j w tau)), so well below it only c_t acts, and fixing the share
# then leaves c_t, and the force per volt, unbiased.  Decision record 0032.
SHAKER_PARAMS = ("amp_gain_N_per_V", "L_over_R_s", "damping_total_N_s_per_m", "shaker_armature_mass_kg",
                 "shaker_suspension_N_per_m", "back_emf_share")
SHAKER_UPPER = (1e4, 1.0, 2e5, 100.0, 1e8, 1.0)
SHAKER_MIN_STEPS = 8           # fewer steps with a drive ratio: the ideal amplifier at the median ratio
SHAKER_P_VALUE = 0.01          # the shaker model must beat one constant gain at this level (F-test)
SHAKER_FIX_ORDER = (5, 4, 3, 1, 2, 0)    # s, k_a, m_a, tau, c_t, A: which undetermined one to fix first
SHAKER_STARTS = 12             # least-squares starts: the defaults, then each free parameter x 0.1-10 at random


def documented_shaker(m: dict) -> dict:
    """From a rig's documented [rig.model] table (bench/defaults/sim_rig.toml's): R, and
    the value of a shaker parameter the steps cannot determine."""
    R = float(m["shaker_resistance_ohm"])
    ce, ca = float(m["shaker_force_constant_N_per_A"]) ** 2 / R, float(m["shaker_damping_N_s_per_m"])
    return dict(R=R, values=(float(m["amp_gain_N_per_V"]), float(m["shaker_inductance_H"]) / R, ce + ca,
                             float(m["shaker_armature_mass_kg"]), float(m["shaker_suspension_N_per_m"]), ce / (ce + ca)))


def shaker_ratio(theta, freqs_Hz, Zs) -> np.ndarray:
    """|P/V| of decision 0025's formula with theta = (A, tau, c_t, m_a, k_a, s):
    c_e = s c_t, c_a = (1 - s) c_t."""
    A, tau, ct, ma, ka, share = theta
    ce, ca = share * ct, (1 - share) * ct
    w = 2 * np.pi * np.asarray(freqs_Hz, float)
    pole = 1 + 1j * w * tau
    return A / np.abs(pole) * np.abs(Zs) / np.abs(Zs + 1j * w * ma + ca + ka / (1j * w) + ce / pole)


@dataclass
class ShakerFit:
    keys: dict                    # [rig.model] keys to write ({} for the ideal amplifier)
    parameters: dict              # SHAKER_PARAMS name -> {value, low, high, fitted}
    steps: int
    rms_residual: float           # rms of ln(model/measured) over the steps
    ideal_rms_residual: float     # the same for one constant gain (the median ratio)
    p_value: float                # of the F-test shaker model vs one constant gain
    not_fitted: list[dict] = field(default_factory=list)    # {cause, reason}
    note: str = ""

    def as_dict(self) -> dict:
        return dict(model="shaker" if self.keys else "ideal amplifier", parameters=self.parameters,
                    steps=self.steps, rms_residual=self.rms_residual, ideal_rms_residual=self.ideal_rms_residual,
                    p_value=self.p_value, keys=self.keys, note=self.note)


def _fit_free(freqs, ratio, Zs, free, theta0, scale):
    """Least squares of ln(model/measured) over the free parameters, in ln(parameter)
    (positive, spanning decades), from several starts (the problem is not convex: a start
    without damping can settle where the back-EMF is 0).  Returns (theta, result)."""
    from scipy.optimize import least_squares
    idx = np.flatnonzero(free)
    lo = np.log(scale[idx] * 1e-6)
    hi = np.log(np.array(SHAKER_UPPER)[idx])

    def resid(u):
        th = theta0.copy()
        th[idx] = np.exp(u)
        return np.log(shaker_ratio(th, freqs, Zs) / ratio)

    rng = np.random.default_rng(0)                  # deterministic starts
    starts = [np.log(theta0[idx])] + [np.log(theta0[idx]) + rng.uniform(-2.3, 2.3, idx.size) * (idx != 0)
                                      for _ in range(SHAKER_STARTS - 1)]
    best = None
    for u0 in starts:
        r = least_squares(resid, np.clip(u0, lo + 1e-9, hi - 1e-9), bounds=(lo, hi), xtol=1e-12, ftol=1e-12,
                          gtol=1e-12)
        if best is None or r.cost < best.cost:
            best = r
    th = theta0.copy()
    th[idx] = np.exp(best.x)
    return th, best


def shaker_model(freqs_Hz, ratio_N_per_V, Zs, defaults: dict) -> ShakerFit:
    """Fit the electrodynamic shaker of decision 0025 to a run's measured force per drive
    volt (|P1|/|V| per step: the generator's phase is not recorded) given each step's
    measured drive-point impedance ``Zs`` = j w P1 / A1 (N s/m, complex); ``defaults``:
    ``documented_shaker`` of the documented rig.

    Identifiable: A, tau = L/R, c_e = Bl^2/R, m_a, k_a, c_a (module comment), fitted in
    ln(parameter) with 95 % intervals from the Jacobian and the residuals' scatter (Student
    t); a parameter whose interval spans more than a factor e either way (the steps do not
    determine it) is fixed at its default and the rest fitted again (the damping's share s
    first, then k_a, m_a, tau: SHAKER_FIX_ORDER).  The shaker model
    is kept only when it beats one constant gain (F-test at SHAKER_P_VALUE); otherwise, and
    with fewer than SHAKER_MIN_STEPS steps, the ideal amplifier at the median ratio."""
    from scipy import stats
    freqs = np.asarray(freqs_Hz, float)
    ratio = np.asarray(ratio_N_per_V, float)
    Zs = np.asarray(Zs, complex)
    n = ratio.size
    med = float(np.median(ratio)) if n else math.nan
    ideal_rms = float(np.sqrt(np.mean(np.log(ratio / np.exp(np.mean(np.log(ratio)))) ** 2))) if n else math.nan
    ideal = ShakerFit(keys={}, parameters={}, steps=n, rms_residual=ideal_rms, ideal_rms_residual=ideal_rms,
                      p_value=1.0)
    if n < SHAKER_MIN_STEPS:
        ideal.note = (f"{n} steps with a drive ratio (fewer than {SHAKER_MIN_STEPS}): no shaker fitted, "
                      f"the ideal amplifier at the median {med:.4g} N/V") if n else ""
        return ideal
    d = defaults
    scale = np.array(d["values"])
    theta0 = scale.copy()
    theta0[0] = med
    free = np.ones(6, bool)
    fixed_why: dict[int, str] = {}
    while True:
        th, res = _fit_free(freqs, ratio, Zs, free, theta0, scale)
        k = int(free.sum())
        dof = n - k
        rss = float(res.fun @ res.fun)
        J = res.jac                                         # d resid / d ln(theta)
        s2 = rss / max(dof, 1)
        _, sv, Vt = np.linalg.svd(J, full_matrices=False)   # a direction J cannot see has a huge variance
        sv = np.maximum(sv, 1e-12 * max(float(sv.max()), 1e-300))
        cov = s2 * (Vt.T / sv ** 2) @ Vt
        t = float(stats.t.ppf(0.975, max(dof, 1)))
        half = t * np.sqrt(np.maximum(np.diag(cov), 0.0))  # of ln(theta): about the relative half-width
        rel = np.where(np.isfinite(half), half, np.inf)
        u, lo_u, hi_u = np.log(th[free]), np.log(scale[free] * 1e-6), np.log(np.array(SHAKER_UPPER)[free])
        rel[(u - lo_u < 1e-6) | (hi_u - u < 1e-6)] = np.inf     # pinned at a bound: its interval means nothing
        if dof >= 2 and rel.max() <= 1.0:
            break
        # fix an undetermined one, in the order of SHAKER_FIX_ORDER (the damping's share first)
        idx = [int(j) for j in np.flatnonzero(free)]
        undetermined = [j for j in idx if rel[idx.index(j)] > 1.0] if dof >= 2 else idx
        i = next(j for j in SHAKER_FIX_ORDER if j in undetermined)
        worst = idx.index(i)
        if i == 0:                                          # A itself undetermined: nothing to fit
            ideal.note = "the drive ratios do not determine the blocked force per volt: the ideal amplifier"
            return ideal
        fixed_why[i] = (f"the steps do not determine it (fitted {th[i]:.3g}, 95 % interval a factor "
                        f"{math.exp(min(half[worst], 700.0)):.3g} either way)"
                        if dof >= 2 else f"too few steps ({n}) for {k} parameters")
        free[i] = False
        theta0[i] = scale[i]
    rms = math.sqrt(rss / n)
    # F-test: the shaker's k parameters against one constant gain
    rss0 = ideal_rms ** 2 * n
    F = ((rss0 - rss) / (k - 1)) / (rss / dof) if k > 1 and rss > 0 else (math.inf if rss0 > rss else 0.0)
    p = float(stats.f.sf(F, k - 1, dof)) if k > 1 and math.isfinite(F) else (0.0 if F == math.inf else 1.0)
    params: dict[str, dict] = {}
    hw = dict(zip(np.flatnonzero(free), half))
    for i, name in enumerate(SHAKER_PARAMS):
        if free[i]:
            params[name] = dict(value=float(th[i]), low=float(th[i] * math.exp(-hw[i])),
                                high=float(min(th[i] * math.exp(hw[i]), SHAKER_UPPER[i])), fitted=True)
            if fixed_why:        # an interval given the fixed ones: it does not hold their uncertainty
                params[name]["given"] = [SHAKER_PARAMS[j] for j in sorted(fixed_why)]
        else:
            params[name] = dict(value=float(th[i]), low=float(th[i]), high=float(th[i]), fitted=False,
                                reason=fixed_why[i])
    if p > SHAKER_P_VALUE:
        ideal.parameters, ideal.p_value = params, p
        ideal.note = (f"one constant gain explains the drive ratios (rms {100 * ideal_rms:.3g} %; the shaker model "
                      f"{100 * rms:.3g} %, F-test p = {p:.2g}): the ideal amplifier at the median {med:.4g} N/V")
        return ideal
    A, tau, ct, ma, ka, share = (float(v) for v in th)
    ce, ca = share * ct, (1 - share) * ct
    R = d["R"]
    keys = dict(amp_gain_N_per_V=A, shaker_force_constant_N_per_A=math.sqrt(ce * R), shaker_resistance_ohm=R,
                shaker_inductance_H=tau * R, shaker_armature_mass_kg=ma, shaker_suspension_N_per_m=ka,
                shaker_damping_N_s_per_m=ca)
    not_fitted = [dict(cause="shaker_response", reason=(
        f"shaker_force_constant_N_per_A and shaker_resistance_ohm separately: only Bl^2/R and L/R act on the "
        f"plant and the measurement; R fixed at the default {R:g} ohm, Bl = sqrt((Bl^2/R) R), L = (L/R) R"))]
    for i in sorted(fixed_why):
        not_fitted.append(dict(cause="shaker_response", reason=f"{SHAKER_PARAMS[i]}: {fixed_why[i]}; "
                                                              f"fixed at the default {scale[i]:.4g}"))
    return ShakerFit(keys=keys, parameters=params, steps=n, rms_residual=rms, ideal_rms_residual=ideal_rms,
                     p_value=p, not_fitted=not_fitted,
                     note=(f"shaker fitted to {n} steps' drive ratios ({float(ratio.min()):.4g}-{float(ratio.max()):.4g} "
                           f"N/V): rms {100 * rms:.3g} % (one constant gain: {100 * ideal_rms:.3g} %)"))
