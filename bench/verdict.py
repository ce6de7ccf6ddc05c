"""What a run's procedure promised and whether the stored steps keep it (decision 0052).

A stepped sine promises each step's force within tolerance; a response-controlled stepped
sine the response within tolerance at each step; phase resonance a locked point at every
planned level; a refined plan each refined peak known within its tolerance.  The report's
overall line and ``bench run``'s exit status read the same :func:`promise` (a completed
run with a level not locked, or a refinement that spent its budget, exits 1).

The promise is a value (decision 0067): what was kept and each shortfall a :class:`Said`
of a :class:`Kept` or :class:`Short` code and its fields; their words are made by
:data:`bench.words.terminal.PROMISE` (the report says the same).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from procedures.kind import ProcedureKind, of_stored_plan

from .words import Said


class Kept(StrEnum):
    """What the procedure kept (the words: ``bench.words.terminal.PROMISE``)."""

    LEVELS_LOCKED = "levels_locked"         # phase resonance: locked, levels
    LEVEL_HELD = "level_held"               # response control: name, symbol, tolerance, refined
    FORCE_HELD = "force_held"               # stepped sine: tolerance, refined


class Short(StrEnum):
    """Where the procedure fell short, one phrase each."""

    NOT_LOCKED = "not_locked"               # locked, levels, lost: [(level, why or None, measured)]
    OUT_OF_TOLERANCE = "out_of_tolerance"   # name, symbol (None: the force), steps
    BUDGET_SPENT = "budget_spent"           # mode, level, tolerance, steps


@dataclass(frozen=True)
class Promise:
    """What the procedure promised (``kept``) and where it fell short (``short``: one value
    each); ``fatal``: the shortfall means the procedure did not measure what it was run for
    (exit status 1 of a completed run)."""

    kind: ProcedureKind
    kept: Said
    short: tuple[Said, ...]
    fatal: bool


def _missed_tolerance(results: list[dict], name: str = "force", symbol: str | None = None) -> tuple[Said, ...]:
    off = [r for r in results if not r.get("force_converged", True)]
    return (Said(Short.OUT_OF_TOLERANCE, {"name": name, "symbol": symbol, "steps": len(off)}),) if off else ()


def refinement(plan: dict, results: list[dict], rig: dict | None = None) -> tuple[dict | None, tuple[Said, ...]]:
    """A refined plan's ([plan.resonance] refine) end per level and mode: (what it kept:
    the peaks that converged and those with no peak inside the grid, the peaks still not
    known within the tolerance when the budget ran out).  None and () for a plan without
    refinement or one this version cannot read."""
    if not plan.get("refine") or not results:
        return None, ()
    from procedures.resonance import Refiner

    from .config import ConfigError, parse_stored_plan
    try:
        p = parse_stored_plan(plan, "run.json")
    except ConfigError:
        return None, ()
    from procedures.plan import stored_model
    from sim.modal import pitch_band_Hz
    model = stored_model(rig)
    band = pitch_band_Hz(model) if model else None
    no_pitch = model is not None and band is None   # as the run (0056)
    refiner = Refiner(p, lambda: results, band, no_pitch=no_pitch)
    q = p.level_quantity
    ends = [(q.format(level), mode, how, n) for li, level in enumerate(p.levels_N)
            for mode, how, n in refiner.outcome(li, level)]
    short = tuple(Said(Short.BUDGET_SPENT, {"mode": mode, "level": lv, "tolerance": p.refine_tolerance, "steps": n})
                  for lv, mode, how, n in ends if how == "budget_spent")
    kept = {"converged": sum(1 for e in ends if e[2] == "converged"),
            "no_peak": sum(1 for e in ends if e[2] == "no_peak")}
    return kept, short


def promise(plan: dict, results: list[dict], rig: dict | None = None, *, completed: bool = True) -> Promise:
    """The procedure's promise against the stored steps ``results`` of a run whose stored
    plan is ``plan`` (run.json's; an older one without ``procedure`` is a stepped sine); a
    refined plan's refinement too, once ``completed`` (converged, or the budget spent: then
    not "went well" and ``fatal``: `bench run` exits 1, issue 30 item 4)."""
    kind, level = of_stored_plan(plan)
    tol = plan.get("force_tolerance")
    tolerance = tol if isinstance(tol, (int, float)) else None
    if kind is ProcedureKind.PHASE_RESONANCE:
        levels = [float(v) for v in plan.get("levels_N") or []]
        points = {int(r.get("level_index", -1)): r["backbone"] for r in results if isinstance(r.get("backbone"), dict)}
        locked = [i for i, b in points.items() if b.get("locked")]
        lost = [(level.format(v), points[i].get("why") if i in points else None, i in points)
                for i, v in enumerate(levels) if i not in locked]
        count = {"locked": len(locked), "levels": len(levels)}
        short = (Said(Short.NOT_LOCKED, {**count, "lost": lost}),) if lost else ()
        return Promise(kind, Said(Kept.LEVELS_LOCKED, count), short + _missed_tolerance(results), bool(lost))
    refined, unrefined = refinement(plan, results, rig) if completed else (None, ())
    if kind is ProcedureKind.RESPONSE_CONTROLLED:
        name = level.name
        return Promise(kind, Said(Kept.LEVEL_HELD, {"name": name, "symbol": level.symbol, "tolerance": tolerance,
                                                    "refined": refined}),
                       _missed_tolerance(results, name, level.symbol) + unrefined, bool(unrefined))
    return Promise(kind, Said(Kept.FORCE_HELD, {"tolerance": tolerance, "refined": refined}),
                   _missed_tolerance(results) + unrefined, bool(unrefined))
