"""Identification with the model of the rig: F_s, x_s, n and m fitted together with the
modes and effects the rig file declares (decision record 0042).

A carriage with a column pitches (decision 0013); the one-mode identification
(:mod:`sim.identify`) then reads the pitching mode's share of the accelerometer as mass and
friction and lands far from the truth with a reduced chi-square of millions (issue 25:
F_s 16.95 N for 12, x_s 11.25 um for 7).  Here the identification fits the analysis' own
:class:`~sim.discrepancy.models.Model` with the effects :func:`rig_effects` reads from the
rig file's ``[rig.model]`` (the pitching mode from J, k_th, c_th, h, e; viscous damping, a
linear spring, speed-dependent friction, a probe delay or gain error), started at the
declared values and refitted with them free, in the noise of the model's own residuals
(:meth:`~sim.discrepancy.fit.Weights.propagated`) with the empirical per-step floor on the
covariance (decision 0036).  Causes an analysis named (``analysis.json``) are added the
same way.  The online variant (:class:`OnlineRigFit`) holds the declared effects at the
rig file's values and fits the four parameters, bounded to a factor
:data:`BOUND_FACTOR` of the expected values; an estimate on a bound is flagged.

Misfit: when the reduced chi-square is above what the noise explains
(:func:`sim.identify.misfit_text`), every estimate says so in words; the intervals are already widened
by sqrt(reduced chi-square) and by the empirical floor.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import least_squares

from ..errors import ConfigurationError
from ..identify import MISFIT_CHI2, PARAMS, PRIOR_SIGMA, StepHarmonics, misfit_text
from ..step_record import records_of
from .analysis import base_fit, data_from_steps
from .fit import N_BOUNDS, Fit, Weights, fit
from .models import EFFECTS, Data, Model

if TYPE_CHECKING:
    from ..rig import RigModel

BOUND_FACTOR = 20.0        # online: F_s, x_s, m within this factor of the rig file's expected values


@dataclass(frozen=True)
class _Step:
    """A step as :func:`~sim.discrepancy.analysis.data_from_steps` reads it."""

    harmonics: StepHarmonics
    level_N: float
    key: str = ""


def step_harmonics_of(result: dict) -> StepHarmonics:
    """A stored step result's harmonics: every harmonic its record holds (format version 2,
    decision 0047), else the plan's harmonics of its fits (version 1).  A fit from the
    plan's 5-9 harmonics rebuilds the motion from those alone and is biased (decision 0049);
    `bench identify` and the run's final fit read the record, and so does every caller here
    (decision 0064)."""
    rec = records_of(result)
    return StepHarmonics.from_records(rec) if rec is not None else StepHarmonics.from_result(result)  # type: ignore[arg-type]


def as_steps(steps) -> list:
    """Measured steps (anything with ``harmonics`` and ``level_N``), :class:`StepHarmonics`
    or stored step results (dicts: :func:`step_harmonics_of`) as steps for
    :func:`data_from_steps`."""
    out = []
    for s in steps:
        if isinstance(s, dict):
            s = step_harmonics_of(s)
        if isinstance(s, StepHarmonics):
            s = _Step(s, float(abs(s.force[0])) if s.force.size else 0.0)
        out.append(s)
    return out


def rig_effects(model: RigModel | Mapping | None) -> dict[str, np.ndarray]:
    """Effect id -> start values (the Model's fit units) of what ``[rig.model]`` declares:
    a rig's parsed model, or its keys (a key not given is 0)."""
    if not model:
        return {}
    keys: Mapping = model if isinstance(model, Mapping) else asdict(model)

    def g(k: str) -> float:
        try:
            v = float(keys.get(k) or 0.0)
        except (TypeError, ValueError):
            return 0.0
        return v if math.isfinite(v) else 0.0
    out: dict[str, np.ndarray] = {}
    if g("pitch_inertia_kg_m2") > 0 and g("pitch_stiffness_N_m_per_rad") > 0 and g("drive_height_m") > 0:
        J, k_th, h = g("pitch_inertia_kg_m2"), g("pitch_stiffness_N_m_per_rad"), g("drive_height_m")
        w_p = math.sqrt(k_th / J)
        zeta = min(max(g("pitch_damping_N_m_s_per_rad") / (2 * J * w_p), 2e-4), 0.45)
        out["second_mode"] = np.array([math.log(w_p / (2 * math.pi)), zeta, h * h / J, g("cg_height_m") / h])
    if g("viscous_N_s_per_m") > 0:
        out["viscous_damping"] = np.array([g("viscous_N_s_per_m")])
    if g("spring_N_per_m") > 0:
        out["linear_spring"] = np.array([g("spring_N_per_m")])
    if g("friction_alpha") > 0 and g("friction_v_ref_m_per_s") > 0:
        out["velocity_dependent_friction"] = np.array([g("friction_alpha") / g("friction_v_ref_m_per_s")])
    if g("disp_delay_s") > 0:
        out["sensor_delay"] = np.array([g("disp_delay_s")])
    gain = (1 + g("disp_gain_error")) / (1 + g("accel_gain_error")) - 1
    if abs(gain) > 0:
        out["sensor_gain_error"] = np.array([gain])
    return out


def analysis_effects(analysis: dict | None) -> tuple[str, ...]:
    """The physical causes an ``analysis.json`` named (artefacts are not part of the model)."""
    if not isinstance(analysis, dict):
        return ()
    return tuple(str(c["id"]) for c in analysis.get("causes") or []
                 if isinstance(c, dict) and c.get("id") in EFFECTS and c.get("kind") != "artefact")


def estimate_dict(f: Fit, steps_used: int, source: str, extra_warnings: list[str] | None = None) -> dict:
    """The estimate in :meth:`sim.identify.Estimate.as_dict`'s layout, with the model's
    effects and their parameters, the misfit verdict and where it came from."""
    iv = f.named_intervals()
    values, low, high, rel = {}, {}, {}, {}
    for i, k in enumerate(PARAMS):
        values[k], low[k], high[k] = iv[k]
        sd = math.sqrt(max(float(f.cov[i, i]), 0.0))
        rel[k] = sd / abs(values[k]) if k == "n" and values[k] else sd
    warnings = list(extra_warnings or [])
    warnings += [f"{k} is poorly determined by these steps (relative standard error {100 * rel[k]:.0f} %)"
                 for k in PARAMS if not rel[k] < 0.1]
    mis = misfit_text(f.reduced_chi2, f.dof)
    if mis:
        warnings.insert(0, mis)
    effects = {}
    for e in f.model.effects:
        for name in EFFECTS[e].names if e in EFFECTS else ():
            key = f"{e}.{name}"
            if key in iv:
                effects[key] = dict(value=iv[key][0], low=min(iv[key][1:]), high=max(iv[key][1:]))
    return dict(values=values, low=low, high=high, rel_std=rel, steps_used=steps_used, reduced_chi2=f.reduced_chi2,
                warnings=warnings, model=dict(effects=list(f.model.effects), parameters=effects),
                misfit=bool(mis), source=source)


def identify_rig(steps, guess: dict, rig_model: RigModel | Mapping | None = None, extra: tuple[str, ...] = (),
                 harmonics: int = 9, max_nfev: int = 100, source: str = "final fit with the rig's modes") -> dict:
    """F_s, x_s, n, m with the rig's declared effects (and ``extra`` ones, e.g. an analysis'
    causes) fitted alongside, in the noise of the model's own residuals; an estimate dict
    (:func:`estimate_dict`).  Without effects it is the base model's final fit."""
    steps = as_steps(steps)
    if not steps:
        raise ConfigurationError("no steps to identify from")
    d = data_from_steps(steps, harmonics)
    base, W = base_fit(steps, d, guess, d.X.shape[1])
    declared = rig_effects(rig_model)
    if declared or extra:
        def fitted_from(theta: np.ndarray) -> Fit:
            """The base model with the declared and the extra effects, fitted from ``theta``."""
            model = base.model
            for e, init in declared.items():
                model, theta = model.extend(theta, e, init)
            for e in extra:
                if e not in model.effects:
                    model, theta = model.extend(theta, e, _init(e, model, theta, d, W))
            return fit(model, theta, d, W, max_nfev=max_nfev)
        # start the base parameters at the expected values (the one-mode fit is biased by
        # the very effects added here) unless the one-mode fit already fits
        f = fitted_from(_guess_theta(guess) if base.reduced_chi2 > MISFIT_CHI2 else base.theta)
        if base.reduced_chi2 < f.reduced_chi2:     # from the guess it went astray: from the base fit
            f2 = fitted_from(base.theta)
            f = f2 if f2.reduced_chi2 < f.reduced_chi2 else f
    else:
        f = base
    Wp = Weights.propagated(f.model, f.theta, d)
    f = fit(f.model, f.theta, d, Wp, max_nfev=max_nfev)
    return estimate_dict(f, len(steps), source, few_harmonics_text(f, d.Xf.shape[1] if d.Xf is not None else d.X.shape[1],
                                                                    harmonics))


def few_harmonics_text(f: Fit, recorded: int, wanted: int) -> list[str]:
    """Words when a misfit may come from the steps recording fewer harmonics than the model
    uses: the displacement path, and the friction and |v| along it, are rebuilt from the
    recorded harmonics only, and a large-slip step's reversals need more (issue 25: on the
    pitching rig 5 harmonics gave a reduced chi-square of 5-190 at the TRUE parameters on
    noise-free data and F_s biased by 1-2 standard errors; 9 fitted to the noise, decision 0049)."""
    if recorded >= wanted or not misfit_text(f.reduced_chi2, f.dof):
        return []
    return [f"the steps record {recorded} harmonics and this model rebuilds the motion from them: a misfit "
            f"from too few harmonics biases F_s and x_s; record more ([plan.control] harmonics: at least {wanted}, "
            f"25 with levels well above F_s; min_sample_rate_Hz keeps them below Nyquist)"]


def _init(effect: str, model: Model, theta: np.ndarray, d: Data, W: Weights) -> np.ndarray:
    from .select import init_effect
    cur = Fit(model, theta, np.eye(model.size), 0.0, 1)
    return init_effect(effect, cur, d, W)


def _guess_theta(guess: dict) -> np.ndarray:
    return np.array([math.log(guess["F_s_N"]), math.log(guess["x_s_m"]), guess["n"], math.log(guess["mass_kg"])])


class OnlineRigFit:
    """Online identification with the rig's declared effects held at the rig file's values:
    F_s, x_s, n, m refitted after every step (warm-started, a small budget), with the weak
    prior of :mod:`sim.identify` at the expected values and bounds a factor
    :data:`BOUND_FACTOR` either side of them; an estimate on a bound is flagged."""

    def __init__(self, guess: dict, rig_model: RigModel | Mapping | None, harmonics: int = 5):
        self.guess = dict(guess)
        self.K = harmonics
        self.model = Model((), harmonics)
        theta = _guess_theta(guess)
        for e, init in rig_effects(rig_model).items():
            self.model, theta = self.model.extend(theta, e, init)
        self.theta = theta
        self.prior = theta[:4].copy()
        self.steps: list = []
        self._weights: list[Weights] = []
        self.estimate: dict | None = None

    def add(self, step) -> None:
        """A step, with the noise of the model's residuals propagated through it once, at
        the current estimate (the pitching mode feeds the probe's noise into the force
        balance hundreds of times over: decision 0020)."""
        s = as_steps([step])
        d = data_from_steps(s, self.K)
        self._weights.append(Weights.propagated(self.model, self.theta, d, tail_draws=4))
        self.steps += s

    def fit(self, max_nfev: int = 25) -> dict:
        if not self.steps:
            raise ConfigurationError("no steps to identify from")
        d = data_from_steps(self.steps, self.K)
        K = d.X.shape[1]
        ws = self._weights

        def cat(name: str, axis: int) -> np.ndarray:
            return np.concatenate([np.asarray(getattr(w, name))[(slice(None),) * axis + (slice(None), slice(0, K))]
                                   for w in ws], axis=axis)
        W = Weights(cat("s_F", 1), cat("c", 1), cat("s_Kc", 1), cat("bias_F", 0), cat("bias_K", 0))
        lo4 = np.array([self.prior[0] - math.log(BOUND_FACTOR), self.prior[1] - math.log(BOUND_FACTOR), N_BOUNDS[0],
                        self.prior[3] - math.log(BOUND_FACTOR)])
        hi4 = np.array([self.prior[0] + math.log(BOUND_FACTOR), self.prior[1] + math.log(BOUND_FACTOR), N_BOUNDS[1],
                        self.prior[3] + math.log(BOUND_FACTOR)])
        th = self.theta.copy()

        def resid(x: np.ndarray) -> np.ndarray:
            th[:4] = x
            rF, rK = self.model.residuals(th, d)
            wF, wK = W.whiten(rF, rK)
            return np.concatenate([wF.real.ravel(), wF.imag.ravel(), wK.real.ravel(), wK.imag.ravel(),
                                   (x - self.prior) / PRIOR_SIGMA])
        x0 = np.clip(self.theta[:4], lo4 + 1e-9, hi4 - 1e-9)
        res = least_squares(resid, x0, bounds=(lo4, hi4), x_scale=np.full(4, 0.1), max_nfev=max_nfev,
                            method="trf", ftol=1e-5, xtol=1e-5)
        th[:4] = res.x
        self.theta = th.copy()
        data = res.fun[:-4]
        dof = max(1, data.size - 4)
        chi2 = float(data @ data / dof)
        _, sv, Vt = np.linalg.svd(res.jac, full_matrices=False)
        sv = np.maximum(sv, sv.max() * 1e-12)
        cov = np.zeros((self.model.size, self.model.size))
        cov[:4, :4] = (Vt.T / sv ** 2) @ Vt * max(chi2, 1.0)
        f = Fit(self.model, th.copy(), cov, chi2 * dof, data.size + 4)
        at_bound = [PARAMS[i] for i in (0, 1, 3) if min(res.x[i] - lo4[i], hi4[i] - res.x[i]) < 1e-3]
        flags = [f"{k} reached the bound of the search ({BOUND_FACTOR:g}x the rig file's expected value): "
                 f"not an estimate" for k in at_bound]
        est = estimate_dict(f, len(self.steps), "online (the rig's declared modes held at the rig file's values)",
                            flags)
        est["at_bound"] = at_bound
        self.estimate = est
        return est


def fixed_effects_note(rig_model: RigModel | Mapping | None) -> str:
    """Words for what the rig file declares (for reports)."""
    e = rig_effects(rig_model)
    return ", ".join(EFFECTS[k].label for k in e) if e else ""




def identify_steps(steps, guess: dict, rig_model: RigModel | Mapping | None = None, extra: tuple[str, ...] = (),
                   harmonics: int = 9) -> dict:
    """The one identification of stored or measured steps every output uses (``bench
    identify``, the run's final fit, studies): :func:`identify_rig`, with the modes and
    effects the rig file declares and the causes an analysis named, or the Masing carriage
    alone.  An estimate dict with ``source``.

    The plain carriage too is fitted in the noise of the model's own residuals, the mean
    the noise adds to them subtracted and the residuals' correlation across harmonics in
    the covariance (:meth:`~sim.discrepancy.fit.Weights.propagated`): the one-mode
    :func:`sim.identify.identify_results` ignores both, and its F_s came out low by
    1.25 +- 0.35 standard errors on 24 steps (the demo's 168 steps: x_s and n 2.4-2.7 out;
    decision 0064)."""
    if rig_effects(rig_model) or extra:
        return identify_rig(steps, guess, rig_model, extra, harmonics,
                            source="final fit with the rig's modes" + (" and the analysis' causes" if extra else ""))
    return identify_rig(steps, guess, None, (), harmonics, source="final fit")


__all__ = ["BOUND_FACTOR", "MISFIT_CHI2", "OnlineRigFit", "analysis_effects", "as_steps", "estimate_dict",
           "few_harmonics_text", "identify_rig", "identify_steps", "misfit_text", "rig_effects",
           "step_harmonics_of"]
