"""Test plan and rig configuration (TOML), validated before anything moves.

Every error names the file, the key and the allowed values.  See ``bench/defaults/`` for
annotated examples (the demo's plan and the simulated rig).
"""

from __future__ import annotations

import difflib
import logging
import math
import tomllib
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drivers import check_daq_url, check_generator_url, check_sensor_url
from procedures.capacity import block_problems, step_count_problems
from procedures.kind import ProcedureKind
from procedures.plan import Backbone, Limits, Plan, Rig
from sim.errors import ConfigurationError

from .files import TooLarge, UnreadableFile, read_file

if TYPE_CHECKING:      # sim.rig compiles the plant's kernels: imported when a model is parsed
    from sim.rig import RigModel

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
MAX_FILE_BYTES = 2**20        # a plan or rig TOML file (the demo's plan is 3 kB)

LIMIT_KEYS = ("drive_V", "force_N", "disp_m", "accel_m_s2")
# Every key each table may hold (a table's path -> its keys); an unknown key is named, with
# the close valid one, before any value is read (a misspelled required key is reported as
# the misspelling, not as the key it was meant to be).  [rig.model]: model_schema() below.
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
    "rig": ("name", "notes", "simulated", "instruments", "calibration", "limits", "expected", "model"),
    "rig.instruments": ("generator", "sensor", "daq"),
    "rig.calibration": ("force_V_per_N", "accel_V_per_m_s2", "disp_V_per_m", "amp_gain_N_per_V"),
    "rig.limits": LIMIT_KEYS,
    "rig.expected": ("mass_kg", "x_s_m", "F_s_N", "n"),
}


ConfigError = ConfigurationError     # a configuration value is missing, unknown or out of range


