"""What `bench dry-run` promises about a stepped-sine plan (decision record 0056): the
steps it will run, listed (``--steps``), and an upper bound on the rig time that holds.

The bound counts, for every step, what procedures.stepped_sine may at most do: each
force-control iteration (``max_iterations`` of them) a wait and a block of
``control_cycles`` plus a quarter-phase alignment (at most one period); the settle and
the measured block (a dwell's ``dwell_cycles``); ``max_extra_settle_blocks`` more blocks,
each after a wait of at most max(settle, MAX_SETTLE_WAIT_S); from rest (a new sweep, a
refinement or dwell step) the ramp down of what ran before and the ramp up, each at most
max(40 periods, ramp_s) of one-period steps plus one alignment each.  A step whose
frequency is chosen online (adaptive, refinement, dwell) is counted at the lowest
frequency it may have (the grid's lowest for refinement and dwell steps, the sweep's for
adaptive ones): a block of whole periods lasts longest there.  It leaves out what is not
rig time (sensor checks, resent blocks).  ``planned_steps`` (bench.session) remains the
typical figure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import Any

from procedures.plan import Plan
from procedures.stepped_sine import MAX_SETTLE_WAIT_S

from .words.terminal_config import planned_step

REST_S = 0.1               # the session's reference block at rest, output off (10 periods at 100 Hz)


def _ramp_s(plan: Plan, f: float) -> float:
    steps = max(40, math.ceil(plan.ramp_s * f))
    return (1 + 2 * steps) / f          # the first block at rest, then one change (+ alignment) and one period each


def step_seconds_max(plan: Plan, f: float, *, from_rest: bool, dwell_cycles: int = 0,
                     f_before: float | None = None, extra_settle: bool = True) -> float:
    """The longest rig time one step at ``f`` may take (module docstring); ``f_before``:
    the frequency of the ramp down before it (default ``f``); without ``extra_settle``, a
    step that needs no extra settle block."""
    t = plan.max_iterations * (2 * plan.control_cycles + 1) / f
    settle = max(plan.settle_cycles, math.ceil(plan.min_settle_s * f))
    block = max(plan.measure_cycles, math.ceil(plan.min_measure_s * f), dwell_cycles)
    t += (settle + block) / f
    if extra_settle:
        t += plan.max_extra_settle_blocks * extra_block_seconds_max(plan, f, dwell_cycles)
    if from_rest:
        t += _ramp_s(plan, f) + _ramp_s(plan, f_before or f)
    return t + 1 / f                     # the alignment of the first change


def extra_block_seconds_max(plan: Plan, f: float, dwell_cycles: int = 0) -> float:
    """The longest rig time one extra settle block at ``f`` takes: the wait the check may
    ask for (at most max(settle, MAX_SETTLE_WAIT_S)) and the block again."""
    settle = max(plan.settle_cycles, math.ceil(plan.min_settle_s * f))
    block = max(plan.measure_cycles, math.ceil(plan.min_measure_s * f), dwell_cycles)
    return (max(settle, math.ceil(MAX_SETTLE_WAIT_S * f)) + block) / f


class Online(StrEnum):
    """What chooses a planned step's frequency online (its words, with the step's ``detail``:
    bench.words.terminal_config.PLANNED_STEP)."""

    ADAPTIVE = "adaptive"       # chosen (per sweep), of (the sweep's frequencies), low_Hz, high_Hz
    REFINED = "refined"         # mode, steps (at most), tolerance
    DWELL = "dwell"             # mode, cycles


@dataclass(frozen=True)
class PlannedStep:
    """One line of ``bench dry-run --steps``: the key (a pattern for steps chosen online),
    the level, the frequency (NaN: chosen online), what chooses it and its fields."""

    key: str
    level_N: float
    freq_Hz: float
    count: int = 1                       # steps this line stands for (at most)
    online: Online | str = ""            # what chooses it online ("": the plan)
    detail: Mapping[str, Any] = field(default_factory=dict)

    def line(self) -> str:
        return planned_step(self.key, self.level_N, self.freq_Hz, self.online, self.detail)


def planned_step_list(plan: Plan) -> list[PlannedStep]:
    """The steps of a stepped-sine plan in the order they run: the grid's steps (an
    adaptive sweep as one line per sweep: how many of which frequencies, chosen online),
    after each level's last sweep its refinement steps per mode (at most ``refine_steps``)
    and dwell steps."""
    out: list[PlannedStep] = []
    steps = plan.schedule()
    levels = sorted({s.level_index for s in steps})
    for li in levels:
        mine = [s for s in steps if s.level_index == li]
        for d in dict.fromkeys(s.direction for s in mine):
            sw = [s for s in mine if s.direction == d]
            if plan.adaptive_per_sweep and plan.adaptive_per_sweep < len(sw):
                out.append(PlannedStep(f"{sw[0].key[:9]}F***-{d}", sw[0].force_N, math.nan, plan.adaptive_per_sweep,
                                       Online.ADAPTIVE, {"chosen": plan.adaptive_per_sweep, "of": len(sw),
                                                         "low_Hz": min(s.freq_Hz for s in sw),
                                                         "high_Hz": max(s.freq_Hz for s in sw)}))
            else:
                out += [PlannedStep(s.key, s.force_N, s.freq_Hz) for s in sw]
        if plan.refine and mine:
            last = mine[-1]
            for mode in plan.refine_modes:
                out.append(PlannedStep(f"{last.index:05d}-L{li:02d}-R{mode[0].upper()}***-{last.direction}",
                                       last.force_N, math.nan, plan.refine_steps, Online.REFINED,
                                       {"mode": mode, "steps": plan.refine_steps, "tolerance": plan.refine_tolerance}))
            if plan.dwell_cycles:
                for mode in plan.refine_modes:
                    out.append(PlannedStep(f"{last.index:05d}-L{li:02d}-W{mode[0].upper()}000-{last.direction}",
                                           last.force_N, math.nan, 1, Online.DWELL,
                                           {"mode": mode, "cycles": plan.dwell_cycles}))
    return out


def rig_time_bound_s(plan: Plan, *, extra_settle: bool = True) -> float:
    """An upper bound on a stepped-sine plan's rig time (module docstring); without
    ``extra_settle``, the bound for a run in which no step needs an extra settle block
    (the steps' ``settle_extra_blocks`` say whether one did)."""
    f_lo = min(plan.freqs_Hz)
    t, f_prev, sweep_prev = REST_S, None, None
    for p in planned_step_list(plan):
        sweep = (p.key[6:9], p.key.rsplit("-", 1)[1])     # (level, direction) of the key
        online = not math.isfinite(p.freq_Hz)
        f = f_lo if online else p.freq_Hz
        from_rest = online or sweep != sweep_prev or p.count > 1
        dwell = plan.dwell_cycles if p.online == Online.DWELL else 0
        t += p.count * step_seconds_max(plan, f, from_rest=from_rest, dwell_cycles=dwell,
                                        f_before=f_lo if online or f_prev is None else f_prev,
                                        extra_settle=extra_settle)
        f_prev, sweep_prev = (f_lo if online else f), (None if online else sweep)
    return t + _ramp_s(plan, f_prev or f_lo)       # the last ramp down


def backbone_time_bound_s(plan: Plan) -> float:
    """An upper bound on a phase-resonance plan's rig time (decision record 0063): each
    point (one per level) from rest, as if every level probed its phase slope again (a lost
    lock does) and spent ``max_blocks`` controller blocks, each after the longest wait the
    loop allows (5 x ``block_periods``) and an alignment of a drive change, then settled,
    measured and given its extra settle blocks; every period at the lowest frequency it may
    have (the window's, less the probe's step below it)."""
    bb = plan.backbone
    assert bb is not None                                   # a phase-resonance plan
    bb = bb.resolved()
    f_lo = bb.min_Hz * (1 - bb.probe_step)
    probe = 3 * 2 * bb.block_periods / f_lo                 # three probe points: a wait and a block each
    blocks = bb.max_blocks * (6 * bb.block_periods + 1) / f_lo
    frame = step_seconds_max(replace(plan, max_iterations=0), f_lo, from_rest=True)
    return REST_S + len(plan.schedule()) * (probe + blocks + frame)
