"""Damping ratios with a name (decision record 0056): the three definitions the bench
reports for a mode at a force level, each with an interval that covers.

- **energy balance at resonance** (:func:`energy_balance`): zeta = |F1| sin(-phase) /
  (2 m w^2 |X1|), the definition phase resonance uses (procedures.phase_resonance,
  decision 0044): the force's quadrature part against the kinetic term of an equivalent
  one-mass mode, evaluated on one measured step at (or nearest to) the resonance.  ``m``
  is a stated mass: the carriage's for the feed mode; for the pitching mode the rig
  model's drive-point modal mass (:func:`pitch_modal_mass_kg`), never the carriage's.
  In terms of the receptance H = X1/F1 it is -Im(H) / (2 m w^2 |H|^2).
- **single-mode fit**: sim.modal's local rational-fraction fit (its ``damping_ratio``).
- **half-power**: (f2 - f1) / (2 f_r) from the measured points (:func:`half_power_interval`).

On a linear mode the three agree; on a Masing peak they describe different things and
differ by 10-20 % (shared notes, "Damping ratios on a friction mode").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

Z95 = 1.959964

DEFINITIONS = {
    "fit": "single-mode fit (rational fraction, one mode + residual)",
    "energy_balance": "energy balance at resonance, |F1| sin(-phase) / (2 m w^2 |X1|)",
    "half_power": "half-power bandwidth (f2 - f1) / (2 f_r) of the measured points",
}


def energy_balance_zeta(f_Hz: float, receptance: complex, mass_kg: float) -> float:
    """|F1| sin(-phase) / (2 m w^2 |X1|) = -Im(H) / (2 m w^2 |H|^2) with H = X1/F1."""
    w = 2 * math.pi * f_Hz
    H = complex(receptance)
    return -H.imag / (2 * mass_kg * w * w * abs(H) ** 2)


@dataclass(frozen=True)
class StepFRF:
    """One measured step as the energy balance needs it: its key, frequency, drive-point
    receptance X1/F1 and that ratio's relative standard error (from the harmonic fits'
    standard errors of the two fundamentals; 0 when unknown)."""

    key: str
    f_Hz: float
    receptance: complex
    rel_sd: float = 0.0
    kind: str = "sweep"            # "dwell", "refined" or "sweep"


@dataclass(frozen=True)
class EnergyBalance:
    """The energy-balance ratio of one mode at one level, from the step ``step_key``
    (``source``: dwell / refined / sweep) at ``f_step_Hz``, with its mass and what that
    mass is.  The interval holds the step's noise (+-1.96 sd) and the offset of the step
    from the resonance: on a linear mode the ratio a step at f gives is zeta f_r / f, so
    the value is also moved to both ends of the resonance's interval."""

    value: float
    low: float
    high: float
    step_key: str
    source: str
    f_step_Hz: float
    mass_kg: float
    mass_note: str


def energy_balance(steps: Sequence[StepFRF], resonance_Hz: float, low_Hz: float, high_Hz: float,
                   mass_kg: float, mass_note: str) -> EnergyBalance | None:
    """The energy balance at the resonance from the dwell step nearest it, else the
    refined step, else across the sweep steps nearest it (:func:`_across_steps`; the
    nearest sweep step alone when fewer than ACROSS_MIN); None without a step, a resonance
    or a mass."""
    if not steps or not (math.isfinite(resonance_Hz) and math.isfinite(mass_kg) and mass_kg > 0):
        return None
    rank = {"dwell": 0, "refined": 1, "sweep": 2}
    best_kind = min(rank.get(s.kind, 2) for s in steps)
    s = min((s for s in steps if rank.get(s.kind, 2) == best_kind),
            key=lambda s: abs(math.log(s.f_Hz / resonance_Hz)))
    z = energy_balance_zeta(s.f_Hz, s.receptance, mass_kg)
    lo_f = low_Hz if math.isfinite(low_Hz) and low_Hz > 0 else resonance_Hz
    hi_f = high_Hz if math.isfinite(high_Hz) and high_Hz > 0 else resonance_Hz
    if best_kind == rank["sweep"] and (across := _across_steps(steps, resonance_Hz, lo_f, hi_f, mass_kg)):
        return EnergyBalance(*across, s.key, "across sweep steps", s.f_Hz, mass_kg, mass_note)
    moved = [z, z * s.f_Hz / hi_f, z * s.f_Hz / lo_f, z * s.f_Hz / resonance_Hz]
    sd = abs(z) * s.rel_sd
    return EnergyBalance(z, min(moved) - Z95 * sd, max(moved) + Z95 * sd, s.key, s.kind, s.f_Hz, mass_kg, mass_note)


