"""Response-controlled stepped sine (Karaagacli and Ozguven 2020-2021; decision 0044).

The stepped sine's schedule and measurement, with its control loop around the response
instead of the force: at each frequency the drive is iterated until the fundamental of
the displacement (or the drive-point acceleration) is at the level, so each level's FRF
is quasi-linear; the force it needed is the measurement.  Levels are response amplitudes
(m or m/s^2, the plan's ``levels_N`` holds them); every drive request and block still
passes the safety supervisor (drive, force, displacement, acceleration limits).  Each
step's record carries ``response_control`` (quantity, target, measured, error);
``target_force_N`` is the force the level needed.
"""

from __future__ import annotations

import logging
import math

from .analysis import fit_harmonics
from .plan import StepSpec
from .stepped_sine import FIRST_DRIVE_MARGIN, Record, SteppedSine, StepResult, next_drive

log = logging.getLogger(__name__)

FREE_MASS_SHARE = 0.5      # a sweep's first drive: half the free mass's force m w^2 X (safe below resonance)


class ResponseControlled(SteppedSine):
    """Runs a plan with ``procedure = "response_controlled"``."""

    def __init__(self, *args, quantity: str, mass_kg: float, **kwargs):
        super().__init__(*args, **kwargs)
        if quantity not in ("disp", "accel"):
            raise ValueError(f"quantity must be 'disp' or 'accel', got {quantity!r}")
        self.quantity, self.mass_kg = quantity, mass_kg
        self.response_per_vpp = 0.0             # the latest response amplitude per Vpp

    def _displacement(self, level: float, freq_Hz: float) -> float:
        w = 2 * math.pi * freq_Hz
        return level if self.quantity == "disp" else level / (w * w)

    def _first_vpp(self, step: StepSpec, new_sweep: bool = False) -> float:
        """Inside a sweep: the level over the response per volt of the step before, 10 %
        low; a new sweep: half the free mass's force for the level, through the force per
        volt measured so far (the mode's spring only lowers the force needed below it)."""
        if not new_sweep and self.response_per_vpp > 0:
            return min(FIRST_DRIVE_MARGIN * step.force_N / self.response_per_vpp, self.max_vpp)
        w = 2 * math.pi * step.freq_Hz
        force = FREE_MASS_SHARE * self.mass_kg * w * w * self._displacement(step.force_N, step.freq_Hz)
        return min(force / self.drive.gain_N_per_Vpp, self.max_vpp)

    def control_force(self, step: StepSpec) -> tuple[float, int, bool, str]:
        """Iterate the drive until the response fundamental is within the plan's
        ``force_tolerance`` of the level (the same secant update as the force control)."""
        f, target = step.freq_Hz, step.force_N
        err, it = math.inf, 0
        prev: tuple[float, float] | None = None
        self.history = []
        for it in range(1, self.plan.max_iterations + 1):
            self._wait(f, 0.0, min_periods=self.plan.control_cycles)
            block = self._acquire(f, self.plan.control_cycles)
            x = block.disp_m if self.quantity == "disp" else block.accel_m_s2
            R1 = float(fit_harmonics(x, block.fs_Hz, f, 1).amplitude[0])
            F1 = float(fit_harmonics(block.force_N, block.fs_Hz, f, 1).amplitude[0])
            vpp = self.drive.amplitude_Vpp
            err = R1 / target - 1.0
            self.history.append((vpp, F1))
            log.debug("step %s iteration %d: %.5g Vpp -> response %.5g (error %+.2f %%), %.4g N", step.key, it,
                      vpp, R1, 100 * err, F1)
            if R1 > 0:
                self.response_per_vpp = R1 / vpp
            if F1 > 0:
                self.drive.gain_N_per_Vpp = self.gain_at[f] = F1 / vpp
            if abs(err) <= self.plan.force_tolerance:
                return err, it, True, ""
            if R1 <= 0 or not math.isfinite(R1):
                return err, it, False, f"no response measured at {vpp:.4g} Vpp"
            nxt = next_drive(vpp, R1, target, prev)
            if nxt > self.max_vpp:
                if vpp >= self.max_vpp * (1 - 1e-6):
                    return err, it, False, (f"response {target:g} unreachable at {f:g} Hz within the drive limit "
                                            f"{self.max_vpp / 2:.4g} V: {R1:.4g} at the limit")
                nxt = self.max_vpp
            prev = (vpp, R1)
            self._change(vpp=nxt)
        return err, it, False, f"not within {100 * self.plan.force_tolerance:g} % after {it} iterations"

    def step(self, step: StepSpec, *, new_sweep: bool, record: Record) -> StepResult | None:
        def amend(spec: StepSpec, result: StepResult, raw: dict) -> None:
            fit = result["disp"] if self.quantity == "disp" else result["accel"]
            got = float(fit["amplitude"][0])
            err = got / spec.force_N - 1.0
            result["response_control"] = {"quantity": self.quantity, "target": spec.force_N, "measured": got,
                                          "error": err}
            result["target_force_N"] = result["force_N"]      # what the level needed: the measurement
            result["force_error"] = 0.0
            result["force_converged"] = abs(err) <= self.plan.force_tolerance
            record(spec, result, raw)
        return super().step(step, new_sweep=new_sweep, record=amend)