class _Section:
    """Typed access to one TOML table that remembers where it came from."""

    def __init__(self, source: str, path: str, data: dict, keys=None, errors: list[str] | None = None):
        # errors: the file's problems so far (collected: one ConfigError for them all at the
        # end, see _collecting); None: each problem raises at once
        self.source, self.path, self.used, self.errors = source, path, set(), errors
        self.named: set[str] = set()
        self.bad: set[str] = set()        # keys whose value was a problem (a stand-in was used)
        if not isinstance(data, dict):
            self.problem(f"{source}: [{path}] must be a table")
            data = {}
        self.data = data
        if keys is not None:
            self.unknown(keys)

    def problem(self, message: str) -> None:
        """A problem of this file: collected, or raised when nothing collects."""
        if self.errors is None:
            raise ConfigError(message)
        self.errors.append(message)

    def _or(self, get, fallback, suffix="", key=""):
        """``get()``, or, if it finds a problem, the problem collected and ``fallback`` (a
        value of the right type the rest of the file's checks can go on with; ``key`` is
        then remembered as bad, see :meth:`rule`)."""
        try:
            return get()
        except ConfigError as e:
            if self.errors is None:
                raise ConfigError(f"{e}{suffix}") from None
            self.errors.extend(f"{line}{suffix}" for line in str(e).splitlines())
            self.bad.add(key)
            return fallback

    def rule(self, message: str, *keys: tuple[_Section, str]) -> None:
        """A problem across keys: collected, unless one of ``keys`` ((section, key) pairs)
        already had its own problem (its value here was a stand-in; its own line names it)."""
        if not any(key in sec.bad for sec, key in keys):
            self.problem(message)

    def unknown(self, keys) -> None:
        """Name every key outside ``keys``, with the close valid one when there is one."""
        problems = []
        self.named = {k for k in self.data if k not in keys}      # named here, not again by done()
        for key in [k for k in self.data if k not in keys]:
            table = isinstance(self.data[key], dict)
            near = difflib.get_close_matches(key, list(keys), n=1, cutoff=0.6)
            full = lambda k: f"{self.path}.{k}" if self.path else k     # noqa: E731
            if table:
                hint = f"did you mean [{full(near[0])}]?" if near else f"allowed: {sorted(keys)}"
                problems.append(f"[{full(key)}]: unknown table; {hint}")
            else:
                hint = f"did you mean {near[0]}?" if near else f"allowed: {sorted(keys)}"
                problems.append(f"{'[' + self.path + '] ' if self.path else ''}{key}: unknown key; {hint}")
        for problem in problems:
            self.problem(f"{self.source}: {problem}")

    def where(self, key: str) -> str:
        return f"{self.source}: [{self.path}] {key}"

    def _get(self, key, default):
        self.used.add(key)
        if key not in self.data:
            if default is _REQUIRED:
                raise ConfigError(f"{self.where(key)}: missing (required)")
            return default
        return self.data[key]

    def _number(self, key, default=None, lo=-math.inf, hi=math.inf, *, lo_open=False, integer=False, note=""):
        v = self._get(key, default)
        kind = "an integer" if integer else "a number"
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (integer and not float(v).is_integer()):
            raise ConfigError(f"{self.where(key)}: must be {kind}, got {v!r}")
        ok = (v > lo if lo_open else v >= lo) and v <= hi and math.isfinite(v)
        if not ok:
            lo_s = f"> {lo:g}" if lo_open else f">= {lo:g}"
            raise ConfigError(f"{self.where(key)}: must be {lo_s} and <= {hi:g}{note}, got {v!r}")
        return int(v) if integer else float(v)

    def _numbers(self, key, default=None, lo=-math.inf, hi=math.inf, *, lo_open=False, note="", most=None):
        v = self._get(key, default)
        if not isinstance(v, list) or not v:
            raise ConfigError(f"{self.where(key)}: must be a non-empty list of numbers, got {_short(v)}")
        if most is not None and len(v) > most:
            raise ConfigError(f"{self.where(key)}: {len(v)} values; at most {most}")
        # every bad element named, one line each
        sub = _Section(self.source, self.path, {f"{key}[{i}]": x for i, x in enumerate(v)}, errors=[])
        out = [sub.number(f"{key}[{i}]", lo=lo, hi=hi, lo_open=lo_open, note=note) for i in range(len(v))]
        if sub.errors:
            raise ConfigError("\n".join(sub.errors))
        return out

    def _choice(self, key, default, allowed):
        v = self._get(key, default)
        if v not in allowed:
            raise ConfigError(f"{self.where(key)}: must be one of {list(allowed)}, got {v!r}")
        return v

    def _text(self, key, default=""):
        v = self._get(key, default)
        if not isinstance(v, str):
            raise ConfigError(f"{self.where(key)}: must be a string, got {v!r}")
        return v

    def _flag(self, key, default=False):
        v = self._get(key, default)
        if not isinstance(v, bool):
            raise ConfigError(f"{self.where(key)}: must be true or false, got {v!r}")
        return v

    # the accessors: a bad value is a problem of the file (collected), the rest goes on
    def number(self, key, default=None, lo=-math.inf, hi=math.inf, *, lo_open=False, integer=False, note="",
               suffix=""):
        ok_default = isinstance(default, (int, float)) and not isinstance(default, bool)
        fallback = default if ok_default else _inside(lo, hi, lo_open)
        return self._or(lambda: self._number(key, default, lo, hi, lo_open=lo_open, integer=integer, note=note),
                        int(fallback) if integer else float(fallback), suffix, key)

    def numbers(self, key, default=None, lo=-math.inf, hi=math.inf, *, lo_open=False, note="", most=None):
        return self._or(lambda: self._numbers(key, default, lo, hi, lo_open=lo_open, note=note, most=most),
                        [_inside(lo, hi, lo_open)], key=key)

    def choice(self, key, default, allowed):
        return self._or(lambda: self._choice(key, default, allowed), default if default in allowed else allowed[0],
                        key=key)

    def text(self, key, default=""):
        return self._or(lambda: self._text(key, default), default if isinstance(default, str) else "", key=key)

    def flag(self, key, default=False):
        return self._or(lambda: self._flag(key, default), default if isinstance(default, bool) else False, key=key)

    def table(self, key) -> _Section:
        self.used.add(key)
        path = f"{self.path}.{key}" if self.path else key
        return _Section(self.source, path, self.data.get(key, {}), KEYS.get(path), self.errors)

    def done(self) -> None:
        unknown = sorted(set(self.data) - self.used - self.named)
        if unknown:
            self.problem(f"{self.source}: [{self.path}] unknown key(s) {unknown}; allowed: {sorted(self.used)}")


