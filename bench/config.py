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
from pathlib import Path

import numpy as np

from procedures.capacity import block_problems, step_count_problems
from procedures.kind import ProcedureKind
from procedures.plan import Backbone, Plan, Rig

from .rig_config import LIMIT_KEYS, RIG_KEYS, _limits, load_rig, model_schema, parse_rig, rig_toml, stored_rig
from .toml_tables import _REQUIRED, MAX_FILE_BYTES, ConfigError, _collecting, _load, _Section, _short, read_toml

__all__ = ["DEFAULTS", "KEYS", "MAX_FILE_BYTES", "MAX_FREQUENCIES", "MAX_LEVELS", "MAX_STEPS", "ConfigError",
           "Plan", "Rig", "load_plan", "load_rig", "model_schema", "parse_plan", "parse_rig", "parse_stored_plan",
           "plan_toml", "read_toml", "rig_toml", "stored_rig"]

log = logging.getLogger(__name__)

# The bench's working range (README, bench/defaults/demo_plan.toml, `bench run --help`):
# force levels 0.1-100 N (force amplitude, half peak-to-peak), frequencies 20-1000 Hz.
MIN_LEVEL_N, MAX_LEVEL_N = 0.1, 100.0
MIN_FREQ_HZ, MAX_FREQ_HZ = 20.0, 1000.0
FORCE_RANGE = f" (the bench's force range, {MIN_LEVEL_N:g}-{MAX_LEVEL_N:g} N)"
FREQ_RANGE = f" (the bench's frequency range, {MIN_FREQ_HZ:g}-{MAX_FREQ_HZ:g} Hz)"
DEFAULTS = Path(__file__).with_name("defaults")

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
                             note=f" (response = \"{response}\": the phase against the force, degrees)"),
        gain=sec.number("gain", 0.7, 0, 1, lo_open=True),
        slope_deg_per_Hz=sec.number("slope_deg_per_Hz", 0.0, -1e4, 0, note=" (0 = estimated; the phase falls "
                                    "with frequency through a resonance)"),
        probe_step=sec.number("probe_step", 0.02, 0.001, 0.2),
        block_periods=sec.number("block_periods", 10, 2, 1000, integer=True),
        phase_band_deg=sec.number("phase_band_deg", 1.0, 0, 30, lo_open=True),
        amplitude_band=sec.number("amplitude_band", 0.01, 0, 0.5, lo_open=True),
        settle_periods=sec.number("settle_periods", 20, 1, 10000, integer=True),
        max_step_Hz=sec.number("max_step_Hz", 0.0, 0, MAX_FREQ_HZ, note=" (0 = 5 % of start_Hz)"),
        min_Hz=sec.number("min_Hz", 0.0, 0, MAX_FREQ_HZ, note=" (0 = start_Hz / 2, at least 20 Hz)"),
        max_Hz=sec.number("max_Hz", 0.0, 0, MAX_FREQ_HZ, note=" (0 = 2 x start_Hz, at most 1000 Hz)"),
        max_blocks=sec.number("max_blocks", 60, 3, 100000, integer=True),
        lost_phase_deg=sec.number("lost_phase_deg", 45.0, 1, 180),
        collapse=sec.number("collapse", 0.2, 0, 1, lo_open=True)).resolved()
    if not MIN_FREQ_HZ <= b.min_Hz < b.start_Hz * (1 - b.probe_step) < b.start_Hz * (1 + b.probe_step) < b.max_Hz \
            <= MAX_FREQ_HZ:
        sec.rule(f"{sec.where('min_Hz')} / max_Hz: the window {b.min_Hz:g}-{b.max_Hz:g} Hz must hold "
                 f"start_Hz {b.start_Hz:g} Hz and its probe blocks (x (1 -+ probe_step {b.probe_step:g})) "
                 f"inside the bench's range {MIN_FREQ_HZ:g}-{MAX_FREQ_HZ:g} Hz",
                 *((sec, k) for k in ("min_Hz", "max_Hz", "start_Hz", "probe_step")))
    if b.phase_band_deg >= b.lost_phase_deg:
        sec.rule(f"{sec.where('phase_band_deg')}: {b.phase_band_deg:g} deg must be below "
                 f"lost_phase_deg {b.lost_phase_deg:g} deg", (sec, "phase_band_deg"), (sec, "lost_phase_deg"))
    sec.done()
    return b


