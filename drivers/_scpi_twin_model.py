"""State machine of the simulated Keysight 33500-style function generator.

Transport-free: :meth:`ScpiGeneratorModel.execute` takes one program message (one line)
and returns the response line or ``None``. The servers in ``_scpi_twin_server`` feed it
from TCP connections and a pseudo-terminal. Every change of the output is pushed to the
plant with ``rig.set_generator(...)`` while holding ``rig.lock``.

Voltages are displayed for the selected load (``OUTP:LOAD``), as on the real instrument:
the open-circuit voltage the amplifier input (high impedance) sees is the displayed value
times ``(R + 50) / R``; with ``OUTP:LOAD INF`` the two are equal. The plant gets the
open-circuit value, so a driver that forgets ``OUTP:LOAD INF`` drives twice the voltage.
"""

from __future__ import annotations

import collections
import contextlib
import logging
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ._scpi_syntax import (
    HeaderPattern,
    ParameterError,
    ProgramUnit,
    format_number,
    parse_bool,
    parse_number,
    parse_unit,
    split_message,
)

log = logging.getLogger(__name__)

ERROR_QUEUE_DEPTH = 20
IDN = "Keysight Technologies,33511B,TWIN000001,sim-0.1 (guideway-bench twin)"
SOURCE_OHM = 50.0
OPEN_CIRCUIT_MAX_VPP = 20.0
OPEN_CIRCUIT_MIN_VPP = 2e-3
OPEN_CIRCUIT_MAX_PEAK_V = 10.0
FREQ_MIN_HZ = 1e-6
FREQ_MAX_HZ = 20e6
INF_LOAD = 9.9e37

ERRORS = {
    -100: "Command error",
    -104: "Data type error",
    -108: "Parameter not allowed",
    -109: "Missing parameter",
    -113: "Undefined header",
    -221: "Settings conflict",
    -222: "Data out of range",
    -224: "Illegal parameter value",
    -350: "Queue overflow",
    -420: "Query UNTERMINATED",
}


@dataclass
class GeneratorState:
    function: str = "SIN"
    freq_Hz: float = 1000.0
    amplitude_Vpp: float = 0.1      # displayed, for the selected load
    offset_V: float = 0.0           # displayed, for the selected load
    output_on: bool = False
    load_ohm: float = SOURCE_OHM    # INF_LOAD for high impedance
    limit_high_V: float = 5.0
    limit_low_V: float = -5.0
    limit_state: bool = False
    range_auto: bool = True


