"""Resonance search (``[plan.resonance] refine = true``, decision record 0043): after a
level's sweeps, each peak the data show is bracketed and refined with extra steps until
its frequency is known within the plan's tolerance, at most ``refine_steps`` per mode and level.

A refinement step is an ordinary step (:class:`procedures.plan.StepSpec` with ``refined``
= its number in the level): controlled, supervised, settled, stored, resumable.  What the
next one is depends only on the level's stored steps, so a resumed run chooses what an
uninterrupted one would.  The peaks: the feed mode's compliance_pp maximum and the
pitching mode's accelerance maximum, found and fitted by :mod:`sim.modal`; a maximum at
the grid's edge is not a peak and is not chased.  The steps' measured noise says which
points are tied with the maximum: on a flat top their plateau is bracketed (decision
record 0069).

The dwell (``[plan.resonance] dwell_cycles`` > 0): once a level's refinement is over, one
more step at each refined resonance (the estimate from the level's sweep and refinement
steps) whose measured block is ``dwell_cycles`` periods long, keyed with ``W`` where a
refinement step has ``R``.  Dwell steps do not enter the estimates that choose steps.

The end of each mode's refinement at each level is told to ``on_end`` once (decision record
0050): a reason code (:data:`END_REASONS`), the refinement steps measured and whether a dwell
is owed; the session stores it as a ``refinement_end`` event, from which ``bench check``
knows a refined run complete or names what it still owes.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import numpy as np

from sim.modal import LevelData, estimate_mode, find_feed, find_pitch, level_modes, next_refinement_Hz

from .plan import Plan, StepSpec

log = logging.getLogger(__name__)

# a mode's peak as the search sees it: (estimate Hz, damping ratio, index of the measured
# maximum, the curve, its measured noise or None; decision 0069)
Found = tuple[float, float, int, np.ndarray, "np.ndarray | None"]

# why a mode's refinement at a level ended (a code, stored as is; never parsed from words)
END_REASONS = {
    "converged": "the peak is known within the tolerance",
    "budget_spent": "max_steps refinement steps measured, the peak not yet known within the tolerance",
    "no_peak": "no peak inside the grid to refine",
    "no_progress": "the next step would repeat a measured frequency",
    "too_few_steps": "fewer than 3 steps measured at the level",
    "not_measured": "a refinement step it asked for was not measured (skipped at run time)",
}


class Refiner:
    """``next_step(last)``: the next refinement step of the level whose sweep ended with
    ``last`` (a step of the schedule), or None when every peak is known within the
    tolerance or the level's budget is spent.  ``results()`` returns the stored steps."""

    def __init__(self, plan: Plan, results: Callable[[], list], pitch_band_Hz: tuple[float, float] | None = None,
                 on_end: Callable[..., None] | None = None, no_pitch: bool = False):
        self.plan = plan
        # a rig model without a pitching mode: its pitch is not chased (decision 0056)
        self.modes = tuple(m for m in plan.refine_modes if not (no_pitch and m == "pitch"))
        self._results = results
        self._snapshot: list | None = None    # the stored steps, read once per next_step
        self.pitch_band_Hz = pitch_band_Hz
        self.f_min, self.f_max = min(plan.freqs_Hz), max(plan.freqs_Hz)
        self.on_end = on_end                  # on_end(level_index=, level=, mode=, reason=, steps=, dwell_owed=)
        self._ended: set[tuple[int, str]] = set()
        self._asked: set[str] = set()         # keys of the refinement steps asked for
        self._tracked: dict[tuple[int, int], float | None] = {}   # (level index, steps) -> its feed Hz

    def _end(self, last: StepSpec, mode: str, reason: str, steps: int, found) -> None:
        """Tell ``on_end`` (once per level and mode) that ``mode``'s refinement ended; one
        that ended without the peak known within the tolerance is also a warning."""
        if (last.level_index, mode) in self._ended:
            return
        self._ended.add((last.level_index, mode))
        owed = bool(self.plan.dwell_cycles > 0 and found is not None)
        log.info("level %g N: the %s refinement ended: %s (%d steps)%s", last.force_N, mode, END_REASONS[reason],
                 steps, "; a dwell follows" if owed else "")
        if reason in NOT_CONVERGED:
            log.warning("level %g N: the %s peak is not known within %g %% after %d refinement steps (%s%s)",
                        last.force_N, mode, 100 * self.plan.refine_tolerance, steps, END_REASONS[reason],
                        "; plan: [plan.resonance] max_steps" if reason == "budget_spent" else "")
        if self.on_end:
            self.on_end(level_index=last.level_index, level=last.force_N, mode=mode, reason=reason, steps=steps,
                        dwell_owed=owed)

    def results(self) -> list:
        """The stored steps: read once per :meth:`next_step` (each read checks every step
        file; a refined run's 48 steps were read 94 times, decision 0083)."""
        return self._snapshot if self._snapshot is not None else self._results()

    def next_step(self, last: StepSpec) -> StepSpec | None:
        self._snapshot = self._results()
        try:
            return self._next_step(last)
        finally:
            self._snapshot = None

    def _next_step(self, last: StepSpec) -> StepSpec | None:
        li = last.level_index
        level = [r for r in self.results() if r["level_index"] == li]
        steps = [r for r in level if "-W" not in r["key"]]    # dwells do not choose steps
        if len(steps) < 3:
            for mode in self.modes:
                self._end(last, mode, "too_few_steps", 0, None)
            return None
        d = LevelData.from_steps(last.force_N, steps)
        stored = {r["key"] for r in steps}
        for mode in self.modes:
            done = sum(1 for r in steps if f"-R{mode[0].upper()}" in r["key"])
            found = self._resonance(mode, d, li)
            prev = last_refined_Hz(steps, mode)
            why = refinement_end(self, mode, d, done, prev, li)
            if why is not None:
                self._end(last, mode, why, done, found)
                continue
            f = float(f"{self._next_from(found, d, prev):.6g}")      # type: ignore[arg-type]  # found: why is None
            step = StepSpec(last.index, li, -1, last.direction, last.force_N, f, refined=done, refined_mode=mode)
            if step.key in self._asked and step.key not in stored:      # asked for before, not measured
                self._end(last, mode, "not_measured", done, found)
                return step              # (the procedure does not take a step twice: it goes on)
            self._asked.add(step.key)
            log.info("level %g N: refining the %s peak: step at %.5g Hz", last.force_N, mode, f)
            return step
        if self.plan.dwell_cycles > 0:
            for mode in self.modes:
                if any(f"-W{mode[0].upper()}" in r["key"] for r in level):
                    continue
                found = self._resonance(mode, d, li)
                if found is None:
                    log.info("level %g N: no %s peak inside the grid: no dwell", last.force_N, mode)
                    continue
                f = float(f"{min(max(found[0], self.f_min), self.f_max):.6g}")   # inside the checked grid
                log.info("level %g N: dwell of %d cycles at the %s resonance, %.5g Hz", last.force_N,
                         self.plan.dwell_cycles, mode, f)
                return StepSpec(last.index, li, -1, last.direction, last.force_N, f, refined=0, refined_mode=mode,
                                dwell_cycles=self.plan.dwell_cycles)
        return None

    def outcome(self, level_index: int, level: float) -> list[tuple[str, str, int]]:
        """How the refinement of a finished level ended, per refined mode: (mode, "converged"
        | "budget_spent" | "no_peak", refinement steps taken), the run's own decision
        (:func:`refinement_end`) replayed from the stored steps (decision 0052)."""
        steps = [r for r in self.results() if r["level_index"] == level_index and "-W" not in r["key"]]
        if len(steps) < 3:
            return []
        d = LevelData.from_steps(level, steps)
        out = []
        for mode in self.modes:
            done = sum(1 for r in steps if f"-R{mode[0].upper()}" in r["key"])
            why = refinement_end(self, mode, d, done, last_refined_Hz(steps, mode), level_index) or "converged"
            out.append((mode, why if why in ("no_peak", "budget_spent") else "converged", done))
        return out

    def _resonance(self, mode: str, d: LevelData, level_index: int | None = None) -> Found | None:
        """(resonance estimate in Hz, damping ratio, index of the measured maximum, the
        peak's magnitudes, their measured noise or None) of ``mode`` in ``d`` (the steps of
        level ``level_index``), or None without a peak inside the grid."""
        predicted = self._feed_Hz_before(level_index)
        if mode == "feed":
            i = find_feed(d, predicted)
            mag, H, kind, curve, sd = d.compliance_pp, d.compliance, "receptance", d.compliance_pp, d.compliance_pp_sd
        else:
            feed = find_feed(d, predicted)
            i = find_pitch(d, None, self.pitch_band_Hz, None if feed is None else float(d.f_Hz[feed]))
            mag, H, kind, curve, sd = np.abs(d.accelerance), d.accelerance, "accelerance", None, d.accelerance_sd
        if i is None or i in (0, d.f_Hz.size - 1):
            return None                  # no peak inside the grid: nothing to bracket
        est = estimate_mode(d.f_Hz, H, mode=mode, kind=kind, curve=curve, peak_index=i, sd=sd)
        fr = est.resonance_Hz if est.ok else self._parabola(d.f_Hz, mag, i)
        return fr, est.damping_ratio, i, mag, sd

    def _feed_Hz_before(self, level_index: int | None) -> float | None:
        """The feed resonance of the level measured before ``level_index`` (the plan's
        order), from its stored steps, or None (the first level, or no peak inside its
        grid): the feed peak is tracked from level to level as `bench modes` tracks it
        (sim.modal.track_modes), the maximum of compliance_pp nearest the one before. The
        lowest maximum alone would take a superharmonic resonance below the feed mode (the
        pitching rig at 3 N: a 23.6 Hz bump, 0.29 of the 61 Hz peak, was refined and called
        converged while the report's feed row stayed coarse; decision 0072)."""
        if not level_index:
            return None
        steps = [r for r in self.results() if r["level_index"] == level_index - 1 and "-W" not in r["key"]]
        if len(steps) < 3:
            return None
        key = (level_index - 1, len(steps))
        if key not in self._tracked:
            d = LevelData.from_steps(self.plan.levels_N[level_index - 1], steps)
            feed = level_modes(d, feed_predicted_Hz=self._feed_Hz_before(level_index - 1))[0]
            self._tracked[key] = feed.resonance_Hz if math.isfinite(feed.resonance_Hz) else None
        return self._tracked[key]

    def _next_from(self, found: Found, d: LevelData, last_Hz: float | None = None) -> float | None:
        fr, zeta, i, mag, sd = found
        return next_refinement_Hz(d.f_Hz, mag, i, fr, zeta, self.plan.refine_tolerance, self.f_min, self.f_max,
                                  last_Hz, sd)

    @staticmethod
    def _parabola(f: np.ndarray, mag: np.ndarray, i: int) -> float:
        """Vertex of the parabola through the maximum and its neighbours (log f, log mag)."""
        x, y = np.log(f[i - 1:i + 2]), np.log(mag[i - 1:i + 2])
        a, b, _ = np.polyfit(x, y, 2)
        return float(math.exp(-b / (2 * a))) if a < 0 else float(f[i])


