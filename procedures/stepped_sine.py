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
from dataclasses import dataclass

import numpy as np

from drivers import plan_block
from sim.step_result import FitSummary, StepMeasurement, StepResult

from .analysis import HarmonicFit, fit_harmonics
from .instruments import Block, BlockSource, SineSource, StepMarker
from .plan import Plan, StepSpec

__all__ = ["MIN_VPP", "DriveState", "SteppedSine", "StepResult"]

Record = Callable[[StepSpec, StepResult, dict[str, np.ndarray]], None]

log = logging.getLogger(__name__)

MIN_VPP = 2e-3       # the generator's smallest amplitude into a high-impedance load


@dataclass
class DriveState:
    freq_Hz: float = 0.0
    amplitude_Vpp: float = 0.0
    on: bool = False
    gain_N_per_Vpp: float = 0.0       # latest measured force amplitude per Vpp
    phase_rad: float | None = None    # drive phase now (from the last force fit)
    next_quarter: int = 1             # changes alternate between phase pi/2 and 3 pi/2


def _fit_summary(fit: HarmonicFit) -> FitSummary:
    return FitSummary(amplitude=fit.amplitude.tolist(), phase_rad=fit.phase_rad.tolist(),
                offset=fit.offset, thd=fit.thd, noise_rms=fit.noise_rms, peak_to_peak=fit.peak_to_peak,
                raw_peak_to_peak=fit.raw_peak_to_peak)


