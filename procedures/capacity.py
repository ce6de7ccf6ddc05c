"""What the rig's instruments can do, against every plan value a procedure turns into a
block (decision record 0050).

A procedure asks the DAQ for blocks of whole periods (:func:`drivers.plan_block`: the
smallest whole number of samples per period that reaches ``min_sample_rate_Hz``); the DAQ
records at most :data:`drivers.MAX_BLOCK_SAMPLES` samples a block (436900: three channels in
at most 65535 CAN frames of 20 values; not the 2^24-1 its configuration field would hold),
at most :data:`drivers.MAX_SAMPLE_RATE_HZ` samples a second.  :func:`block_problems` names, before anything is
switched on, each plan value whose block would not fit, with its key, its unit and the
largest value that fits; the procedures take their block lengths from the same functions
(:func:`measure_periods`, :func:`controller_block_periods`), so the check and the run
cannot disagree.

The frequencies a block can be taken at: every frequency of a stepped-sine grid; any
frequency between the grid's ends for a refinement or dwell step (chosen online,
decision 0043); any in the phase-resonance window (decision 0044).  Over such a range the
largest block is found exactly, interval by interval of the samples per period.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

from drivers import MAX_BLOCK_SAMPLES, MAX_SAMPLE_RATE_HZ

from .plan import Plan

log = logging.getLogger(__name__)


def measure_periods(plan: Plan, freq_Hz: float, dwell_cycles: int = 0) -> int:
    """Periods of a step's measured block: ``measure_cycles``, ``min_measure_s`` and, for a
    dwell step, ``dwell_cycles``, whichever is longest."""
    return max(plan.measure_cycles, math.ceil(plan.min_measure_s * freq_Hz), dwell_cycles)


def controller_block_periods(block_periods: int) -> int:
    """Longest block of the phase-resonance loop: after a change it waits up to 5 x
    ``block_periods`` for the transient, then ``block_periods`` are estimated from."""
    return 6 * block_periods


def samples_per_period(freq_Hz: float, min_rate_Hz: float) -> int:
    """As :func:`drivers.plan_block` chooses them."""
    return max(2, math.ceil(min_rate_Hz / freq_Hz - 1e-9))


@dataclass(frozen=True)
class Where:
    """The frequencies blocks are taken at: a grid's (exact) or a range's (any between)."""

    freqs_Hz: tuple[float, ...]
    lo_Hz: float = 0.0
    hi_Hz: float = 0.0
    what: str = ""            # "a refinement step", "the phase-resonance window", ...

    def points(self, min_rate_Hz: float) -> list[float]:
        """The frequencies where a block's samples per period or periods can be largest:
        the grid's, or for a range each interval of constant samples per period at its
        upper end (periods grow with frequency) and the range's lower end."""
        if not self.what:
            return list(self.freqs_Hz)
        a, b = self.lo_Hz, self.hi_Hz
        k_lo, k_hi = samples_per_period(b, min_rate_Hz), samples_per_period(a, min_rate_Hz)
        out = [a, b]
        for k in range(max(k_lo, 3), k_hi + 1):     # spp = k on [R/k, R/(k-1)): its upper end, just below
            top = min_rate_Hz / (k - 1) * (1 - 1e-6)  # (an online frequency has 6 significant digits)
            if a <= top <= b:
                out.append(top)
        return out

    def text(self, f: float) -> str:
        return f"{f:.6g} Hz" + (f" ({self.what} can be anywhere in {self.lo_Hz:g}-{self.hi_Hz:g} Hz)"
                                if self.what else "")


def _where(plan: Plan) -> list[Where]:
    """Where each kind of block of ``plan`` is taken (see the module's text)."""
    if plan.backbone is not None:
        bb = plan.backbone.resolved()
        return [Where((), bb.min_Hz, bb.max_Hz, "the phase-resonance loop")]
    out = [Where(tuple(plan.freqs_Hz))]
    if plan.refine:
        out.append(Where((), min(plan.freqs_Hz), max(plan.freqs_Hz), "a refinement or dwell step"))
    return out


def _fastest(wheres: list[Where], rate: float) -> tuple[float, float, Where]:
    """(the fastest sample rate plan_block chooses with ``min_sample_rate_Hz`` = ``rate``, its
    frequency, where)."""
    return max(((samples_per_period(f, rate) * f, f, w) for w in wheres for f in w.points(rate)),
               key=lambda x: x[:2])


def _largest_block(points: list[float], rate: float, periods) -> tuple[int, float]:
    """(largest block in samples, its frequency) with ``periods(f)`` periods at each point."""
    return max((samples_per_period(f, rate) * periods(f), f) for f in points)


