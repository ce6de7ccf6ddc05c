"""The report's words (markdown, decision 0067), by code.

``PROBLEM``: a run directory's problems, as the terminal says them (the report lists the
steps it could not use with the words ``bench check`` prints for them).

``CONCERN``: the overall line's reasons for attention and notes
(:class:`bench.reports._overall.Concern`), and the procedure's shortfalls as the terminal
says them (:data:`bench.words.terminal.PROMISE`); ``OVERALL``: the line itself, by verdict
(:class:`bench.reports._overall.Verdict`).

``REFINEMENT``: how a refinement ended without converging (the outcome codes of
:func:`procedures.resonance.refinement_outcomes`), in a mode's note (modes.csv and the
report's modes table) and the report's line under the modes.
"""

from __future__ import annotations

from . import Said, Words, say
from .numbers import number
from .terminal import PROBLEM as _TERMINAL_PROBLEM
from .terminal import PROMISE, promised

PROBLEM: Words = dict(_TERMINAL_PROBLEM)


def problem(code: str, fields) -> str:
    """A run directory's problem in the report's words."""
    return say(PROBLEM, code, fields)


def _steps(n: int, what: str = "step") -> str:
    return f"{n} {what}{'s' * (n != 1)}"


_STATUS = {"interrupted": "the run was interrupted (bench resume continues it)",
           "aborted": "the run was stopped by a limit",
           "running": "the run is still running, or ended without recording its end"}


def _interrupted(times: int, reasons: list[str], unrecorded: bool, resumes: int) -> str:
    how = ", ".join(reasons)
    if unrecorded:
        how += (", " if how else "") + "ended without recording why (killed, crashed or power lost)"
    return (f"interrupted {_steps(times, 'time')} ({how}) and resumed {_steps(resumes, 'time')}: resumed steps "
            "restart from the step before, not from the rig's uninterrupted history (decision 0013)")


CONCERN: Words = {
    "run_status": lambda status: _STATUS.get(status, f"the run ended with status '{status}'"),
    "missing": lambda steps: f"{_steps(steps)} missing",
    "damaged": lambda steps: f"{_steps(steps)} damaged",
    "rejected": lambda steps: f"{_steps(steps)} rejected by the step-quality check (see Steps needing attention)",
    "quality_unknown": lambda error: f"the step quality could not be computed ({error})",
    "limit_trip": lambda reasons: "limit trip: " + "; ".join(reasons),
    "errors": lambda count: f"{count} instrument or run error{'s' * (count != 1)} (see the events below)",
    "orphans": lambda count, names: (f"{count} file{'s' * (count != 1)} in steps/ that no planned step owns "
                                     f"({', '.join(names)})"),
    "interrupted": _interrupted,
    "ident_failed": lambda error: f"the final identification failed ({error})",
    "misfit": lambda reduced_chi2, analyzed: (f"the identified model does not fit the data beyond the noise (reduced "
                                              f"chi^2 {number(reduced_chi2, fmt='.3g')}): its parameters are biased"
                                              + ("" if analyzed else "; `bench analyze` names what is missing")),
    "flagged": lambda steps, reasons: (f"{_steps(steps)} flagged by the step-quality check, used with their noise as "
                                       f"weight ({', '.join(f'{k} {why}' for why, k in reasons)}; see Steps needing "
                                       "attention)"),
    "truth_missed": lambda misses: ("the simulated rig's truth lies outside the 95 % interval of "
                                    + ", ".join(f"{label} ({k:.2g} standard errors out)" for label, k in misses)
                                    + ": the estimate misses it by more than its interval allows"),
    "below_resolution": lambda steps, rms_m, source: (f"{_steps(steps)} move{'s' * (steps == 1)} less than the probe "
                                                      f"resolves ({1e9 * rms_m:.3g} nm rms, {source}): their "
                                                      "displacement is noise; their force and acceleration are still "
                                                      "good (accelerance, mass)"),
    **PROMISE,
}


def _but(skipped: int, quantity: str) -> str:
    return (f" but {skipped} skipped at run time as the plan allows (infeasible = \"skip\": {quantity} unreachable "
            "within the drive limit)" if skipped else "")


OVERALL: Words = {
    "no_plan": lambda **_: "Overall: **needs attention**: no readable plan.",
    "needs_attention": lambda why, notes, **_: (f"Overall: **needs attention**: {'; '.join(why)}."
                                                + (f" Also: {'; '.join(notes)}." if notes else "")),
    "went_well_with_notes": lambda kept, notes, skipped, quantity, **_: (
        f"Overall: **went well, with notes**: every planned step measured, intact and usable{_but(skipped, quantity)}, "
        f"{kept}, no limit trip or error; but {'; '.join(notes)}."),
    "went_well": lambda kept, skipped, quantity, fits, **_: (
        f"Overall: **went well**: every planned step measured, intact and usable{_but(skipped, quantity)}, {kept}, "
        f"no limit trip, error or interruption{', the identified model fits' if fits else ''}."),
}


def concern(said: Said) -> str:
    """A reason for attention, a note, or a shortfall of the procedure, in words."""
    return say(CONCERN, said.code, said.fields)


def overall(o) -> str:
    """The overall line of a verdict (:class:`bench.reports._overall.Overall`)."""
    return say(OVERALL, o.verdict, {"why": [concern(s) for s in o.why], "notes": [concern(s) for s in o.notes],
                                    "kept": promised(o.kept.kept) if o.kept else "", "skipped": o.skipped,
                                    "quantity": o.quantity, "fits": o.fits})


REFINEMENT: Words = {
    "budget_spent": lambda: "the refinement budget ([plan.resonance] max_steps) was spent",
    "no_progress": lambda: "the next step could not be measured (a frequency measured already, or the step skipped)",
    "not finished": lambda: "the run stopped before the level's refinement ended",
}


def refinement_note(why: str, note: str) -> str:
    """A mode's note when its level's refinement did not converge (``note``: the fit's own)."""
    return (f"refinement not converged: {say(REFINEMENT, why, {})}; the interval holds the measured maximum's bracket"
            + (f" ({note})" if note else ""))


def refinement_line(why: str, mode: str, level_N: float) -> str:
    """The report's line of a refinement that did not converge."""
    return f"- Refinement not converged: {mode} mode at {level_N:g} N: {say(REFINEMENT, why, {})}."
