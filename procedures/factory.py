"""The one place a plan becomes a procedure (issue 31 item 1, decision 0052): the run and
its resume (``bench.session``), the backbone run (``bench.backbone``) and the Monte-Carlo
study (``bench.studies.montecarlo``) all build it here, so a new kind is wired once."""

from __future__ import annotations

from .control import controller_for
from .instruments import BlockSource, SineSource
from .kind import ProcedureKind
from .plan import Plan
from .stepped_sine import SteppedSine


def procedure_for(plan: Plan, generator: SineSource, daq: BlockSource, *, amp_gain_N_per_V: float, mass_kg: float,
                  **options) -> SteppedSine:
    """The procedure of ``plan``'s kind on these instruments: the stepped-sine loop with the
    force's or the response's controller, or the phase-resonance loop.  ``options``: the
    loop's (``sensor_check``, ``marker``, ``drive_limit_V``; ``on_skip`` for the stepped
    sines, ``on_event`` and ``on_block`` for phase resonance)."""
    if plan.procedure is ProcedureKind.PHASE_RESONANCE:
        from .phase_resonance import PhaseResonance
        return PhaseResonance(plan, generator, daq, amp_gain_N_per_V=amp_gain_N_per_V, mass_kg=mass_kg, **options)
    return SteppedSine(plan, generator, daq, amp_gain_N_per_V=amp_gain_N_per_V,
                       controller=controller_for(plan, mass_kg=mass_kg), **options)
