"""The stepped-sine test: for each force level and frequency, control the force
amplitude, settle, measure one block of whole periods, extract harmonics, record.

Instruments come through the safety supervisor (:mod:`procedures.safety`), so every
drive request and every block is checked against the limits.  Completed steps are
skipped (resume); each finished step is handed to ``record`` at once.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from drivers import plan_block
from sim.artefacts import HARMONIC_GUARD, Rejection, StepQuality, assess_step, sentences, si
from sim.step_record import BlockRecord, measure_block
from sim.step_result import ControlIteration, StepMeasurement, StepResult

from .capacity import measure_periods
from .control import FIRST_DRIVE_MARGIN, Controller, ForceControl, Outcome, Reason, next_drive
from .instruments import Block, BlockSource, SineSource, StepMarker
from .kind import Quantity
from .plan import Plan, StepSpec
from .safety import LimitExceeded

__all__ = ["FIRST_DRIVE_MARGIN", "MIN_VPP", "DriveState", "ForceUnreachable", "Schedule", "SteppedSine", "StepResult",
           "Unsettled", "next_drive", "unsettled"]

Record = Callable[[StepSpec, StepResult, dict[str, np.ndarray]], None]

log = logging.getLogger(__name__)

MIN_VPP = 2e-3       # the generator's smallest amplitude into a high-impedance load


class ForceUnreachable(LimitExceeded):
    """A step's level cannot be reached within the drive limit (plan: infeasible = "refuse");
    the output has been ramped down and switched off."""


SETTLE_KINDS = ("unsettled_transient", "offset_drift")   # what settling longer cures
MAX_SETTLE_WAIT_S = 2.0      # the longest extra wait one re-settle takes on the check's advice


@dataclass(frozen=True)
class Unsettled:
    """What :func:`unsettled` found: whether settling longer may cure something
    (``found``, the decision), the check's words of it (``why``), the drive cycles its
    transients still need (0 when it gives none) and the frequencies of the vibrations in
    the block (to know them again in the next block of the step)."""

    why: str = ""
    cycles: int = 0
    vibrations_Hz: tuple[float, ...] = ()
    found: bool = False


def unsettled(block: Block, freq_Hz: float, ringing_at: tuple[float, ...] = ()) -> Unsettled:
    """What the offline step-quality check (:func:`sim.artefacts.assess_step`, the one the
    report and ``bench analyze`` apply to the stored records) would find in ``block`` that
    settling longer cures: an unsettled transient or free vibration, an offset drift, or a
    record not periodic enough (the carriage still moving between the halves), in its own
    words (channel, size, decay).  Clipping, drop-outs and lines are left to the offline
    check: waiting does not remove them, with one exception the procedure can see and one
    record cannot: a "line" at the frequency of a vibration an earlier block of the same
    step showed (``ringing_at``) is that vibration, now too weak for the record alone to
    show it decay or to see it on the accelerometer (decision 0033), so still unsettled."""
    try:
        q = assess_step(block.force_N, block.accel_m_s2, block.disp_m, block.fs_Hz, freq_Hz).quality
    except ValueError:
        return Unsettled()  # too short to assess: the offline check says so; waiting does not change it
    return unsettled_in(q, block.fs_Hz, block.n_samples, ringing_at)


def unsettled_in(q: StepQuality, fs_Hz: float, n_samples: int, ringing_at: tuple[float, ...] = ()) -> Unsettled:
    """:func:`unsettled` from the block's quality already assessed (``n_samples`` long at ``fs_Hz``)."""
    guard = HARMONIC_GUARD * fs_Hz / max(n_samples, 1)
    arts = [a for a in q.artefacts if a.kind in SETTLE_KINDS]
    still = [a for a in q.artefacts if a.kind == "line_interference"
             and any(abs(a.freq_Hz - fr) <= guard for fr in ringing_at)]
    if q.status == "rejected":
        if q.rejected_by is not Rejection.NOT_PERIODIC:
            return Unsettled()
        words = [q.reason]         # it names the transient it saw, if any
    else:
        words = [a.describe() for a in arts]
    words += [sentences.still_ringing(a) for a in still]
    freqs = tuple(a.freq_Hz for a in arts + still if math.isfinite(a.freq_Hz))
    return Unsettled("; ".join(words), max((a.settle_cycles for a in arts), default=0), freqs, bool(words))