NOT_CONVERGED = ("budget_spent", "no_progress")


def last_refined_Hz(steps: list[dict], mode: str) -> float | None:
    """The frequency of the level's latest refinement step of ``mode`` (the highest number
    in its key), or None before the first: the line search's memory (decision 0063), read
    from the stored steps like everything else the refiner decides on."""
    tag = f"-R{mode[0].upper()}"
    refined = [r for r in steps if tag in r["key"]]
    return float(max(refined, key=lambda r: r["key"].split(tag)[1])["freq_Hz"]) if refined else None


def refinement_end(refiner: Refiner, mode: str, d: LevelData, done: int, last_Hz: float | None = None,
                   level_index: int | None = None) -> str | None:
    """Why a level's refinement of ``mode`` is over, from its stored steps ``d`` (sweep and
    ``done`` refinement steps of that mode), or None while it goes on: "converged" (the
    peak known within the tolerance), "no_peak" (none inside the grid), "budget_spent"
    (``refine_steps`` taken, the peak still not known), "no_progress" (the next frequency
    is one measured already)."""
    found = refiner._resonance(mode, d, level_index)
    if found is None:
        return "no_peak"
    f = refiner._next_from(found, d, last_Hz)
    if f is None:
        return "converged"
    if done >= refiner.plan.refine_steps:
        return "budget_spent"
    if np.any(np.isclose(d.f_Hz, float(f"{f:.6g}"), rtol=1e-9, atol=0)):
        return "no_progress"
    return None


def refinement_outcomes(plan: Plan, results: list[dict], pitch_band_Hz: tuple[float, float] | None = None,
                        no_pitch: bool = False) -> dict[tuple[int, str], str]:
    """(level index, mode) -> how each level's refinement of each refined mode ended
    (:func:`refinement_end`; "not finished" for a level whose refinement had not ended when
    the run stopped), from the stored steps alone: what the run decided depends only on
    them (module docstring), so a report knows it without the run's events."""
    if not plan.refine:
        return {}
    refiner = Refiner(plan, lambda: results, pitch_band_Hz, no_pitch=no_pitch)
    out: dict[tuple[int, str], str] = {}
    for li, level_N in enumerate(plan.levels_N):
        steps = [r for r in results if r["level_index"] == li and "-W" not in r["key"]]
        if len(steps) < 3:
            continue
        d = LevelData.from_steps(level_N, steps)
        for mode in refiner.modes:
            done = sum(1 for r in steps if f"-R{mode[0].upper()}" in r["key"])
            out[(li, mode)] = refinement_end(refiner, mode, d, done, last_refined_Hz(steps, mode), li) or "not finished"
    return out
