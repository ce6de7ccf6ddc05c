"""Phase-resonance testing: a block-wise phase-locked loop traces a mode's backbone.

Phase resonance is a controller and a schedule on the one stepped-sine loop
(:class:`procedures.stepped_sine.SteppedSine`; decision 0060): :class:`PhaseLock` holds
the phase (deg) and returns a typed outcome (locked, not converged, lock lost, window
left, collapse), :class:`LockSchedule` walks the levels from the frequency locked last;
ramps, limits, supervision, stop, storage and resume are the loop's.

For each force level of the plan, in order, the generator's frequency is moved block by
block until the fundamental of the response (displacement, or acceleration) is at the
target phase against the force's (-90 degrees for displacement: the mode's nonlinear
natural frequency, Peter and Leine 2017), while the force control holds the level.  The
point counts as locked when the phase error stays within ``phase_band_deg`` and the
response amplitude within ``amplitude_band`` for ``settle_periods`` consecutive periods
(NLtest's rule: the counter restarts when a period leaves a band, each period fitted on
its own).  Then a block is measured (the stepped sine's settle and measurement) and
recorded with the damping ratio from the energy balance,

    zeta = |F1| sin(-(phi_x - phi_F)) / (2 m w^2 |X1|)

(m: the rig file's expected mass, stated in every record), and the next level starts
from the frequency just locked.

The loop: a Newton step on the phase error, f <- f - gain * error / slope, the slope
d phase / d f estimated at the start from three probe blocks around start_Hz and updated
by secants as the loop moves; each change at most ``max_step_Hz``.  A 33500-series
generator changes frequency phase-continuously (a DDS: FREQ loads a new phase increment,
the phase accumulator goes on), so frequency changes are sent at once; amplitude changes
keep the stepped sine's quarter-phase rule.

Lock loss (the phase error above ``lost_phase_deg`` and growing over three blocks, the
response amplitude below ``collapse`` x the level's largest, the frequency leaving the
window) ramps the level down, switches the output off, is reported through ``on_event``
with the reason (and its code) and recorded as an unlocked point from the loop's last
block; the next level starts afresh.
Decision record 0044.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import numpy as np

from sim.step_result import BackboneRecord, StepMeasurement, StepResult

from .analysis import fit_harmonics
from .control import FIRST_DRIVE_MARGIN, ControlFields, Loop, Outcome, Reason, next_drive
from .instruments import Block
from .kind import PHASE, Quantity
from .plan import Backbone, Plan, StepSpec
from .stepped_sine import Schedule, SteppedSine

__all__ = ["LockSchedule", "PhaseLock", "damping_ratio", "phase_error_deg", "phase_resonance"]

log = logging.getLogger(__name__)

MAX_DRIVE_CHANGE = 2.0        # one force-control update changes the drive by at most this factor
FALLBACK_ZETA = 0.05          # the slope a linear mode of this damping has, when the probe finds none


def phase_error_deg(phase_deg: float, target_deg: float) -> float:
    """phase - target wrapped into [-180, 180)."""
    return (phase_deg - target_deg + 180.0) % 360.0 - 180.0


def damping_ratio(force_N: complex, disp_m: complex, freq_Hz: float, mass_kg: float) -> float:
    """Equivalent viscous damping ratio from the energy balance of one mass: the force's
    quadrature part |F1| sin(-(phi_x - phi_F)) does the work the damping takes, against
    the kinetic term m w^2 |X1| (fundamentals as complex amplitudes)."""
    w = 2 * math.pi * freq_Hz
    lag = np.angle(disp_m / force_N)
    return float(abs(force_N) * math.sin(-lag) / (2 * mass_kg * w * w * abs(disp_m)))


class PhaseLock:
    """The phase of the response's fundamental against the force's at ``bb.phase_deg``
    (deg): the phase-resonance controller on the stepped-sine loop.  Its control moves the
    frequency (a Newton step per block) while it holds the level's force with the drive;
    its :class:`Outcome` is locked, not converged (``max_blocks`` spent), lock lost (the
    phase error growing), window left or collapse (the response fallen), with ``freq_Hz``
    the frequency it ended at."""

    quantity = PHASE

    def __init__(self, bb: Backbone, *, mass_kg: float, on_event: Callable[..., None] | None = None,
                 on_block: Callable[[dict], None] | None = None):
        self.bb = bb
        self.mass_kg = mass_kg
        self.on_event = on_event or (lambda kind, **fields: None)
        self.on_block = on_block              # the lock's state after each block (watch page)
        self.slope: float | None = None       # d phase / d f, degrees per Hz (< 0)
        self.loop: Loop | None = None         # the loop of the latest control (its periods, for the record)

    def first_vpp(self, proc: Loop, step: StepSpec, new_sweep: bool) -> float:
        """FIRST_DRIVE_MARGIN below the level's force through the latest force per volt."""
        return min(FIRST_DRIVE_MARGIN * step.force_N / proc.drive.gain_N_per_Vpp, proc.max_vpp)

    # ------------------------------------------------------------------ the phase
    def _phase(self, block: Block, f: float, last: int = 0) -> tuple[float, float, float, np.ndarray, np.ndarray]:
        """Phase (deg) and amplitudes of the fundamentals (response against force) of the
        block's ``last`` periods (0: all), and each period's phase error and response amplitude."""
        resp = block.disp_m if self.bb.response == "disp" else block.accel_m_s2
        per = max(1, int(round(block.n_samples * f / block.fs_Hz)))
        tail = -(block.n_samples * min(last, per) // per) if last else 0
        F = fit_harmonics(block.force_N[tail:], block.fs_Hz, f, 1)
        R = fit_harmonics(resp[tail:], block.fs_Hz, f, 1)
        phase = math.degrees(R.phase_rad[0] - F.phase_rad[0])
        errs, amps = [], []
        for fp, rp in zip(np.array_split(block.force_N, per), np.array_split(resp, per)):
            if fp.size < 8:
                continue
            Fk, Rk = fit_harmonics(fp, block.fs_Hz, f, 1), fit_harmonics(rp, block.fs_Hz, f, 1)
            errs.append(phase_error_deg(math.degrees(Rk.phase_rad[0] - Fk.phase_rad[0]), self.bb.phase_deg))
            amps.append(Rk.amplitude[0])
        return phase, float(F.amplitude[0]), float(R.amplitude[0]), np.array(errs), np.array(amps)

    def probe(self, proc: Loop, f0: float) -> float:
        """d phase / d f (deg/Hz) near ``f0`` from three blocks at f0 (1 - d), f0, f0 (1 + d);
        a slope that is not negative gives the one of a linear mode of 5 % damping."""
        fs, ps = [], []
        for f in (f0 * (1 - self.bb.probe_step), f0, f0 * (1 + self.bb.probe_step)):
            proc.glide(f)
            proc._wait(f, 0.0, min_periods=self.bb.block_periods)
            fs.append(f)
            ps.append(self._phase(proc._acquire(f, self.bb.block_periods), f)[0])
        ps = list(np.degrees(np.unwrap(np.radians(ps))))
        slope = float(np.polyfit(fs, ps, 1)[0])
        fallback = -math.degrees(1.0) / (FALLBACK_ZETA * f0)
        if not slope < fallback / 100:       # falling, and not flat
            log.warning("phase-resonance probe: phase slope %.3g deg/Hz at %.4g Hz is not falling; using %.3g deg/Hz "
                        "(a linear mode of %g %% damping)", slope, f0, fallback, 100 * FALLBACK_ZETA)
            slope = fallback
        self.on_event("backbone_probe", freq_Hz=f0, slope_deg_per_Hz=slope, phases_deg=ps)
        log.info("phase-resonance probe at %.4g Hz: %.3g deg/Hz", f0, slope)
        proc.glide(f0)
        return slope

    # ------------------------------------------------------------------ one level
    def _lost(self, proc: Loop, step: StepSpec, b: int, err: float, f: float, reason: Reason, why: str) -> Outcome:
        """The lock given up: the next level probes again; the loop ramps down and records the last block."""
        log.warning("level %g N: lock lost: %s; ramping down", step.force_N, why)
        self.slope = None
        self.on_event("lock_lost", key=step.key, level_N=step.force_N, freq_Hz=f, reason=why, code=reason.value)
        return Outcome(err, b, reason, f"lock lost: {why}", freq_Hz=f)

    def control(self, proc: Loop, step: StepSpec) -> Outcome:
        """Lock the level's resonance (the drive is on at the level's first drive)."""
        bb, self.loop = self.bb, proc
        f = proc.drive.freq_Hz
        if self.slope is None:
            self.slope = self.probe(proc, f) if bb.slope_deg_per_Hz == 0 else bb.slope_deg_per_Hz
        count, err = 0, math.nan
        amps_in_run: list[float] = []
        errors: list[float] = []
        largest = 0.0
        prev_fp: tuple[float, float, float] | None = None     # (frequency, phase, drive) of the block before
        prev_drive: tuple[float, float] | None = None
        changed = True
        proc.history = []
        for b in range(1, bb.max_blocks + 1):
            # the loop's estimate comes from the block's last block_periods; the periods
            # before let a change's transient decay (a linear mode's time constant is
            # |d phase / d f| / 360 s; two of them) and count for the settle rule
            wait = min(math.ceil(2 * abs(self.slope) / 360.0 * f), 5 * bb.block_periods) if changed else 0
            block = proc._acquire(f, wait + bb.block_periods)
            phase, F1, R1, errs, amps = self._phase(block, f, bb.block_periods)
            changed = False
            err = phase_error_deg(phase, bb.phase_deg)
            vpp = proc.drive.amplitude_Vpp
            proc.history.append((vpp, F1))
            # settle counter: each period in both bands, else restart
            for e, a in zip(errs, amps):
                ref = float(np.mean(amps_in_run)) if amps_in_run else a
                if abs(e) <= bb.phase_band_deg and abs(a / ref - 1) <= bb.amplitude_band:
                    count += 1
                    amps_in_run.append(a)
                else:
                    count, amps_in_run = (1, [a]) if abs(e) <= bb.phase_band_deg else (0, [])
            force_err = F1 / step.force_N - 1
            if self.on_block:
                self.on_block({"level_N": step.force_N, "freq_Hz": f, "phase_error_deg": err,
                               "amplitude": R1, "force_N": F1, "settled_periods": count})
            log.debug("level %g N block %d: %.5g Hz phase error %+.2f deg, force %+.1f %%, settled %d periods",
                      step.force_N, b, f, err, 100 * force_err, count)
            errors.append(abs(err))
            largest = max(largest, R1)
            if len(errors) >= 3 and errors[-1] > bb.lost_phase_deg and errors[-1] > errors[-2] > errors[-3]:
                return self._lost(proc, step, b, err, f, Reason.LOCK_LOST,
                                  f"phase error {err:+.1f} deg above lost_phase_deg {bb.lost_phase_deg:g} and "
                                  f"growing for 3 blocks at {f:.4g} Hz")
            if b > 2 and R1 < bb.collapse * largest:
                return self._lost(proc, step, b, err, f, Reason.COLLAPSE,
                                  f"response amplitude {R1:.3g} fell below collapse {bb.collapse:g} x the "
                                  f"level's largest {largest:.3g} at {f:.4g} Hz")
            if count >= bb.settle_periods and abs(force_err) <= proc.plan.force_tolerance:
                return Outcome(err, b, Reason.LOCKED, freq_Hz=f)
            # force control: hold the level
            if F1 > 0:
                proc.drive.gain_N_per_Vpp = F1 / vpp
            if abs(force_err) > proc.plan.force_tolerance / 2 and F1 > 0:
                nxt = next_drive(vpp, F1, step.force_N, prev_drive)
                nxt = min(max(nxt, vpp / MAX_DRIVE_CHANGE), vpp * MAX_DRIVE_CHANGE, proc.max_vpp)
                prev_drive = (vpp, F1)
                if nxt != vpp:
                    proc._change(vpp=nxt)
                    changed = True
            # phase control: a Newton step on the error; the slope follows secants between
            # blocks at the same drive (an amplitude change moves a nonlinear mode's phase
            # too), blended geometrically; one that does not fall is not a resonance's
            if prev_fp is not None and abs(f - prev_fp[0]) > 1e-4 * f and prev_fp[2] == vpp:
                s = phase_error_deg(phase, prev_fp[1]) / (f - prev_fp[0])
                if s < 0:
                    self.slope = -math.sqrt(self.slope * s)
            prev_fp = (f, phase, proc.drive.amplitude_Vpp)
            df = -bb.gain * err / self.slope
            df = max(-bb.max_step_Hz, min(bb.max_step_Hz, df))
            nf = f + df
            if not bb.min_Hz <= nf <= bb.max_Hz:
                return self._lost(proc, step, b, err, f, Reason.WINDOW_LEFT,
                                  f"frequency {nf:.4g} Hz left the window {bb.min_Hz:g}-{bb.max_Hz:g} Hz "
                                  f"(phase error {err:+.1f} deg at {f:.4g} Hz)")
            if abs(err) > bb.phase_band_deg / 4:      # well inside the band: no change, no transient
                proc.glide(nf)
                f = proc.drive.freq_Hz
                changed = True
        why = f"not settled within max_blocks = {bb.max_blocks} blocks"
        self.on_event("not_locked", key=step.key, level_N=step.force_N, freq_Hz=f, reason=why)
        return Outcome(err, bb.max_blocks, Reason.NOT_CONVERGED, why, freq_Hz=f)

    def fields(self, step: StepSpec, measured: StepMeasurement, outcome: Outcome) -> ControlFields:
        """The force's fields (the level held) and the point's :class:`BackboneRecord`."""
        assert self.loop is not None
        fits_F = measured["force"]
        F1 = fits_F["amplitude"][0] * np.exp(1j * fits_F["phase_rad"][0])
        d = measured["disp"]
        X1 = d["amplitude"][0] * np.exp(1j * d["phase_rad"][0])
        f = measured["freq_Hz"]
        if self.bb.response == "disp":
            R = X1
        else:             # the drive point's displacement from the accelerometer (it sees a pitch, the probe not)
            a = measured["accel"]
            R = a["amplitude"][0] * np.exp(1j * a["phase_rad"][0])
            X1 = -R / (2 * math.pi * f) ** 2
        phase = math.degrees(float(np.angle(R / F1)))
        force_err = measured["force_N"] / step.force_N - 1.0
        bbrec = BackboneRecord(
            mode=self.bb.mode, response=self.bb.response, amplitude_m=float(abs(X1)), frequency_Hz=f, phase_deg=phase,
            phase_target_deg=self.bb.phase_deg, phase_error_deg=phase_error_deg(phase, self.bb.phase_deg),
            damping_ratio=damping_ratio(F1, X1, f, self.mass_kg), mass_kg=self.mass_kg, locked=outcome.ok,
            why=outcome.message, periods=int(round(self.loop.periods)), blocks=outcome.iterations)
        return ControlFields(target_force_N=step.force_N, force_error=force_err,
                             force_converged=abs(force_err) <= self.loop.plan.force_tolerance, backbone=bbrec)


class LockSchedule(Schedule):
    """Phase resonance's walk over the plan's levels: each level starts where the drive is
    (from the frequency locked last, or ``start_Hz``; no ramp down between levels), and the
    frequency is the controller's, so there is no grid to choose from or refine."""

    fixed_frequencies = False
    restart_sweeps = False

    def __init__(self, bb: Backbone):
        self.bb = bb
        self.f_locked: float | None = None    # the last locked frequency

    def start_Hz(self, proc: SteppedSine, step: StepSpec) -> float:
        return proc.drive.freq_Hz if proc.drive.on else (self.f_locked or self.bb.start_Hz)

    def preload(self, results: list) -> None:
        """A resumed run goes on from the last frequency locked before."""
        for r in sorted(results, key=lambda r: r["index"]):
            if r.get("backbone", {}).get("locked"):
                self.f_locked = r["freq_Hz"]

    def after(self, step: StepSpec, result: StepResult) -> None:
        if result["backbone"]["locked"]:
            self.f_locked = result["freq_Hz"]

    def describe(self, quantity: Quantity, step: StepSpec, res: StepResult | None) -> str:
        assert res is not None
        b = res["backbone"]
        return (f"{step.force_N:g} N {b['frequency_Hz']:7.2f} Hz phase {b['phase_deg']:+.1f} deg zeta "
                f"{100 * b['damping_ratio']:.2f} % " + ("locked" if b["locked"] else "NOT locked")
                + f" ({b['periods']} periods)")


def phase_resonance(plan: Plan, *, mass_kg: float, on_event: Callable[..., None] | None = None,
                    on_block: Callable[[dict], None] | None = None) -> tuple[PhaseLock, LockSchedule]:
    """The controller and schedule of a phase-resonance plan (``[plan.backbone]``)."""
    if plan.backbone is None:
        raise ValueError("a phase-resonance plan needs [plan.backbone]")
    bb = plan.backbone.resolved()
    return PhaseLock(bb, mass_kg=mass_kg, on_event=on_event, on_block=on_block), LockSchedule(bb)