@dataclass
class DriveState:
    freq_Hz: float = 0.0
    amplitude_Vpp: float = 0.0
    on: bool = False
    gain_N_per_Vpp: float = 0.0       # latest measured force amplitude per Vpp
    phase_rad: float | None = None    # drive phase now (from the last force fit)
    next_quarter: int = 1             # changes alternate between phase pi/2 and 3 pi/2


class Schedule:
    """How the loop walks a plan's points for its controller (this one: the stepped sine's).
    Each point is at the plan's frequency, a new sweep starts from rest (ramp down, output
    off, sensor check, ramp up) and the adaptive choice and the refinement may pick points.
    A controller that moves the frequency (phase resonance) has a schedule of its own:
    :class:`procedures.phase_resonance.LockSchedule`."""

    fixed_frequencies = True      # False: the controller finds each point's frequency (no choose, no refine)
    restart_sweeps = True         # False: a new sweep (level) goes on from the drive as it is

    def start_Hz(self, proc: SteppedSine, step: StepSpec) -> float:
        """The frequency a point's drive starts at."""
        return step.freq_Hz

    def preload(self, results: list) -> None:
        """What a resumed run's stored points tell the schedule."""

    def after(self, step: StepSpec, result: StepResult) -> None:
        """A point recorded."""

    def describe(self, quantity: Quantity, step: StepSpec, res: StepResult | None) -> str:
        """The progress line's words for a point (None: skipped)."""
        return (f"{quantity.format(step.force_N)} {step.freq_Hz:7.1f} Hz {step.direction:4s} "
                + (f"err {100 * _control_error(res):+.1f}% THD(x) {100 * res['disp']['thd']:.1f}%"
                   if res else f"skipped: {quantity.name} unreachable"))