_REQUIRED = object()


def _inside(lo: float, hi: float, lo_open: bool) -> float:
    """A value within the bounds, for the checks after a bad one to go on with."""
    if math.isfinite(lo) and not lo_open:
        return float(lo)
    if math.isfinite(lo) and math.isfinite(hi):
        return (lo + hi) / 2
    return float(hi) if math.isfinite(hi) else 1.0


def _collecting(parse, data: dict, source: str):
    """``parse(data, source, errors)`` with the file's problems collected: one ConfigError
    naming each, one line per problem (each bad element of a list, each unknown key, each
    bad value, each key a procedure does not use).  A rule across keys is collected too
    (:meth:`_Section.rule`) unless one of its keys already had its own problem: it would
    have seen a stand-in value; it waits for the next run, once that key is fixed."""
    errors: list[str] = []
    try:
        out = parse(data, source, errors)
    except Exception:
        if not errors:
            raise
        out = None
    if errors:
        raise ConfigError("\n".join(dict.fromkeys(errors)))
    return out


def _short(v) -> str:
    text = repr(v)
    return text if len(text) <= 80 else f"{text[:60]}... ({type(v).__name__} of {len(v)})"


def _load(path: Path) -> dict:
    """A TOML file's tables.  The file is read as UTF-8 (TOML's encoding; a UTF-8 byte-order
    mark is accepted), at most :data:`MAX_FILE_BYTES`; a file saved as UTF-16 or in a legacy
    encoding, nested too deeply or too large is named with the problem."""
    path = Path(path)
    try:
        data = read_file(path, MAX_FILE_BYTES)
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except TooLarge as e:
        raise ConfigError(f"{path}: {e.size} bytes; a plan or rig file is at most {MAX_FILE_BYTES} bytes") from None
    except UnreadableFile as e:
        raise ConfigError(str(e)) from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: a directory, not a TOML file") from None
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise ConfigError(f"{path}: saved as UTF-16; TOML files are UTF-8 (save it again as UTF-8)")
    nul = data.find(b"\x00")
    if nul >= 0:                  # never in TOML; every other byte of UTF-16 text without its mark
        raise ConfigError(f"{path}: NUL bytes at offset {nul}: the file seems saved as UTF-16 "
                          f"without a byte-order mark; TOML files are UTF-8 (save it again as UTF-8)")
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        raise ConfigError(f"{path}: not UTF-8: byte 0x{data[e.start]:02x} at line {line} "
                          f"(offset {e.start}); the file seems saved in another encoding (Latin-1, "
                          f"Windows-1252, ...); TOML files are UTF-8 "
                          f"(save it again as UTF-8)") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML: {e}") from None
    except RecursionError:
        raise ConfigError(f"{path}: not a plan or rig: tables or arrays nested too deeply") from None


def read_toml(path: Path) -> dict:
    """A TOML file's tables; a missing or malformed file is a ConfigError naming it."""
    return _load(path)


def _limits(sec: _Section, required: bool = True) -> Limits:
    """The rig's limits (all four required) or a plan's tighter ones (each optional: one
    left out is the rig's, procedures.safety.tightest)."""
    need = _REQUIRED if required else None

    def one(key, hi):
        return sec.number(key, need, 0, hi, lo_open=True) if required or key in sec.data else None
    lim = Limits(drive_V=one("drive_V", 10), force_N=one("force_N", 1000), disp_m=one("disp_m", 0.01),
                 accel_m_s2=one("accel_m_s2", 1e4))
    sec.done()
    return lim


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
    top = _Section(source, "", data, ("plan",), errors)
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


def model_schema() -> dict:
    """[rig.model]: each key of sim.rig.RigModel as it declares itself (unit, range, choices;
    decision 0058), key -> sim.rig.ModelKey.  Ranges are what a real carriage rig can have;
    cross-field rules (n != 1, J > m e^2, ...) are the model's own and reach the user through
    the same error."""
    from sim.rig import model_keys
    return model_keys()


