"""Test plan and rig configuration (TOML), validated before anything moves: this module
holds the plan (and the names everything else imports from here); the rig file is
:mod:`bench.rig_config`, reading a file and checking its tables :mod:`bench.toml_tables`.

Every error names the file, the key and the allowed values.  See ``bench/defaults/`` for
annotated examples (the demo's plan and the simulated rig).
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace
from enum import StrEnum
from pathlib import Path

import numpy as np

from procedures.capacity import block_problems, step_count_problems
from procedures.kind import ProcedureKind
from procedures.plan import Backbone, Plan, Rig

from .rig_config import LIMIT_KEYS, RIG_KEYS, _limits, load_rig, model_schema, parse_rig, rig_toml, stored_rig
from .toml_tables import (
    _REQUIRED,
    MAX_FILE_BYTES,
    ConfigError,
    ConfigProblem,
    Line,
    _collecting,
    _error,
    _load,
    _problems,
    _Section,
    _short,
    read_toml,
)
from .words import Said, terminal
from .words.terminal import refused

__all__ = ["DEFAULTS", "KEYS", "MAX_FILE_BYTES", "MAX_FREQUENCIES", "MAX_LEVELS", "MAX_STEPS", "ConfigError",
           "ConfigRule", "Plan", "RangeNote", "Rig", "load_plan", "load_rig", "model_schema", "parse_plan",
           "parse_rig", "parse_stored_plan", "plan_toml", "read_toml", "rig_toml", "stored_rig"]

log = logging.getLogger(__name__)

# The bench's working range (README, bench/defaults/demo_plan.toml, `bench run --help`):
# force levels 0.1-100 N (force amplitude, half peak-to-peak), frequencies 20-1000 Hz.
MIN_LEVEL_N, MAX_LEVEL_N = 0.1, 100.0
MIN_FREQ_HZ, MAX_FREQ_HZ = 20.0, 1000.0
DEFAULTS = Path(__file__).with_name("defaults")
DEFAULT_NAME = ProcedureKind.STEPPED_SINE.label    # a plan's name when it gives none


class RangeNote(StrEnum):
    """Why a value's range is what it is, said after its bounds (the field ``note`` of
    ConfigProblem.OUT_OF_RANGE, a Said; its words: bench.words.terminal_config.NOTE)."""

    FORCE_RANGE = "force_range"             # low, high (N)
    FREQUENCY_RANGE = "frequency_range"     # low, high (Hz)
    PHASE = "phase"                         # response (the quantity the phase is of)
    SLOPE_ESTIMATED = "slope_estimated"     # (0 stands for the estimate)
    MAX_STEP_DEFAULT = "max_step_default"   # (0 stands for the default)
    MIN_HZ_DEFAULT = "min_Hz_default"
    MAX_HZ_DEFAULT = "max_Hz_default"
    RESPONSE_LEVEL = "response_level"       # unit


class ConfigRule(StrEnum):
    """A plan's rule across keys, or a stored plan's problem (its words:
    bench.words.terminal_config.RULE); fields source, table and, where it names one, key."""

    WINDOW_OUTSIDE = "window_outside"             # min_Hz, max_Hz, start_Hz, probe_step, low, high (the bench's)
    BAND_ABOVE_LOST = "band_above_lost"           # band, lost (deg)
    NOT_USED = "not_used"                         # key (None: the table), procedure
    NEEDS_PROCEDURE = "needs_procedure"           # procedure (the table's)
    REPEATED_FREQUENCIES = "repeated_frequencies"
    TOO_MANY_STEPS = "too_many_steps"             # levels, frequencies, both (directions), steps, most
    NOT_MODES = "not_modes"                       # key, allowed, value
    DWELL_NEEDS_REFINE = "dwell_needs_refine"
    ABOVE_NYQUIST = "above_nyquist"               # most, top_Hz, rate_Hz, value
    NO_STORED_PLAN = "no_stored_plan"             # got (what run.json holds, shortened)
    NOT_ASCENDING = "not_ascending"               # key
    NOT_A_STORED_PLAN = "not_a_stored_plan"       # error (its type's name), detail (its words)
    BAD_SKIP = "bad_skip"                         # key, got (shortened)


FORCE_RANGE = Said(RangeNote.FORCE_RANGE, {"low": MIN_LEVEL_N, "high": MAX_LEVEL_N})
FREQ_RANGE = Said(RangeNote.FREQUENCY_RANGE, {"low": MIN_FREQ_HZ, "high": MAX_FREQ_HZ})

# Bounds on a plan's size (decision record 0041; README, docs/run-format.md): checked before
# anything is expanded, so a 10-million-step plan is refused in microseconds.  At a few
# seconds a step, MAX_STEPS is about three days of rig time.
MAX_LEVELS = 1000
MAX_FREQUENCIES = 10_000
MAX_STEPS = 50_000

# Every key each table may hold (a table's path -> its keys); an unknown key is named, with
# the close valid one, before any value is read (a misspelled required key is reported as
# the misspelling, not as the key it was meant to be).  [rig.model]: model_schema().
KEYS = {
    "plan": ("name", "levels_N", "frequencies", "control", "limits", "infeasible", "adaptive_per_sweep",
             "resonance", "procedure", "backbone", "response"),
    "plan.resonance": ("refine", "tolerance", "max_steps", "modes", "dwell_cycles"),
    "plan.response": ("quantity", "levels"),
    "plan.backbone": ("start_Hz", "mode", "response", "phase_deg", "gain", "slope_deg_per_Hz", "probe_step",
                      "block_periods", "phase_band_deg", "amplitude_band", "settle_periods", "max_step_Hz",
                      "min_Hz", "max_Hz", "max_blocks", "lost_phase_deg", "collapse"),
    "plan.frequencies": ("list_Hz", "start_Hz", "stop_Hz", "points", "spacing", "direction"),
    "plan.control": ("settle_cycles", "min_settle_s", "measure_cycles", "min_measure_s", "control_cycles",
                     "force_tolerance", "max_iterations", "harmonics", "ramp_s", "min_sample_rate_Hz",
                     "max_extra_settle_blocks"),
    "plan.limits": LIMIT_KEYS,
    **RIG_KEYS,
}


def _backbone(sec: _Section) -> Backbone:
    """[plan.backbone], each key checked; cross-key rules named with both keys."""
    start = sec.number("start_Hz", _REQUIRED, MIN_FREQ_HZ, MAX_FREQ_HZ, note=FREQ_RANGE)
    response = sec.choice("response", "disp", ("disp", "accel"))
    default_phase = -90.0 if response == "disp" else 90.0
    lo, hi = (-180.0, 0.0) if response == "disp" else (0.0, 180.0)
    b = Backbone(
        start_Hz=start, mode=sec.text("mode", "feed") or "feed", response=response,
        phase_deg=sec.number("phase_deg", default_phase, lo, hi, lo_open=True,
                             note=Said(RangeNote.PHASE, {"response": response})),
        gain=sec.number("gain", 0.7, 0, 1, lo_open=True),
        slope_deg_per_Hz=sec.number("slope_deg_per_Hz", 0.0, -1e4, 0, note=Said(RangeNote.SLOPE_ESTIMATED)),
        probe_step=sec.number("probe_step", 0.02, 0.001, 0.2),
        block_periods=sec.number("block_periods", 10, 2, 1000, integer=True),
        phase_band_deg=sec.number("phase_band_deg", 1.0, 0, 30, lo_open=True),
        amplitude_band=sec.number("amplitude_band", 0.01, 0, 0.5, lo_open=True),
        settle_periods=sec.number("settle_periods", 20, 1, 10000, integer=True),
        max_step_Hz=sec.number("max_step_Hz", 0.0, 0, MAX_FREQ_HZ, note=Said(RangeNote.MAX_STEP_DEFAULT)),
        min_Hz=sec.number("min_Hz", 0.0, 0, MAX_FREQ_HZ, note=Said(RangeNote.MIN_HZ_DEFAULT)),
        max_Hz=sec.number("max_Hz", 0.0, 0, MAX_FREQ_HZ, note=Said(RangeNote.MAX_HZ_DEFAULT)),
        max_blocks=sec.number("max_blocks", 60, 3, 100000, integer=True),
        lost_phase_deg=sec.number("lost_phase_deg", 45.0, 1, 180),
        collapse=sec.number("collapse", 0.2, 0, 1, lo_open=True)).resolved()
    if not MIN_FREQ_HZ <= b.min_Hz < b.start_Hz * (1 - b.probe_step) < b.start_Hz * (1 + b.probe_step) < b.max_Hz \
            <= MAX_FREQ_HZ:
        sec.rule(ConfigRule.WINDOW_OUTSIDE, *((sec, k) for k in ("min_Hz", "max_Hz", "start_Hz", "probe_step")),
                 source=sec.source, table=sec.path, min_Hz=b.min_Hz, max_Hz=b.max_Hz, start_Hz=b.start_Hz,
                 probe_step=b.probe_step, low=MIN_FREQ_HZ, high=MAX_FREQ_HZ)
    if b.phase_band_deg >= b.lost_phase_deg:
        sec.rule(ConfigRule.BAND_ABOVE_LOST, (sec, "phase_band_deg"), (sec, "lost_phase_deg"), source=sec.source,
                 table=sec.path, band=b.phase_band_deg, lost=b.lost_phase_deg)
    sec.done()
    return b


def _response_levels(rc: _Section) -> tuple[list[float], str]:
    """[plan.response] levels, in the unit of its quantity; the table's keys checked."""
    quantity = rc.choice("quantity", "disp", ("disp", "accel"))
    lo, hi, unit = (1e-9, 1e-3, "m") if quantity == "disp" else (1e-4, 1e3, "m/s^2")
    levels = rc.numbers("levels", _REQUIRED, lo, hi, note=Said(RangeNote.RESPONSE_LEVEL, {"unit": unit}),
                        most=MAX_LEVELS)
    rc.done()
    return levels, quantity


