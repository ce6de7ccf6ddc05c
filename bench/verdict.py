"""What a run's procedure promised and whether the stored steps keep it (decision 0052).

A stepped sine promises each step's force within tolerance; a response-controlled stepped
sine the response within tolerance at each step; phase resonance a locked point at every
planned level; a refined plan each refined peak known within its tolerance.  The report's
overall line and ``bench run``'s exit status read the same :func:`promise` (a completed
run with a level not locked, or a refinement that spent its budget, exits 1).
"""

from __future__ import annotations

from dataclasses import dataclass

from procedures.kind import ProcedureKind, of_stored_plan


@dataclass(frozen=True)
class Promise:
    """What the procedure promised (``kept``: in words) and where it fell short (``short``:
    one phrase each); ``fatal``: the shortfall means the procedure did not measure what it
    was run for (exit status 1 of a completed run)."""

    kind: ProcedureKind
    kept: str
    short: tuple[str, ...]
    fatal: bool


def _missed_tolerance(results: list[dict], what: str) -> tuple[str, ...]:
    off = [r for r in results if not r.get("force_converged", True)]
    return (f"{what} out of tolerance at {len(off)} step{'s' * (len(off) != 1)}",) if off else ()


def refinement(plan: dict, results: list[dict], rig: dict | None = None) -> tuple[str, tuple[str, ...]]:
    """A refined plan's ([plan.resonance] refine) end per level and mode: (what it kept,
    the peaks still not known within the tolerance when the budget ran out).  Empty for a
    plan without refinement or one this version cannot read."""
    if not plan.get("refine") or not results:
        return "", ()
    from procedures.resonance import Refiner

    from .config import ConfigError, parse_stored_plan
    try:
        p = parse_stored_plan(plan, "run.json")
    except ConfigError:
        return "", ()
    from procedures.plan import stored_model
    from sim.modal import pitch_band_Hz
    model = stored_model(rig)
    band = pitch_band_Hz(model) if model else None
    no_pitch = model is not None and band is None   # as the run (0056)
    refiner = Refiner(p, lambda: results, band, no_pitch=no_pitch)
    q = p.level_quantity
    ends = [(q.format(level), mode, how, n) for li, level in enumerate(p.levels_N)
            for mode, how, n in refiner.outcome(li, level)]
    short = tuple(f"refinement: the {mode} peak at {lv} not within {100 * p.refine_tolerance:g} % after {n} steps "
                  "(budget spent; [plan.resonance] max_steps)" for lv, mode, how, n in ends if how == "budget spent")
    converged = sum(1 for e in ends if e[2] == "converged")
    kept = (f"the refinement converged for {converged} peak{'s' * (converged != 1)}"
            + (f" ({sum(1 for e in ends if e[2] == 'no peak')} more had no peak inside the grid to refine)"
               if any(e[2] == "no peak" for e in ends) else ""))
    return kept, short


def promise(plan: dict, results: list[dict], rig: dict | None = None, *, completed: bool = True) -> Promise:
    """The procedure's promise against the stored steps ``results`` of a run whose stored
    plan is ``plan`` (run.json's; an older one without ``procedure`` is a stepped sine); a
    refined plan's refinement too, once ``completed`` (converged, or the budget spent: then
    not "went well" and ``fatal``: `bench run` exits 1, issue 30 item 4)."""
    kind, level = of_stored_plan(plan)
    tol = plan.get("force_tolerance")
    within = f"within {100 * tol:g} %" if isinstance(tol, (int, float)) else "within tolerance"
    if kind is ProcedureKind.PHASE_RESONANCE:
        levels = [float(v) for v in plan.get("levels_N") or []]
        points = {int(r.get("level_index", -1)): r["backbone"] for r in results if isinstance(r.get("backbone"), dict)}
        locked = [i for i, b in points.items() if b.get("locked")]
        lost = [f"{level.format(v)}: {points[i].get('why') or 'not locked'}" if i in points
                else f"{level.format(v)}: not measured" for i, v in enumerate(levels) if i not in locked]
        short = (f"{len(locked)} of {len(levels)} levels locked; not locked: {'; '.join(lost)}",) if lost else ()
        return Promise(kind, f"{len(locked)} of {len(levels)} levels locked (the phase held in its band), "
                             "each a point of the backbone; phase resonance identifies no model",
                       short + _missed_tolerance(results, "force"), bool(lost))
    refined, unrefined = refinement(plan, results, rig) if completed else ("", ())
    also = f", {refined}" if refined else ""
    if kind is ProcedureKind.RESPONSE_CONTROLLED:
        name = level.name
        return Promise(kind, f"the {name} ({level.symbol}) held {within} of its level at every step{also}",
                       _missed_tolerance(results, f"{name} ({level.symbol})") + unrefined, bool(unrefined))
    return Promise(kind, f"the force {within} at every step{also}", _missed_tolerance(results, "force") + unrefined,
                   bool(unrefined))
