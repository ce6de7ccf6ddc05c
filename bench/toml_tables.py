"""A plan or rig TOML file read and its tables checked (:mod:`bench.config` and
:mod:`bench.rig_config` say what the tables hold): typed access that names the file, the
table and the key of every problem, and collects a file's problems into one error."""

from __future__ import annotations

import difflib
import math
import tomllib
from pathlib import Path

from sim.errors import ConfigurationError

from .files import TooLarge, UnreadableFile, read_file

MAX_FILE_BYTES = 2**20        # a plan or rig TOML file (the demo's plan is 3 kB)

ConfigError = ConfigurationError     # a configuration value is missing, unknown or out of range


class _Section:
    """Typed access to one TOML table that remembers where it came from."""

    def __init__(self, source: str, path: str, data: dict, keys=None, errors: list[str] | None = None,
                 schema: dict | None = None):
        # errors: the file's problems so far (collected: one ConfigError for them all at the
        # end, see _collecting); None: each problem raises at once.  schema: every table's
        # keys (a table's path -> its keys), passed on to the tables read from this one
        self.source, self.path, self.used, self.errors = source, path, set(), errors
        self.schema = schema or {}
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
        return _Section(self.source, path, self.data.get(key, {}), self.schema.get(path), self.errors, self.schema)

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