def load_plan(path: Path) -> Plan:
    return parse_plan(_load(path), str(path))


def parse_plan(data: dict, source: str = "plan") -> Plan:
    """The plan in ``data``; every independent problem of it named in one ConfigError."""
    return _collecting(_parse_plan, data, source)


def _parse_plan(data: dict, source: str, errors: list[str]) -> Plan:
    top = _Section(source, "", data, ("plan",), errors, KEYS)
    p = top.table("plan")
    top.done()
    procedure = p.choice("procedure", "stepped_sine", ("stepped_sine", "phase_resonance", "response_controlled"))
    rc = p.table("response")
    quantity = ""
    if procedure == "response_controlled":
        if "levels_N" in p.data:
            p.used.add("levels_N")
            p.coded(ConfigRule.NOT_USED, source=source, table=p.path, key="levels_N", procedure=procedure)
        levels, quantity = _response_levels(rc)
    elif rc.data:
        p.rule(ConfigRule.NEEDS_PROCEDURE, (p, "procedure"), source=source, table=rc.path,
               procedure=ProcedureKind.RESPONSE_CONTROLLED)
        _response_levels(rc)            # its values' own problems too
    if procedure != "response_controlled":
        levels = p.numbers("levels_N", _REQUIRED, MIN_LEVEL_N, MAX_LEVEL_N, note=FORCE_RANGE, most=MAX_LEVELS)
    fr = p.table("frequencies")
    bb = p.table("backbone")
    backbone = None
    if procedure == "phase_resonance":
        if fr.data:
            p.coded(ConfigRule.NOT_USED, source=source, table=fr.path, key=None, procedure=procedure)
            fr = _Section(source, "plan.frequencies", {}, errors=p.errors)
        backbone = _backbone(bb)
        freqs = [backbone.start_Hz]
    elif bb.data:
        p.rule(ConfigRule.NEEDS_PROCEDURE, (p, "procedure"), source=source, table=bb.path,
               procedure=ProcedureKind.PHASE_RESONANCE)
        if "start_Hz" in bb.data:       # its values' own problems too
            _backbone(bb)
        else:
            bb.choice("response", "disp", ("disp", "accel"))
            bb.done()
    if procedure == "phase_resonance":
        pass
    elif "list_Hz" in fr.data:
        freqs = sorted(fr.numbers("list_Hz", None, MIN_FREQ_HZ, MAX_FREQ_HZ, note=FREQ_RANGE, most=MAX_FREQUENCIES))
    else:
        start = fr.number("start_Hz", _REQUIRED, MIN_FREQ_HZ, MAX_FREQ_HZ, note=FREQ_RANGE)
        stop = fr.number("stop_Hz", _REQUIRED, start, MAX_FREQ_HZ, note=FREQ_RANGE)
        points = fr.number("points", _REQUIRED, 1, MAX_FREQUENCIES, integer=True)
        spacing = fr.choice("spacing", "log", ("log", "linear"))
        grid = np.geomspace(start, stop, points) if spacing == "log" else np.linspace(start, stop, points)
        freqs = [float(f"{f:.6g}") for f in grid]
    if len(set(freqs)) != len(freqs):
        fr.coded(ConfigRule.REPEATED_FREQUENCIES, source=source, table=fr.path)
        freqs = sorted(set(freqs))
    direction = fr.choice("direction", "up", ("up", "down", "both"))
    steps = len(levels) * len(freqs) * (2 if direction == "both" else 1)
    if steps > MAX_STEPS:                     # nothing is expanded after this
        raise refused(ConfigError, ConfigRule.TOO_MANY_STEPS, source=source, levels=len(levels),
                      frequencies=len(freqs), both=direction == "both", steps=steps, most=MAX_STEPS)
    fr.done()
    c = p.table("control")
    lim = p.table("limits")
    res = p.table("resonance")
    modes = res._get("modes", ["feed", "pitch"])
    if not isinstance(modes, list) or not modes or any(m not in ("feed", "pitch") for m in modes):
        res.coded(ConfigRule.NOT_MODES, source=source, table=res.path, key="modes", allowed=["feed", "pitch"],
                  value=modes)
        modes = ["feed", "pitch"]
    plan = Plan(
        name=p.text("name", DEFAULT_NAME), levels_N=tuple(levels), freqs_Hz=tuple(freqs),
        direction=direction,
        settle_cycles=c.number("settle_cycles", 20, 0, 1e6, integer=True),
        min_settle_s=c.number("min_settle_s", 0.05, 0, 3600),
        measure_cycles=c.number("measure_cycles", 10, 1, 1e6, integer=True),
        min_measure_s=c.number("min_measure_s", 0.0, 0, 3600),
        control_cycles=c.number("control_cycles", 4, 1, 1e6, integer=True),
        force_tolerance=c.number("force_tolerance", 0.02, 0, 0.5, lo_open=True),
        max_iterations=c.number("max_iterations", 8, 1, 100, integer=True),
        harmonics=c.number("harmonics", 5, 1, 50, integer=True),
        ramp_s=c.number("ramp_s", 0.1, 0, 60),
        min_sample_rate_Hz=c.number("min_sample_rate_Hz", 25600.0, 1000, 204800),
        max_extra_settle_blocks=c.number("max_extra_settle_blocks", 3, 0, 100, integer=True),
        limits=_limits(lim, required=False) if lim.data else None,
        infeasible=p.choice("infeasible", "refuse", ("refuse", "skip")),
        adaptive_per_sweep=p.number("adaptive_per_sweep", 0, 0, 10000, integer=True),
        refine=res.flag("refine", False),
        refine_tolerance=res.number("tolerance", 0.002, 0, 0.1, lo_open=True),
        refine_steps=res.number("max_steps", 10, 1, 999, integer=True),
        refine_modes=tuple(dict.fromkeys(modes)),
        dwell_cycles=res.number("dwell_cycles", 0, 0, 1e6, integer=True),
        procedure=ProcedureKind(procedure), backbone=backbone, response=quantity)
    res.done()
    if plan.dwell_cycles and not plan.refine:
        res.rule(ConfigRule.DWELL_NEEDS_REFINE, (res, "refine"), source=source, table=res.path)
    if backbone is not None and plan.adaptive_per_sweep:
        p.coded(ConfigRule.NOT_USED, source=source, table=p.path, key="adaptive_per_sweep", procedure=procedure)
    if backbone is not None and plan.refine:
        p.coded(ConfigRule.NOT_USED, source=source, table=res.path, key="refine", procedure=procedure)
    # every fitted harmonic must stay below Nyquist at the highest frequency (the DAQ samples
    # at >= min_sample_rate_Hz); above it harmonics alias and the fit's amplitudes are wrong;
    # phase resonance: anywhere in its frequency window
    top = backbone.max_Hz if backbone is not None else max(plan.freqs_Hz)
    max_harmonics = math.ceil(plan.min_sample_rate_Hz / (2 * top)) - 1
    if plan.harmonics > max_harmonics:
        c.rule(ConfigRule.ABOVE_NYQUIST, (c, "harmonics"), (c, "min_sample_rate_Hz"), source=source, table=c.path,
               most=max_harmonics, top_Hz=top, rate_Hz=plan.min_sample_rate_Hz, value=plan.harmonics)
    if not (p.bad | fr.bad | bb.bad | c.bad | res.bad):   # a stand-in for a bad value makes blocks no plan asks for
        _instrument_capacity(p, plan, source)
    c.done()
    p.done()
    return plan