ACROSS_POINTS = 7        # the sweep steps nearest the resonance the energy balance's curve is fitted to
ACROSS_MIN = 5           # fewer: the nearest step alone (its offset from the resonance moved as a linear mode's)


def _across_steps(steps: Sequence[StepFRF], resonance_Hz: float, lo_f: float, hi_f: float,
                  mass_kg: float) -> tuple[float, float, float] | None:
    """(value, low, high) of the energy balance at the resonance from the sweep steps' ratios
    zeta(f_i) (decision record 0085): a quadratic in f fitted to the ACROSS_POINTS steps
    nearest the resonance, its value there; the interval the curve's over the resonance's
    interval +- t(0.975, dof) of its standard error (the steps' noise: their stated sd where
    every step states one, the residuals' scale where larger or where none is stated).  A
    non-viscous mode's ratio is no zeta f_r / f across the band (a hysteretic one's goes as
    1 / f^2; a friction peak's with the amplitude), so no step's value is moved by a model;
    None with fewer than ACROSS_MIN sweep steps."""
    near = sorted((s for s in steps if s.kind == "sweep"), key=lambda s: abs(math.log(s.f_Hz / resonance_Hz)))
    near = near[:ACROSS_POINTS]
    if len({s.f_Hz for s in near}) < ACROSS_MIN:
        return None
    f = np.array([s.f_Hz for s in near]) / resonance_Hz - 1.0
    zs = np.array([energy_balance_zeta(s.f_Hz, s.receptance, mass_kg) for s in near])
    sd = np.abs(zs) * np.array([s.rel_sd for s in near])
    stated = bool(np.all(np.isfinite(sd) & (sd > 0)))
    w = 1.0 / sd if stated else np.ones_like(zs)
    X = np.column_stack([np.ones_like(f), f, f * f])
    coef, *_ = np.linalg.lstsq(X * w[:, None], zs * w, rcond=None)
    dof = f.size - 3
    chi2 = float(np.sum(((X @ coef - zs) * w) ** 2)) / dof
    scale = max(chi2, 1.0) if stated else chi2
    try:
        cov = scale * np.linalg.inv((X * w[:, None]).T @ (X * w[:, None]))
    except np.linalg.LinAlgError:
        return None
    from scipy import stats
    t = float(stats.t.ppf(0.975, dof)) if (not stated or chi2 > 1.0) else Z95
    ends = []
    for x in {lo_f, resonance_Hz, hi_f}:
        b = np.array([1.0, x / resonance_Hz - 1.0, (x / resonance_Hz - 1.0) ** 2])
        q, se = float(b @ coef), math.sqrt(max(float(b @ cov @ b), 0.0))
        ends += [q - t * se, q + t * se]
    return float(coef[0]), min(ends), max(ends)


def ratio_rel_sd(num: complex, num_sigma: float, den: complex, den_sigma: float) -> float:
    """Relative standard error of num/den from each complex amplitude's standard error
    of its real and imaginary parts (independent): sqrt(2) sigma / |.| each, in quadrature."""
    if abs(num) == 0 or abs(den) == 0:
        return math.inf
    return math.hypot(math.sqrt(2) * num_sigma / abs(num), math.sqrt(2) * den_sigma / abs(den))