def block_problems(plan: Plan, source: str) -> list[str]:
    """Each plan value whose block, sample rate or step count the instruments cannot take,
    one line each: the key, its unit, the block it makes and the largest value that fits."""
    rate = plan.min_sample_rate_Hz
    out: list[str] = []
    cap = MAX_BLOCK_SAMPLES
    cap_text = f"the DAQ's largest block is {cap} samples"

    def at(f: float) -> str:
        return f"{samples_per_period(f, rate)} samples a period at min_sample_rate_Hz = {rate:g}"

    wheres = _where(plan)
    points = [(w, f) for w in wheres for f in w.points(rate)]
    # the sample rate plan_block chooses: spp x f, at most the DAQ's
    worst_rate, f_rate, w_rate = _fastest(wheres, rate)
    if worst_rate > MAX_SAMPLE_RATE_HZ:
        fits = math.floor(rate)
        while fits > 1000 and _fastest(wheres, fits)[0] > MAX_SAMPLE_RATE_HZ:
            fits = math.floor(min(fits - 1, fits * MAX_SAMPLE_RATE_HZ / _fastest(wheres, fits)[0]))
        out.append(f"{source}: [plan.control] min_sample_rate_Hz: {rate:g} S/s makes {worst_rate:.6g} S/s at "
                   f"{w_rate.text(f_rate)} (whole samples a period), above the DAQ's {MAX_SAMPLE_RATE_HZ:g} S/s; "
                   f"the largest that fits: {fits} S/s")
        return out                        # block lengths mean little at a rate the DAQ refuses
    f_low = min(f for _, f in points)
    spp_max = samples_per_period(f_low, rate)

    def cycles(table: str, key: str, value: int, factor: int = 1, what: str = "", online: bool = False) -> None:
        """An integer count of periods (``factor`` x ``value`` of them in one block);
        ``online``: taken only at a frequency chosen online (a range's)."""
        need = spp_max * factor * value
        if need > cap:
            w = [w for w, f in points if f == f_low][-1 if online else 0]
            out.append(f"{source}: [{table}] {key}: {value} cycles{what} at {w.text(f_low)} make a block of "
                       f"{need} samples ({at(f_low)}); {cap_text}; the largest that fits: {cap // (spp_max * factor)} cycles")

    if plan.backbone is not None:
        cycles("plan.backbone", "block_periods", plan.backbone.block_periods,
               controller_block_periods(1), " (x 6: a block after a change waits up to 5 x block_periods)")
    cycles("plan.control", "measure_cycles", plan.measure_cycles)
    cycles("plan.control", "control_cycles", plan.control_cycles)
    if plan.dwell_cycles:
        cycles("plan.resonance", "dwell_cycles", plan.dwell_cycles, online=True)
    if plan.min_measure_s > 0:
        need, f_big = _largest_block([f for _, f in points], rate, lambda f: math.ceil(plan.min_measure_s * f))
        if need > cap:
            w = next(w for w, g in points if g == f_big)
            fits_s = min(cap // samples_per_period(g, rate) / g for _, g in points)
            out.append(f"{source}: [plan.control] min_measure_s: {plan.min_measure_s:g} s at {w.text(f_big)} makes a "
                       f"block of {need} samples ({at(f_big)}); {cap_text}; the largest that fits: "
                       f"{math.floor(fits_s * 1000) / 1000:g} s")
    return out


def step_count_problems(plan: Plan, source: str, max_steps: int) -> list[str]:
    """A refined plan's steps at most (its grid, ``max_steps`` refinement steps per mode and
    level, one dwell each) against ``max_steps`` the bench runs in one plan; its step keys
    number the levels in two digits."""
    if not plan.refine:
        return []
    out = []
    grid = len(plan.schedule())
    per = len(plan.refine_modes) * len(plan.levels_N)
    total = grid + per * (plan.refine_steps + (1 if plan.dwell_cycles else 0))
    if total > max_steps:
        fits = (max_steps - grid) // per - (1 if plan.dwell_cycles else 0)
        out.append(f"{source}: [plan.resonance] max_steps: {plan.refine_steps} steps per mode and level make "
                   f"{total} steps with the grid's {grid}; at most {max_steps} steps a plan: "
                   + (f"the largest that fits: {fits} steps per mode and level" if fits >= 1 else
                      "split the test into several plans"))
    if len(plan.levels_N) > 100:
        out.append(f"{source}: [plan] levels: {len(plan.levels_N)} levels; a refined plan (refine = true) has at most "
                   f"100 (its refinement steps' keys number the levels in two digits)")
    return out
