"""The simulated rig against its model: the rig model's compliance_pp per force level as
lines, and the relative differences of the stored compliance_pp from the same lines.

The model is the one the identification fits (decision records 0042, 0054): the rig file's
[rig.model] with every declared effect and the pitching mode (:mod:`sim.rig_response`);
noise, an interference line and the shaker are left out (an ideal force at the measured
level).  A plain Masing carriage runs on the shooting engine, any other rig on the compiled
plant.  The lines are computed at the steps' own frequencies too, so each step's difference
is read off its level's line: a line and its difference panel cannot disagree.  Only for
runs on a simulated rig with a stored model.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ._steps import UNSETTLED_RESIDUAL, residual_ratio

if TYPE_CHECKING:
    from sim.rig import RigModel

log = logging.getLogger(__name__)

MODEL_GRID_POINTS = 120        # dense frequency grid of the model curves (shooting engine)
PLANT_GRID_POINTS = 40         # the compiled plant's grid (plus the steps' frequencies): its points cost more


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

    model: RigModel                           # the rig model used (its defaults filled in)
    omega_s: float
    curves: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]]   # level -> (f, C_pp, flags)
    at_steps: dict[str, float]                # step key -> model compliance_pp (m/N)
    levels: list[LevelComparison]
    engine_notes: list[str] = field(default_factory=list)
    responses: dict = field(default_factory=dict)     # level -> sim.rig_response.LevelResponse (compiled plant)

    def resonance(self, level_N: float) -> tuple[float, float]:
        f, c, _ = self.curves[level_N]
        ok = np.isfinite(c)
        if not ok.any():
            return math.nan, math.nan
        i = int(np.nanargmax(np.where(ok, c, -np.inf)))
        return float(f[i]), float(c[i])


def _model_effects(model) -> dict[str, str]:
    """Rig effects the dimensionless engine leaves out, when switched on: key -> words."""
    names = {"viscous_N_s_per_m": "viscous damping", "spring_N_per_m": "linear spring",
             "disp_delay_s": "displacement-channel delay", "force_gain_error": "force gain error",
             "accel_gain_error": "acceleration gain error", "disp_gain_error": "displacement gain error",
             "friction_alpha": "speed-dependent friction", "pitch_inertia_kg_m2": "pitching mode",
             "cubic_spring_N_per_m3": "cubic spring", "quadratic_damping_N_s2_per_m2": "quadratic damping",
             "friction_asymmetry": "asymmetric friction",
             "shaker_force_constant_N_per_A": "electrodynamic shaker (the force has harmonics)",
             "line_amplitude": f"interference line on the {model.line_channel or '?'} sensor at "
                               f"{model.line_freq_Hz:g} Hz"}
    return {k: f"{label} ({k} = {getattr(model, k):g})" for k, label in names.items() if getattr(model, k, 0)}


def model_comparison(meta: dict, results: list[dict], flagged: set[str] | None = None) -> ModelComparison | None:
    """None unless the run is on a simulated rig with a stored model.  ``flagged``: keys of
    the steps the step quality check (sim.artefacts) did not find simply usable; None
    flags by the stored displacement residual instead."""
    from procedures.plan import stored_model
    model = stored_model(meta.get("rig"))
    if model is None or not results:
        return None
    from sim.rig_response import LEFT_OUT, line_model, plain_masing

    ws = model.omega_s
    plan = meta.get("plan") or {}
    levels_N = plan.get("levels_N") or sorted({r["target_force_N"] for r in results})
    freqs = np.array(sorted({r["freq_Hz"] for r in results}))
    plain = plain_masing(line_model(model))
    dense = np.geomspace(freqs.min() / 1.1, freqs.max() * 1.1, MODEL_GRID_POINTS if plain else PLANT_GRID_POINTS)
    grid = np.union1d(dense, freqs)
    effects = _model_effects(model)
    left_out = [e for k, e in effects.items() if k in LEFT_OUT]
    if plain:
        engine_notes = [f"omega_s = sqrt(F_s/(x_s m)) = {ws:.4g} rad/s ({ws / (2 * math.pi):.4g} Hz); "
                        f"compliance = G x_s/F_s with G from sim.shooting.frf_shooting (n = {model.n:g})"]
    else:
        engine_notes = ["the rig's model with every effect its file declares ("
                        + ", ".join(e for k, e in effects.items() if k not in LEFT_OUT) + "; decision 0054): steady states "
                        "of the compiled plant (sim.rig_response), an upward sweep at each level"]
    engine_notes.append("lines and differences are one computation: each step's difference is measured / the line at "
                        "its frequency - 1")
    if left_out:
        engine_notes.append("left out (an ideal force at the measured level): " + ", ".join(left_out))

    curves, at_steps, levels, responses = {}, {}, [], {}
    by_level: dict[int, list[dict]] = {}
    for r in results:
        by_level.setdefault(r["level_index"], []).append(r)
    for li, steps in sorted(by_level.items()):
        level = float(levels_N[li]) if li < len(levels_N) else float(steps[0]["target_force_N"])
        gamma0 = level / model.friction_level_N
        notes = []
        if level > model.amp_force_limit_N:
            notes.append(f"level above the amplifier's force limit {model.amp_force_limit_N:g} N")
        try:
            f_model, C, flags = (_shooting_line if plain else _plant_line)(model, level, grid, notes)
            if not plain:
                from sim.rig_response import level_response
                responses[level] = level_response(model, level, grid)     # cached: the line just computed
        except Exception as e:          # the report must come out even if the engine fails
            log.warning("model FRF at %g N failed: %s", level, e)
            notes.append(f"model engine failed: {type(e).__name__}: {e}")
            f_model, C, flags = grid, np.full(grid.size, np.nan), np.ones(grid.size, bool)
        curves[level] = (f_model, C, flags)
        diff = []
        for s in steps:
            c_model = float(C[int(np.argmin(np.abs(f_model - s["freq_Hz"])))])   # the line at the step's frequency
            at_steps[s["key"]] = c_model
            diff.append(s["compliance_pp_m_per_N"] / c_model - 1.0)
        bad = np.array([s["key"] in flagged if flagged is not None else residual_ratio(s) > UNSETTLED_RESIDUAL
                        for s in steps])
        diff = np.array(diff)
        levels.append(LevelComparison(level, gamma0, len(steps), int(bad.sum()), _median(diff), _signed_max(diff),
                                      _signed_max(diff[~bad]), notes))
    return ModelComparison(model, ws, curves, at_steps, levels, engine_notes, responses)


def _shooting_line(model, level: float, grid: np.ndarray, notes: list[str]):
    """(f, compliance_pp, flags) of the Masing carriage by half-period shooting."""
    from sim.shooting import frf_shooting
    ws, gamma0 = model.omega_s, level / model.F_s_N
    fr, fell_back = frf_shooting(2 * math.pi * grid / ws, gamma0, model.n)
    G = np.where(fr.converged, fr.G, np.nan)
    flags = np.array(fr.gross_rolling) | ~np.array(fr.converged)
    if (~fr.converged).any():
        notes.append(f"model: no steady state at {int((~fr.converged).sum())} of {grid.size} frequencies")
    if fell_back.any():
        notes.append(f"model: RK4 fallback at {int(fell_back.sum())} of {grid.size} frequencies")
    if np.any(fr.gross_rolling) or gamma0 >= 1:
        notes.append("gamma0 >= 1: gross rolling; model = centred periodic orbit, the rig's "
                     "carriage may drift: indicative only" if gamma0 >= 1
                     else "model: gross rolling at some frequencies")
    return fr.beta * ws / (2 * math.pi), G * model.x_s_m / model.F_s_N, flags


def _plant_line(model, level: float, grid: np.ndarray, notes: list[str]):
    """(f, compliance_pp, flags) of the rig's full model on the compiled plant."""
    from sim.rig_response import MAX_PERIODS, level_response
    resp = level_response(model, level, grid)
    if (~resp.converged).any():
        notes.append(f"model: no steady state within {MAX_PERIODS} periods at {int((~resp.converged).sum())} of "
                     f"{grid.size} frequencies")
    return resp.freq_Hz, np.where(resp.converged, resp.compliance_pp, np.nan), ~resp.converged


def _median(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else math.nan


def _signed_max(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(x[np.argmax(np.abs(x))]) if x.size else math.nan
