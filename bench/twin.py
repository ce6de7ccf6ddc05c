"""``bench twin SOURCE``: a simulated rig (and its plan) that behaves like the measured one.

SOURCE is a run directory or a UFF58 file of time records (:mod:`bench.sources`).  The
analysis (:mod:`bench.analyze`, or an existing ``analysis.json`` given with ``--analysis``)
supplies F_s, x_s, n, m and the causes it named; this module turns them into

- ``rig.toml``: ``[rig.model]`` with the identified friction and mass, every named cause
  as a plant or sensor effect (:data:`CAUSE_KEYS`), the measured noise of each channel, the
  measured drive-voltage-to-force ratio; the source rig's calibration, limits and
  expected values when the source is a run (documented defaults for a foreign file);
  ``simulated = true``;
- ``plan.toml``: the source's force levels, frequencies, sweep direction and
  settle/measure cycles (a run's plan verbatim; a file's rebuilt from its steps);
- ``twin.json``: the same in machine-readable form, with provenance, the parameters'
  intervals and ``not_in_plant``: every named cause (or part of one) the plant cannot
  represent, with the reason.  Nothing is dropped silently; the TOML files list them too.

Both TOML files carry their provenance (source path, its SHA-256, the analysis' and this
software's version) in header comments: the config loaders accept no extra tables, so the
files stay loadable by every ``bench`` command.  Decision record 0026.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

import numpy as np

from sim.artefacts import REPEAT_STEPS, mains_line
from sim.discrepancy.analysis import level_groups, stored_analysis
from sim.errors import ConfigurationError
from sim.rig import RigModel, model_keys
from sim.shaker_fit import documented_shaker, shaker_model

from . import __version__
from .analyze import analyze_source
from .config import (
    DEFAULTS,
    MAX_FREQ_HZ,
    MAX_LEVEL_N,
    MIN_FREQ_HZ,
    MIN_LEVEL_N,
    load_rig,
    parse_plan,
    parse_rig,
    plan_toml,
    rig_toml,
)
from .files import MAX_BYTES, read_file
from .sources import Source, SourceProblem, load_source
from .storage import write_json
from .words import terminal_data as words

log = logging.getLogger(__name__)

SCHEMA = "guideway-bench/twin/2"
PITCH_DRIVE_HEIGHT_M = 0.1     # h of a foreign rig's pitching mode (only h^2/J, e/h, k_th/J, c_th/J are observable)
FOREIGN_MIN_AMP_GAIN = 20.0    # N/V, the simulated rig's amplifier, raised if the largest level needs more than 5 V
FOREIGN_SIGNAL_V = 5.0         # a foreign file's largest reading is put at this voltage (the DAQ clips at 10 V)
FREQ_MERGE = 1e-3              # a file's step frequencies within 0.1 % are one plan frequency


class NotInPlant(StrEnum):
    """Why a cause the analysis named is not in the twin's plant (twin.json's ``not_in_plant``;
    words: :data:`bench.words.terminal_data.NOT_IN_PLANT`)."""

    UNSETTLED = "unsettled"                 # an unsettled transient: the rig's own free vibration
    FREE_VIBRATION = "free_vibration"       # freq_Hz, steps: a line in too few steps, not mains
    NO_FORM = "no_form"                     # no entry in CAUSE_KEYS
    NO_PARAMETER = "no_parameter"           # parameter: the one the analysis does not give
    NOT_IN_THIS_PLANT = "not_in_this_plant"  # absent: keys RigModel lacks; keys: the cause's
    TAKEN = "taken"                         # taken: keys, owners: the causes that took them; keys
    NOT_A_PLANT = "not_a_plant"             # detail: the rig loader's error
    UNEXPLAINED = "unexplained"             # reasons: the analysis' first three


class TwinNote(StrEnum):
    """A default the twin used, and why (twin.json's ``notes``; words:
    :data:`bench.words.terminal_data.TWIN_NOTE`)."""

    LEVELS_OUT = "levels_out"               # levels, low, high (N)
    FREQS_OUT = "freqs_out"                 # count, low, high (Hz)
    DIRECTION_FROM_ORDER = "direction_from_order"   # direction
    PLAN_DEFAULTS = "plan_defaults"
    FOREIGN_RIG = "foreign_rig"
    NO_DRIVE_VOLTAGE = "no_drive_voltage"   # gain (N/V)


class TwinSaid(StrEnum):
    """``bench twin``'s refusals and warning, and the names and comments of the files it
    writes (words: :data:`bench.words.terminal_data.TWIN`)."""

    NO_LEVEL_OR_FREQ = "no_level_or_freq"   # path, level_low, level_high, freq_low, freq_high
    NO_ANALYSIS = "no_analysis"             # path
    ANALYSIS_NOT_JSON = "analysis_not_json"  # path, detail: the parser's error
    ANALYSIS_NOT_OBJECT = "analysis_not_object"     # path
    ANALYSIS_SCHEMA = "analysis_schema"     # path, schema
    NO_STEPS = "no_steps_for_twin"          # path
    ANALYSIS_OF_ANOTHER = "analysis_of_another"     # analysis, of, source (a warning)
    NO_TOML_FORM = "no_toml_form"           # name: the value's type
    RIG_NAME = "rig_name"                   # source, plain
    RIG_NOTES = "rig_notes"                 # source, rig: the source rig's name or None
    PLAN_NAME = "plan_name"                 # name: the source plan's
    RIG_LABEL = "rig_label"                 # the rig's name in its loader's errors
    PLAN_LABEL = "plan_label"
    RIG_HEADER = "rig_header"               # provenance
    PLAN_HEADER = "plan_header"             # provenance
    RIG_COMMENTS = "rig_comments"           # parameters, applied, shaker, not_in_plant, notes


def _value(params: dict, name: str, scale: float = 1.0) -> float:
    return float(params[name]["value"]) * scale


# ---------------------------------------------------------------------------- causes -> [rig.model]
# cause id -> function(cause parameters, context) -> {[rig.model] key: value}.  The context
# holds the twin's mass (kg) and the source rig model's drive height (m) if it has one.  A
# KeyError (a parameter the analysis does not give) lists the cause as not in the plant, as
# does a key sim.rig.RigModel does not declare or declares as not in the plant (in_plant).


def _second_mode(p: dict, ctx: dict) -> dict:
    """The analysis' pitching mode (f_p, zeta, coupling m h^2/J, r = e/h) as plant fields.
    Only h^2/J, e/h, k_th/J and c_th/J are observable; h is the source rig's, else 0.1 m."""
    h = ctx.get("drive_height_m") or PITCH_DRIVE_HEIGHT_M
    w_p = 2 * math.pi * _value(p, "frequency")
    J = ctx["mass_kg"] * h * h / _value(p, "coupling")
    e = _value(p, "cg_over_drive_height") * h
    return dict(pitch_inertia_kg_m2=J, pitch_stiffness_N_m_per_rad=J * w_p ** 2,
                pitch_damping_N_m_s_per_rad=2 * _value(p, "damping_ratio") * w_p * J,
                drive_height_m=h, cg_height_m=e)


