"""A plan or rig TOML file read and its tables checked (:mod:`bench.config` and
:mod:`bench.rig_config` say what the tables hold): typed access that names the file, the
table and the key of every problem, and collects a file's problems into one error."""

from __future__ import annotations

import difflib
import math
import tomllib
from enum import StrEnum
from pathlib import Path

from sim.errors import ConfigurationError

from .files import TooLarge, UnreadableFile, read_file
from .words import Said, terminal
from .words.terminal import refused

MAX_FILE_BYTES = 2**20        # a plan or rig TOML file (the demo's plan is 3 kB)

ConfigError = ConfigurationError     # a configuration value is missing, unknown or out of range


class ConfigProblem(StrEnum):
    """A problem of a plan or rig file (its words: :data:`bench.words.terminal.CONFIG`); a
    key's problem has the fields source (the file), table and key."""

    NOT_A_TABLE = "not_a_table"             # source, table
    UNKNOWN_TABLE = "unknown_table"         # source, table (its full name), near (or None), allowed
    UNKNOWN_KEY = "unknown_key"             # source, table, key, near (or None), allowed
    UNKNOWN_KEYS = "unknown_keys"           # source, table, keys, allowed (keys no procedure uses)
    MISSING = "missing"
    NOT_A_NUMBER = "not_a_number"           # integer, value, unit ("": none named)
    OUT_OF_RANGE = "out_of_range"           # value, low, low_open, high, note (a Said of a RangeNote, or ""), unit
    NOT_A_LIST = "not_a_list"               # got (the value, shortened)
    TOO_MANY = "too_many"                   # count, most
    NOT_ONE_OF = "not_one_of"               # allowed, value
    NOT_A_STRING = "not_a_string"           # value
    NOT_A_BOOL = "not_a_bool"               # value
    FILE_NOT_FOUND = "file_not_found"       # path
    FILE_TOO_LARGE = "file_too_large"       # path, size, most
    FILE_UNREADABLE = "file_unreadable"     # detail (the reader's words)
    FILE_IS_DIR = "file_is_dir"             # path
    UTF16 = "utf16"                         # path
    NUL_BYTES = "nul_bytes"                 # path, offset
    NOT_UTF8 = "not_utf8"                   # path, byte, line, offset
    NOT_TOML = "not_toml"                   # path, detail (the TOML parser's words)
    TOO_DEEP = "too_deep"                   # path
    SEVERAL = "several"                     # problems: each line's Said (code None: a line with words only)


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
            self.coded(ConfigProblem.NOT_A_TABLE, source=source, table=path)
            data = {}
        self.data = data
        if keys is not None:
            self.unknown(keys)

    def problem(self, message: str) -> None:
        """A problem of this file: collected, or raised when nothing collects (a
        :class:`Line`'s code and fields kept)."""
        if self.errors is None:
            raise _error(message)
        self.errors.append(message)

    def coded(self, code: StrEnum, **fields) -> None:
        """A problem of this file named by its code and fields (its words: terminal.CONFIG)."""
        self.problem(Line(terminal.config(code, **fields), code, fields))

    def _or(self, get, fallback, key=""):
        """``get()``, or, if it finds a problem, the problem collected and ``fallback`` (a
        value of the right type the rest of the file's checks can go on with; ``key`` is
        then remembered as bad, see :meth:`rule`)."""
        try:
            return get()
        except ConfigError as e:
            if self.errors is None:
                raise
            self.errors.extend(Line(line, said.code, said.fields)
                               for line, said in zip(str(e).splitlines(), _problems(e), strict=True))
            self.bad.add(key)
            return fallback

    def rule(self, code: StrEnum, *keys: tuple[_Section, str], **fields) -> None:
        """A problem across keys (``code`` and its ``fields``: a rule of bench.config or
        bench.rig_config): collected, unless one of ``keys`` ((section, key) pairs) already had
        its own problem (its value here was a stand-in; its own line names it)."""
        if not any(key in sec.bad for sec, key in keys):
            self.coded(code, **fields)

    def unknown(self, keys) -> None:
        """Name every key outside ``keys``, with the close valid one when there is one."""
        self.named = {k for k in self.data if k not in keys}      # named here, not again by done()
        full = lambda k: f"{self.path}.{k}" if self.path else k     # noqa: E731
        for key in [k for k in self.data if k not in keys]:
            near = difflib.get_close_matches(key, list(keys), n=1, cutoff=0.6)
            if isinstance(self.data[key], dict):
                self.coded(ConfigProblem.UNKNOWN_TABLE, source=self.source, table=full(key),
                           near=full(near[0]) if near else None, allowed=sorted(keys))
            else:
                self.coded(ConfigProblem.UNKNOWN_KEY, source=self.source, table=self.path, key=key,
                           near=near[0] if near else None, allowed=sorted(keys))

    def where(self, key: str) -> str:
        return terminal.where(self.source, self.path, key)

    def _bad(self, code: ConfigProblem, key: str, **fields) -> ConfigError:
        return refused(ConfigError, code, source=self.source, table=self.path, key=key, **fields)

    def _get(self, key, default):
        self.used.add(key)
        if key not in self.data:
            if default is _REQUIRED:
                raise self._bad(ConfigProblem.MISSING, key)
            return default
        return self.data[key]

    def _number(self, key, default=None, lo=-math.inf, hi=math.inf, *, lo_open=False, integer=False, note="",
                unit=""):
        v = self._get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (integer and not float(v).is_integer()):
            raise self._bad(ConfigProblem.NOT_A_NUMBER, key, integer=integer, value=v, unit=unit)
        ok = (v > lo if lo_open else v >= lo) and v <= hi and math.isfinite(v)
        if not ok:
            raise self._bad(ConfigProblem.OUT_OF_RANGE, key, value=v, low=lo, low_open=lo_open, high=hi, note=note,
                            unit=unit)
        return int(v) if integer else float(v)

    def _numbers(self, key, default=None, lo=-math.inf, hi=math.inf, *, lo_open=False, note="", most=None):
        v = self._get(key, default)
        if not isinstance(v, list) or not v:
            raise self._bad(ConfigProblem.NOT_A_LIST, key, got=_short(v))
        if most is not None and len(v) > most:
            raise self._bad(ConfigProblem.TOO_MANY, key, count=len(v), most=most)
        # every bad element named, one line each
        sub = _Section(self.source, self.path, {f"{key}[{i}]": x for i, x in enumerate(v)}, errors=[])
        out = [sub.number(f"{key}[{i}]", lo=lo, hi=hi, lo_open=lo_open, note=note) for i in range(len(v))]
        if sub.errors:
            raise _error("\n".join(sub.errors), sub.errors)
        return out

    def _choice(self, key, default, allowed):
        v = self._get(key, default)
        if v not in allowed:
            raise self._bad(ConfigProblem.NOT_ONE_OF, key, allowed=list(allowed), value=v)
        return v

    def _text(self, key, default=""):
        v = self._get(key, default)
        if not isinstance(v, str):
            raise self._bad(ConfigProblem.NOT_A_STRING, key, value=v)
        return v

    def _flag(self, key, default=False):
        v = self._get(key, default)
        if not isinstance(v, bool):
            raise self._bad(ConfigProblem.NOT_A_BOOL, key, value=v)
        return v

    # the accessors: a bad value is a problem of the file (collected), the rest goes on
    def number(self, key, default=None, lo=-math.inf, hi=math.inf, *, lo_open=False, integer=False, note="",
               unit=""):
        ok_default = isinstance(default, (int, float)) and not isinstance(default, bool)
        fallback = default if ok_default else _inside(lo, hi, lo_open)
        return self._or(lambda: self._number(key, default, lo, hi, lo_open=lo_open, integer=integer, note=note,
                                             unit=unit), int(fallback) if integer else float(fallback), key)

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
            self.coded(ConfigProblem.UNKNOWN_KEYS, source=self.source, table=self.path, keys=unknown,
                       allowed=sorted(self.used))


