"""What a step's controller does, states and returns (issue 31 item 1, decision 0052).

The stepped-sine loop (:class:`procedures.stepped_sine.SteppedSine`: schedule, ramps,
quarter-phase changes, settling, measurement, supervision, stop, storage and resume)
asks its :class:`Controller` at each point for the first drive, then to bring the
controlled quantity to the step's level, then for the control's fields of the step's
record.  A controller states its quantity (unit, symbol) and tolerance and returns a typed
:class:`Outcome` with a :class:`Reason` code, so the loop's branch on "the level is out of
the drive's reach" reads a code, not a message.

- :class:`ForceControl`: the force fundamental at the level (the stepped sine).
- :class:`ResponseControl`: the displacement's or the drive-point acceleration's
  fundamental at the level (response-controlled stepped sine, decision 0044); the force it
  needed is the measurement and the record carries a ``response_control`` record.

- :class:`procedures.phase_resonance.PhaseLock`: the phase of the response against the
  force (deg), moving the frequency while it holds the level's force (decision 0060), on
  its schedule of levels (:class:`procedures.phase_resonance.LockSchedule`).

The first two iterate the drive with the same secant update (:func:`procedures.stepped_sine.next_drive`)
in :class:`AmplitudeControl`; another controller is a small class (a test adds a
constant-voltage sweep in a few dozen lines).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from enum import StrEnum
from typing import NotRequired, Protocol, TypedDict

from sim.step_result import BackboneRecord, ResponseControlRecord, StepMeasurement

from .analysis import fit_harmonics
from .instruments import Block
from .kind import FORCE, ProcedureKind, Quantity, response_quantity
from .plan import Plan, StepSpec

log = logging.getLogger(__name__)

MAX_FACTOR = 10.0    # one control update changes the drive by at most this factor
FIRST_DRIVE_MARGIN = 0.9   # a sweep starts 10 % below the force its gain estimate predicts
FREE_MASS_SHARE = 0.5      # a response sweep's first drive: half the free mass's force m w^2 X


def next_drive(vpp: float, force: float, target: float, prev: tuple[float, float] | None) -> float:
    """The next drive amplitude (Vpp) of the control (decision 0025), for the force or any
    amplitude that grows with the drive.

    Secant in log-log: force ~ drive^s, s from this and the previous iteration (exact for a
    linear rig, s = 1: the measured force per volt scales the drive; a resonance that moves
    with the amplitude makes s < 1 at a force drop-out).  Without a previous iteration, with
    drives within 5 % of each other (what the settling left in the force dominates) or a
    force that did not grow with the drive, s = 1; otherwise s is kept within 0.25-2.  The
    update is bounded to a factor MAX_FACTOR either way."""
    s = 1.0
    if prev is not None:
        v0, f0 = prev
        if abs(math.log(vpp / v0)) > 0.05 and f0 > 0:
            slope = math.log(force / f0) / math.log(vpp / v0)
            if slope > 0:
                s = min(max(slope, 0.25), 2.0)
    nxt = vpp * (target / force) ** (1.0 / s)
    return min(max(nxt, vpp / MAX_FACTOR), vpp * MAX_FACTOR)


class DriveNow(Protocol):
    freq_Hz: float
    amplitude_Vpp: float
    gain_N_per_Vpp: float


class Loop(Protocol):
    """The loop's primitives a controller uses (:class:`procedures.stepped_sine.SteppedSine`)."""

    plan: Plan
    gain_at: dict[float, float]
    history: list[tuple[float, float]]
    max_vpp: float
    periods: float          # drive periods since the point started


    @property
    def drive(self) -> DriveNow: ...

    def _wait(self, freq_Hz: float, seconds: float, min_periods: int = 0) -> None: ...
    def _acquire(self, freq_Hz: float, periods: int) -> Block: ...
    def _change(self, *, vpp: float | None = None, freq_Hz: float | None = None) -> None: ...
    def glide(self, freq_Hz: float) -> None: ...
    def force_first_vpp(self, step: StepSpec, new_sweep: bool = False) -> float: ...


class ControlFields(TypedDict):
    """The control's fields of a step's record (:class:`sim.step_result.StepResult`)."""

    target_force_N: float
    force_error: float
    force_converged: bool
    response_control: NotRequired[ResponseControlRecord]
    backbone: NotRequired[BackboneRecord]