CAUSE_KEYS = {
    # catalog (sim.discrepancy.models)
    "viscous_damping": lambda p, ctx: {"viscous_N_s_per_m": _value(p, "c")},
    "linear_spring": lambda p, ctx: {"spring_N_per_m": _value(p, "k")},
    "velocity_dependent_friction": lambda p, ctx: {"friction_alpha": _value(p, "alpha"),
                                                   "friction_v_ref_m_per_s": _value(p, "v_ref")},
    "sensor_delay": lambda p, ctx: {"disp_delay_s": _value(p, "delay")},
    "sensor_gain_error": lambda p, ctx: {"disp_gain_error": _value(p, "gain_error")},
    "second_mode": _second_mode,
    # forms beyond the catalog (discovered terms and artefacts)
    "cubic_stiffness": lambda p, ctx: {"cubic_spring_N_per_m3": _value(p, "k3")},
    "quadratic_damping": lambda p, ctx: {"quadratic_damping_N_s2_per_m2": _value(p, "c2")},
    "asymmetric_friction": lambda p, ctx: {"friction_asymmetry": _value(p, "a")},     # the analysis' name
    "line_interference": lambda p, ctx: {"line_channel": str(p["channel"]["value"]),
                                         "line_freq_Hz": _value(p, "frequency"),
                                         "line_amplitude": _value(p, "amplitude")},
}