class SteppedSine:
    """Runs a :class:`~bench.config.Plan` on supervised instruments: the one loop over its
    points (level, frequency) with a :class:`procedures.control.Controller` that brings the
    controlled quantity to each level (default: the force) and a :class:`Schedule` that
    says where each point starts (default: the plan's frequencies)."""

    def __init__(self, plan: Plan, generator: SineSource, daq: BlockSource, *, amp_gain_N_per_V: float,
                 sensor_check: Callable[[], object] | None = None, marker: StepMarker | None = None,
                 drive_limit_V: float = math.inf, on_skip: Callable[[StepSpec, str], None] | None = None,
                 controller: Controller | None = None, schedule: Schedule | None = None):
        self.plan = plan
        self.controller: Controller = controller or ForceControl()
        self.schedule = schedule or Schedule()
        self.gen = generator
        self.daq = daq
        self.sensor_check = sensor_check          # gap in range? called before each sweep
        self.marker = marker                      # told each step's key before its measured block
        self.disp_noise_floor_m = 0.0             # rms at rest; set by the session
        self.drive = DriveState(gain_N_per_Vpp=amp_gain_N_per_V / 2.0)
        # the largest drive the control may ask for: the peak limit, a hair inside it
        self.max_vpp = 2.0 * drive_limit_V * (1.0 - 1e-6)
        self.on_skip = on_skip                    # a step skipped (force unreachable) and why
        self.gain_at: dict[float, float] = {}     # frequency -> latest measured force per Vpp
        self.history: list[tuple[float, float]] = []   # (Vpp, force) of the last control
        self.periods = 0.0                        # drive periods since the point started
        self.last_block: Block | None = None      # the latest block acquired

    def preload(self, results: list) -> None:
        """A resumed run knows the force per volt its stored steps measured (the last control
        iteration of each, in schedule order), so its first drives are those of an
        uninterrupted run."""
        for r in sorted(results, key=lambda r: r["index"]):
            history = r.get("control_history")
            if history and history[-1]["force_N"] > 0 and history[-1]["drive_Vpp"] > 0:
                gain = history[-1]["force_N"] / history[-1]["drive_Vpp"]
                self.drive.gain_N_per_Vpp = self.gain_at[r["freq_Hz"]] = gain
        self.schedule.preload(results)

    def _first_vpp(self, step: StepSpec, new_sweep: bool = False) -> float:
        """First drive of a step, the controller's (within the drive limit)."""
        return self.controller.first_vpp(self, step, new_sweep)

    def force_first_vpp(self, step: StepSpec, new_sweep: bool = False) -> float:
        """First drive of a force level, within the drive limit: inside a sweep, from the force per
        volt of the step before (same level, the next frequency); a new sweep (a new level)
        from the force per volt measured at its first frequency before (an earlier level),
        FIRST_DRIVE_MARGIN below it: the force per volt depends on the level (the rig's
        resonance moves), and a ramp to a force above the target, plus the start's
        transient, could reach the force limit."""
        if not new_sweep:
            return min(step.force_N / self.drive.gain_N_per_Vpp, self.max_vpp)
        gain = self.gain_at.get(step.freq_Hz, self.drive.gain_N_per_Vpp)
        if step.freq_Hz not in self.gain_at and self.gain_at:
            # a frequency not measured before (a refinement step): the larger force per volt
            # of the measured frequencies either side, so the first drive errs low
            fs = sorted(self.gain_at)
            below = [f for f in fs if f < step.freq_Hz][-1:]
            above = [f for f in fs if f > step.freq_Hz][:1]
            gain = max(self.gain_at[f] for f in below + above)
        return min(FIRST_DRIVE_MARGIN * step.force_N / gain, self.max_vpp)

    # ------------------------------------------------------------------ primitives
    def _acquire(self, freq_Hz: float, periods: int) -> Block:
        block = self.last_block = self.daq.acquire_periods(freq_Hz, max(1, periods), self.plan.min_sample_rate_Hz)
        self.periods += max(1, periods)
        self._track_phase(block, freq_Hz)
        return block

    def _track_phase(self, block: Block, freq_Hz: float, fit_samples: int | None = None) -> None:
        """Drive phase at the end of ``block``, from its force signal's fundamental over
        whole periods (all of a block of whole periods, or its first ``fit_samples``): there
        the fundamental's sine and cosine are orthogonal to each other, to the offset and to
        the other harmonics, so the projection is the least-squares fit's phase."""
        if not self.drive.on or block.n_samples < 8:
            return
        x = block.force_N[:fit_samples]
        wt = 2 * math.pi * freq_Hz / block.fs_Hz * np.arange(x.size)
        phi0 = math.atan2(float(x @ np.cos(wt)), float(x @ np.sin(wt)))
        self.drive.phase_rad = (phi0 + 2 * math.pi * freq_Hz * block.n_samples / block.fs_Hz) % (2 * math.pi)

    def _align(self) -> None:
        """Wait until the drive is at phase pi/2 or 3 pi/2 (alternately) before a change.

        A free-rolling carriage keeps any velocity mismatch between the old and the new
        steady motion as drift.  At pi/2 and 3 pi/2 the steady velocity is zero at every
        amplitude and frequency, so a change leaves no drift; alternating the two quarters
        cancels the small displacement offsets a change leaves there."""
        phi, f = self.drive.phase_rad, self.drive.freq_Hz
        if phi is None or not self.drive.on:
            return
        rate, n = self._to_quarter(phi, f, 0)
        if n >= 1:
            self.daq.acquire_samples(rate, n)
        self.drive.phase_rad = (phi + 2 * math.pi * f * n / rate) % (2 * math.pi)

    def _to_quarter(self, phi: float, f: float, periods: int) -> tuple[float, int]:
        """(rate, samples) from drive phase ``phi`` through ``periods`` whole periods to the
        next quarter (see _align), which is then the one after."""
        target = self.drive.next_quarter * math.pi / 2
        self.drive.next_quarter = 4 - self.drive.next_quarter
        rate, per_period = plan_block(f, 1, self.plan.min_sample_rate_Hz)
        phi_end = phi + 2 * math.pi * f * periods * per_period / rate
        return rate, periods * per_period + int(round(((target - phi_end) % (2 * math.pi)) / (2 * math.pi * f) * rate))

    def _period_to_quarter(self, freq_Hz: float) -> bool:
        """A ramp's period and the wait to the next quarter after it in one block (as one
        period, then :meth:`_align`, would acquire them: the same samples, one request);
        False, nothing acquired, while the drive phase is not known."""
        phi = self.drive.phase_rad
        if phi is None or not self.drive.on:
            return False
        rate, n = self._to_quarter(phi, freq_Hz, 1)
        block = self.last_block = self.daq.acquire_samples(rate, n)
        self.periods += 1
        self._track_phase(block, freq_Hz, fit_samples=plan_block(freq_Hz, 1, self.plan.min_sample_rate_Hz)[1])
        return True

    def _change(self, *, vpp: float | None = None, freq_Hz: float | None = None) -> None:
        """Change frequency and/or amplitude at a quarter phase (see _align)."""
        self._align()
        if freq_Hz is not None and freq_Hz != self.drive.freq_Hz:
            self.drive.freq_Hz = self.gen.set_frequency(freq_Hz)
        if vpp is not None:
            self.drive.amplitude_Vpp = self.gen.set_amplitude(max(vpp, MIN_VPP))

    def glide(self, freq_Hz: float) -> None:
        """Change the frequency at once, no alignment wait: a 33500-series generator changes it
        phase-continuously (a DDS: FREQ loads a new phase increment, the accumulator goes on)."""
        self.drive.freq_Hz = self.gen.set_frequency(freq_Hz)

    def _wait(self, freq_Hz: float, seconds: float, min_periods: int = 0) -> None:
        """Let time pass with the output as it is: acquire (and so supervise) blocks."""
        periods = max(min_periods, math.ceil(seconds * freq_Hz))
        while periods > 0:
            chunk = min(periods, max(1, int(freq_Hz)))   # blocks of at most ~1 s
            self._acquire(freq_Hz, chunk)
            periods -= chunk

    def ramp(self, target_Vpp: float, freq_Hz: float) -> None:
        """Soft change of amplitude: one small step per period over at least ramp_s and
        40 periods.  (An amplitude step dP gives a free-rolling carriage a mean velocity
        dP/(m w); many small steps keep the drift of the carriage small.)"""
        start = self.drive.amplitude_Vpp if self.drive.on else 0.0
        if not self.drive.on:
            self.drive.freq_Hz = self.gen.set_frequency(freq_Hz)
            self.drive.amplitude_Vpp = self.gen.set_amplitude(MIN_VPP)
            self.gen.set_output(True)
            self.drive.on = True
            self.drive.phase_rad = None
            self._acquire(freq_Hz, 1)
        else:
            self._change(freq_Hz=freq_Hz)
        steps = max(40, math.ceil(self.plan.ramp_s * freq_Hz))
        aligned = False
        for k in range(1, steps + 1):
            if not aligned:
                self._align()
            self.drive.amplitude_Vpp = self.gen.set_amplitude(max(start + (target_Vpp - start) * k / steps, MIN_VPP))
            aligned = k < steps and self._period_to_quarter(freq_Hz)
            if not aligned:
                self._acquire(freq_Hz, 1)

    def stop(self) -> None:
        """Soft stop: ramp to the minimum amplitude, then output off."""
        if self.drive.on:
            self.ramp(MIN_VPP, self.drive.freq_Hz)
            self.gen.set_output(False)
            self.drive.on = False

    # ------------------------------------------------------------------ one step
    def control_force(self, step: StepSpec) -> Outcome:
        """Bring the controlled quantity to the step's level (the controller's control: the
        force, or the response); each iteration's (Vpp, force) is kept in ``history``."""
        return self.controller.control(self, step)

    def _measure_block(self, block: Block, f: float) -> BlockRecord:
        """The block's one analysis, from which its step record is made (decision 0047)."""
        return measure_block(block.force_N, block.accel_m_s2, block.disp_m, block.fs_Hz, f, self.plan.harmonics)

    def measure(self, step: StepSpec) -> tuple[StepMeasurement, dict[str, np.ndarray]]:
        """Settle, then measure; re-measure while the block is not settled (decision 0037).

        A block is discarded and another taken (at most ``max_extra_settle_blocks`` of the
        plan) while the offline step-quality check would find in it something that
        settling cures (:func:`unsettled`: a transient, a free vibration, an offset drift,
        a record not periodic enough), each time logged with the check's words, or while
        the displacement residual is above 3x the sensor noise at rest and still falling
        by more than 10 % from block to block (a weakly damped mode, small-amplitude
        pre-rolling, can ring for hundreds of periods).  What the check still finds after
        the limit is logged as a warning and kept in the result (``unsettled``).  A dwell
        step's block is its ``dwell_cycles`` long."""
        f = step.freq_Hz
        periods = measure_periods(self.plan, f, step.dwell_cycles)
        self._wait(f, self.plan.min_settle_s, min_periods=self.plan.settle_cycles)
        if self.marker is not None:   # a simulated rig reseeds its noise here (decision 0013)
            self.marker.mark_step(step.key)
        block = self._acquire(f, periods)
        m = self._measure_block(block, f)
        extra, before, found = 0, math.inf, Unsettled()
        settle = max(self.plan.settle_cycles, math.ceil(self.plan.min_settle_s * f))
        while True:
            found = unsettled_in(m.quality, block.fs_Hz, block.n_samples, found.vibrations_Hz)
            noise = m.disp_noise_rms
            ringing = noise > 3 * self.disp_noise_floor_m and noise < 0.9 * before
            if not (found.found or ringing) or extra >= self.plan.max_extra_settle_blocks:
                break
            log.info("step %s: settling one more block (%d of at most %d): %s", step.key, extra + 1,
                     self.plan.max_extra_settle_blocks, found.why if found.found else
                     f"displacement residual {si(noise, 'm')} > 3 x the noise at rest "
                     f"{si(self.disp_noise_floor_m, 'm')}")
            if found.found:        # the plan's settle again, or what the check says the transient still
                # needs: its cycles count from the block's start, and the block has passed
                need = min(found.cycles - periods, math.ceil(MAX_SETTLE_WAIT_S * f))
                self._wait(f, 0.0, min_periods=max(settle, need))
            before = noise
            block = self._acquire(f, periods)
            m = self._measure_block(block, f)
            extra += 1
        why = found.why if found.found else ""
        if found.found:
            log.warning("step %s: still unsettled after %d extra blocks (plan: max_extra_settle_blocks = %d), "
                        "recorded as it is: %s", step.key, extra, self.plan.max_extra_settle_blocks, why)
        return self.block_result(block, m, extra, why)

    def block_result(self, block: Block, m: BlockRecord, extra: int = 0,
                     why: str = "") -> tuple[StepMeasurement, dict[str, np.ndarray]]:
        """A measured block's record (the result's measurement part: the block's one
        analysis ``m``, the drive and the block's identity) and its raw arrays."""
        result = StepMeasurement(
            **m.fields, drive_Vpp=self.drive.amplitude_Vpp,
            t0_s=block.t0_s, block_id=block.block_id, resends=block.resends, settle_extra_blocks=extra, unsettled=why)
        raw = dict(force_N=block.force_N, accel_m_s2=block.accel_m_s2, disp_m=block.disp_m,
                   fs_Hz=np.array(block.fs_Hz), t0_s=np.array(block.t0_s))
        return result, raw

    # ------------------------------------------------------------------ the test
    def run(self, done: set[str], record: Record,
            progress: Callable[[int, int, str], None] | None = None,
            choose: Callable[[list[StepSpec]], list[StepSpec]] | None = None,
            refine: Callable[[StepSpec], StepSpec | None] | None = None) -> None:
        """Run the schedule, skipping ``done`` keys.  ``choose`` (adaptive mode) picks,
        at the start of each sweep, the subset of its steps to measure.  ``refine``
        (resonance search, :class:`procedures.resonance.Refiner`) is asked after a level's
        last sweep for one more step at a time, until it says None; each starts from rest
        like a new sweep (ramp, force control), since it jumps in frequency.  A schedule
        whose controller finds the frequencies (phase resonance) has no grid to choose from or
        refine: asking it to is a ValueError, before the drive is touched."""
        if (choose or refine) and not self.schedule.fixed_frequencies:
            raise ValueError(f"{self.plan.procedure.label}: the controller finds each point's frequency, so "
                             f"there is no grid for {'adaptive choice' if choose else 'resonance refinement'}")
        sweeps: list[list[StepSpec]] = []
        for step in self.plan.schedule():
            if not sweeps or (step.level_index, step.direction) != (sweeps[-1][0].level_index,
                                                                     sweeps[-1][0].direction):
                sweeps.append([])
            sweeps[-1].append(step)
        per_sweep = self.plan.adaptive_per_sweep if choose else 0
        total = sum(min(len(sw), per_sweep) if per_sweep else len(sw) for sw in sweeps)
        finished = len(done)
        q = self.plan.level_quantity         # the progress line prints each level in its unit
        prev: StepSpec | None = None
        for n_sweep, sweep in enumerate(sweeps):
            before: StepSpec | None = None          # the step measured before, in this sweep
            for step in (choose(sweep) if choose else sweep):
                if step.key in done:
                    before = step
                    continue
                new_sweep = prev is None or (step.level_index, step.direction) != (prev.level_index, prev.direction)
                if new_sweep and before is not None:
                    # resuming inside a sweep: come from the step before, as the sweep would
                    # have (a nonlinear rig keeps the branch its history put it on)
                    self.approach(before)
                    new_sweep = False
                res = self.step(step, new_sweep=new_sweep, record=record)
                before = step
                finished += 1
                if progress:
                    progress(finished, total, self.schedule.describe(q, step, res))
                prev = step
            if refine and (n_sweep == len(sweeps) - 1 or sweeps[n_sweep + 1][0].level_index != sweep[0].level_index):
                tried: set[str] = set()
                while (extra := refine(sweep[-1])) is not None and extra.key not in tried:
                    tried.add(extra.key)
                    if extra.key in done:
                        continue
                    res = self.step(extra, new_sweep=True, record=record)
                    finished += 1
                    total += 1
                    if progress:
                        progress(finished, total, f"{q.format(extra.force_N)} {extra.freq_Hz:7.2f} Hz "
                                 + (f"dwell {extra.dwell_cycles} cycles " if extra.dwell_cycles else "refine ")
                                 + (f"err {100 * _control_error(res):+.1f}%" if res else f"skipped: {q.name} unreachable"))
                    prev = extra
        self.stop()

    def approach(self, step: StepSpec) -> None:
        """Drive ``step`` (already measured) as its sweep did: ramp, control, settle for its
        measurement's length, without recording.  The next step then starts from the state
        an uninterrupted sweep leaves it."""
        if self.drive.on:
            self.stop()
        if self.sensor_check:
            self.sensor_check()
        self.ramp(self._first_vpp(step, new_sweep=True), step.freq_Hz)
        self.control_force(step)
        periods = measure_periods(self.plan, step.freq_Hz)
        self._wait(step.freq_Hz, self.plan.min_settle_s, min_periods=self.plan.settle_cycles + periods)

    def step(self, step: StepSpec, *, new_sweep: bool, record: Record) -> StepResult | None:
        """One step: drive, control, settle, measure, record.  A step whose level the drive
        limit cannot reach is not measured: the plan's ``infeasible`` says whether that
        stops the test (``refuse``: ramp down, output off, ForceUnreachable) or the step is
        skipped (``skip``: ``on_skip`` is told why; returns None).  A point the controller
        lost (:attr:`Reason.lost`: phase resonance's lock) is ramped down at once and
        recorded from the control's last block; a control that moved the frequency is
        measured where it ended."""
        self.periods = 0.0
        first_vpp = self._first_vpp(step, new_sweep)
        if new_sweep:
            if self.drive.on and self.schedule.restart_sweeps:
                self.stop()
            if not self.drive.on and self.sensor_check:
                self.sensor_check()
            self.ramp(first_vpp, self.schedule.start_Hz(self, step))
        else:
            self._change(freq_Hz=step.freq_Hz, vpp=first_vpp)
        outcome = self.control_force(step)
        if outcome.reason is Reason.UNREACHABLE:
            log.warning("step %s: %s", step.key, outcome.message)
            if self.plan.infeasible == "refuse":
                self.stop()
                raise ForceUnreachable(f"step {step.key}: {outcome.message} (plan: infeasible = \"refuse\"; "
                                       f"\"skip\" goes on without it)")
            if self.on_skip:
                self.on_skip(step, outcome.message)
            return None
        where = step if outcome.freq_Hz is None else replace(step, freq_Hz=outcome.freq_Hz)
        if outcome.reason.lost:
            block = self.last_block
            assert block is not None              # a control is lost on a block
            self.stop()
            measured, raw = self.block_result(block, self._measure_block(block, where.freq_Hz))
        else:
            if not outcome.ok:
                log.warning("step %s: %s", step.key, outcome.message)
            measured, raw = self.measure(where)
        result = StepResult(**measured, key=step.key, index=step.index, level_index=step.level_index,
                            freq_index=step.freq_index, direction=step.direction,
                            control_iterations=outcome.iterations,
                            control_history=[ControlIteration(drive_Vpp=v, force_N=F) for v, F in self.history],
                            **self.controller.fields(step, measured, outcome))
        record(step, result, raw)
        self.schedule.after(step, result)
        return result


def _control_error(res: StepResult) -> float:
    """The error of the quantity the step's level holds: the response's when a
    response_control record says so, else the force's."""
    rc = res.get("response_control")
    return float(rc["error"]) if isinstance(rc, dict) else float(res["force_error"])
