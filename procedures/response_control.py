"""Response-controlled stepped sine (Karaagacli and Ozguven 2020-2021; decisions 0044, 0052).

The stepped sine's loop with :class:`procedures.control.ResponseControl` as its
controller: at each frequency the drive is iterated until the fundamental of the
displacement (or the drive-point acceleration) is at the level, so each level's FRF is
quasi-linear; the force it needed is the measurement.  Levels are response amplitudes
(m or m/s^2, ``Plan.level_quantity``); every drive request and block still passes the
safety supervisor.  Each step's record carries ``response_control`` (quantity, target,
measured, error); ``target_force_N`` is the force the level needed.
"""

from __future__ import annotations

from .control import ResponseControl
from .stepped_sine import SteppedSine


class ResponseControlled(SteppedSine):
    """Runs a plan with ``procedure = "response_controlled"`` (the loop with the response's controller)."""

    def __init__(self, *args, quantity: str, mass_kg: float, **kwargs):
        plan = args[0] if args else kwargs["plan"]
        super().__init__(*args, controller=ResponseControl(quantity, mass_kg, plan.force_tolerance), **kwargs)