class Reason(StrEnum):
    """Why a control ended."""

    WITHIN = "within"                   # the quantity within the tolerance of the level
    NOT_CONVERGED = "not_converged"     # the iterations ran out
    UNREACHABLE = "unreachable"         # still short with the drive at its limit (plan: infeasible)
    NO_SIGNAL = "no_signal"             # nothing measured to control on
    LOCKED = "locked"                   # phase resonance: the phase and the response settled in their bands
    LOCK_LOST = "lock_lost"             # the phase error above lost_phase_deg and growing
    WINDOW_LEFT = "window_left"         # the frequency would leave the plan's window
    COLLAPSE = "collapse"               # the response fell below a share of its largest

    @property
    def lost(self) -> bool:
        """The point is lost: the loop ramps down at once and records the control's last block."""
        return self in (Reason.LOCK_LOST, Reason.WINDOW_LEFT, Reason.COLLAPSE)


@dataclass(frozen=True)
class Outcome:
    """A control's end: the error of the controlled quantity (relative; the phase's in
    deg), the iterations it took, why it ended and, unless within, the words for a person;
    ``freq_Hz``, the frequency it ended at when the control moves it (phase resonance)."""

    error: float
    iterations: int
    reason: Reason
    message: str = ""
    freq_Hz: float | None = None

    @property
    def ok(self) -> bool:
        return self.reason in (Reason.WITHIN, Reason.LOCKED)


class Controller(Protocol):
    """What the stepped-sine loop asks of a controller (the level is ``step.force_N``, in
    the controller's quantity's unit)."""

    quantity: Quantity

    def first_vpp(self, proc: Loop, step: StepSpec, new_sweep: bool) -> float:
        """The step's first drive (Vpp), within ``proc.max_vpp``."""
        ...

    def control(self, proc: Loop, step: StepSpec) -> Outcome:
        """Bring the quantity to the level with the output on (through ``proc``'s primitives)."""
        ...

    def fields(self, step: StepSpec, measured: StepMeasurement, outcome: Outcome) -> ControlFields:
        """The record's control fields: ``target_force_N``, ``force_error``,
        ``force_converged`` and any record of the controller's own."""
        ...


class AmplitudeControl:
    """Iterate the drive until one fundamental amplitude of a control block is within the
    plan's ``force_tolerance`` of the level (secant in log-log, decision 0025)."""

    quantity: Quantity = FORCE

    def amplitude(self, block: Block, freq_Hz: float) -> float:
        raise NotImplementedError

    def observe(self, proc: Loop, vpp: float, value: float) -> None:
        """What an iteration teaches beyond the force per volt (the loop learns that)."""

    def control(self, proc: Loop, step: StepSpec) -> Outcome:
        f, target, q = step.freq_Hz, step.force_N, self.quantity
        err, it = math.inf, 0
        prev: tuple[float, float] | None = None
        proc.history = []
        for it in range(1, proc.plan.max_iterations + 1):
            proc._wait(f, 0.0, min_periods=proc.plan.control_cycles)      # let the change settle
            block = proc._acquire(f, proc.plan.control_cycles)
            value = self.amplitude(block, f)
            F1 = value if q == FORCE else float(fit_harmonics(block.force_N, block.fs_Hz, f, 1).amplitude[0])
            vpp = proc.drive.amplitude_Vpp
            err = value / target - 1.0
            proc.history.append((vpp, F1))
            log.debug("step %s iteration %d: %.5g Vpp -> %s %.5g %s (error %+.2f %%), %.4g N", step.key, it, vpp,
                      q.name, value, q.unit, 100 * err, F1)
            if value > 0:
                self.observe(proc, vpp, value)
            if F1 > 0:
                proc.drive.gain_N_per_Vpp = proc.gain_at[f] = F1 / vpp
            if abs(err) <= proc.plan.force_tolerance:
                return Outcome(err, it, Reason.WITHIN)
            if value <= 0 or not math.isfinite(value):
                return Outcome(err, it, Reason.NO_SIGNAL, f"no {q.name} measured at {vpp:.4g} Vpp")
            nxt = next_drive(vpp, value, target, prev)
            if nxt > proc.max_vpp:
                if vpp >= proc.max_vpp * (1 - 1e-6):
                    return Outcome(err, it, Reason.UNREACHABLE, self.unreachable(proc, step, vpp, value))
                nxt = proc.max_vpp
            prev = (vpp, value)
            proc._change(vpp=nxt)
        return Outcome(err, it, Reason.NOT_CONVERGED,
                       f"{q.name} {q.format(target, '.3g')} not reached within {100 * proc.plan.force_tolerance:.1f} % "
                       f"after {it} iterations (error {100 * err:+.1f} %)")

    def unreachable(self, proc: Loop, step: StepSpec, vpp: float, value: float) -> str:
        return (f"{self.quantity.name} {self.quantity.format(step.force_N)} unreachable at {step.freq_Hz:g} Hz within "
                f"the drive limit {proc.max_vpp / 2:.4g} V: {self.quantity.format(value, '.4g')} at the limit")


