"""One stepped-sine step's result: the record a procedure produces, a run directory stores
as ``steps/<key>.json`` and every reader (identification, export, reports, watch page,
analysis) reads.  The on-disk schema, field by field, is docs/run-format.md.

It lives in the lowest layer because :mod:`sim.identify` reads it as well as the bench.
A ``TypedDict`` keeps the JSON form and ``result["key"]`` access everywhere; a type
checker sees every field and its type.

Format versions (``format_version`` in each step file; decision record 0027):

- 1: the fields below.  Files written before the field existed have the same content and
  no ``format_version``: they are read as version 1.

A reader meets a newer version than it knows only when a newer guideway-bench wrote the
file; :func:`check_step_version` names the file and the versions instead of guessing.
"""

from __future__ import annotations

from typing import NotRequired, TypedDict

from .errors import RunDirectoryError

STEP_FORMAT_VERSION = 1


class ComplexValue(TypedDict):
    re: float
    im: float


class FitSummary(TypedDict):
    """Harmonic fit of one channel's block: amplitudes and phases of harmonics 1..K of
    ``A_k sin(k w t + phi_k)`` (in the channel's SI unit), offset, THD, the rms of what
    the harmonics do not explain, and peak-to-peak of the fitted and the raw signal."""

    amplitude: list[float]
    phase_rad: list[float]
    offset: float
    thd: float
    noise_rms: float
    peak_to_peak: float
    raw_peak_to_peak: float


class StepMeasurement(TypedDict):
    """What one measured block gives (:meth:`procedures.stepped_sine.SteppedSine.measure`)."""

    freq_Hz: float
    force_N: float                      # measured force amplitude (fundamental)
    drive_Vpp: float
    compliance_m_per_N: ComplexValue    # X1 / F1
    compliance_abs_m_per_N: float
    compliance_phase_rad: float
    accelerance_abs_kg_inv: float       # |A1 / F1|
    accelerance_phase_rad: float
    compliance_pp_m_per_N: float        # seed Eq. 9: half the steady peak-to-peak per force amplitude
    force: FitSummary
    accel: FitSummary
    disp: FitSummary
    fs_Hz: float
    n_samples: int
    t0_s: float
    block_id: int
    resends: int
    settle_extra_blocks: int
    # what the step-quality check still finds that settling longer would cure, after the
    # plan's max_extra_settle_blocks (decision 0037); absent or "" = settled
    unsettled: NotRequired[str]


class ControlIteration(TypedDict):
    drive_Vpp: float                    # generator amplitude of the iteration
    force_N: float                      # force fundamental it gave


class BackboneRecord(TypedDict):
    """A phase-resonance point (procedure = "phase_resonance", decision record 0044)."""

    mode: str                           # the plan's name of the mode ("feed", "pitch", ...)
    response: str                       # "disp" or "accel": whose phase the loop held
    amplitude_m: float                  # |X1|: the probe's displacement fundamental (disp), or the drive
                                        # point's, |A1| / w^2 (accel)
    frequency_Hz: float
    phase_deg: float                    # response fundamental's phase minus the force's
    phase_target_deg: float
    phase_error_deg: float
    damping_ratio: float                # |F1| sin(-(phi_x - phi_F)) / (2 m w^2 |X1|), X1 as amplitude_m
    mass_kg: float                      # m of the energy balance: the rig file's expected mass
    locked: bool
    why: str                            # "" when locked, else why not
    periods: int                        # drive periods the point took (ramp, probe, loop, measurement)
    blocks: int                         # controller blocks


class ResponseControlRecord(TypedDict):
    """A response-controlled step (procedure = "response_controlled", decision record 0044)."""

    quantity: str                       # "disp" (m) or "accel" (m/s^2)
    target: float                       # the level: the response fundamental's amplitude asked for
    measured: float                     # the measured block's
    error: float                        # measured / target - 1


class StepResult(StepMeasurement):
    """A step's result as stored: the measurement, where it sits in the plan, and how the
    force control went."""

    key: str                            # plan step key, also the file name
    index: int
    level_index: int
    freq_index: int
    direction: str                      # "up" or "down"
    target_force_N: float
    control_iterations: int
    force_converged: bool
    force_error: float                  # force_N / target_force_N - 1
    control_history: NotRequired[list[ControlIteration]]   # each force-control iteration (decision 0025)
    format_version: NotRequired[int]    # written by the run store; absent = 1
    backbone: NotRequired[BackboneRecord]   # phase-resonance runs only
    response_control: NotRequired[ResponseControlRecord]   # response-controlled runs only


def check_step_version(result: dict, where: str) -> None:
    """Refuse a step file written in a newer format than this version reads."""
    version = result.get("format_version", 1)
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise RunDirectoryError(f"{where}: format_version {version!r} is not a format version")
    if version > STEP_FORMAT_VERSION:
        raise RunDirectoryError(f"{where}: step format version {version}, written by a newer guideway-bench "
                                f"(this one reads versions up to {STEP_FORMAT_VERSION}); update to read it")