# ---------------------------------------------------------------------------- the shaker
# The fit itself is system identification: sim/shaker_fit.py (decision records 0032, 0057).

def shaker_defaults() -> dict:
    """The documented defaults (bench/defaults/sim_rig.toml) as the shaker fit needs them:
    R, and the value of a shaker parameter the steps cannot determine."""
    import tomllib
    return documented_shaker(tomllib.loads((DEFAULTS / "sim_rig.toml").read_text())["rig"]["model"])


def check_model(model: dict) -> None:
    """ValueError naming the key when ``model`` is not a valid [rig.model] (as `bench run`
    would load it: the simulated rig's file with this model)."""
    import tomllib
    rig = tomllib.loads((DEFAULTS / "sim_rig.toml").read_text())
    rig["rig"]["model"] = model
    parse_rig(rig, "twin")


def _free_vibration(cause: dict) -> tuple[NotInPlant, dict] | None:
    """Why ``cause`` is the measured rig's own free vibration, which a twin never builds in
    (its plant rings by itself when its steps change), as a code and its fields, or None: an
    unsettled transient, or a "line" no steady source explains (in fewer than
    ``REPEAT_STEPS`` steps and not mains: the fundamental, or a harmonic in at least 2 steps;
    an analysis.json written before decision 0045 named those lines)."""
    if cause["id"] == "unsettled_transient":
        return NotInPlant.UNSETTLED, {}
    if cause["id"] != "line_interference":
        return None
    f = cause.get("parameters", {}).get("frequency", {}).get("value")
    steps = cause.get("evidence", {}).get("steps", [])
    src = mains_line(float(f)) if f is not None else None
    if f is None or len(steps) >= REPEAT_STEPS or (src is not None and (src[1] == 1 or len(steps) >= 2)):
        return None
    return NotInPlant.FREE_VIBRATION, dict(freq_Hz=float(f), steps=len(steps))


def _missed(cause: str, code: NotInPlant, **fields) -> dict:
    """A cause not in the plant, with its reason's words (twin.json's ``not_in_plant``)."""
    return dict(cause=cause, reason=words.said(code, **fields))


def apply_causes(model: dict, causes: list[dict], ctx: dict) -> tuple[dict, dict, list[dict]]:
    """``model`` ([rig.model] keys) with every cause of ``causes`` (analysis.json's
    ``causes``) that the plant can represent: (new model, {cause id: keys written},
    [{cause, reason}] for the rest).  ``ctx``: the twin's ``mass_kg`` and the source rig's
    ``drive_height_m`` (or None)."""
    known = {k for k, key in model_keys().items() if key.in_plant}
    applied, missed = {}, []
    for c in causes:
        cid = c["id"]
        why_not = _free_vibration(c)
        if why_not is not None:
            missed.append(_missed(cid, why_not[0], **why_not[1]))
            continue
        if cid not in CAUSE_KEYS:
            missed.append(_missed(cid, NotInPlant.NO_FORM))
            continue
        params = dict(c.get("parameters", {}))
        if "channel" in c and "channel" not in params:     # an artefact's channel is the cause's, not a parameter
            params["channel"] = dict(value=c["channel"])
        try:
            keys = CAUSE_KEYS[cid](params, ctx)
        except KeyError as e:
            missed.append(_missed(cid, NotInPlant.NO_PARAMETER, parameter=e.args[0]))
            continue
        absent = sorted(set(keys) - known)
        if absent:
            missed.append(_missed(cid, NotInPlant.NOT_IN_THIS_PLANT, absent=absent, keys=keys))
            continue
        taken = {k: owner for owner, ks in applied.items() for k in ks if k in keys}
        if taken:
            missed.append(_missed(cid, NotInPlant.TAKEN, taken=sorted(taken), owners=sorted(set(taken.values())),
                                  keys=keys))
            continue
        trial = dict(model, **keys)
        try:
            check_model(trial)
        except ValueError as e:
            missed.append(_missed(cid, NotInPlant.NOT_A_PLANT, detail=str(e)))
            continue
        model = trial
        applied[cid] = keys
    return model, applied, missed