class ForceControl(AmplitudeControl):
    """The force fundamental at the level (N): the stepped sine's control."""

    quantity = FORCE

    def amplitude(self, block: Block, freq_Hz: float) -> float:
        return float(fit_harmonics(block.force_N, block.fs_Hz, freq_Hz, 1).amplitude[0])

    def first_vpp(self, proc: Loop, step: StepSpec, new_sweep: bool) -> float:
        return proc.force_first_vpp(step, new_sweep)

    def unreachable(self, proc: Loop, step: StepSpec, vpp: float, value: float) -> str:
        return (f"force {step.force_N:g} N unreachable at {step.freq_Hz:g} Hz within the drive limit "
                f"{proc.max_vpp / 2:.4g} V: {value:.4g} N at the limit ({value / vpp:.4g} N/Vpp)")

    def fields(self, step: StepSpec, measured: StepMeasurement, outcome: Outcome) -> ControlFields:
        return ControlFields(target_force_N=step.force_N, force_converged=outcome.ok,
                             force_error=measured["force_N"] / step.force_N - 1.0)


class ResponseControl(AmplitudeControl):
    """The response's fundamental at the level: the displacement (m) or the drive-point
    acceleration (m/s^2).  The force the level needed is the measurement: the record's
    ``target_force_N`` is that force, its ``response_control`` the quantity, target,
    measured and error, and ``force_converged`` says whether the response was within."""

    def __init__(self, quantity: str, mass_kg: float, tolerance: float):
        self.quantity = response_quantity(quantity)
        self.mass_kg, self.tolerance = mass_kg, tolerance
        self.response_per_vpp = 0.0             # the latest response amplitude per Vpp

    def amplitude(self, block: Block, freq_Hz: float) -> float:
        x = block.disp_m if self.quantity.key == "disp" else block.accel_m_s2
        return float(fit_harmonics(x, block.fs_Hz, freq_Hz, 1).amplitude[0])

    def observe(self, proc: Loop, vpp: float, value: float) -> None:
        self.response_per_vpp = value / vpp

    def _displacement(self, level: float, freq_Hz: float) -> float:
        w = 2 * math.pi * freq_Hz
        return level if self.quantity.key == "disp" else level / (w * w)

    def first_vpp(self, proc: Loop, step: StepSpec, new_sweep: bool) -> float:
        """Inside a sweep: the level over the response per volt of the step before, 10 %
        low; a new sweep: half the free mass's force for the level, through the force per
        volt measured so far (the mode's spring only lowers the force needed below it)."""
        if not new_sweep and self.response_per_vpp > 0:
            return min(FIRST_DRIVE_MARGIN * step.force_N / self.response_per_vpp, proc.max_vpp)
        w = 2 * math.pi * step.freq_Hz
        force = FREE_MASS_SHARE * self.mass_kg * w * w * self._displacement(step.force_N, step.freq_Hz)
        return min(force / proc.drive.gain_N_per_Vpp, proc.max_vpp)

    def fields(self, step: StepSpec, measured: StepMeasurement, outcome: Outcome) -> ControlFields:
        fit = measured["disp"] if self.quantity.key == "disp" else measured["accel"]
        got = float(fit["amplitude"][0])
        err = got / step.force_N - 1.0
        return ControlFields(target_force_N=measured["force_N"], force_error=0.0,
                             force_converged=abs(err) <= self.tolerance,
                             response_control=ResponseControlRecord(quantity=self.quantity.key, target=step.force_N,
                                                                    measured=got, error=err))


def controller_for(plan: Plan, *, mass_kg: float) -> Controller:
    """The controller a stepped-sine plan's kind asks for (phase resonance's, with its
    schedule: :func:`procedures.phase_resonance.phase_resonance`)."""
    if plan.procedure is ProcedureKind.RESPONSE_CONTROLLED:
        return ResponseControl(plan.response, mass_kg, plan.force_tolerance)
    return ForceControl()
