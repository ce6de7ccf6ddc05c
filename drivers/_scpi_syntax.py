"""SCPI program-message syntax used by the SCPI twin: headers, compounds, numbers.

Header patterns are written as space-separated mnemonics; a leading ``?`` marks an
optional node: ``"?SOURce FREQuency"`` matches ``FREQ``, ``freq``, ``SOUR:FREQuency``,
``:source1:frequency``. The upper-case prefix of a mnemonic is its short form.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass

log = logging.getLogger(__name__)

_NODE_RE = re.compile(r"^([A-Z]+)([0-9]*)$")


@dataclass(frozen=True)
class Mnemonic:
    short: str
    long: str
    optional: bool

    @classmethod
    def parse(cls, text: str) -> Mnemonic:
        optional = text.startswith("?")
        word = text.lstrip("?")
        short = "".join(ch for ch in word if ch.isupper() or ch.isdigit())
        return cls(short=short, long=word.upper(), optional=optional)

    def matches(self, node: str) -> bool:
        m = _NODE_RE.match(node)
        if m is None:
            return False
        word, suffix = m.groups()
        if suffix not in ("", "1"):
            return False
        return word in (self.short, self.long)


class HeaderPattern:
    """One command header, matched case-insensitively in short or long form."""

    def __init__(self, spec: str) -> None:
        self.spec = spec
        self.nodes = tuple(Mnemonic.parse(part) for part in spec.split())

    def match(self, nodes: list[str]) -> bool:
        return self._match(0, nodes, 0)

    def _match(self, i: int, nodes: list[str], j: int) -> bool:
        if i == len(self.nodes):
            return j == len(nodes)
        pattern = self.nodes[i]
        if j < len(nodes) and pattern.matches(nodes[j]) and self._match(i + 1, nodes, j + 1):
            return True
        return pattern.optional and self._match(i + 1, nodes, j)


@dataclass(frozen=True)
class ProgramUnit:
    """One command of a compound message: header nodes, query flag, parameter text."""

    nodes: tuple[str, ...]
    is_query: bool
    is_common: bool
    argument: str
    text: str


def split_message(line: str) -> list[str]:
    """Split a program message on ``;`` outside quoted strings."""
    units, current, quote = [], [], ""
    for ch in line:
        if quote:
            current.append(ch)
            if ch == quote:
                quote = ""
        elif ch in "'\"":
            quote = ch
            current.append(ch)
        elif ch == ";":
            units.append("".join(current))
            current = []
        else:
            current.append(ch)
    units.append("".join(current))
    return [u.strip() for u in units]


def parse_unit(text: str, previous_path: tuple[str, ...]) -> ProgramUnit:
    """Parse one command; a header without leading ``:`` is relative to the previous one."""
    header, _, argument = text.partition(" ")
    header = header.strip().upper()
    argument = argument.strip()
    is_query = header.endswith("?")
    header = header.rstrip("?")
    if header.startswith("*"):
        return ProgramUnit((header,), is_query, True, argument, text)
    absolute = header.startswith(":")
    nodes = tuple(n for n in header.strip(":").split(":"))
    if not absolute and previous_path:
        nodes = previous_path + nodes
    return ProgramUnit(nodes, is_query, False, argument, text)


_SUFFIX_SCALE = {"": 1.0, "HZ": 1.0, "KHZ": 1e3, "MAHZ": 1e6, "V": 1.0, "VPP": 1.0,
                 "MV": 1e-3, "MVPP": 1e-3, "OHM": 1.0}
_NUMBER_RE = re.compile(r"^([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*([A-Za-z]*)$")


class ParameterError(ValueError):
    """A parameter is not a number, keyword or boolean the command accepts."""


def parse_number(argument: str) -> float | str:
    """A decimal number with an optional unit suffix, or a keyword (MIN, MAX, DEF, INF)."""
    text = argument.strip()
    if not text:
        raise ParameterError("missing parameter")
    keyword = text.upper()
    for long, short in (("MINIMUM", "MIN"), ("MAXIMUM", "MAX"), ("DEFAULT", "DEF"),
                        ("INFINITY", "INF")):
        if keyword in (long, short):
            return short
    m = _NUMBER_RE.match(text)
    if m is None:
        raise ParameterError(f"not a number: {text!r}")
    value, suffix = m.groups()
    scale = _SUFFIX_SCALE.get(suffix.upper())
    if scale is None:
        raise ParameterError(f"unknown suffix: {suffix!r}")
    return float(value) * scale


def parse_bool(argument: str) -> bool:
    keyword = argument.strip().upper()
    if keyword in ("ON", "1"):
        return True
    if keyword in ("OFF", "0"):
        return False
    raise ParameterError(f"not a boolean: {argument!r}")


def format_number(value: float) -> str:
    """Keysight-style NR3 response, e.g. ``+1.00000000000000E+03``."""
    return f"{value:+.14E}"