class ScpiGeneratorModel:
    """The instrument's settings, error queue and command table."""

    def __init__(self, rig: Any | None = None) -> None:
        self._rig = rig
        self._lock = threading.RLock()
        self.state = GeneratorState()
        self.errors: collections.deque[tuple[int, str]] = collections.deque()
        self._table: list[tuple[HeaderPattern, Callable[[ProgramUnit], str | None]]] = [
            (HeaderPattern("SYSTem ERRor ?NEXT"), self._system_error),
            (HeaderPattern("?SOURce FUNCtion ?SHAPe"), self._function),
            (HeaderPattern("?SOURce FREQuency ?CW"), self._frequency),
            (HeaderPattern("?SOURce VOLTage ?LEVel ?IMMediate ?AMPLitude"), self._amplitude),
            (HeaderPattern("?SOURce VOLTage ?LEVel ?IMMediate OFFSet"), self._offset),
            (HeaderPattern("?SOURce VOLTage UNIT"), self._unit),
            (HeaderPattern("?SOURce VOLTage LIMit HIGH"), self._limit_high),
            (HeaderPattern("?SOURce VOLTage LIMit LOW"), self._limit_low),
            (HeaderPattern("?SOURce VOLTage LIMit STATe"), self._limit_state),
            (HeaderPattern("?SOURce VOLTage RANGe AUTO"), self._range_auto),
            (HeaderPattern("OUTPut ?STATe"), self._output),
            (HeaderPattern("OUTPut LOAD"), self._load),
            (HeaderPattern("?SOURce APPLy SINusoid"), self._apply_sine),
            (HeaderPattern("?SOURce APPLy"), self._apply_query),
            (HeaderPattern("SIMulation STEP"), self._sim_step),
        ]
        self._common: dict[str, Callable[[ProgramUnit], str | None]] = {
            "*IDN": self._idn, "*OPC": self._opc, "*CLS": self._cls, "*RST": self._rst,
            "*WAI": lambda unit: None,
        }
        self._push_to_rig()

    # ----------------------------------------------------------------- error queue
    def push_error(self, code: int, detail: str = "") -> None:
        with self._lock:
            message = ERRORS.get(code, "Error")
            if detail:
                message = f"{message}; {detail}"
            log.debug("SCPI twin error %d %s", code, message)
            if len(self.errors) >= ERROR_QUEUE_DEPTH:
                self.errors[-1] = (-350, ERRORS[-350])
            else:
                self.errors.append((code, message))

    def next_error(self) -> tuple[int, str]:
        with self._lock:
            return self.errors.popleft() if self.errors else (0, "No error")

    # ----------------------------------------------------------------- execution
    def execute(self, line: str) -> str | None:
        """Run one program message; return the response line (without LF) or None."""
        line = line.strip()
        if not line:
            return None
        responses: list[str] = []
        path: tuple[str, ...] = ()
        with self._lock:
            for text in split_message(line):
                if not text:
                    continue
                unit = parse_unit(text, path)
                handler = self._lookup(unit)
                if handler is None and path and not text.startswith(":"):
                    unit = parse_unit(text, ())  # lenient: also try the header as absolute
                    handler = self._lookup(unit)
                if handler is None:
                    self.push_error(-113, text.split(" ")[0])
                    continue
                if not unit.is_common:
                    path = unit.nodes[:-1]
                try:
                    response = handler(unit)
                except ParameterError as exc:
                    self.push_error(-109 if "missing" in str(exc) else -104, str(exc))
                    continue
                if response is not None:
                    responses.append(response)
        return ";".join(responses) if responses else None

    def unterminated_query(self, fragment: str) -> None:
        """The link closed or idled with a query that never got its terminator."""
        self.push_error(-420, fragment.strip()[:40])

    def _lookup(self, unit: ProgramUnit) -> Callable[[ProgramUnit], str | None] | None:
        if unit.is_common:
            return self._common.get(unit.nodes[0])
        nodes = list(unit.nodes)
        for pattern, handler in self._table:
            if pattern.match(nodes):
                return handler
        return None

    # ----------------------------------------------------------------- plant
    def _open_circuit_factor(self) -> float:
        load = self.state.load_ohm
        return 1.0 if load >= INF_LOAD else (load + SOURCE_OHM) / load

    def _push_to_rig(self) -> None:
        if self._rig is None:
            return
        s, k = self.state, self._open_circuit_factor()
        with self._rig.lock:
            self._rig.set_generator(freq_Hz=s.freq_Hz, amplitude_Vpp=s.amplitude_Vpp * k,
                                    offset_V=s.offset_V * k, output_on=s.output_on)

    # ----------------------------------------------------------------- limits
    def _amplitude_limits(self) -> tuple[float, float]:
        k = self._open_circuit_factor()
        return OPEN_CIRCUIT_MIN_VPP / k, OPEN_CIRCUIT_MAX_VPP / k

    def _peak_limits(self) -> tuple[float, float]:
        """Allowed displayed (low, high) instantaneous voltage: envelope and user clamp."""
        peak = OPEN_CIRCUIT_MAX_PEAK_V / self._open_circuit_factor()
        low, high = -peak, peak
        if self.state.limit_state:
            low, high = max(low, self.state.limit_low_V), min(high, self.state.limit_high_V)
        return low, high

    def _clip(self, value: float, low: float, high: float, what: str) -> float:
        if value < low or value > high or math.isnan(value):
            clipped = min(max(value, low), high) if not math.isnan(value) else low
            self.push_error(-222, f"{what} {value:g} clipped to {clipped:g}")
            return clipped
        return value

    def _resolve(self, arg: float | str, minimum: float, maximum: float, default: float) -> float:
        if isinstance(arg, float):
            return arg
        return {"MIN": minimum, "MAX": maximum, "DEF": default}.get(arg, math.nan)

    # ----------------------------------------------------------------- handlers
    def _idn(self, unit: ProgramUnit) -> str | None:
        return IDN if unit.is_query else None

    def _opc(self, unit: ProgramUnit) -> str | None:
        return "1" if unit.is_query else None

    def _cls(self, unit: ProgramUnit) -> None:
        self.errors.clear()

    def _rst(self, unit: ProgramUnit) -> None:
        self.state = GeneratorState()
        self._push_to_rig()

    def _system_error(self, unit: ProgramUnit) -> str | None:
        if not unit.is_query:
            self.push_error(-113, "SYST:ERR is a query")
            return None
        code, message = self.next_error()
        return f"{code:+d},\"{message}\""

    def _function(self, unit: ProgramUnit) -> str | None:
        if unit.is_query:
            return self.state.function
        shape = unit.argument.strip().upper()
        if shape not in ("SIN", "SINUSOID"):
            self.push_error(-224, f"only SIN is simulated, got {unit.argument!r}")
            return None
        self.state.function = "SIN"
        return None

    def _frequency(self, unit: ProgramUnit) -> str | None:
        if unit.is_query:
            if unit.argument:
                return format_number(self._resolve(parse_number(unit.argument),
                                                   FREQ_MIN_HZ, FREQ_MAX_HZ, 1000.0))
            return format_number(self.state.freq_Hz)
        value = self._resolve(parse_number(unit.argument), FREQ_MIN_HZ, FREQ_MAX_HZ, 1000.0)
        self.state.freq_Hz = self._clip(value, FREQ_MIN_HZ, FREQ_MAX_HZ, "frequency")
        self._push_to_rig()
        return None

    def _amplitude(self, unit: ProgramUnit) -> str | None:
        lo, hi = self._amplitude_limits()
        if unit.is_query:
            if unit.argument:
                return format_number(self._resolve(parse_number(unit.argument), lo, hi, 0.1))
            return format_number(self.state.amplitude_Vpp)
        value = self._clip(self._resolve(parse_number(unit.argument), lo, hi, 0.1), lo, hi,
                           "amplitude")
        low_V, high_V = self._peak_limits()
        room = 2.0 * min(high_V - self.state.offset_V, self.state.offset_V - low_V)
        if value > room:
            clipped = max(room, lo)
            self.push_error(-221, f"amplitude {value:g} Vpp with offset "
                                  f"{self.state.offset_V:g} V exceeds limits, set {clipped:g}")
            value = clipped
        self.state.amplitude_Vpp = value
        self._push_to_rig()
        return None

    def _offset(self, unit: ProgramUnit) -> str | None:
        low_V, high_V = self._peak_limits()
        if unit.is_query:
            return format_number(self.state.offset_V)
        value = self._clip(self._resolve(parse_number(unit.argument), low_V, high_V, 0.0),
                           low_V, high_V, "offset")
        half = self.state.amplitude_Vpp / 2.0
        allowed = min(max(value, low_V + half), high_V - half)
        if allowed != value:
            self.push_error(-221, f"offset {value:g} V with amplitude "
                                  f"{self.state.amplitude_Vpp:g} Vpp exceeds limits, "
                                  f"set {allowed:g}")
            value = allowed
        self.state.offset_V = value
        self._push_to_rig()
        return None

    def _unit(self, unit: ProgramUnit) -> str | None:
        if unit.is_query:
            return "VPP"
        if unit.argument.strip().upper() != "VPP":
            self.push_error(-224, f"only VPP is simulated, got {unit.argument!r}")
        return None

    def _limit_value(self, unit: ProgramUnit, attr: str) -> str | None:
        peak = OPEN_CIRCUIT_MAX_PEAK_V / self._open_circuit_factor()
        if unit.is_query:
            return format_number(getattr(self.state, attr))
        value = self._clip(self._resolve(parse_number(unit.argument), -peak, peak, 0.0),
                           -peak, peak, attr)
        new_low = value if attr == "limit_low_V" else self.state.limit_low_V
        new_high = value if attr == "limit_high_V" else self.state.limit_high_V
        if new_low >= new_high:
            self.push_error(-221, f"voltage limit low {new_low:g} V >= high {new_high:g} V")
            return None
        if self.state.limit_state and not self._within(new_low, new_high):
            self.push_error(-221, "present output exceeds the new voltage limit")
            return None
        setattr(self.state, attr, value)
        return None

    def _within(self, low_V: float, high_V: float) -> bool:
        s = self.state
        return (s.offset_V + s.amplitude_Vpp / 2 <= high_V + 1e-12
                and s.offset_V - s.amplitude_Vpp / 2 >= low_V - 1e-12)

    def _limit_high(self, unit: ProgramUnit) -> str | None:
        return self._limit_value(unit, "limit_high_V")

    def _limit_low(self, unit: ProgramUnit) -> str | None:
        return self._limit_value(unit, "limit_low_V")

    def _limit_state(self, unit: ProgramUnit) -> str | None:
        if unit.is_query:
            return "1" if self.state.limit_state else "0"
        on = parse_bool(unit.argument)
        if on and not self._within(self.state.limit_low_V, self.state.limit_high_V):
            self.push_error(-221, "present output exceeds the voltage limits")
            return None
        self.state.limit_state = on
        return None

    def _range_auto(self, unit: ProgramUnit) -> str | None:
        if unit.is_query:
            return "1" if self.state.range_auto else "0"
        if unit.argument.strip().upper() == "ONCE":
            return None
        self.state.range_auto = parse_bool(unit.argument)
        return None

    def _output(self, unit: ProgramUnit) -> str | None:
        if unit.is_query:
            return "1" if self.state.output_on else "0"
        self.state.output_on = parse_bool(unit.argument)
        self._push_to_rig()
        return None

    def _apply_sine(self, unit: ProgramUnit) -> str | None:
        """APPLy:SINusoid [<freq>[,<ampl>[,<offset>]]]: function, frequency, amplitude and
        offset in one command (omitted or DEF = the defaults 1 kHz, 0.1 Vpp, 0 V; MIN/MAX
        as in FREQ/VOLT/VOLT:OFFS), then the output on, as on the 33500 series."""
        if unit.is_query:
            return self._apply_query(unit)
        args = [a.strip() for a in unit.argument.split(",")] if unit.argument.strip() else []
        if len(args) > 3:
            self.push_error(-108, f"APPLy:SIN takes at most 3 parameters, got {len(args)}")
            return None
        args += ["DEF"] * (3 - len(args))
        for arg in args:          # all parameters parse before anything changes
            parse_number(arg or "DEF")
        with self._rig.lock if self._rig is not None else contextlib.nullcontext():
            self.state.function = "SIN"
            self.state.offset_V = 0.0     # the new offset is then fitted to the new amplitude
            for handler, arg in ((self._frequency, args[0]), (self._amplitude, args[1]),
                                 (self._offset, args[2])):
                handler(ProgramUnit((), False, False, arg or "DEF", unit.text))
            self.state.output_on = True
            self._push_to_rig()
        return None

    def _apply_query(self, unit: ProgramUnit) -> str | None:
        """APPLy? -> "SIN <freq>,<ampl>,<offset>" (quoted, as the 33500 series answers)."""
        if not unit.is_query:
            self.push_error(-109, "APPLy needs a function, e.g. APPLy:SINusoid")
            return None
        s = self.state
        return '"' + f"{s.function} " + ",".join(f"{v:+.15E}" for v in (s.freq_Hz, s.amplitude_Vpp, s.offset_V)) + '"'

    def _sim_step(self, unit: ProgramUnit) -> str | None:
        """Twin only: SIMulation:STEP "<key>" tells the plant a new step starts (noise reseeded
        from the rig seed and the key, see decision record 0013).  Real instruments answer
        -113; the driver sends it only to a twin."""
        if unit.is_query:
            self.push_error(-113, "SIM:STEP has no query")
            return None
        key = unit.argument.strip().strip('"').strip("'")
        if not key:
            self.push_error(-109, "SIM:STEP needs a step key")
            return None
        if self._rig is not None and hasattr(self._rig, "mark_step"):
            with self._rig.lock:
                self._rig.mark_step(key)
        return None

    def _load(self, unit: ProgramUnit) -> str | None:
        if unit.is_query:
            return format_number(self.state.load_ohm)
        arg = parse_number(unit.argument)
        value = {"INF": INF_LOAD, "MAX": 10e3, "MIN": 1.0, "DEF": SOURCE_OHM}.get(arg, arg) \
            if isinstance(arg, str) else arg
        if value < INF_LOAD:
            value = self._clip(value, 1.0, 10e3, "load")
        old = self._open_circuit_factor()
        self.state.load_ohm = value
        # The output voltage stays; the displayed values follow the new load, as on the real unit.
        scale = old / self._open_circuit_factor()
        self.state.amplitude_Vpp *= scale
        self.state.offset_V *= scale
        self.state.limit_high_V *= scale
        self.state.limit_low_V *= scale
        self._push_to_rig()
        return None