@dataclass
class Twin:
    rig: dict                    # the TOML layout of rig.toml (top table "rig")
    plan: dict                   # the TOML layout of plan.toml (top table "plan")
    provenance: dict
    parameters: dict             # F_s_N, x_s_m, n, mass_kg: {value, low, high}
    causes: list[str]
    applied: dict                # cause id -> {key: value} written to [rig.model]
    not_in_plant: list[dict] = field(default_factory=list)    # {cause, reason}
    notes: list[str] = field(default_factory=list)            # defaults used, and why
    drive_ratio: list[dict] = field(default_factory=list)     # {freq_Hz, N_per_V, Z_s_N_s_per_m} per step of a run
    shaker: dict = field(default_factory=dict)                # ShakerFit.as_dict() of a run, {} for a file

    def to_dict(self) -> dict:
        return dict(schema=SCHEMA, provenance=self.provenance, parameters=self.parameters, causes=self.causes,
                    applied=self.applied, not_in_plant=self.not_in_plant, notes=self.notes,
                    drive_ratio=self.drive_ratio, shaker=self.shaker, rig=self.rig, plan=self.plan)


# ---------------------------------------------------------------------------- provenance


def source_sha256(path: Path) -> str:
    """SHA-256 of a file; of a run directory, over the names and bytes of steps/* in sorted
    order (the measurement: run.json changes when a run is identified again)."""
    h = hashlib.sha256()
    if path.is_dir():
        for f in sorted((path / "steps").glob("*")):
            try:
                data = read_file(f)              # regular files only, bounded (bench.files)
            except (OSError, ValueError):
                continue
            h.update(os.fsencode(f.name) + b"\0")
            h.update(data)
    else:
        h.update(path.read_bytes())
    return h.hexdigest()


# ---------------------------------------------------------------------------- measured quantities


def channel_noise(src: Source) -> dict:
    """Median per-sample noise rms of each channel over the steps (from the harmonics'
    standard errors: sigma = rms sqrt(2 / N), N the samples analysed)."""
    out = {}
    for key, attr in (("force_noise_N", "sigma_force"), ("accel_noise_m_s2", "sigma_accel"),
                      ("disp_noise_m", "sigma_disp")):
        vals = [getattr(s.harmonics, attr) * math.sqrt(s.periods * s.fs_Hz / s.freq_Hz / 2.0)
                for s in src.steps if s.periods > 0]
        vals = [v for v in vals if math.isfinite(v)]
        out[key] = float(np.median(vals)) if vals else 0.0
    return out


