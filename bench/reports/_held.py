"""The model at a held response: a response-controlled run's model comparison (decisions 0052, 0060).

A response-controlled step holds the response's fundamental at its level, so the model is
asked the same: at each frequency the force the rig's one model (every declared effect and
the pitching mode, as every other line: :func:`sim.rig_response.held_response`, decision
0054) needs for the held |X1| (or the drive point's |A1|), found by a secant on the
compiled plant's steady states; the line is the compliance_pp there.  Each step's
difference compares its compliance_pp with the model's at the amplitude it measured (the
line's at the level, moved by the local slope d log|R1| / d log|F1|: the steps hold the
level within the plan's tolerance).  No FRF engine at a "force" made of metres.
"""

from __future__ import annotations

import math

import numpy as np

from procedures.kind import ProcedureKind, of_stored_plan

from ._model import (
    LevelComparison,
    ModelComparison,
    _median,
    _model_effects,
    _signed_max,
    model_comparison,
)
from ._steps import UNSETTLED_RESIDUAL, residual_ratio

HELD_GRID_POINTS = 40      # the held line's frequencies (each a secant of steady states), and the steps'


def held_response_comparison(meta: dict, results: list[dict], flagged: set[str] | None,
                             quantity: str) -> ModelComparison:
    """The comparison of a response-controlled run whose levels hold ``quantity`` ("disp"
    or "accel"), per level: the model's compliance_pp at the held level (the line) and at
    each step's measured amplitude (the difference)."""
    from procedures.plan import stored_model
    from sim.rig_response import LEFT_OUT, held_response, line_model
    declared = stored_model(meta["rig"])
    assert declared is not None                 # called for a simulated rig's run only
    model = line_model(declared)
    levels = (meta.get("plan") or {}).get("levels_N") or []
    freqs = np.array(sorted({r["freq_Hz"] for r in results}))
    grid = np.union1d(np.geomspace(freqs.min() / 1.1, freqs.max() * 1.1, HELD_GRID_POINTS), freqs)
    unit = "m" if quantity == "disp" else "m/s^2"
    effects = _model_effects(declared)
    left_out = [e for k, e in effects.items() if k in LEFT_OUT]
    effects = {k: e for k, e in effects.items() if k not in LEFT_OUT}
    notes = [f"response-controlled: the rig's model ({', '.join(effects.values()) or 'the Masing carriage'}; decision 0054) at "
             f"the held {'|X1|' if quantity == 'disp' else '|A1|'}: at each frequency the force that holds it, by a "
             f"secant on the compiled plant's steady states (sim.rig_response.held_response), no FRF engine at a "
             f"force level"]
    if left_out:
        notes.append("left out (an ideal sine force): " + ", ".join(left_out))
    curves, at_steps, out = {}, {}, []
    by_level: dict[int, list[dict]] = {}
    for r in results:
        by_level.setdefault(r["level_index"], []).append(r)
    for li, steps in sorted(by_level.items()):
        level = float(levels[li]) if li < len(levels) else float(steps[0]["response_control"]["target"])
        held = held_response(model, level, grid, quantity)
        curves[level] = (held.freq_Hz, held.compliance_pp, ~held.converged)
        if (~held.converged).any():
            notes.append(f"{level:g} {unit}: the model's force not found at {int((~held.converged).sum())} of "
                         f"{grid.size} frequencies (left out of the line)")
        diff = []
        for s in steps:
            k = int(np.argmin(np.abs(held.freq_Hz - s["freq_Hz"])))
            got = float((s["disp"] if quantity == "disp" else s["accel"])["amplitude"][0]) / level
            # compliance_pp ~ X1 / F1 with F1 ~ R1^(1 / slope): moved from the level to the step's amplitude
            c_model = float(held.compliance_pp[k]) * got ** (1.0 - 1.0 / held.slope[k])
            at_steps[s["key"]] = c_model
            diff.append(s["compliance_pp_m_per_N"] / c_model - 1.0)
        bad = np.array([s["key"] in flagged if flagged is not None else residual_ratio(s) > UNSETTLED_RESIDUAL
                        for s in steps])
        d = np.array(diff)
        out.append(LevelComparison(level, math.nan, len(steps), int(bad.sum()), _median(d), _signed_max(d),
                                   _signed_max(d[~bad]), []))
    return ModelComparison(model, model.omega_s, curves, at_steps, out, notes)


def comparison_of(meta: dict, results: list[dict], flagged: set[str] | None = None) -> ModelComparison | None:
    """The model comparison of any run (None unless on a simulated rig with a stored model):
    a response-controlled run's at the held response, any other's by the FRF engine at its
    force levels (:func:`bench.reports._model.model_comparison`)."""
    rig, plan = meta.get("rig") or {}, meta.get("plan") or {}
    kind, level = of_stored_plan(plan)
    if kind is ProcedureKind.RESPONSE_CONTROLLED and results and rig.get("simulated") and rig.get("model"):
        return held_response_comparison(meta, results, flagged, level.key)
    return model_comparison(meta, results, flagged)
