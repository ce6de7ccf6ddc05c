"""One stepped-sine step's result: the record a procedure produces, a run directory stores
as ``steps/<key>.json`` and every reader (identification, export, reports, watch page,
analysis) reads.  The on-disk schema, field by field, is docs/run-format.md.

It lives in the lowest layer because :mod:`sim.identify` reads it as well as the bench.
A ``TypedDict`` keeps the JSON form and ``result["key"]`` access everywhere; a type
checker sees every field and its type.

Format versions (``format_version`` in each step file; decision record 0027):

- 1: the fields below without ``quality`` and ``harmonics``.  Files written before the
  field existed have the same content and no ``format_version``: they are read as version 1.
- 2 (decision record 0047): the measured fields come from the block's one analysis
  (:func:`sim.step_record.measure_block`: the step-quality check and the harmonics of its
  cleaned records), which the step keeps whole: ``harmonics`` (every harmonic of each
  channel with its standard error, the noise, the periodicity score) and ``quality`` (the
  verdict with its reasons and artefacts); each channel summary has its ``sigma``.  Readers
  take the measured numbers from there and re-assess the raw block of a version-1 step only.

A reader meets a newer version than it knows only when a newer guideway-bench wrote the
file; :func:`check_step_version` names the file and the versions instead of guessing.
"""

from __future__ import annotations

import functools
import types
import typing
from typing import NotRequired, TypedDict

from .errors import RunDirectoryError

STEP_FORMAT_VERSION = 2


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
    sigma: NotRequired[float]           # version 2: standard error of one harmonic's real or imaginary part


class ChannelRecord(TypedDict):
    """Version 2: every harmonic of one channel, C_k = re_k + i im_k of A_k sin(k w t + phi_k)
    (k = 1..K, all below Nyquist, at most 200), the offset, the noise rms per sample and
    one harmonic's standard error (of its real or imaginary part)."""

    re: list[float]
    im: list[float]
    offset: float
    noise_rms: float
    sigma: float


class BlockHarmonics(TypedDict):
    """Version 2: the block's one analysis (:class:`sim.records.PeriodicRecords` of the
    cleaned records; of the raw ones when clipping or a drop-out rejected the block)."""

    freq_Hz: float
    fs_Hz: float
    periods: int                        # whole periods analysed
    samples: int
    start: int                          # first sample kept (periods dropped for a transient)
    drift_sigma: float                  # periodicity score: halves of the record, standard errors
    drift_detail: str                   # its channel and harmonic
    force: ChannelRecord
    accel: ChannelRecord
    disp: ChannelRecord


class QualityRecord(TypedDict):
    """Version 2: the step-quality verdict (:class:`sim.artefacts.StepQuality`, every field)."""

    status: str                         # usable | flagged | rejected
    reason: str                         # why rejected
    notes: list[str]                    # why flagged
    freq_Hz: float | None
    level_N: float | None
    record_s: float | None
    artefacts: list[dict]               # sim.artefacts.Artefact fields (NaN as null)


class BlockMeasurement(TypedDict):
    """What the one analysis of a block gives (:func:`sim.step_record.measure_block`)."""

    freq_Hz: float
    force_N: float                      # measured force amplitude (fundamental)
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
    quality: NotRequired[QualityRecord]      # version 2
    harmonics: NotRequired[BlockHarmonics]   # version 2


class StepMeasurement(BlockMeasurement):
    """What one measured block gives (:meth:`procedures.stepped_sine.SteppedSine.measure`)."""

    drive_Vpp: float
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


# What every reader uses without asking first (export, report, identification): a step file
# without one of them, or with any field of the wrong type, is not a step result.  The
# checksum guards what this code wrote; this guards what it did not (a step of the format
# before checksums, written or edited by hand).
READ_FIELDS = ("key", "index", "level_index", "freq_index", "direction", "freq_Hz", "target_force_N", "force_N",
               "force_error", "drive_Vpp", "compliance_m_per_N", "compliance_abs_m_per_N", "compliance_phase_rad",
               "accelerance_abs_kg_inv", "accelerance_phase_rad", "force", "accel", "disp", "fs_Hz")


def step_fields_problem(result: dict) -> str | None:
    """Why ``result`` is not a step result by its fields (one missing that readers use, or
    any field present of the wrong type, also inside the channel fits), or None."""
    missing = [k for k in READ_FIELDS if k not in result]
    if missing:
        return f"not a step result: lacks {', '.join(missing)}"
    if result["direction"] not in ("up", "down"):
        return f"not a step result: direction: 'up' or 'down' expected, found {str(result['direction'])[:40]!r}"
    version = result.get("format_version", 1)
    if isinstance(version, int) and version >= 2:
        lacking = [k for k in ("quality", "harmonics") if k not in result]
        if lacking:
            return f"not a version-2 step result: lacks {', '.join(lacking)}"
    problem = _typed_problem(result, StepResult, "")
    return f"not a step result: {problem}" if problem else None


# the exact types a JSON reader gives each scalar hint (a bool is not a number; the slow path
# below says why a value of another type, e.g. a subclass, is or is not one)
_SCALAR_TYPES = {float: (float, int), int: (int,), str: (str,), bool: (bool,)}


@functools.cache
def _hints(typed_dict) -> dict:
    return typing.get_type_hints(typed_dict)


def _typed_problem(value, hint, where: str) -> str | None:
    origin = typing.get_origin(hint)
    if origin is typing.NotRequired:
        hint = typing.get_args(hint)[0]
        origin = typing.get_origin(hint)
    if isinstance(hint, type) and typing.is_typeddict(hint):
        if not isinstance(value, dict):
            return f"{where or 'the step'} is not an object"
        hints = _hints(hint)
        for key, sub in value.items():
            if key in hints:
                problem = _typed_problem(sub, hints[key], f"{where}.{key}" if where else key)
                if problem:
                    return problem
        return None
    if origin is types.UnionType:       # X | None
        if value is None and type(None) in typing.get_args(hint):
            return None
        hint = next(h for h in typing.get_args(hint) if h is not type(None))
    if origin is list:
        if not isinstance(value, list):
            return f"{where}: a list was expected, found {type(value).__name__}"
        item = typing.get_args(hint)[0]
        if item in _SCALAR_TYPES:       # a waveform: thousands of numbers, checked by their exact types at once
            allowed = _SCALAR_TYPES[item]
            i = next((i for i, v in enumerate(value) if type(v) not in allowed), None)
            return None if i is None else _typed_problem(value[i], item, f"{where}[{i}]")
        return next((p for i, v in enumerate(value) if (p := _typed_problem(v, item, f"{where}[{i}]"))), None)
    ok = {float: lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
          int: lambda v: isinstance(v, int) and not isinstance(v, bool),
          bool: lambda v: isinstance(v, bool),
          str: lambda v: isinstance(v, str),
          dict: lambda v: isinstance(v, dict)}[hint](value)
    return None if ok else f"{where}: {hint.__name__} expected, found {type(value).__name__} {str(value)[:40]!r}"