def _check_model(sec: _Section) -> RigModel | None:
    """Each [rig.model] key against its unit and range, then the model's own rules: the
    parsed sim.rig.RigModel, or None when a key's problem was collected."""
    from sim import rig as sim_rig

    schema = model_schema()
    sec.unknown(set(schema))
    for key in sec.data:
        spec = schema[key]
        if spec.choices:
            sec.choice(key, None, spec.choices)
            continue
        sec.number(key, None, spec.lo, spec.hi, lo_open=spec.lo_open, integer=spec.integer,
                   suffix=f" (unit: {spec.unit})" if spec.unit else "")
    if sec.errors:
        return None              # the model's own rules once its values are right
    try:
        return sim_rig.RigModel.from_dict(sec.data)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{sec.source}: [rig.model] {e}") from None


def load_rig(path: Path) -> Rig:
    return parse_rig(_load(path), str(path))


def parse_rig(data: dict, source: str = "rig") -> Rig:
    """The rig in ``data``; every independent problem of it named in one ConfigError."""
    return _collecting(_parse_rig, data, source)


def _parse_rig(data: dict, source: str, errors: list[str]) -> Rig:
    top = _Section(source, "", data, ("rig",), errors)
    r = top.table("rig")
    top.done()
    simulated = r.flag("simulated", False)
    ins = r.table("instruments")
    # a simulated rig starts its own twins and fills the URLs in at run time
    urls = {k: ins.text(k, "" if simulated else _REQUIRED) for k in ("generator", "sensor", "daq")}
    for key, check in (("generator", check_generator_url), ("sensor", check_sensor_url), ("daq", check_daq_url)):
        if urls[key] or not simulated:         # only known schemes: pyserial's spy:// writes files
            try:
                check(urls[key])
            except ValueError as e:
                ins.problem(f"{ins.where(key)}: {e}")
    ins.done()
    cal = r.table("calibration")
    exp = r.table("expected")
    rig = Rig(
        name=r.text("name", "rig"), notes=r.text("notes", ""), simulated=simulated,
        generator_url=urls["generator"], sensor_url=urls["sensor"], daq_url=urls["daq"],
        force_V_per_N=cal.number("force_V_per_N", _REQUIRED, 0, 100, lo_open=True),
        accel_V_per_m_s2=cal.number("accel_V_per_m_s2", _REQUIRED, 0, 100, lo_open=True),
        disp_V_per_m=cal.number("disp_V_per_m", _REQUIRED, 0, 1e7, lo_open=True),
        amp_gain_N_per_V=cal.number("amp_gain_N_per_V", _REQUIRED, 0, 1e4, lo_open=True),
        limits=_limits(r.table("limits")),
        expected_mass_kg=exp.number("mass_kg", 10.0, 0, 1e4, lo_open=True),
        expected_x_s_m=exp.number("x_s_m", 20e-6, 0, 1e-2, lo_open=True),
        expected_F_s_N=exp.number("F_s_N", 10.0, 0, 1e4, lo_open=True),
        expected_n=exp.number("n", 1.5, 0.05, 10))
    r.used.add("model")
    if r.data.get("model") and not simulated:
        raise ConfigError(f"{source}: [rig.model] is only allowed with simulated = true")
    if simulated:
        rig = replace(rig, model=_check_model(r.table("model")))
    cal.done()
    exp.done()
    r.done()
    return rig


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


def stored_rig(r: dict, source: str) -> Rig:
    """The rig of a stored run (run.json's ``rig``), checked as its file was."""
    return parse_rig({"rig": rig_toml(r)}, source)


def rig_toml(r: dict) -> dict:
    """The stored rig (run.json) back into the TOML layout."""
    return {"name": r["name"], "notes": r["notes"], "simulated": r["simulated"],
            "instruments": {"generator": r["generator_url"], "sensor": r["sensor_url"], "daq": r["daq_url"]},
            "calibration": {k: r[k] for k in ("force_V_per_N", "accel_V_per_m_s2", "disp_V_per_m",
                                              "amp_gain_N_per_V")},
            "limits": r["limits"],
            "expected": {"mass_kg": r["expected_mass_kg"], "x_s_m": r["expected_x_s_m"],
                         "F_s_N": r["expected_F_s_N"], "n": r["expected_n"]},
            **({"model": dict(r["model"])} if r["model"] else {})}