_REQUIRED = object()


class Line(str):
    """One problem's line of a ConfigError, with its ``code`` and ``fields`` (a ConfigProblem,
    or a rule's code of bench.config or bench.rig_config; None: a line whose words a layer
    below made, an instrument's capacity or a model's own check)."""

    code: StrEnum | None
    fields: dict

    def __new__(cls, text: str, code: StrEnum | None = None, fields: dict | None = None):
        line = super().__new__(cls, text)
        line.code, line.fields = code, dict(fields or {})
        return line


def _problems(e: Exception) -> list[Said]:
    """The problems a ConfigError names, one a line: each with its code and fields (a line
    without a code: code None, its words the field ``text``)."""
    lines = getattr(e, "fields", {}).get("problems") if getattr(e, "code", None) == ConfigProblem.SEVERAL else None
    if lines is not None:
        return list(lines)
    if getattr(e, "code", None) is not None and len(str(e).splitlines()) == 1:
        return [Said(e.code, e.fields)]                                           # type: ignore[attr-defined]
    return [Said(None, {"text": line}) for line in str(e).splitlines()]      # type: ignore[arg-type]


def _error(message: str, lines: list[str] | None = None) -> ConfigError:
    """The ConfigError of ``message``: one problem's with its code and fields, several
    problems' (``lines``) with the code SEVERAL and each problem's :class:`Said`."""
    lines = lines if lines is not None else [message]
    if len(lines) == 1 and getattr(lines[0], "code", None) is not None:
        e = ConfigError(message)
        e.code, e.fields = lines[0].code, lines[0].fields                          # type: ignore[attr-defined]
        return e
    said = [Said(getattr(x, "code", None), getattr(x, "fields", None) or ({} if getattr(x, "code", None) else
                                                                            {"text": str(x)})) for x in lines]
    e = ConfigError(message)
    e.code, e.fields = ConfigProblem.SEVERAL, {"problems": said}                   # type: ignore[attr-defined]
    return e


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
        lines = list(dict.fromkeys(errors))
        raise _error("\n".join(lines), lines)
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
        raise refused(ConfigError, ConfigProblem.FILE_NOT_FOUND, path=path) from None
    except TooLarge as e:
        raise refused(ConfigError, ConfigProblem.FILE_TOO_LARGE, path=path, size=e.size, most=MAX_FILE_BYTES) from None
    except UnreadableFile as e:
        raise refused(ConfigError, ConfigProblem.FILE_UNREADABLE, detail=str(e)) from None
    except IsADirectoryError:
        raise refused(ConfigError, ConfigProblem.FILE_IS_DIR, path=path) from None
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise refused(ConfigError, ConfigProblem.UTF16, path=path)
    nul = data.find(b"\x00")
    if nul >= 0:                  # never in TOML; every other byte of UTF-16 text without its mark
        raise refused(ConfigError, ConfigProblem.NUL_BYTES, path=path, offset=nul)
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        raise refused(ConfigError, ConfigProblem.NOT_UTF8, path=path, byte=data[e.start], line=line,
                      offset=e.start) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise refused(ConfigError, ConfigProblem.NOT_TOML, path=path, detail=str(e)) from None
    except RecursionError:
        raise refused(ConfigError, ConfigProblem.TOO_DEEP, path=path) from None


def read_toml(path: Path) -> dict:
    """A TOML file's tables; a missing or malformed file is a ConfigError naming it."""
    return _load(path)
