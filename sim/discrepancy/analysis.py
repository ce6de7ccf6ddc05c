"""analyze_steps: from measured stepped-sine steps to a verdict on the Masing model.

1. The steps' harmonics become arrays (:class:`~sim.discrepancy.models.Data`); steps are
   grouped into force levels by their force amplitude (gaps of more than 15 %).
2. Base fit: :class:`sim.identify.Identifier` (the project's identification) from the
   guess, then the base model refitted on both residuals (force balance and kinematics).
3. :func:`sim.discrepancy.select.select`: candidates and gates, in the base model's noise
   units; then :func:`~sim.discrepancy.select.settle_final` refits the chosen model with
   the noise of its own residuals (its intervals) and tests what remains for structure.
4. :class:`Analysis` keeps the fits and renders the analysis.json schema
   (``docs/analysis.md``) with :meth:`Analysis.to_dict`.

Steps are duck-typed (``bench.sources.MeasuredStep`` or :class:`~sim.discrepancy.cases.Step`):
``key``, ``level_N``, ``freq_Hz``, ``harmonics`` (StepHarmonics), ``direction`` and
optionally one averaged period of ``force_N``, ``accel_m_s2``, ``disp_m``.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigurationError
from ..identify import Estimate, Identifier, displacement_harmonics, synthesize
from . import rivals
from .fit import Fit, Weights, fit, whitened
from .gain import frf, heldout_error
from .loops import friction_model_loops, loop_steps, measured_period
from .models import BASE_PARAMS, CENTRE, CENTRED, EFFECTS, LIBRARY, Data, Model
from .rounding import interval_text
from .select import BIC_GATE, CHI2_UNEXPLAINED, Selection, select, settle_final
from .terms import accelerance_pair, second_mode_phrase, speed_friction, speed_friction_phrase

log = logging.getLogger(__name__)

SCHEMA = "guideway-bench/analysis/2"
LEVEL_GAP = 1.15
LOOPS = 4
# analysis/1 named the mass m_kg; analysis/2 gives the parameters the rig model's names (decision 0066)
OLD_NAMES = {"m_kg": "mass_kg"}


def stored_analysis(d):
    """An analysis dict (analysis.json's object) as this version writes it: one written as
    analysis/1 has its parameters (final and base) renamed (``m_kg`` -> ``mass_kg``) and its
    schema read as this one's; anything else is returned as it is."""
    if not isinstance(d, dict) or d.get("schema") != "guideway-bench/analysis/1":
        return d

    def renamed(p):
        return {OLD_NAMES.get(k, k): v for k, v in p.items()} if isinstance(p, dict) else p
    out = dict(d, schema=SCHEMA, parameters=renamed(d.get("parameters")))
    if isinstance(d.get("base"), dict):
        out["base"] = dict(d["base"], parameters=renamed(d["base"].get("parameters")))
    return out


def level_groups(levels_N: np.ndarray) -> np.ndarray:
    """Group index per step: force amplitudes within 15 % of their neighbour share a level."""
    order = np.argsort(levels_N)
    group = np.empty(levels_N.size, int)
    g, prev = 0, None
    for i in order:
        if prev is not None and levels_N[i] > LEVEL_GAP * prev:
            g += 1
        group[i] = g
        prev = levels_N[i]
    return group


def data_from_steps(steps, harmonics: int = 9) -> Data:
    """Arrays of the first ``harmonics`` harmonics (the residuals), and every harmonic of
    both motion channels with their inverse-variance weights (the friction along x,
    :func:`sim.identify.displacement_harmonics`).  Levels: the response levels held when
    every step held one (response control), else the force amplitudes."""
    if not steps:
        raise ConfigurationError("no steps to analyse")
    H = [s.harmonics for s in steps]
    K = min([harmonics] + [min(h.force.size, h.accel.size, h.disp.size) for h in H])
    Kf = max(K, max(min(h.force.size, h.accel.size, h.disp.size) for h in H))
    Xf, XAf, Pf = (np.zeros((len(H), Kf), complex) for _ in range(3))
    wDf = np.ones((len(H), Kf))
    for i, h in enumerate(H):
        X, wD, _ = displacement_harmonics(h)
        k = np.arange(1, X.size + 1)
        j = min(X.size, h.force.size)
        Xf[i, :j], wDf[i, :j], Pf[i, :j] = h.disp[:j], wD[:j], h.force[:j]
        XAf[i, :j] = -h.accel[:j] / (k[:j] * 2 * math.pi * h.freq_Hz) ** 2
    held = [float((getattr(s, "held", None) or (0.0,))[0]) for s in steps]     # response control: the level held
    means = np.array([float(np.mean(s.disp_m)) if np.size(getattr(s, "disp_m", ())) > 1 else math.nan
                      for s in steps])
    x0 = np.nan_to_num(means - np.nanmedian(means)) if np.isfinite(means).any() else np.zeros(len(steps))
    return Data(omega=np.array([2 * math.pi * h.freq_Hz for h in H]), x0=x0,
                P=np.array([h.force[:K] for h in H]), A=np.array([h.accel[:K] for h in H]),
                X=np.array([h.disp[:K] for h in H]), sP=np.array([h.sigma_force for h in H]),
                sA=np.array([h.sigma_accel for h in H]), sX=np.array([h.sigma_disp for h in H]),
                level=level_groups(np.array(held if all(held) else [float(s.level_N) for s in steps])),
                Xf=Xf, XAf=XAf, wDf=wDf, Pf=Pf)


def guess_from_data(d: Data) -> dict:
    """Rough starting values when none are given: mass from the highest frequencies, F_s from
    the largest friction, x_s from the stiffness at the smallest amplitude."""
    hi = d.omega >= np.quantile(d.omega, 0.8)
    m = float(np.median(np.abs(d.P[hi, 0] / d.A[hi, 0])))
    Fr = np.abs(d.P[:, 0] - m * d.A[:, 0])
    F_s = float(Fr.max() * 1.2)
    lo = np.argmin(np.abs(d.X[:, 0]))
    x_s = float(F_s / max(Fr[lo] / abs(d.X[lo, 0]), 1e-300))
    return dict(F_s_N=F_s, x_s_m=x_s, n=1.5, mass_kg=m)


def base_fit(steps, d: Data, guess: dict | None, harmonics: int) -> tuple[Fit, Weights]:
    starts = [guess] if guess else [dict(guess_from_data(d), n=n) for n in (0.5, 1.5, 2.5)]
    best: Estimate | None = None
    best_ident: Identifier | None = None
    for g in starts:
        ident = Identifier(g, harmonics)
        for s in steps:
            ident.add(s.harmonics)
        est = ident.fit(max_nfev=200)
        if best is None or est.cost < best.cost:
            best, best_ident = est, ident
    assert best is not None and best_ident is not None      # at least one start
    v = best.values
    theta = np.array([math.log(v["F_s_N"]), math.log(v["x_s_m"]), v["n"], math.log(v["mass_kg"])])
    W = Weights.from_data(d, v["mass_kg"], friction_noise=best_ident.residual_noise(d.X.shape[1]))
    return fit(Model((), d.X.shape[1]), theta, d, W, max_nfev=200), W


@dataclass
class Analysis:
    steps: list
    data: Data
    weights: Weights
    selection: Selection
    source: str = ""
    software_version: str = ""
    rejected: list = field(default_factory=list)
    v_ref_m_per_s: float | None = None     # the rig file's friction_v_ref_m_per_s: alpha is stated there
    artefacts: list = field(default_factory=list)   # causes of kind "artefact" (sim.artefacts.artefact_causes)
    friction: rivals.FrictionChoice | None = None          # every friction model's fit and the preferred one (decision 0078)

    # ------------------------------------------------------------------ helpers
    @property
    def base(self) -> Fit:
        return self.selection.base

    @property
    def final(self) -> Fit:
        return self.selection.final

    @property
    def causes(self) -> list[str]:
        return [c.id for c in self.selection.named]

    @property
    def unexplained(self) -> bool:
        if self.friction is not None and self.friction.name in rivals.NO_CATALOG:
            return self.friction.preferred.reduced_chi2 > CHI2_UNEXPLAINED
        return self.selection.unexplained

    @property
    def friction_model(self) -> str:
        return "masing" if self.friction is None else self.friction.name

    def f_res_Hz(self, f: Fit) -> float:
        v = f.model.values(f.theta)
        return math.sqrt(v["F_s_N"] / (v["x_s_m"] * v["mass_kg"])) / (2 * math.pi)

    @staticmethod
    def _params(f: Fit) -> dict:
        """F_s, x_s, n, m with 95 % intervals; an end the data do not bound is null, with
        ``bounded: false`` (:meth:`Fit.unbounded`).  A Dahl head: F_c, sigma, exponent, m."""
        if f.model.friction == "dahl":
            return {k: {a: b for a, b in v.items() if a != "unit"} for k, v in rivals.head_parameters("dahl", f).items()}
        iv = f.named_intervals()
        loose = set(f.unbounded())
        return {k: dict(value=iv[k][0], low=_end(iv[k][1]), high=_end(iv[k][2]),
                                    **(dict(bounded=False) if k in loose else {})) for k in BASE_PARAMS}

    def cause_parameters(self, effect: str, f: Fit) -> dict:
        """The effect's parameters with 95 % intervals, in physical units (and derived sizes)."""
        iv = f.named_intervals()
        v = f.model.values(f.theta)
        w_res = 2 * math.pi * self.f_res_Hz(f)
        out = {}

        def put(name, triple, unit, scale=1.0):
            lo, hi = sorted((triple[1] * scale, triple[2] * scale))
            bounded = math.isfinite(lo) and math.isfinite(hi)
            out[name] = dict(value=triple[0] * scale, low=_end(lo), high=_end(hi), unit=unit,
                             **({} if bounded else dict(bounded=False)))
        if effect == "viscous_damping":
            put("c", iv["viscous_damping.c"], "N s/m")
            put("damping_ratio_at_resonance", iv["viscous_damping.c"], "1", 1 / (2 * v["mass_kg"] * w_res))
        elif effect == "linear_spring":
            put("k", iv["linear_spring.k"], "N/m")
            put("k_relative_to_F_s_over_x_s", iv["linear_spring.k"], "1", v["x_s_m"] / v["F_s_N"])
        elif effect == "velocity_dependent_friction":
            v_ref, source = ((self.v_ref_m_per_s, "rig") if self.v_ref_m_per_s
                             else (w_res * v["x_s_m"], "friction resonance"))
            out["alpha"] = speed_friction(iv["velocity_dependent_friction.beta"], v_ref)
            out["v_ref"] = dict(value=v_ref, low=v_ref, high=v_ref, unit="m/s", source=source)
        elif effect == "sensor_delay":
            put("delay", iv["sensor_delay.delay"], "s")
            put("delay_relative_to_resonance_period", iv["sensor_delay.delay"], "1", w_res / (2 * math.pi))
        elif effect == "sensor_gain_error":
            put("gain_error", iv["sensor_gain_error.gain"], "1")
        elif effect == "second_mode":
            put("frequency", iv["second_mode.f_p"], "Hz")
            put("damping_ratio", iv["second_mode.zeta"], "1")
            put("coupling", iv["second_mode.a"], "1", v["mass_kg"])     # m h^2 / J
            put("cg_over_drive_height", iv["second_mode.r"], "1")
            f_p = v["second_mode.f_p"]
            d = self.data
            pair = accelerance_pair(d.omega / (2 * math.pi), np.abs(d.A[:, 0] / d.P[:, 0]), d.level,
                                    (0.5 * f_p, 4.0 * f_p))
            for name, e in zip(("anti_resonance_Hz", "resonance_Hz"), pair):
                if e is not None:        # as the measured accelerance shows it, between grid points
                    out[name] = dict(value=e.freq_Hz, low=e.low_Hz, high=e.high_Hz, unit="Hz")
        elif effect == "similarity_ratio":
            t = iv["similarity_ratio.d"]
            put("lambda", (2 + t[0], 2 + t[1], 2 + t[2]), "1")
        elif EFFECTS[effect].kind == "discovered":
            term = EFFECTS[effect]
            for name, unit in zip(term.names, term.units):
                put(name, iv[f"{effect}.{name}"], unit)
            if effect in CENTRED and CENTRE in f.model.slices:     # the springs' rest position (shared)
                put("x_c", iv[f"{CENTRE}.x_c"], "m")
        if EFFECTS[effect].force is not None:
            peak = self.term_peak_N(effect, f)
            out["peak_force_relative_to_F_s"] = dict(value=peak / v["F_s_N"], low=math.nan, high=math.nan, unit="1")
        return out

    def term_peak_N(self, effect: str, f: Fit) -> float:
        """Largest force the term adds over any measured period (N), at its fitted size."""
        ctx = f.model.context(f.theta, self.data)
        sl = f.model.slices[effect]
        force = EFFECTS[effect].force
        assert force is not None, effect
        G = force(ctx, f.theta[sl] * f.model.scales[effect])
        return float(np.abs(synthesize(G, 256)).max())

    def _predicted_frf(self, f: Fit) -> tuple[np.ndarray, np.ndarray]:
        P, A = f.model.predict(f.theta, self.data)
        return frf(P, A, self.data.X)

    # ------------------------------------------------------------------ verdict
    def verdict(self) -> str:
        sel = self.selection
        base_err = 100 * sel.heldout_base
        parts = []
        ch = self.friction
        if ch is not None and ch.name != "masing":
            parts.append(f"The Masing model alone mis-predicts compliance and accelerance by {base_err:.1f} % "
                         f"(rms over held-out force levels; reduced chi-square {self.base.reduced_chi2:.1f}).")
            parts += rivals.choice_sentences(ch)
            parts += [self.sentence(c) for c in sel.named]
            if sel.named:
                parts.append(f"Out-of-sample error falls from {base_err:.1f} % to {100 * sel.named[-1].heldout_error:.2f} %.")
            if ch.name in rivals.NO_CATALOG:
                parts.append(rivals.no_catalog_sentence(ch.name))
        elif sel.named:
            first = sel.named[0]
            parts.append(f"The Masing model alone mis-predicts compliance and accelerance by {base_err:.1f} % "
                         f"(rms over held-out force levels; reduced chi-square {self.base.reduced_chi2:.1f})"
                         f"{self._resonance_phrase()}.")
            for c in sel.named:
                parts.append(self.sentence(c))
            last = sel.named[-1]
            parts.append(f"Out-of-sample error falls from {100 * first.heldout_before:.1f} % to "
                         f"{100 * last.heldout_error:.1f} %.")
            parts += self._not_separable_phrases()
        elif not self.unexplained:
            parts.append(f"The Masing model explains the data within the noise (reduced chi-square "
                         f"{self.base.reduced_chi2:.2f}, held-out error {base_err:.2f} %); no effect in the "
                         f"catalog and no term of the library improves both the BIC and the held-out prediction.")
        if ch is not None and ch.name == "masing" and (ch.passed_bare or ch.not_separable):
            parts += rivals.choice_sentences(ch)
        if self.unexplained and ch is not None and ch.name in rivals.NO_CATALOG:
            parts.append(rivals.leaves_structure_sentence(ch, sel.explanations or sel.reasons))
        elif self.unexplained:
            what = ("the extended model" if sel.named else "the Masing model") if ch is None or ch.name != "dahl" \
                else ("Dahl's model with the causes above" if sel.named else "Dahl's model")
            said = sel.explanations or sel.reasons
            parts.append(f"Structure remains that {what} does not explain: {'; '.join(said[:4])}. "
                         f"Neither the catalog nor the library of force terms accounts for it"
                         + (f"; the intervals above are widened {sel.interval_inflation:.1f}x for it"
                            if sel.interval_inflation > 1.05 else "") + ".")
        parts += self._unbounded_phrases()
        caveat = self._spring_caveat()
        if caveat:
            parts.append(caveat)
        parts += artefact_verdict(self.artefacts)
        return " ".join(parts)

    def _not_separable_phrases(self) -> list[str]:
        """Library forms that lowered the chi-square beside a named cause but did not predict
        the held-out levels better than it: not named, and said (issue 33)."""
        sel = self.selection
        out = []
        for c in sel.tried:
            if (c.kind == "discovered" and not c.named and c.round > 1 and c.delta_bic < BIC_GATE
                    and math.isfinite(c.heldout_error) and c.id not in self.causes):
                beside = ", ".join(EFFECTS[n.id].label for n in sel.named if n.round < c.round)
                out.append(f"{EFFECTS[c.id].label} also lowers the chi-square beside {beside} (BIC by "
                           f"{-c.delta_bic:.0f}) but does not predict the held-out levels better than it (held-out error "
                           f"{100 * c.heldout_before:.2f} % -> {100 * c.heldout_error:.2f} %): the data cannot separate "
                           f"it from {beside}, so it is not named.")
        return out

    def _unbounded_phrases(self) -> list[str]:
        """Words for parameters the data do not bound (an interval beyond any finite value)."""
        out = []
        base, final = self.base.unbounded(), self.final.unbounded()
        if base and self.selection.named and not final:
            v = self.base.model.values(self.base.theta)
            out.append(f"Alone, the Masing model cannot bound {' and '.join(base)} on these data (its fit runs off "
                       f"to F_s = {v['F_s_N']:.3g} N, x_s = {v['x_s_m']:.3g} m: their 95 % intervals reach beyond "
                       f"any finite value); with the causes above they are bounded.")
        if final:
            out.append(f"The data do not bound {', '.join(final)}: the 95 % interval reaches beyond any finite "
                       f"value (stated as unbounded, with no limit, in analysis.json); the steps do not show the "
                       f"part of the friction curve that fixes it.")
        return out

    def largest_amplitude_over_x_s(self) -> float:
        """Largest half peak-to-peak displacement of any step over the final model's x_s:
        below 1 every Masing branch stays in pre-rolling."""
        x = synthesize(self.data.X, 256)
        amp = 0.5 * (x.max(axis=1) - x.min(axis=1)).max()
        return float(amp / self.final.model.values(self.final.theta)["x_s_m"])

    def spring_separable(self) -> bool:
        """Whether the data can tell a linear spring from the Masing curve.  In pre-rolling
        the virgin curve is f1 = A x^n + B x; a spring k in parallel only turns B into B + k,
        which is again a Masing curve with other F_s and x_s (the Masing rule holds for the
        sum, branch by branch).  Only steps beyond x_s, where f1 gives way to F_s but the
        spring keeps rising, separate the two."""
        return "linear_spring" in self.causes or self.largest_amplitude_over_x_s() > 1.0

    def _spring_caveat(self) -> str:
        if self.spring_separable():
            return ""
        return (f"Every step stayed in pre-rolling (largest amplitude {self.largest_amplitude_over_x_s():.2f} x_s): "
                f"there a linear spring in parallel (cables, hoses, preload) cannot be told from a stiffer Masing "
                f"curve, so F_s and x_s include any such spring; steps whose amplitude exceeds x_s would "
                f"separate them.")

    def _resonance_phrase(self) -> str:
        """', and over-predicts the compliance at the resonance by 12 %' (median over levels)."""
        d = self.data
        C_meas = np.abs(d.X[:, 0] / d.P[:, 0])
        C_base = np.abs(self._predicted_frf(self.base)[0])
        errs = []
        for lv in np.unique(d.level):
            idx = np.flatnonzero(d.level == lv)
            i = idx[np.argmax(C_meas[idx])]
            errs.append(C_base[i] / C_meas[i] - 1)
        e = float(np.median(errs))
        return f", and {'over' if e > 0 else 'under'}-predicts the compliance at the resonance by {100 * abs(e):.1f} %"

    def sentence(self, c) -> str:
        """One sentence per named cause: what it is, its size with a 95 % interval, the gain."""
        gain = f"held-out error {100 * c.heldout_before:.1f} % -> {100 * c.heldout_error:.1f} %"
        if c.kind == "catalog":
            return f"The data are explained by {self._phrase(c)} (BIC falls by {-c.delta_bic:.0f}; {gain})."
        return f"Not in the catalog: {self._discovered_phrase(c)} explains it ({gain})."

    def _discovered_phrase(self, c) -> str:
        e = EFFECTS[c.id]
        p = self.cause_parameters(c.id, self.final)
        name = "lambda" if c.id == "similarity_ratio" else e.names[0]
        q = p[name]
        unit = "" if q["unit"] == "1" else f" {q['unit']}"
        size = interval_text(q["value"], q["low"], q["high"], unit, signed=q["unit"] == "1")
        peak = p.get("peak_force_relative_to_F_s", {}).get("value", math.nan)
        peak_s = f", up to {100 * peak:.1f} % of F_s over the measured motion" if math.isfinite(peak) else ""
        v = self.final.model.values(self.final.theta)
        if c.id == "cubic_stiffness":
            what = f"a {'hardening' if q['value'] > 0 else 'softening'} cubic stiffness k3 x^3, k3 = {size}"
        elif c.id == "asymmetric_friction":
            F_s = v["F_s_N"]
            what = (f"asymmetric friction a = {size}: the friction saturates at +{F_s * (1 + q['value']):.3g} N "
                    f"and -{F_s * (1 - q['value']):.3g} N ({e.words})")
        elif c.id == "similarity_ratio":
            what = f"a Masing similarity ratio lambda = {size} instead of 2 ({e.words})"
        else:
            what = f"{e.label} {e.formula}, {name} = {size} ({e.words})"
        if "x_c" in p:
            xc = p["x_c"]
            at = interval_text(1e6 * xc["value"], 1e6 * xc["low"], 1e6 * xc["high"], " um", signed=True)
            what += f", acting about x_c = {at} (the springs' rest position, measured from the median step's mean position)"
        return what + peak_s

    def _phrase(self, c) -> str:
        p = self.cause_parameters(c.id, self.final)

        def iv(name, fmt, scale=1.0, unit=""):
            q = p[name]
            return interval_text(q["value"] * scale, q["low"] * scale, q["high"] * scale, unit,
                                 signed="+" in fmt)
        if c.id == "viscous_damping":
            return (f"viscous damping c = {iv('c', '.3g', unit=' N s/m')}, an equivalent damping ratio of "
                    f"{100 * p['damping_ratio_at_resonance']['value']:.1f} % at the friction resonance")
        if c.id == "linear_spring":
            return (f"a linear spring k = {iv('k', '.3g', unit=' N/m')}, "
                    f"{100 * p['k_relative_to_F_s_over_x_s']['value']:.1f} % of the friction stiffness F_s/x_s")
        if c.id == "velocity_dependent_friction":
            return speed_friction_phrase(p)
        if c.id == "sensor_delay":
            return (f"a displacement channel delay of {iv('delay', '.3g', 1e6, ' us')}, "
                    f"{100 * p['delay_relative_to_resonance_period']['value']:.1f} % of the resonance period")
        if c.id == "sensor_gain_error":
            return (f"a displacement scale inconsistent with the accelerometer by "
                    f"{iv('gain_error', '+.1f', 100, ' %')}")
        if c.id == "second_mode":
            return second_mode_phrase(p)
        return EFFECTS[c.id].label

    # ------------------------------------------------------------------ schema
    def to_dict(self) -> dict:
        sel, d = self.selection, self.data
        C_meas, A_meas = frf(d.P, d.A, d.X)
        C_base, A_base = self._predicted_frf(self.base)
        C_fin, A_fin = self._predicted_frf(self.final)
        rb = whitened(self.base.theta, self.base.model, d, self.weights).reshape(4, *d.X.shape)
        res_h = np.sqrt((rb ** 2).mean(axis=0))
        ri = lambda z: [float(z.real), float(z.imag)]      # noqa: E731
        steps = [dict(key=s.key, level_N=float(s.level_N), freq_Hz=float(s.freq_Hz), direction=s.direction,
                      level_index=int(d.level[i]),
                      measured=dict(compliance=ri(C_meas[i]), accelerance=ri(A_meas[i])),
                      base=dict(compliance=ri(C_base[i]), accelerance=ri(A_base[i])),
                      final=dict(compliance=ri(C_fin[i]), accelerance=ri(A_fin[i])),
                      residual_by_harmonic=[float(x) for x in res_h[i]])
                 for i, s in enumerate(self.steps)]
        causes = [dict(id=c.id, kind=c.kind, label=EFFECTS[c.id].label, formula=EFFECTS[c.id].formula,
                       parameters=self.cause_parameters(c.id, self.final),
                       gain=dict(heldout_error_before=c.heldout_before, heldout_error_after=c.heldout_error,
                                 delta_bic=c.delta_bic), sentence=self.sentence(c))
                  for c in sel.named]
        candidates = [dict(id=c.id, kind=c.kind, round=c.round, delta_bic=c.delta_bic,
                           heldout_error=None if math.isnan(c.heldout_error) else c.heldout_error,
                           named=c.named, **({} if math.isnan(c.screened_chi2_drop)
                                             else dict(screened_chi2_drop=c.screened_chi2_drop)))
                      for c in sel.tried]
        return dict(
            schema=SCHEMA, source=self.source, software_version=self.software_version,
            parameters=self._params(self.final),
            base=dict(parameters=self._params(self.base), reduced_chi2=self.base.reduced_chi2,
                      heldout_error=sel.heldout_base,
                      diagnostics=dict(structure_final=sel.structure, unexplained_reasons=sel.reasons,
                                       unexplained_in_words=sel.explanations,
                                       interval_inflation=sel.interval_inflation,
                                       library_screen=[dict(round=r, id=t, chi2_drop=x) for r, t, x in sel.screened],
                                       f_res_Hz=self.f_res_Hz(self.base),
                                       largest_amplitude_over_x_s=self.largest_amplitude_over_x_s(),
                                       spring_separable=self.spring_separable())),
            final=dict(effects=list(self.final.model.effects), reduced_chi2=self.final.reduced_chi2),
            causes=causes + list(self.artefacts), unexplained=self.unexplained, verdict=self.verdict(),
            friction_model=self.friction_model,
            **({} if self.friction is None else dict(friction_models=self.friction_models())),
            candidates=candidates, steps_used=[s.key for s in self.steps], steps_rejected=list(self.rejected),
            steps_flagged=steps_flagged(self.steps),
            steps=steps, loops=self.loops(), restoring_force=self.restoring_force())

    def restoring_force(self, points: int = 32) -> dict:
        """The force the base model leaves out, r = P - m a - F_Masing(x), sampled over one
        period of every step against the displacement and velocity (the restoring-force
        surface: a function of x alone is a stiffness, of v alone a damping)."""
        d, f = self.data, self.base
        rF, _ = f.model.residuals(f.theta, d)
        x = synthesize(d.X, points)
        v = synthesize(1j * d.Omega * d.X, points)
        r = synthesize(rF, points)
        if d.x0 is not None:
            x = x + d.x0[:, None]
        lv = np.repeat(d.level, points)
        return dict(x_m=[float(a) for a in x.ravel()], v_m_s=[float(a) for a in v.ravel()],
                    force_N=[float(a) for a in r.ravel()], level_index=[int(a) for a in lv])

    def loops(self, count: int = LOOPS) -> list[dict]:
        """Measured and Masing (base and final) friction loops at the most compliant step of a
        few levels (:mod:`sim.discrepancy.loops`)."""
        d = self.data
        out = []
        m_fin = self.final.model.values(self.final.theta)["mass_kg"]
        for i in loop_steps(d, count):
            s = self.steps[i]
            disp, force, accel = measured_period(s, d, i)
            meas = force - m_fin * accel
            sub = d.subset(np.arange(d.X.shape[0]) == i)

            def model_loop(f: Fit):
                G, _ = f.model.terms(f.theta, sub, sub.P)
                return synthesize(G, disp.size)[0] + float(np.mean(meas))
            out.append(dict(key=s.key, level_N=float(s.level_N), freq_Hz=float(s.freq_Hz),
                            disp_m=[float(x) for x in disp], friction_meas_N=[float(x) for x in meas],
                            friction_base_N=[float(x) for x in model_loop(self.base)],
                            friction_final_N=[float(x) for x in model_loop(self.final)]))
        return out

    def friction_models(self) -> dict:
        """analysis.json's ``friction_models``: the table of :func:`rivals.choice_dict`, each
        fitted model's row with its loops at every level (:func:`friction_model_loops`)."""
        assert self.friction is not None
        out = rivals.choice_dict(self.friction)
        loops = friction_model_loops(self.steps, self.data, self.friction.fits,
                                     self.final.model.values(self.final.theta)["mass_kg"])
        for row in out["table"]:
            if row.get("model") in loops:
                row["loops"] = loops[row["model"]]
        return out


def _end(x: float) -> float | None:
    """An interval's end for analysis.json: None (null) beyond the floats."""
    return float(x) if math.isfinite(x) else None


def artefact_verdict(artefacts: list) -> list[str]:
    """The verdict's sentence on measurement artefacts (causes of kind "artefact")."""
    if not artefacts:
        return []
    return ["Measurement artefacts, found in the time records before the fit: "
            + "; ".join(c["sentence"] for c in artefacts) + "."]


def steps_flagged(steps) -> list[dict]:
    """``{step, reason}`` of the used steps the step quality check flagged (sim.artefacts)."""
    out = []
    for s in steps:
        q = getattr(s, "quality", None)
        if q is not None and q.status == "flagged":
            out.append(dict(step=s.key, reason=q.text))
    return out


def analyze_steps(steps, guess: dict | None = None, *, harmonics: int = 9, source: str = "",
                  software_version: str = "", rejected: list | None = None,
                  v_ref_m_per_s: float | None = None, artefacts: list | None = None,
                  library: tuple[str, ...] | None = None, friction_models: bool = True) -> Analysis:
    """Fit the base model, try the catalog, name what survives both gates (see module doc).

    ``guess``: rough F_s_N, x_s_m, n, mass_kg (e.g. a rig file's expected values); None
    estimates them from the data.  ``v_ref_m_per_s``: the speed at which to state a
    velocity-dependent friction (the rig file's); None: the speed at the friction resonance.
    ``artefacts``: causes of kind "artefact" found in the time records
    (:func:`sim.artefacts.artefact_causes`), reported beside the physics.
    ``library``: the library terms to search (default all of
    :data:`~sim.discrepancy.effects.LIBRARY`; ``()`` for the catalog alone).
    ``friction_models``: fit the rival friction models and prefer one where the data do
    (:mod:`sim.discrepancy.rivals`, decision 0078); False: Masing alone."""
    steps = list(steps)
    d = data_from_steps(steps, harmonics)
    if np.unique(d.level).size < 2:
        raise ConfigurationError("need steps at two force levels at least (held-out checks leave one level out)")
    base, W = base_fit(steps, d, guess, harmonics)
    log.info("base fit: reduced chi2 %.2f", base.reduced_chi2)
    g = guess or guess_from_data(d)
    restart = np.array([math.log(g["F_s_N"]), math.log(g["x_s_m"]), g["n"], math.log(g["mass_kg"])])
    lib = LIBRARY if library is None else tuple(library)
    base_thetas: list = []
    held = (heldout_error(base.model, base.theta, d, W, thetas=base_thetas), base_thetas)
    masing = rivals.head_fit("masing", base, d, W, heldout=held[0], thetas=base_thetas)
    fits = rivals.fit_all(masing, d, W) if friction_models else {
        n: (masing if n == "masing" else rivals.ModelFit(n, fitted=False)) for n in rivals.FRICTION_MODELS}
    if rivals.passed_bare(fits) and lib:
        # a rival beats bare Masing: Masing's own shape corrections (the library) compete with
        # it only if Masing with the catalog's causes does not already keep Masing (decision 0078),
        # or if the rival is one the catalog is not searched on and leaves structure (decision 0086)
        sel = select(base, d, W, library=(), restart=restart, heldout=held, nfev=rivals.ON_RIVAL_NFEV)
        choice = rivals.choose_after(fits, sel)
        if choice.name == "masing" or rivals.leaves_structure(choice):
            sel = select(base, d, W, library=lib, restart=restart, heldout=held)
            choice = rivals.choose_after(fits, sel)
    else:
        sel = select(base, d, W, library=lib, restart=restart, heldout=held)
        choice = rivals.choose_after(fits, sel)
    if choice.name == "dahl":
        # the catalog's effects on top of the preferred model (the library's forms are Masing's)
        rival = choice.preferred
        assert rival.fit is not None
        sel_r = select(rival.fit, d, W, library=(), nfev=rivals.ON_RIVAL_NFEV,
                       heldout=(rival.heldout, rival.heldout_thetas))
        sel = settle_final(sel_r, d)
        sel.base, sel.heldout_base = base, choice.gain[0]
    elif choice.name in rivals.NO_CATALOG:
        # the elements (or a rate-dependent law) replace Masing's shape: no cause named on Sakai's curve stands (decision 0078)
        sel = settle_final(Selection(base=base, final=base, named=[], tried=sel.tried, heldout_base=held[0],
                                     screened=sel.screened, base_heldout_thetas=base_thetas), d)
    else:
        sel = settle_final(sel, d)
    return Analysis(steps=steps, data=d, weights=W, selection=sel, source=source,
                    software_version=software_version, rejected=list(rejected or []), v_ref_m_per_s=v_ref_m_per_s,
                    artefacts=list(artefacts or []), friction=choice)
