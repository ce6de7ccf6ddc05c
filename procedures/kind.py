"""What a procedure is and what it controls, typed from the plan to every output (decision 0052).

A plan's ``procedure`` is a :class:`ProcedureKind`; its levels are amplitudes of one
:class:`Quantity` (``Plan.level_quantity``: force for a stepped sine and phase resonance,
the response for a response-controlled stepped sine), and its controller holds one
quantity at each point (``Plan.controlled``: the force, the response, or the phase).
Everything that prints a level asks the quantity for its name, unit and format, so a
response level never carries "N".
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


class ProcedureKind(StrEnum):
    """The procedures a plan can run (``[plan] procedure``); the value is the plan file's word
    and what run.json stores (a ``str``: older run.json files read unchanged; f-strings print it)."""

    STEPPED_SINE = "stepped_sine"
    RESPONSE_CONTROLLED = "response_controlled"
    PHASE_RESONANCE = "phase_resonance"

    @property
    def label(self) -> str:
        """The procedure's name in a sentence or a report title."""
        return {"stepped_sine": "stepped sine", "response_controlled": "response-controlled stepped sine",
                "phase_resonance": "phase resonance"}[self.value]

    @classmethod
    def of(cls, value: object) -> ProcedureKind:
        """The kind a stored plan names; a plan stored before the field existed is a stepped sine."""
        return cls(str(value or cls.STEPPED_SINE.value))


@dataclass(frozen=True)
class Quantity:
    """A quantity a controller holds or a level is given in: its key (the plan's word),
    its name in a sentence, its SI unit and its symbol (the fundamental's amplitude)."""

    key: str
    name: str
    unit: str
    symbol: str

    def format(self, value: float, fmt: str = "g") -> str:
        """'0.9 mm' is never written: the value in the quantity's SI unit, with it ('9e-04 m')."""
        return f"{value:{fmt}} {self.unit}"

    @property
    def heading(self) -> str:
        """A table column: 'level (m)'."""
        return f"level ({self.unit})"


FORCE = Quantity("force", "force", "N", "F1")
DISP = Quantity("disp", "displacement", "m", "X1")
ACCEL = Quantity("accel", "acceleration", "m/s^2", "A1")
PHASE = Quantity("phase", "phase", "deg", "phi")
QUANTITIES = {q.key: q for q in (FORCE, DISP, ACCEL, PHASE)}


def response_quantity(response: str) -> Quantity:
    """A response's quantity from the plan's word ("disp" or "accel")."""
    if response not in ("disp", "accel"):
        raise ValueError(f"response must be 'disp' or 'accel', got {response!r}")
    return QUANTITIES[response]


def level_quantity(kind: ProcedureKind, response: str = "") -> Quantity:
    """What the plan's levels are amplitudes of."""
    return response_quantity(response) if kind is ProcedureKind.RESPONSE_CONTROLLED else FORCE


def controlled_quantity(kind: ProcedureKind, response: str = "") -> Quantity:
    """What the procedure's controller holds at each point: the force (stepped sine), the
    response (response control), the phase of the response against the force (phase
    resonance, whose levels are forces held by the drive)."""
    if kind is ProcedureKind.PHASE_RESONANCE:
        return PHASE
    return level_quantity(kind, response)


def describe(kind: ProcedureKind, response: str = "") -> dict[str, str]:
    """What run.json records of the procedure (``meta["procedure"]``)."""
    lq, cq = level_quantity(kind, response), controlled_quantity(kind, response)
    return {"kind": kind.value, "level_quantity": lq.key, "level_unit": lq.unit,
            "controlled_quantity": cq.key, "controlled_unit": cq.unit}


def of_stored_plan(plan: dict) -> tuple[ProcedureKind, Quantity]:
    """(kind, level quantity) of a plan stored in run.json, old or new; an unknown word
    reads as a stepped sine (the stored plan's validator names it elsewhere)."""
    try:
        kind = ProcedureKind.of(plan.get("procedure"))
    except ValueError:
        kind = ProcedureKind.STEPPED_SINE
    response = plan.get("response") or ""
    if kind is ProcedureKind.RESPONSE_CONTROLLED and response not in ("disp", "accel"):
        response = "disp"
    return kind, level_quantity(kind, response)