class SteppedSine:
    """Runs a :class:`~bench.config.Plan` on supervised instruments."""

    def __init__(self, plan: Plan, generator: SineSource, daq: BlockSource, *, amp_gain_N_per_V: float,
                 sensor_check: Callable[[], object] | None = None, marker: StepMarker | None = None):
        self.plan = plan
        self.gen = generator
        self.daq = daq
        self.sensor_check = sensor_check          # gap in range? called before each sweep
        self.marker = marker                      # told each step's key before its measured block
        self.disp_noise_floor_m = 0.0             # rms at rest; set by the session
        self.drive = DriveState(gain_N_per_Vpp=amp_gain_N_per_V / 2.0)

    # ------------------------------------------------------------------ primitives
    def _acquire(self, freq_Hz: float, periods: int) -> Block:
        block = self.daq.acquire_periods(freq_Hz, max(1, periods), self.plan.min_sample_rate_Hz)
        self._track_phase(block, freq_Hz)
        return block

    def _track_phase(self, block: Block, freq_Hz: float) -> None:
        """Drive phase at the end of ``block``, from a fit of its force signal."""
        if not self.drive.on or block.n_samples < 8:
            return
        phi0 = fit_harmonics(block.force_N, block.fs_Hz, freq_Hz, 1).phase_rad[0]
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
        target = self.drive.next_quarter * math.pi / 2
        self.drive.next_quarter = 4 - self.drive.next_quarter
        wait = ((target - phi) % (2 * math.pi)) / (2 * math.pi * f)
        rate, _ = plan_block(f, 1, self.plan.min_sample_rate_Hz)
        n = int(round(wait * rate))
        if n >= 1:
            self.daq.acquire_samples(rate, n)
        self.drive.phase_rad = (phi + 2 * math.pi * f * n / rate) % (2 * math.pi)

    def _change(self, *, vpp: float | None = None, freq_Hz: float | None = None) -> None:
        """Change frequency and/or amplitude at a quarter phase (see _align)."""
        self._align()
        if freq_Hz is not None and freq_Hz != self.drive.freq_Hz:
            self.drive.freq_Hz = self.gen.set_frequency(freq_Hz)
        if vpp is not None:
            self.drive.amplitude_Vpp = self.gen.set_amplitude(max(vpp, MIN_VPP))

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
        for k in range(1, steps + 1):
            self._change(vpp=start + (target_Vpp - start) * k / steps)
            self._acquire(freq_Hz, 1)

    def stop(self) -> None:
        """Soft stop: ramp to the minimum amplitude, then output off."""
        if self.drive.on:
            self.ramp(MIN_VPP, self.drive.freq_Hz)
            self.gen.set_output(False)
            self.drive.on = False

    # ------------------------------------------------------------------ one step
    def control_force(self, step: StepSpec) -> tuple[float, int, bool]:
        """Iterate the drive until the force fundamental is within tolerance.

        Returns (relative force error, iterations, converged)."""
        f, target = step.freq_Hz, step.force_N
        err, it = math.inf, 0
        for it in range(1, self.plan.max_iterations + 1):
            self._wait(f, 0.0, min_periods=self.plan.control_cycles)   # let the change settle
            block = self._acquire(f, self.plan.control_cycles)
            F1 = fit_harmonics(block.force_N, block.fs_Hz, f, 1).amplitude[0]
            err = F1 / target - 1.0
            if F1 > 0:
                self.drive.gain_N_per_Vpp = F1 / self.drive.amplitude_Vpp
            if abs(err) <= self.plan.force_tolerance:
                return err, it, True
            if F1 <= 0 or not math.isfinite(F1):
                break
            self._change(vpp=self.drive.amplitude_Vpp * target / F1)
        return err, it, False

    def _fit_block(self, block: Block, f: float) -> dict[str, HarmonicFit]:
        return {name: fit_harmonics(x, block.fs_Hz, f, self.plan.harmonics)
                for name, x in (("force", block.force_N), ("accel", block.accel_m_s2), ("disp", block.disp_m))}

    def measure(self, step: StepSpec) -> tuple[StepMeasurement, dict[str, np.ndarray]]:
        """Settle, then measure; re-measure while a free vibration is still dying out.

        A weakly damped mode (small-amplitude pre-rolling, n > 1) can ring for hundreds of
        periods after a change.  While the displacement residual (what the harmonics do not
        explain) is above 3x the sensor noise at rest and still falling by more than 10 %
        from block to block, the block is discarded and another taken (at most
        ``max_extra_settle_blocks`` of the plan)."""
        f = step.freq_Hz
        periods = max(self.plan.measure_cycles, math.ceil(self.plan.min_measure_s * f))
        self._wait(f, self.plan.min_settle_s, min_periods=self.plan.settle_cycles)
        if self.marker is not None:   # a simulated rig reseeds its noise here (decision 0013)
            self.marker.mark_step(step.key)
        block = self._acquire(f, periods)
        fits = self._fit_block(block, f)
        extra = 0
        while extra < self.plan.max_extra_settle_blocks and fits["disp"].noise_rms > 3 * self.disp_noise_floor_m:
            nxt = self._acquire(f, periods)
            nfits = self._fit_block(nxt, f)
            extra += 1
            improved = nfits["disp"].noise_rms < 0.9 * fits["disp"].noise_rms
            block, fits = nxt, nfits
            if not improved:
                break
        F1 = fits["force"].fundamental
        X1 = fits["disp"].fundamental
        A1 = fits["accel"].fundamental
        compliance = X1 / F1
        accelerance = A1 / F1
        result = StepMeasurement(
            freq_Hz=f, force_N=abs(F1), drive_Vpp=self.drive.amplitude_Vpp,
            compliance_m_per_N={"re": float(compliance.real), "im": float(compliance.imag)},
            compliance_abs_m_per_N=abs(compliance), compliance_phase_rad=float(np.angle(compliance)),
            accelerance_abs_kg_inv=abs(accelerance), accelerance_phase_rad=float(np.angle(accelerance)),
            # seed Eq. 9 in SI: half the peak-to-peak of the steady (fitted periodic)
            # displacement per force amplitude
            compliance_pp_m_per_N=0.5 * fits["disp"].peak_to_peak / abs(F1),
            force=_fit_summary(fits["force"]), accel=_fit_summary(fits["accel"]),
            disp=_fit_summary(fits["disp"]),
            fs_Hz=block.fs_Hz, n_samples=block.n_samples, t0_s=block.t0_s, block_id=block.block_id,
            resends=block.resends, settle_extra_blocks=extra)
        raw = dict(force_N=block.force_N, accel_m_s2=block.accel_m_s2, disp_m=block.disp_m,
                   fs_Hz=np.array(block.fs_Hz), t0_s=np.array(block.t0_s))
        return result, raw

    # ------------------------------------------------------------------ the test
    def run(self, done: set[str], record: Record,
            progress: Callable[[int, int, str], None] | None = None,
            choose: Callable[[list[StepSpec]], list[StepSpec]] | None = None) -> None:
        """Run the schedule, skipping ``done`` keys.  ``choose`` (adaptive mode) picks,
        at the start of each sweep, the subset of its steps to measure."""
        sweeps: list[list[StepSpec]] = []
        for step in self.plan.schedule():
            if not sweeps or (step.level_index, step.direction) != (sweeps[-1][0].level_index,
                                                                     sweeps[-1][0].direction):
                sweeps.append([])
            sweeps[-1].append(step)
        per_sweep = self.plan.adaptive_per_sweep if choose else 0
        total = sum(min(len(sw), per_sweep) if per_sweep else len(sw) for sw in sweeps)
        finished = len(done)
        prev: StepSpec | None = None
        for sweep in sweeps:
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
                    progress(finished, total, f"{step.force_N:g} N {step.freq_Hz:7.1f} Hz {step.direction:4s} "
                             f"err {100 * res['force_error']:+.1f}% THD(x) {res['disp']['thd']:.2f}")
                prev = step
        self.stop()

    def approach(self, step: StepSpec) -> None:
        """Drive ``step`` (already measured) as its sweep did: ramp, control, settle for its
        measurement's length, without recording.  The next step then starts from the state
        an uninterrupted sweep leaves it."""
        if self.drive.on:
            self.stop()
        if self.sensor_check:
            self.sensor_check()
        self.ramp(step.force_N / self.drive.gain_N_per_Vpp, step.freq_Hz)
        self.control_force(step)
        periods = max(self.plan.measure_cycles, math.ceil(self.plan.min_measure_s * step.freq_Hz))
        self._wait(step.freq_Hz, self.plan.min_settle_s, min_periods=self.plan.settle_cycles + periods)

    def step(self, step: StepSpec, *, new_sweep: bool, record: Record) -> StepResult:
        """One step: drive, control the force, settle, measure, record."""
        first_vpp = step.force_N / self.drive.gain_N_per_Vpp
        if new_sweep:
            if self.drive.on:
                self.stop()
            if self.sensor_check:
                self.sensor_check()
            self.ramp(first_vpp, step.freq_Hz)
        else:
            self._change(freq_Hz=step.freq_Hz, vpp=first_vpp)
        err, iterations, ok = self.control_force(step)
        if not ok:
            log.warning("step %s: force %.3g N not reached within %.1f %% after %d iterations "
                        "(error %+.1f %%)", step.key, step.force_N, 100 * self.plan.force_tolerance,
                        iterations, 100 * err)
        measured, raw = self.measure(step)
        result = StepResult(**measured, key=step.key, index=step.index, level_index=step.level_index,
                            freq_index=step.freq_index, direction=step.direction,
                            target_force_N=step.force_N, control_iterations=iterations,
                            force_converged=ok, force_error=measured["force_N"] / step.force_N - 1.0)
        record(step, result, raw)
        return result