def _response_levels(rc: _Section) -> tuple[list[float], str]:
    """[plan.response] levels, in the unit of its quantity; the table's keys checked."""
    quantity = rc.choice("quantity", "disp", ("disp", "accel"))
    lo, hi, unit = (1e-9, 1e-3, "m") if quantity == "disp" else (1e-4, 1e3, "m/s^2")
    levels = rc.numbers("levels", _REQUIRED, lo, hi, note=f" ({unit}, the response fundamental's amplitude)",
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
            p.problem(f"{p.where('levels_N')}: not used with procedure = \"response_controlled\" "
                      f"(give [plan.response] levels, response amplitudes)")
        levels, quantity = _response_levels(rc)
    elif rc.data:
        p.rule(f"{source}: [plan.response] needs procedure = \"response_controlled\" in [plan]", (p, "procedure"))
        _response_levels(rc)            # its values' own problems too
    if procedure != "response_controlled":
        levels = p.numbers("levels_N", _REQUIRED, MIN_LEVEL_N, MAX_LEVEL_N, note=FORCE_RANGE, most=MAX_LEVELS)
    fr = p.table("frequencies")
    bb = p.table("backbone")
    backbone = None
    if procedure == "phase_resonance":
        if fr.data:
            p.problem(f"{source}: [plan.frequencies] is not used with procedure = \"phase_resonance\" "
                      f"(the controller finds the frequency; give [plan.backbone] start_Hz)")
            fr = _Section(source, "plan.frequencies", {}, errors=p.errors)
        backbone = _backbone(bb)
        freqs = [backbone.start_Hz]
    elif bb.data:
        p.rule(f"{source}: [plan.backbone] needs procedure = \"phase_resonance\" in [plan]", (p, "procedure"))
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
        fr.problem(f"{fr.where('frequencies')}: grid has repeated frequencies")
        freqs = sorted(set(freqs))
    direction = fr.choice("direction", "up", ("up", "down", "both"))
    steps = len(levels) * len(freqs) * (2 if direction == "both" else 1)
    if steps > MAX_STEPS:                     # nothing is expanded after this
        raise ConfigError(f"{source}: [plan] {len(levels)} levels x {len(freqs)} frequencies"
                          f"{' x 2 directions' if direction == 'both' else ''} = {steps} steps; at most {MAX_STEPS} "
                          f"(split the test into several plans)")
    fr.done()
    c = p.table("control")
    lim = p.table("limits")
    res = p.table("resonance")
    modes = res._get("modes", ["feed", "pitch"])
    if not isinstance(modes, list) or not modes or any(m not in ("feed", "pitch") for m in modes):
        res.problem(f"{res.where('modes')}: must be a non-empty list of \"feed\", \"pitch\", got {modes!r}")
        modes = ["feed", "pitch"]
    plan = Plan(
        name=p.text("name", "stepped sine"), levels_N=tuple(levels), freqs_Hz=tuple(freqs),
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
        res.rule(f"{res.where('dwell_cycles')}: needs refine = true (the dwell is at the refined resonance)",
                 (res, "refine"))
    if backbone is not None and plan.adaptive_per_sweep:
        p.problem(f"{p.where('adaptive_per_sweep')}: not used with procedure = \"phase_resonance\"")
    if backbone is not None and plan.refine:
        p.problem(f"{res.where('refine')}: not used with procedure = \"phase_resonance\" (the loop finds the "
                  f"resonance itself)")
    # every fitted harmonic must stay below Nyquist at the highest frequency (the DAQ samples
    # at >= min_sample_rate_Hz); above it harmonics alias and the fit's amplitudes are wrong;
    # phase resonance: anywhere in its frequency window
    top = backbone.max_Hz if backbone is not None else max(plan.freqs_Hz)
    max_harmonics = math.ceil(plan.min_sample_rate_Hz / (2 * top)) - 1
    if plan.harmonics > max_harmonics:
        c.rule(f"{c.where('harmonics')}: must be <= {max_harmonics} (below Nyquist at "
               f"{top:g} Hz with min_sample_rate_Hz = {plan.min_sample_rate_Hz:g}), "
               f"got {plan.harmonics}", (c, "harmonics"), (c, "min_sample_rate_Hz"))
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


def parse_stored_plan(p, source: str) -> Plan:
    """The plan stored in a run's ``run.json`` (``Plan.to_dict()``), checked by the same
    validator as a plan file (:func:`parse_plan`: ranges, bounds, the harmonics below
    Nyquist), with the steps the envelope left out (``skip``).  A ConfigError names
    ``source`` and the key: nothing is counted, reported or resumed against a plan that a
    plan file could not hold."""
    if not isinstance(p, dict):
        raise ConfigError(f"{source}: no plan stored ([plan] missing or not a table: {_short(p)})")
    for key in ("levels_N", "freqs_Hz"):
        if key not in p:
            raise ConfigError(f"{source}: [plan] {key}: missing (required)")
    freqs = p["freqs_Hz"]
    if isinstance(freqs, list) and len(freqs) > MAX_FREQUENCIES:
        raise ConfigError(f"{source}: [plan] freqs_Hz: {len(freqs)} values; at most {MAX_FREQUENCIES}")
    if isinstance(freqs, list) and all(isinstance(f, (int, float)) for f in freqs) and freqs != sorted(freqs):
        raise ConfigError(f"{source}: [plan] freqs_Hz: not in ascending order (the step keys number them so)")
    try:
        plan = parse_plan({"plan": plan_toml(dict({"name": "stepped sine", "direction": "up"}, **p))}, source)
    except ConfigError as e:               # name run.json's key, not the plan file's
        raise ConfigError(str(e).replace("[plan.frequencies] list_Hz", "[plan] freqs_Hz")) from None
    except (TypeError, AttributeError, KeyError) as e:
        raise ConfigError(f"{source}: [plan] not a stored plan ({type(e).__name__}: {e})") from None
    skip = p.get("skip") or []
    if not isinstance(skip, list) or not all(
            isinstance(s, list) and len(s) == 2 and all(isinstance(i, int) and not isinstance(i, bool) for i in s)
            and 0 <= s[0] < len(plan.levels_N) and 0 <= s[1] < len(plan.freqs_Hz) for s in skip):
        raise ConfigError(f"{source}: [plan] skip: must be a list of [level index, frequency index] pairs "
                          f"within the plan, got {_short(skip)}")
    return replace(plan, skip=tuple(tuple(s) for s in skip))