def pitch_modal_mass_kg(model, f_Hz: float) -> tuple[float, str]:
    """The drive-point modal mass of a rig model's pitching mode at ``f_Hz`` (its
    measured resonance): the 2-DOF of sim.rig (M = [[m, m e], [m e, J]], K = diag(k_x,
    k_th), force and accelerometer at height h) with the feed stiffness k_x that puts its
    upper undamped frequency at ``f_Hz`` (friction adds to k_x; at or below the
    friction-free frequency k_x is the rig's spring alone); modal mass phi^T M phi /
    (phi_x + h phi_th)^2.  NaN (and the reason) for a model without a pitching mode."""
    J = float(getattr(model, "pitch_inertia_kg_m2", 0.0) or 0.0)
    if J <= 0 or not math.isfinite(f_Hz):
        return math.nan, "no pitching mode in the rig model"
    m, e, h = model.mass_kg, model.cg_height_m, model.drive_height_m
    kth, k0 = model.pitch_stiffness_N_m_per_rad, model.spring_N_per_m
    M = np.array([[m, m * e], [m * e, J]])
    w2 = (2 * math.pi * f_Hz) ** 2
    kx = w2 * m + (w2 * m * e) ** 2 / (kth - w2 * J) if kth != w2 * J else math.inf
    note = "pitch modal mass at the drive point (rig model 2-DOF, k_x set to its measured frequency)"
    if not (math.isfinite(kx) and kx >= k0):
        kx = k0
    ev, vec = np.linalg.eig(np.linalg.solve(M, np.diag([kx, kth])))
    if kx == k0 or not np.isclose(ev.real.max(), w2, rtol=1e-6):
        kx = k0
        ev, vec = np.linalg.eig(np.linalg.solve(M, np.diag([kx, kth])))
        note = "pitch modal mass at the drive point (rig model 2-DOF, friction free)"
    phi = vec[:, int(np.argmax(ev.real))].real
    b = phi[0] + h * phi[1]
    if abs(b) < 1e-12 * np.linalg.norm(phi):
        return math.nan, "the pitching mode does not move the drive point"
    return float(phi @ M @ phi / (b * b)), note


def half_power_interval(f_Hz: ArrayLike, mag: ArrayLike, f_peak: float, peak: float
                        ) -> tuple[float, float, float]:
    """(zeta, low, high) of the half-power ratio from measured points: each half-power
    frequency interpolated between the two points that bracket the level peak/sqrt(2),
    its interval the bracket itself (it holds the crossing of a curve monotonic between
    the points, whatever the interpolation's error); NaNs when the band is not measured
    on both sides of ``f_peak``."""
    f, m = np.asarray(f_Hz, float), np.asarray(mag, float)
    o = np.argsort(f)
    f, m = f[o], m[o]
    level = peak / math.sqrt(2.0)

    def bracket(idx) -> tuple[float, float, float, float] | None:
        """(f, mag) of the last point above the level and the first below, walking
        away from the peak along ``idx`` (the peak itself when no point is above)."""
        fa, ma = f_peak, peak
        for j in idx:
            if m[j] <= level:
                return fa, ma, float(f[j]), float(m[j])
            fa, ma = float(f[j]), float(m[j])
        return None
    lo = bracket(np.nonzero(f < f_peak)[0][::-1])
    hi = bracket(np.nonzero(f > f_peak)[0])
    if lo is None or hi is None:
        return math.nan, math.nan, math.nan

    def cross(fa: float, ma: float, fb: float, mb: float) -> float:
        return fa + (ma - level) * (fb - fa) / (ma - mb) if ma != mb else fa
    f1, f2 = cross(*lo), cross(*hi)
    z = (f2 - f1) / (2 * f_peak)
    return float(z), float(max((hi[0] - lo[0]) / (2 * f_peak), 0.0)), float((hi[2] - lo[2]) / (2 * f_peak))