def _instrument_capacity(p: _Section, plan: Plan, source: str) -> None:
    """Every block, sample rate and step count the plan makes against what the DAQ and the
    bench take (procedures.capacity, decision 0050), each problem named with its key."""
    for problem in block_problems(plan, source) + step_count_problems(plan, source, MAX_STEPS):
        p.problem(problem)



def plan_toml(p: dict) -> dict:
    """The stored plan back into the TOML layout (the stored grid is used verbatim)."""
    keys = ("settle_cycles", "min_settle_s", "measure_cycles", "min_measure_s", "control_cycles", "force_tolerance",
            "max_iterations", "harmonics", "ramp_s", "min_sample_rate_Hz", "max_extra_settle_blocks")
    def as_list(v):              # anything else is left for the validator to name
        return list(v) if isinstance(v, (list, tuple)) else v
    out = {"name": p["name"], "levels_N": as_list(p["levels_N"]), "infeasible": p.get("infeasible", "refuse"),
           "adaptive_per_sweep": p.get("adaptive_per_sweep", 0),
           "frequencies": {"list_Hz": as_list(p["freqs_Hz"]), "direction": p["direction"]},
           "control": {k: p[k] for k in keys if k in p}}
    res = {"refine": bool(p.get("refine")), "tolerance": p.get("refine_tolerance", 0.002),
           "max_steps": p.get("refine_steps", 10), "modes": list(p.get("refine_modes") or ("feed", "pitch")),
           "dwell_cycles": p.get("dwell_cycles", 0)}
    if res["refine"] or res != {"refine": False, "tolerance": 0.002, "max_steps": 10, "modes": ["feed", "pitch"],
                                "dwell_cycles": 0}:       # refine off with its settings kept: they come back
        out["resonance"] = res
    if p.get("procedure", "stepped_sine") == "response_controlled":
        out["procedure"] = "response_controlled"
        out["response"] = {"quantity": p["response"], "levels": out.pop("levels_N")}
    if p.get("procedure", "stepped_sine") == "phase_resonance":
        del out["frequencies"], out["adaptive_per_sweep"]
        out["procedure"], out["backbone"] = "phase_resonance", dict(p["backbone"])
    if p.get("limits"):
        out["limits"] = {k: v for k, v in p["limits"].items() if v is not None}   # None: the rig's
    return out


