"""The simulated rig against the model engine: the sim/ shooting engine's compliance_pp for
the rig model's true parameters, per force level, and the relative differences of the
stored compliance_pp.  Only for runs on a simulated rig with a stored model; the engine
leaves out the rig's optional effects, which are then named in the notes.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from ._steps import UNSETTLED_RESIDUAL, residual_ratio

log = logging.getLogger(__name__)

MODEL_GRID_POINTS = 120        # dense frequency grid of the model curves


@dataclass
class LevelComparison:
    """Relative differences measured / model - 1 of one level; max = the one of largest magnitude."""

    level_N: float
    gamma0: float
    n_steps: int
    n_flagged: int               # steps flagged or rejected by the step quality check
    median: float                # of the stored compliance_pp, all steps
    max: float
    max_unflagged: float         # unflagged steps only
    notes: list[str]


@dataclass
class ModelComparison:
    """The sim/ engine's compliance_pp for the rig's true parameters, per level."""

    params: dict                              # the RigModel used (defaults filled in)
    omega_s: float
    curves: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]]   # level -> (f, C_pp, flags)
    at_steps: dict[str, float]                # step key -> model compliance_pp (m/N)
    levels: list[LevelComparison]
    engine_notes: list[str] = field(default_factory=list)

    def resonance(self, level_N: float) -> tuple[float, float]:
        f, c, _ = self.curves[level_N]
        ok = np.isfinite(c)
        if not ok.any():
            return math.nan, math.nan
        i = int(np.nanargmax(np.where(ok, c, -np.inf)))
        return float(f[i]), float(c[i])


def _model_effects(model) -> list[str]:
    """Rig effects the dimensionless engine leaves out, when switched on."""
    names = {"viscous_N_s_per_m": "viscous damping", "spring_N_per_m": "linear spring",
             "disp_delay_s": "displacement-channel delay", "force_gain_error": "force gain error",
             "accel_gain_error": "acceleration gain error", "disp_gain_error": "displacement gain error",
             "friction_alpha": "speed-dependent friction", "pitch_inertia_kg_m2": "pitching mode",
             "cubic_spring_N_per_m3": "cubic spring", "quadratic_damping_N_s2_per_m2": "quadratic damping",
             "friction_asymmetry": "asymmetric friction",
             "shaker_force_constant_N_per_A": "electrodynamic shaker (the force has harmonics)",
             "line_amplitude": f"interference line on the {model.line_channel or '?'} sensor at "
                               f"{model.line_freq_Hz:g} Hz"}
    return [f"{label} ({k} = {getattr(model, k):g})" for k, label in names.items() if getattr(model, k, 0)]


def model_comparison(meta: dict, results: list[dict], flagged: set[str] | None = None) -> ModelComparison | None:
    """None unless the run is on a simulated rig with a stored model.  ``flagged``: keys of
    the steps the step quality check (sim.artefacts) did not find simply usable; None
    flags by the stored displacement residual instead."""
    rig = meta.get("rig") or {}
    if not (rig.get("simulated") and rig.get("model")) or not results:
        return None
    from sim.rig import RigModel
    from sim.shooting import frf_shooting

    model = RigModel.from_dict(rig["model"])
    ws = model.omega_s
    scale = model.x_s_m / model.F_s_N                     # G (dimensionless) -> m/N
    plan = meta.get("plan") or {}
    levels_N = plan.get("levels_N") or sorted({r["target_force_N"] for r in results})
    freqs = np.array(sorted({r["freq_Hz"] for r in results}))
    dense = np.geomspace(freqs.min() / 1.1, freqs.max() * 1.1, MODEL_GRID_POINTS)
    engine_notes = [f"omega_s = sqrt(F_s/(x_s m)) = {ws:.4g} rad/s ({ws / (2 * math.pi):.4g} Hz); "
                    f"compliance = G x_s/F_s with G from sim.shooting.frf_shooting (n = {model.n:g})"]
    effects = _model_effects(model)
    rig_ratio = _rig_model_ratio(rig["model"], model, results)
    if rig_ratio:
        engine_notes.append("differences: from the model of the rig with the modes and effects its file declares ("
                            + ", ".join(rig_ratio["effects"]) + ", at the rig file's values; decision 0042): "
                            "the force that model needs to make the measured motion against the force measured, "
                            "so model compliance_pp = measured compliance_pp x |P1 measured| / |P1 model|; the lines "
                            "are the one-mode engine's and leave out: " + ", ".join(effects))
    elif effects:
        engine_notes.append("the rig model has effects the engine leaves out, so differences are expected: "
                            + ", ".join(effects))

    curves, at_steps, levels = {}, {}, []
    by_level: dict[int, list[dict]] = {}
    for r in results:
        by_level.setdefault(r["level_index"], []).append(r)
    for li, steps in sorted(by_level.items()):
        level = float(levels_N[li]) if li < len(levels_N) else float(steps[0]["target_force_N"])
        gamma0 = level / model.F_s_N
        notes = []
        if level > model.amp_force_limit_N:
            notes.append(f"level above the amplifier's force limit {model.amp_force_limit_N:g} N")
        grid = np.union1d(dense, freqs)
        try:
            fr, fell_back = frf_shooting(2 * math.pi * grid / ws, gamma0, model.n)
            G = np.where(fr.converged, fr.G, np.nan)
            f_model = fr.beta * ws / (2 * math.pi)
            flags = np.array(fr.gross_rolling) | ~np.array(fr.converged)
            if (~fr.converged).any():
                notes.append(f"model: no steady state at {int((~fr.converged).sum())} of {grid.size} frequencies")
            if fell_back.any():
                notes.append(f"model: RK4 fallback at {int(fell_back.sum())} of {grid.size} frequencies")
            if np.any(fr.gross_rolling) or gamma0 >= 1:
                notes.append("gamma0 >= 1: gross rolling; model = centred periodic orbit, the rig's "
                             "carriage may drift: indicative only" if gamma0 >= 1
                             else "model: gross rolling at some frequencies")
        except Exception as e:          # the report must come out even if the engine fails
            log.warning("model FRF at %g N failed: %s", level, e)
            notes.append(f"model engine failed: {type(e).__name__}: {e}")
            f_model, G, flags = grid, np.full(grid.size, np.nan), np.ones(grid.size, bool)
        C = G * scale
        curves[level] = (f_model, C, flags)
        diff = []
        for s in steps:
            i = int(np.argmin(np.abs(f_model - s["freq_Hz"])))
            c_model = float(C[i])
            if rig_ratio and s["key"] in rig_ratio["ratio"]:
                c_model = s["compliance_pp_m_per_N"] / rig_ratio["ratio"][s["key"]]
            at_steps[s["key"]] = c_model
            diff.append(s["compliance_pp_m_per_N"] / c_model - 1.0)
        bad = np.array([s["key"] in flagged if flagged is not None else residual_ratio(s) > UNSETTLED_RESIDUAL
                        for s in steps])
        diff = np.array(diff)
        levels.append(LevelComparison(level, gamma0, len(steps), int(bad.sum()), _median(diff), _signed_max(diff),
                                      _signed_max(diff[~bad]), notes))
    return ModelComparison(model.__dict__.copy(), ws, curves, at_steps, levels, engine_notes)


def _rig_model_ratio(model_dict: dict, model, results: list[dict]) -> dict | None:
    """For a rig file that declares modes or effects (:func:`sim.discrepancy.rigfit.rig_effects`):
    per step, |P1 measured| / |P1| of the force the rig's model (true parameters, declared
    effects at the file's values) needs to make the measured motion; None otherwise."""
    from sim.discrepancy.analysis import data_from_steps
    from sim.discrepancy.models import Model
    from sim.discrepancy.rigfit import as_steps, rig_effects
    declared = rig_effects(model_dict)
    usable = [r for r in results if all(k in r for k in ("force", "accel", "disp"))]
    if not declared or not usable:
        return None
    d = data_from_steps(as_steps(usable), 9)
    m = Model((), d.X.shape[1])
    theta = np.array([math.log(model.F_s_N), math.log(model.x_s_m), model.n, math.log(model.mass_kg)])
    for e, init in declared.items():
        m, theta = m.extend(theta, e, init)
    P, _ = m.predict(theta, d)
    ratio = np.abs(d.P[:, 0]) / np.maximum(np.abs(P[:, 0]), 1e-300)
    return dict(effects=list(declared), ratio={r["key"]: float(x) for r, x in zip(usable, ratio)})


def _median(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else math.nan


def _signed_max(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(x[np.argmax(np.abs(x))]) if x.size else math.nan