def drive_ratio(src: Source) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frequencies, |P1| / |V| (N/V), drive-point impedance j w P1 / A1 (N s/m)) of a run's
    usable steps: the force fundamental of the measured block per generator amplitude
    (drive_Vpp / 2) of that block, and the impedance from the same block's force and
    acceleration (the impedance head's accelerometer sits at the drive point).  A file has
    no drive voltage: empty arrays."""
    if src.kind != "run":
        return np.zeros(0), np.zeros(0), np.zeros(0, complex)
    from .storage import RunStore
    vpp = {str(r.get("key")): r.get("drive_Vpp") for r in RunStore.open(src.path).results(warn=False)}
    f, r, z = [], [], []
    for s in src.steps:
        v = vpp.get(s.key)
        P1, A1 = complex(s.harmonics.force[0]), complex(s.harmonics.accel[0])
        if v and v > 0 and abs(P1) > 0 and abs(A1) > 0:
            f.append(float(s.freq_Hz))
            r.append(abs(P1) / (0.5 * float(v)))
            z.append(2j * math.pi * s.freq_Hz * P1 / A1)
    return np.array(f), np.array(r), np.array(z, complex)


def _sig(x: float, digits: int = 6) -> float:
    return float(f"{x:.{digits}g}")


def plan_from_steps(src: Source) -> tuple[dict, list[str]]:
    """A file's plan: levels (median force amplitude per level group), frequencies (merged
    within 0.1 %), sweep direction (the steps' tags, else their order), measure cycles (the
    records' periods); settle cycles and the rest are the plan defaults (listed in notes)."""
    notes = []
    levels_N = np.array([s.level_N for s in src.steps])
    group = level_groups(levels_N)
    levels = [_sig(float(np.median(levels_N[group == g])), 4) for g in np.unique(group)]
    out = [lv for lv in levels if not MIN_LEVEL_N <= lv <= MAX_LEVEL_N]
    if out:
        notes.append(words.said(TwinNote.LEVELS_OUT, levels=out, low=MIN_LEVEL_N, high=MAX_LEVEL_N))
        levels = [lv for lv in levels if MIN_LEVEL_N <= lv <= MAX_LEVEL_N]
    freqs: list[float] = []
    for f in sorted(s.freq_Hz for s in src.steps):
        if not freqs or f > freqs[-1] * (1 + FREQ_MERGE):
            freqs.append(f)
    out = [f for f in freqs if not MIN_FREQ_HZ <= f <= MAX_FREQ_HZ]
    if out:
        notes.append(words.said(TwinNote.FREQS_OUT, count=len(out), low=MIN_FREQ_HZ, high=MAX_FREQ_HZ))
    freqs = [_sig(f) for f in freqs if MIN_FREQ_HZ <= f <= MAX_FREQ_HZ]
    if not (levels and freqs):
        raise words.refused(ConfigurationError, TwinSaid.NO_LEVEL_OR_FREQ, path=src.path, level_low=MIN_LEVEL_N,
                            level_high=MAX_LEVEL_N, freq_low=MIN_FREQ_HZ, freq_high=MAX_FREQ_HZ)
    dirs = {s.direction for s in src.steps if s.direction}
    if dirs:
        direction = "both" if dirs >= {"up", "down"} else dirs.pop()
    else:       # the order of the steps in the file, within each level
        trend = 0
        for g in np.unique(group):
            fs = [s.freq_Hz for s, gg in zip(src.steps, group) if gg == g]
            trend += int(np.sign(np.sum(np.sign(np.diff(fs))))) if len(fs) > 1 else 0
        direction = "down" if trend < 0 else "up"
        notes.append(words.said(TwinNote.DIRECTION_FROM_ORDER, direction=direction))
    periods = [s.periods for s in src.steps if s.periods > 0]
    fs_min = min(s.fs_Hz for s in src.steps)
    min_rate = float(min(204800.0, max(25600.0, _sig(fs_min, 4))))
    nyquist = math.ceil(min_rate / (2 * max(freqs))) - 1
    control = dict(settle_cycles=20, measure_cycles=int(np.median(periods)) if periods else 10,
                   min_sample_rate_Hz=min_rate, harmonics=int(max(1, min(9, nyquist))))
    notes.append(words.said(TwinNote.PLAN_DEFAULTS))
    plan = dict(name=words.said(TwinSaid.PLAN_NAME, name=src.path.name), levels_N=levels, infeasible="skip",
                frequencies=dict(list_Hz=freqs, direction=direction), control=control)
    return plan, notes


def _foreign_rig(src: Source, params: dict, noise: dict) -> tuple[dict, list[str]]:
    """Calibration, limits and expected values for a file: the simulated rig's calibration,
    sensitivities lowered so the largest reading stays at 5 V, an amplifier gain that
    reaches the largest level with at most 5 V of drive, limits twice the plan's envelope
    and three times the largest measured peaks."""
    rig = load_rig(DEFAULTS / "sim_rig.toml")
    peak = {k: max(float(np.max(np.abs(getattr(s, k)))) for s in src.steps)
            for k in ("force_N", "accel_m_s2", "disp_m")}
    F_max = max(s.level_N for s in src.steps)
    f_min = min(s.freq_Hz for s in src.steps)
    m, x_s = params["mass_kg"]["value"], params["x_s_m"]["value"]
    amp = max(FOREIGN_MIN_AMP_GAIN, 1.25 * F_max / 5.0)
    cal = dict(force_V_per_N=min(rig.force_V_per_N, FOREIGN_SIGNAL_V / peak["force_N"]),
               accel_V_per_m_s2=min(rig.accel_V_per_m_s2, FOREIGN_SIGNAL_V / peak["accel_m_s2"]),
               disp_V_per_m=min(rig.disp_V_per_m, FOREIGN_SIGNAL_V / peak["disp_m"]), amp_gain_N_per_V=amp)
    cal = {k: _sig(v, 4) for k, v in cal.items()}
    Fp = 1.25 * F_max
    env_disp = Fp / (m * (2 * math.pi * f_min) ** 2) + 3 * x_s
    limits = dict(drive_V=10.0, force_N=_sig(min(1000.0, 2 * Fp), 4),
                  disp_m=_sig(min(0.01, max(2 * env_disp, 3 * peak["disp_m"])), 4),
                  accel_m_s2=_sig(min(1e4, max(2 * Fp / m, 3 * peak["accel_m_s2"])), 4))
    notes = [words.said(TwinNote.FOREIGN_RIG)]
    return dict(calibration=cal, limits=limits), notes


# ---------------------------------------------------------------------------- the twin


def load_analysis(path: Path) -> dict:
    p = Path(path)
    f = p / "analysis.json" if p.is_dir() else p
    if not f.is_file():
        raise words.refused(ConfigurationError, TwinSaid.NO_ANALYSIS, path=path)
    try:
        d = json.loads(read_file(f, MAX_BYTES["analysis.json"]))
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as e:
        raise words.refused(ConfigurationError, TwinSaid.ANALYSIS_NOT_JSON, path=f, detail=str(e)) from None
    if not isinstance(d, dict):
        raise words.refused(ConfigurationError, TwinSaid.ANALYSIS_NOT_OBJECT, path=f)
    if not str(d.get("schema", "")).startswith("guideway-bench/analysis/"):
        raise words.refused(ConfigurationError, TwinSaid.ANALYSIS_SCHEMA, path=f, schema=d.get("schema"))
    return stored_analysis(d)


def build_twin(source: Path, analysis: dict, *, plain: bool = False, src: Source | None = None) -> Twin:
    """The twin of SOURCE from its analysis dict (``plain``: only the base model's F_s, x_s,
    n, m and the noise: a plain Masing twin, to show what the named causes buy).  ``src``:
    SOURCE already read by :func:`bench.sources.load_source`."""
    source = Path(source)
    src = src if src is not None else load_source(source)
    if not src.steps:
        raise words.refused(ConfigurationError, TwinSaid.NO_STEPS, path=source)
    params = analysis["base"]["parameters"] if plain else analysis["parameters"]
    causes = [] if plain else list(analysis.get("causes", []))
    friction = "masing" if plain else str(analysis.get("friction_model", "masing"))
    rival: dict = {}
    reported = params
    if friction == "dahl":       # the preferred model's own parameters (decision 0078); Masing's slots for the rig's scale
        rival = dict(friction="dahl", **{k: params[k]["value"] for k in ("F_c_N", "sigma_N_per_m", "exponent")})
        params = dict(params, F_s_N=params["F_c_N"], x_s_m=dict(value=rival["F_c_N"] / rival["sigma_N_per_m"]),
                      n=dict(value=1.5))
    notes: list[str] = []
    meta_rig = src.metadata.get("rig") if src.kind == "run" else None
    src_model = (meta_rig or {}).get("model") or {}
    noise = channel_noise(src)

    # rig file: the source's own, or defaults for a file
    if meta_rig:
        rig = rig_toml(meta_rig)
        rig.pop("model", None)
        rig["instruments"] = {}
    else:
        rig, n = _foreign_rig(src, params, noise)
        rig.update(expected=dict(mass_kg=_sig(params["mass_kg"]["value"]), x_s_m=_sig(params["x_s_m"]["value"]),
                                 F_s_N=_sig(params["F_s_N"]["value"]), n=_sig(min(10.0, max(0.05, params["n"]["value"])))))
        notes += n
    rig["name"] = words.said(TwinSaid.RIG_NAME, source=source.name, plain=plain)
    rig["notes"] = words.said(TwinSaid.RIG_NOTES, source=source, rig=meta_rig["name"] if meta_rig else None)
    rig["simulated"] = True
    cal = rig["calibration"]

    head = rival or dict(F_s_N=params["F_s_N"]["value"], x_s_m=params["x_s_m"]["value"], n=params["n"]["value"])
    model = dict(**head, mass_kg=params["mass_kg"]["value"], force_sens_V_per_N=cal["force_V_per_N"],
                 accel_sens_V_per_m_s2=cal["accel_V_per_m_s2"], disp_sens_V_per_m=cal["disp_V_per_m"], **noise)
    f_r, ratio, Zs = drive_ratio(src)
    shaker = shaker_model(f_r, ratio, Zs, shaker_defaults())
    model["amp_gain_N_per_V"] = float(np.median(ratio)) if ratio.size else cal["amp_gain_N_per_V"]
    model.update(shaker.keys)
    not_in_plant = list(shaker.not_fitted)
    if shaker.note:
        notes.append(shaker.note)
    if not ratio.size:
        notes.append(words.said(TwinNote.NO_DRIVE_VOLTAGE, gain=cal["amp_gain_N_per_V"]))
    if "amp_force_limit_N" in src_model:
        model["amp_force_limit_N"] = src_model["amp_force_limit_N"]
    model["amp_force_limit_N"] = max(model.get("amp_force_limit_N", RigModel.amp_force_limit_N),
                                     2 * max(s.level_N for s in src.steps))
    for k in ("probe_standoff_m", "steps_per_period"):
        if k in src_model:
            model[k] = src_model[k]
    # a noise realisation of its own: a simulated source's seed + 1
    model["seed"] = int(src_model.get("seed", 0)) + 1

    ctx = dict(mass_kg=model["mass_kg"], drive_height_m=src_model.get("drive_height_m"))
    model, applied, missed = apply_causes(model, causes, ctx)
    not_in_plant += missed
    if analysis.get("unexplained") and not plain:
        reasons = analysis.get("base", {}).get("diagnostics", {}).get("unexplained_reasons", [])
        not_in_plant.append(_missed("unexplained", NotInPlant.UNEXPLAINED, reasons=reasons[:3]))
    rig["model"] = {k: (_sig(v, 8) if isinstance(v, float) else v) for k, v in model.items()}

    # plan
    if src.kind == "run":
        plan = plan_toml(src.metadata["plan"])
        plan["name"] = words.said(TwinSaid.PLAN_NAME, name=plan["name"])
    else:
        plan, n = plan_from_steps(src)
        notes += n

    prov = dict(source=str(source), source_kind=src.kind, source_sha256=source_sha256(source),
                analysis_source=analysis.get("source", ""),
                analysis_software_version=analysis.get("software_version", ""), software_version=__version__,
                steps_used=len(src.steps), steps_rejected=len(src.rejected), plain=plain)
    twin = Twin(rig={"rig": rig}, plan={"plan": plan}, provenance=prov,
                parameters={k: dict(v) for k, v in reported.items()}, causes=[c["id"] for c in causes],
                applied=applied, not_in_plant=not_in_plant, notes=notes,
                drive_ratio=[dict(freq_Hz=float(f), N_per_V=float(r), Z_s_N_s_per_m=[float(z.real), float(z.imag)])
                             for f, r, z in zip(f_r, ratio, Zs)],
                shaker=shaker.as_dict() if ratio.size else {})
    # both files must load as the commands will load them
    parse_rig(twin.rig, words.said(TwinSaid.RIG_LABEL))
    parse_plan(twin.plan, words.said(TwinSaid.PLAN_LABEL))
    return twin


# ---------------------------------------------------------------------------- TOML output


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else "nan"
    if isinstance(v, str):
        return json.dumps(v)          # a JSON string is a valid TOML basic string
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise words.refused(TypeError, TwinSaid.NO_TOML_FORM, name=type(v).__name__)


def to_toml(data: dict, prefix: str = "") -> str:
    """Nested dicts as TOML tables (scalars first, then sub-tables)."""
    lines, subs = [], []
    for k, v in data.items():
        if isinstance(v, dict):
            subs.append((k, v))
        else:
            lines.append(f"{k} = {_toml_value(v)}")
    out = ("\n".join(lines) + "\n") if lines else ""
    for k, v in subs:
        name = f"{prefix}.{k}" if prefix else k
        out += f"\n[{name}]\n" + to_toml(v, name)
    return out


def write_twin(twin: Twin, out: Path) -> dict[str, Path]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = dict(rig=out / "rig.toml", plan=out / "plan.toml", twin=out / "twin.json")
    paths["rig"].write_text(words.said(TwinSaid.RIG_HEADER, provenance=twin.provenance)
                            + words.said(TwinSaid.RIG_COMMENTS, parameters=twin.parameters, applied=twin.applied,
                                         shaker=twin.shaker, not_in_plant=twin.not_in_plant, notes=twin.notes)
                            + "\n" + to_toml(twin.rig))
    paths["plan"].write_text(words.said(TwinSaid.PLAN_HEADER, provenance=twin.provenance) + "\n" + to_toml(twin.plan))
    write_json(paths["twin"], twin.to_dict())
    return paths


def default_out_dir(source: Path) -> Path:
    """SOURCE/twin for a run directory, <stem>_twin next to a file."""
    return source / "twin" if source.is_dir() else source.parent / f"{source.stem}_twin"


def make_twin(source: Path, analysis_dir: Path | None = None, out: Path | None = None, *,
              plain: bool = False, src: Source | None = None) -> tuple[Twin, dict[str, Path]]:
    """Analyse SOURCE (into OUT/analysis) unless ``analysis_dir`` holds its analysis.json;
    build the twin and write rig.toml, plan.toml and twin.json to OUT."""
    source = Path(source)
    if not source.exists():
        raise words.refused(ConfigurationError, SourceProblem.NO_SUCH_SOURCE, path=source)
    out = Path(out) if out else default_out_dir(source)
    src = src if src is not None else load_source(source)
    if analysis_dir is not None:
        analysis = load_analysis(analysis_dir)
        if analysis.get("source") and Path(analysis["source"]).resolve() != source.resolve():
            log.warning("%s", words.said(TwinSaid.ANALYSIS_OF_ANOTHER, analysis=analysis_dir, of=analysis["source"],
                                         source=source))
    else:
        analysis = analyze_source(source, out / "analysis", src=src)
    twin = build_twin(source, analysis, plain=plain, src=src)
    return twin, write_twin(twin, out)