def _as_stored(e: ConfigError) -> ConfigError:
    """``e``, a stored plan's problems, with the plan file's frequency list named as run.json
    names it (``[plan] freqs_Hz``, its fields: the words follow), each problem's code kept."""
    lines = []
    for said in _problems(e):
        fields = dict(said.fields)
        key = str(fields.get("key", ""))
        if said.code is not None and fields.get("table") == "plan.frequencies" and key.startswith("list_Hz"):
            fields.update(table="plan", key="freqs_Hz" + key.removeprefix("list_Hz"))
        lines.append(Line(terminal.config(said.code, **fields), said.code, fields) if said.code is not None
                     else Line(fields["text"]))
    return _error("\n".join(lines), lines)


def parse_stored_plan(p, source: str) -> Plan:
    """The plan stored in a run's ``run.json`` (``Plan.to_dict()``), checked by the same
    validator as a plan file (:func:`parse_plan`: ranges, bounds, the harmonics below
    Nyquist), with the steps the envelope left out (``skip``).  A ConfigError names
    ``source`` and the key: nothing is counted, reported or resumed against a plan that a
    plan file could not hold."""
    if not isinstance(p, dict):
        raise refused(ConfigError, ConfigRule.NO_STORED_PLAN, source=source, got=_short(p))
    for key in ("levels_N", "freqs_Hz"):
        if key not in p:
            raise refused(ConfigError, ConfigProblem.MISSING, source=source, table="plan", key=key)
    freqs = p["freqs_Hz"]
    if isinstance(freqs, list) and len(freqs) > MAX_FREQUENCIES:
        raise refused(ConfigError, ConfigProblem.TOO_MANY, source=source, table="plan", key="freqs_Hz",
                      count=len(freqs), most=MAX_FREQUENCIES)
    if isinstance(freqs, list) and all(isinstance(f, (int, float)) for f in freqs) and freqs != sorted(freqs):
        raise refused(ConfigError, ConfigRule.NOT_ASCENDING, source=source, table="plan", key="freqs_Hz")
    try:
        plan = parse_plan({"plan": plan_toml(dict({"name": DEFAULT_NAME, "direction": "up"}, **p))}, source)
    except ConfigError as e:               # name run.json's key, not the plan file's
        raise _as_stored(e) from None
    except (TypeError, AttributeError, KeyError) as e:
        raise refused(ConfigError, ConfigRule.NOT_A_STORED_PLAN, source=source, error=type(e).__name__,
                      detail=str(e)) from None
    skip = p.get("skip") or []
    if not isinstance(skip, list) or not all(
            isinstance(s, list) and len(s) == 2 and all(isinstance(i, int) and not isinstance(i, bool) for i in s)
            and 0 <= s[0] < len(plan.levels_N) and 0 <= s[1] < len(plan.freqs_Hz) for s in skip):
        raise refused(ConfigError, ConfigRule.BAD_SKIP, source=source, table="plan", key="skip", got=_short(skip))
    return replace(plan, skip=tuple(tuple(s) for s in skip))
