"""The one place a plan becomes a procedure (issue 31 item 1, decisions 0052 and 0060): the
run and its resume (``bench.session``), the backbone run (``bench.backbone``) and the
Monte-Carlo study (``bench.studies.montecarlo``) all build it here, so a new kind is wired once."""

from __future__ import annotations

from collections.abc import Callable

from .control import controller_for
from .instruments import BlockSource, SineSource
from .kind import ProcedureKind
from .plan import Plan
from .stepped_sine import SteppedSine


def procedure_for(plan: Plan, generator: SineSource, daq: BlockSource, *, amp_gain_N_per_V: float, mass_kg: float,
                  on_event: Callable[..., None] | None = None, on_block: Callable[[dict], None] | None = None,
                  **options) -> SteppedSine:
    """The one loop on these instruments with the controller and schedule of ``plan``'s
    kind: the force's or the response's controller on the plan's grid, or the phase lock
    with its schedule of levels.  ``options``: the loop's (``sensor_check``, ``marker``,
    ``drive_limit_V``, ``on_skip``); ``on_event`` and ``on_block`` are the phase lock's
    (probe, lock lost, not locked; each controller block)."""
    if plan.procedure is ProcedureKind.PHASE_RESONANCE:
        from .phase_resonance import phase_resonance
        controller, schedule = phase_resonance(plan, mass_kg=mass_kg, on_event=on_event, on_block=on_block)
        return SteppedSine(plan, generator, daq, amp_gain_N_per_V=amp_gain_N_per_V, controller=controller,
                           schedule=schedule, **options)
    return SteppedSine(plan, generator, daq, amp_gain_N_per_V=amp_gain_N_per_V,
                       controller=controller_for(plan, mass_kg=mass_kg), **options)
