"""Measured frequency responses read from another program's files (issue 42 item 1):
UFF58 FRF records (through :func:`bench.sources.read_frf_records`, the one UFF58 reader),
CSV and MATLAB ``.mat`` (v5/v7 through :func:`scipy.io.loadmat`, v7.3 through :mod:`bench.mat73`), with an optional mapping
(TOML, ``[import]``: which field is what, units, the response kind, the level's kind).

    read_frfs(path, mapping=None) -> Imported (levels, each f_Hz, the compliance X/F, the force)

Every FRF becomes the compliance X1/F1 (m/N): a mobility V/F is divided by i w, an
accelerance A/F by -w^2.  A level's kind is ``force`` (a force amplitude held) or ``disp`` /
``accel`` (a response amplitude held, response-controlled).  Every problem of the file and
the mapping is collected (:class:`ImportProblem` with fields naming the file, record, field)
and raised at once as one :class:`~sim.errors.ConfigurationError`, one line each (exit 2);
nothing is written by this module.  The run directory is :mod:`bench.frf_run`'s.
"""

from __future__ import annotations

import csv
import math
import re
import tomllib
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

import numpy as np

from sim.errors import ConfigurationError
from sim.modal import MIN_POINTS

from .words import terminal_data as words


class ImportProblem(StrEnum):
    """What is wrong with an imported file or its mapping (words: :data:`bench.words.terminal_data.IMPORT`)."""

    UNKNOWN_FORMAT = "import_unknown_format"         # path, suffix
    MAT_NOT_NUMBERS = "import_mat_not_numbers"       # path, where, cls: a v7.3 value bench import cannot read
    UNREADABLE = "import_unreadable"                 # path, error, detail
    MAPPING_KEY = "import_mapping_key"               # path, key (not a key of [import])
    MAPPING_VALUE = "import_mapping_value"           # path, key, got, allowed
    FIELD_MISSING = "import_field_missing"           # path, field: neither the file nor the mapping says it
    COLUMN_ABSENT = "import_column_absent"           # path, field, name: the mapping's name is not in the file
    UNIT_UNKNOWN = "import_unit_unknown"             # path, field, unit, allowed
    UNIT_KIND = "import_unit_kind"                   # path, field, unit, kind (the unit's), expected
    NOT_A_NUMBER = "import_not_a_number"             # path, where, field, got
    NOT_FINITE = "import_not_finite"                 # path, where, field, count
    NOT_INCREASING = "import_not_increasing"         # path, where, at_Hz, after_Hz
    TOO_FEW = "import_too_few"                       # path, where, points, need
    NO_LEVEL = "import_no_level"                     # path, where
    NO_FRF = "import_no_frf"                         # path
    RECORD_KIND = "import_record_kind"               # path, where, sdt
    RECORD_UNREADABLE = "import_record_unreadable"   # path, where, detail
    POINTS = "import_points"                         # path, where (a level), nodes: no drive point, none chosen
    FORCE_GRID = "import_force_grid"                 # path, where: a force spectrum on other frequencies
    PLAN_RANGE = "import_plan_range"                 # path, detail: the stored plan's validator
    OUT_NOT_NEW = "import_out_not_new"               # path


IMPORTED = "imported"       # run.json's origin.kind of an imported run


def energy_mass_kg(origin: dict) -> float:
    """The energy balance's mass of an imported run: the mapping's ``mass_kg`` where the source
    holds the force beside the response, else NaN (no energy balance)."""
    m = origin.get("mass_kg")
    return float(m) if origin.get("force") and isinstance(m, (int, float)) else math.nan


def origin_of(meta: dict) -> dict | None:
    """run.json's ``origin`` when the run was imported, else None (a bench measurement)."""
    o = meta.get("origin")
    return o if isinstance(o, dict) and o.get("kind") == IMPORTED else None


RESPONSES = ("disp", "vel", "accel")
LEVEL_KINDS = ("force", "disp", "accel")
G = 9.80665
# an FRF's unit -> (the response it is of, the factor to SI per newton); a UFF ordinate label
# is the numerator's unit alone (its denominator is record 10's)
FRF_UNITS = {"m/N": ("disp", 1.0), "mm/N": ("disp", 1e-3), "um/N": ("disp", 1e-6),
             "m/s/N": ("vel", 1.0), "(m/s)/N": ("vel", 1.0), "mm/s/N": ("vel", 1e-3), "(mm/s)/N": ("vel", 1e-3),
             "m/s^2/N": ("accel", 1.0), "(m/s^2)/N": ("accel", 1.0), "g/N": ("accel", G), "kg^-1": ("accel", 1.0),
             "1/kg": ("accel", 1.0)}
NUMERATOR_UNITS = {"m": ("disp", 1.0), "mm": ("disp", 1e-3), "um": ("disp", 1e-6), "m/s": ("vel", 1.0),
                   "mm/s": ("vel", 1e-3), "m/s^2": ("accel", 1.0), "g": ("accel", G)}
LEVEL_UNITS = {"N": ("force", 1.0), "kN": ("force", 1e3), "m": ("disp", 1.0), "mm": ("disp", 1e-3),
               "um": ("disp", 1e-6), "m/s^2": ("accel", 1.0), "g": ("accel", G)}
FREQ_UNITS = {"Hz": 1.0, "kHz": 1e3, "rad/s": 1 / (2 * math.pi)}
FORCE_UNITS = {"N": 1.0, "kN": 1e3}
PHASE_UNITS = {"rad": 1.0, "deg": math.pi / 180}
SDT_RESPONSE = {8: "disp", 11: "vel", 12: "accel"}
SDT_FORCE = 13
FIELDS = ("level", "frequency", "amplitude", "phase", "re", "im", "force")
UNIT_FIELDS = ("level", "frequency", "response", "phase", "force")
# a field's usual names in a CSV header or a struct (lower case, without the unit)
NAMES = {"level": ("level",), "frequency": ("frequency", "freq", "f"), "amplitude": ("amplitude", "abs", "magnitude"),
         "phase": ("phase",), "re": ("re", "real"), "im": ("im", "imag"), "force": ("force",)}
MAPPING_KEYS = ("response", "level_kind", "mass_kg", "variable", "fields", "units", "levels", "level_from",
                "level_pattern", "point", "noise")
_HEAD = re.compile(r"^\s*(?P<name>[^\[(]*?)\s*(?:[\[(](?P<unit>.*)[\])])?\s*$")


def norm_unit(u: str) -> str:
    """A unit as the tables spell it: no spaces, ``²`` and ``s2`` as ``^2``, ``µ`` as ``u``."""
    u = str(u).strip().replace(" ", "").replace("²", "^2").replace("µ", "u").replace("μ", "u")
    return re.sub(r"s2\b", "s^2", u)


@dataclass
class ImportedLevel:
    level: float                 # in the level kind's SI unit (N, m, m/s^2)
    where: tuple                 # (what, id): ("record", 3), ("test", 2), ("level", 1.0)
    f_Hz: np.ndarray
    H: np.ndarray                # compliance X1/F1, m/N
    force_N: np.ndarray | None   # the force amplitude at each frequency, when the source holds it


@dataclass
class Imported:
    path: Path
    format: str                  # "uff58", "csv", "mat"
    response: str                # what the source's FRFs were of: disp, vel, accel
    level_kind: str              # force, disp, accel
    levels: list[ImportedLevel]
    mass_kg: float = math.nan    # the energy balance's mass (mapping ``mass_kg``)
    mapping: dict = field(default_factory=dict)


class _Problems(list):
    def add(self, code: ImportProblem, **fields) -> None:
        self.append(words.said(code, **fields))

    def raise_any(self) -> None:
        if self:
            e = ConfigurationError("\n".join(self))
            e.code, e.fields = "import_problems", {"problems": list(self)}  # type: ignore[attr-defined]
            raise e


def read_mapping(path: Path | None, problems: _Problems) -> dict:
    """The mapping's ``[import]`` table (its keys checked), {} without a mapping."""
    if path is None:
        return {}
    try:
        doc = tomllib.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        problems.add(ImportProblem.UNREADABLE, path=path, error=type(e).__name__, detail=str(e))
        return {}
    m = doc.get("import", {})
    for k in doc:
        if k != "import":
            problems.add(ImportProblem.MAPPING_KEY, path=path, key=k)
    if not isinstance(m, dict):
        problems.add(ImportProblem.MAPPING_VALUE, path=path, key="import", got=m, allowed="table")
        return {}
    for k in m:
        if k not in MAPPING_KEYS:
            problems.add(ImportProblem.MAPPING_KEY, path=path, key=f"import.{k}")
    for k, allowed in (("response", RESPONSES), ("level_kind", LEVEL_KINDS)):
        if k in m and m[k] not in allowed:
            problems.add(ImportProblem.MAPPING_VALUE, path=path, key=f"import.{k}", got=m[k], allowed=allowed)
    for k, allowed in (("fields", FIELDS), ("units", UNIT_FIELDS)):
        for sub in m.get(k, {}) if isinstance(m.get(k, {}), dict) else ():
            if sub not in allowed:
                problems.add(ImportProblem.MAPPING_KEY, path=path, key=f"import.{k}.{sub}")
    mass = m.get("mass_kg")
    if mass is not None and not (isinstance(mass, (int, float)) and math.isfinite(mass) and mass > 0):
        problems.add(ImportProblem.MAPPING_VALUE, path=path, key="import.mass_kg", got=mass, allowed="> 0")
    noise = m.get("noise")      # the FRF's relative sigma per real or imaginary part (bench analyze, decision 0084)
    if noise is not None and not (isinstance(noise, (int, float)) and math.isfinite(noise) and 0 < noise < 1):
        problems.add(ImportProblem.MAPPING_VALUE, path=path, key="import.noise", got=noise, allowed="0 < noise < 1")
    m["_path"] = str(path)
    return m


def read_frfs(path: Path, mapping_path: Path | None = None) -> Imported:
    """The levels of a UFF58, CSV or .mat file; :class:`ConfigurationError` with every problem."""
    path = Path(path)
    problems = _Problems()
    mapping = read_mapping(mapping_path, problems)
    suffix = path.suffix.lower()
    if suffix in (".uff", ".unv", ".uf"):
        imp = _from_uff(path, mapping, problems)
    elif suffix == ".csv":
        imp = _from_csv(path, mapping, problems)
    elif suffix == ".mat":
        imp = _from_mat(path, mapping, problems)
    else:
        problems.add(ImportProblem.UNKNOWN_FORMAT, path=path, suffix=suffix)
        imp = None
    if imp is not None:
        for lv in imp.levels:
            _check_level(path, lv, problems)
        if not imp.levels and not problems:
            problems.add(ImportProblem.NO_FRF, path=path)
    problems.raise_any()
    assert imp is not None
    mass = mapping.get("mass_kg")
    imp.mass_kg = float(mass) if mass is not None else math.nan
    imp.mapping = {k: v for k, v in mapping.items() if k != "_path"}
    imp.levels.sort(key=lambda lv: lv.level)
    return imp


def _check_level(path: Path, lv: ImportedLevel, problems: _Problems) -> None:
    for name, x in (("frequency", lv.f_Hz), ("response", lv.H), ("force", lv.force_N)):
        if x is not None and not np.all(np.isfinite(x)):
            problems.add(ImportProblem.NOT_FINITE, path=path, where=lv.where, field=name,
                         count=int(np.sum(~np.isfinite(x))))
    if not math.isfinite(lv.level) or lv.level <= 0:
        problems.add(ImportProblem.NOT_FINITE, path=path, where=lv.where, field="level", count=1)
    d = np.diff(lv.f_Hz)
    bad = np.nonzero(~(d > 0))[0]
    if bad.size and np.all(np.isfinite(lv.f_Hz)):
        i = int(bad[0])
        problems.add(ImportProblem.NOT_INCREASING, path=path, where=lv.where, at_Hz=float(lv.f_Hz[i + 1]),
                     after_Hz=float(lv.f_Hz[i]))
    if lv.f_Hz.size < MIN_POINTS:
        problems.add(ImportProblem.TOO_FEW, path=path, where=lv.where, points=int(lv.f_Hz.size), need=MIN_POINTS)


def to_compliance(H: np.ndarray, f_Hz: np.ndarray, response: str) -> np.ndarray:
    """X/F from an FRF of ``response`` (compliance, mobility V/F = i w X/F, accelerance -w^2 X/F)."""
    w = 2 * np.pi * np.asarray(f_Hz, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return {"disp": H, "vel": H / (1j * w), "accel": -H / (w * w)}[response]


# ---------------------------------------------------------------------------- units and kinds


def _kinds(path, mapping: dict, problems: _Problems, frf_unit: str | None, level_unit: str | None,
           numerator: bool = False) -> tuple[str | None, float, str | None, float]:
    """(response, the FRF's factor to SI, level kind, the level's factor) from the mapping
    and the units the file gives (the mapping's units first); problems where they disagree."""
    units = mapping.get("units", {}) if isinstance(mapping.get("units", {}), dict) else {}
    fu = units.get("response", frf_unit)
    response, scale = mapping.get("response"), 1.0
    if fu:
        table = dict(FRF_UNITS, **NUMERATOR_UNITS) if numerator else FRF_UNITS
        got = table.get(norm_unit(fu))
        if got is None:
            problems.add(ImportProblem.UNIT_UNKNOWN, path=path, field="response", unit=fu, allowed=tuple(table))
        elif response and got[0] != response:
            problems.add(ImportProblem.UNIT_KIND, path=path, field="response", unit=fu, kind=got[0], expected=response)
        else:
            response, scale = got
    if response is None and not numerator:
        problems.add(ImportProblem.FIELD_MISSING, path=path, field="response")
    lu = units.get("level", level_unit)
    kind, lscale = mapping.get("level_kind"), 1.0
    if lu:
        got = LEVEL_UNITS.get(norm_unit(lu))
        if got is None:
            problems.add(ImportProblem.UNIT_UNKNOWN, path=path, field="level", unit=lu, allowed=tuple(LEVEL_UNITS))
        elif kind and got[0] != kind:
            problems.add(ImportProblem.UNIT_KIND, path=path, field="level", unit=lu, kind=got[0], expected=kind)
        else:
            kind, lscale = got
    return response, scale, kind, lscale


def _unit_factor(path, mapping: dict, problems: _Problems, name: str, given: str | None, table: dict,
                 default: str | None) -> float | None:
    units = mapping.get("units", {}) if isinstance(mapping.get("units", {}), dict) else {}
    u = units.get(name, given) or default
    if u is None:
        problems.add(ImportProblem.FIELD_MISSING, path=path, field=f"{name}_unit")
        return None
    v = table.get(norm_unit(u))
    if v is None:
        problems.add(ImportProblem.UNIT_UNKNOWN, path=path, field=name, unit=u, allowed=tuple(table))
    return v


# ---------------------------------------------------------------------------- CSV and .mat


def _pick(names: list[str], mapping: dict, what: str) -> int | None:
    """The index of ``what``'s column among ``names`` (lower case): the mapping's name, else a usual one."""
    fields = mapping.get("fields", {}) if isinstance(mapping.get("fields", {}), dict) else {}
    if what in fields:
        want = str(fields[what]).strip().lower()
        return names.index(want) if want in names else -1
    return next((names.index(n) for n in NAMES[what] if n in names), None)


def _table(path: Path, names: list[str], units: list[str | None], columns: list[np.ndarray], mapping: dict,
           problems: _Problems, where_of, level_of_group=None) -> Imported | None:
    """Levels from columns (CSV, or one struct element's fields when ``level_of_group`` is given)."""
    idx = {w: _pick(names, mapping, w) for w in FIELDS}
    fields = mapping.get("fields", {}) if isinstance(mapping.get("fields", {}), dict) else {}
    for w, i in idx.items():
        if i == -1:
            problems.add(ImportProblem.COLUMN_ABSENT, path=path, field=w, name=fields[w])
    polar = idx["amplitude"] not in (None, -1) or idx["phase"] not in (None, -1)
    need = ["frequency"] + (["amplitude", "phase"] if polar else ["re", "im"]) + ([] if level_of_group else ["level"])
    for w in need:
        if idx[w] is None:
            problems.add(ImportProblem.FIELD_MISSING, path=path, field=w)
    if any(idx[w] in (None, -1) for w in need):
        return None
    unit = lambda w: units[idx[w]] if idx[w] not in (None, -1) else None     # noqa: E731
    response, scale, kind, lscale = _kinds(path, mapping, problems, unit("amplitude" if polar else "re"),
                                           unit("level"))
    if kind is None:
        kind = "force" if "level_kind" not in mapping else mapping["level_kind"]
    fscale = _unit_factor(path, mapping, problems, "frequency", unit("frequency"), FREQ_UNITS, "Hz")
    pscale = _unit_factor(path, mapping, problems, "phase", unit("phase"), PHASE_UNITS, None) if polar else 1.0
    force_scale = (_unit_factor(path, mapping, problems, "force", unit("force"), FORCE_UNITS, "N")
                   if idx["force"] not in (None, -1) else 1.0)
    if response is None or fscale is None or pscale is None or force_scale is None:
        return None
    col = lambda w: columns[idx[w]]        # noqa: E731
    f = col("frequency") * fscale
    Hraw = (col("amplitude") * np.exp(1j * col("phase") * pscale) if polar else col("re") + 1j * col("im")) * scale
    force = col("force") * force_scale if idx["force"] not in (None, -1) else None
    levels: list[ImportedLevel] = []
    groups = level_of_group if level_of_group is not None else _groups(col("level") * lscale)
    for value, rows, where in groups:
        rows = np.asarray(rows, int)
        levels.append(ImportedLevel(float(value * (lscale if level_of_group is not None else 1.0)), where_of(where),
                                    f[rows], to_compliance(Hraw[rows], f[rows], response),
                                    None if force is None else force[rows]))
    return Imported(path, "", response, kind, levels)


def _groups(level: np.ndarray) -> list[tuple[float, list[int], float]]:
    """Rows of each level value, in the file's order of first appearance."""
    out: dict[float, list[int]] = {}
    for i, v in enumerate(level):
        out.setdefault(float(v), []).append(i)
    return [(v, rows, v) for v, rows in out.items()]


def _from_csv(path: Path, mapping: dict, problems: _Problems) -> Imported | None:
    try:
        with open(path, newline="") as fh:
            rows = [r for r in csv.reader(fh) if r and any(c.strip() for c in r)]
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        problems.add(ImportProblem.UNREADABLE, path=path, error=type(e).__name__, detail=str(e))
        return None
    if not rows:
        problems.add(ImportProblem.NO_FRF, path=path)
        return None
    heads = [_HEAD.match(h) for h in rows[0]]
    names = [(m["name"] if m else h).strip().lower() for m, h in zip(heads, rows[0], strict=True)]
    units = [(m["unit"] or None) if m else None for m in heads]
    cols = []
    for j, name in enumerate(names):
        vals = []
        for n, r in enumerate(rows[1:], start=2):
            cell = r[j].strip() if j < len(r) else ""
            try:
                vals.append(float(cell))
            except ValueError:
                problems.add(ImportProblem.NOT_A_NUMBER, path=path, where=("row", n), field=name, got=cell)
                vals.append(math.nan)
        cols.append(np.array(vals, float))
    imp = _table(path, names, units, cols, mapping, problems, lambda v: ("level", v))
    if imp is not None:
        imp.format = "csv"
    return imp


def _from_mat(path: Path, mapping: dict, problems: _Problems) -> Imported | None:
    try:
        head = Path(path).read_bytes()[:128]
    except OSError as e:
        problems.add(ImportProblem.UNREADABLE, path=path, error=type(e).__name__, detail=str(e))
        return None
    import scipy.io

    from .mat73 import NotNumbers, is_v73, load_mat73
    try:
        doc = load_mat73(path) if is_v73(head) else scipy.io.loadmat(str(path), simplify_cells=True)
    except NotNumbers as e:
        problems.add(ImportProblem.MAT_NOT_NUMBERS, path=path, where=e.args[0], cls=e.args[1])
        return None
    except Exception as e:  # noqa: BLE001 - scipy and h5py raise many kinds for a file they cannot read
        problems.add(ImportProblem.UNREADABLE, path=path, error=type(e).__name__, detail=str(e))
        return None
    names = [k for k in doc if not k.startswith("__")]
    var = mapping.get("variable") or (names[0] if len(names) == 1 else None)
    if var is None or var not in doc:
        problems.add(ImportProblem.FIELD_MISSING if var is None else ImportProblem.COLUMN_ABSENT, path=path,
                     field="variable", name=var)
        return None
    tests = doc[var]
    tests = [tests] if isinstance(tests, dict) else list(tests)
    if not tests or not all(isinstance(t, dict) for t in tests):
        problems.add(ImportProblem.FIELD_MISSING, path=path, field="variable")
        return None
    by_index = mapping.get("levels", {}) if isinstance(mapping.get("levels", {}), dict) else {}
    fieldnames = [k.lower() for k in tests[0]]
    li = _pick(fieldnames, mapping, "level")
    out: Imported | None = None
    for n, t in enumerate(tests, start=1):
        keys = list(t)
        if [k.lower() for k in keys] != fieldnames:
            problems.add(ImportProblem.FIELD_MISSING, path=path, field=f"test {n}")
            continue
        vec = {k.lower(): np.atleast_1d(np.asarray(t[k], float)).ravel() for k in keys if _numeric(t[k])}
        size = max((v.size for v in vec.values()), default=0)
        if str(n) in by_index:
            value = float(by_index[str(n)])
        elif li not in (None, -1) and fieldnames[li] in vec and vec[fieldnames[li]].size >= 1:
            value = float(vec[fieldnames[li]][0])
        else:
            problems.add(ImportProblem.NO_LEVEL, path=path, where=("test", n))
            continue
        cols = [vec.get(k, np.full(size, math.nan)) if vec.get(k, np.zeros(size)).size == size
                else np.full(size, float(vec[k][0])) for k in fieldnames]
        imp = _table(path, fieldnames, [None] * len(fieldnames), cols, mapping, problems, lambda w, n=n: ("test", n),
                     [(value, list(range(size)), n)])
        if imp is None:
            return None
        if out is None:
            out = imp
        else:
            out.levels += imp.levels
    if out is not None:
        out.format = "mat"
    return out


def _numeric(x) -> bool:
    try:
        np.asarray(x, float)
    except (TypeError, ValueError):
        return False
    return True


# ---------------------------------------------------------------------------- UFF58


def _uff_level(rec, mapping: dict) -> tuple[float | None, str | None]:
    """(level, level unit or None) of one record: ``bench export``'s tags, else the mapping's
    ``level_from`` (``load_case`` through ``[import.levels]``, or an id line with ``level_pattern``)."""
    src = mapping.get("level_from")
    if src is None and "level" in rec.tags:
        try:
            return float(rec.tags["level"]), rec.tags.get("unit", "N")
        except ValueError:
            return None, None
    levels = mapping.get("levels", {}) if isinstance(mapping.get("levels", {}), dict) else {}
    if src == "load_case":
        v = levels.get(str(rec.load_case))
        return (float(v), None) if v is not None else (None, None)
    if isinstance(src, str) and re.fullmatch(r"id[1-5]", src):
        m = re.search(str(mapping.get("level_pattern", r"([-+0-9.eE]+)")), rec.ids[int(src[2]) - 1])
        try:
            return (float(m.group(1)), None) if m else (None, None)
        except (ValueError, IndexError):
            return None, None
    return None, None


def _from_uff(path: Path, mapping: dict, problems: _Problems) -> Imported | None:
    from .sources import FUNC_AUTO, FUNC_FRF, FUNC_SPECTRUM, read_frf_records
    try:
        records = read_frf_records(path)
    except ConfigurationError as e:
        problems.append(str(e))
        return None
    frfs: dict[tuple, list] = {}
    forces: dict[float, object] = {}
    units_seen: set[str] = set()
    for rec in records:
        where = ("record", rec.record)
        if rec.error:
            problems.add(ImportProblem.RECORD_UNREADABLE, path=path, where=where, detail=rec.error)
            continue
        level, lunit = _uff_level(rec, mapping)
        if level is None:
            problems.add(ImportProblem.NO_LEVEL, path=path, where=where)
            continue
        if lunit:
            units_seen.add(lunit)
        if rec.func_type in (FUNC_SPECTRUM, FUNC_AUTO) and rec.sdt == SDT_FORCE:
            forces[level] = rec
        elif rec.func_type == FUNC_FRF and rec.sdt in SDT_RESPONSE:
            frfs.setdefault((level, rec.rsp), []).append(rec)
        elif rec.func_type == FUNC_FRF:
            problems.add(ImportProblem.RECORD_KIND, path=path, where=where, sdt=rec.sdt)
    if not frfs:
        if not problems:
            problems.add(ImportProblem.NO_FRF, path=path)
        return None
    lunit = sorted(units_seen)[0] if len(units_seen) == 1 else None
    _, _, kind, lscale = _kinds(path, mapping, problems, None, lunit, numerator=True)
    kind = kind or "force"
    point = mapping.get("point")
    by_level: dict[float, list] = {}
    for (level, rsp), recs in frfs.items():
        by_level.setdefault(level, []).append((rsp, recs))
    levels, responses = [], set()
    for level, pts in sorted(by_level.items()):
        if len(pts) > 1:
            chosen = [p for p in pts if (point is not None and p[0][0] == point)
                      or (point is None and p[0] == p[1][0].ref)]
            if len(chosen) != 1:
                problems.add(ImportProblem.POINTS, path=path, where=("level", level),
                             nodes=sorted({p[0][0] for p in pts}))
                continue
            pts = chosen
        recs = sorted(pts[0][1], key=lambda r: list(SDT_RESPONSE).index(r.sdt))   # compliance first
        rec = recs[0]
        response = SDT_RESPONSE[rec.sdt]
        scale = 1.0
        if rec.unit:
            got = dict(FRF_UNITS, **NUMERATOR_UNITS).get(norm_unit(rec.unit))
            if got is not None and got[0] != response:
                problems.add(ImportProblem.UNIT_KIND, path=path, field=f"record {rec.record}", unit=rec.unit,
                             kind=got[0], expected=response)
                continue
            scale = got[1] if got else 1.0
        if mapping.get("response") and mapping["response"] != response:
            problems.add(ImportProblem.UNIT_KIND, path=path, field=f"record {rec.record}", unit=response,
                         kind=response, expected=mapping["response"])
            continue
        responses.add(response)
        force = None
        if level in forces:
            fr = forces[level]
            if fr.f_Hz.shape != rec.f_Hz.shape or not np.allclose(fr.f_Hz, rec.f_Hz, rtol=1e-6):
                problems.add(ImportProblem.FORCE_GRID, path=path, where=("record", fr.record))
            else:
                # a linear spectrum holds the amplitude, an auto spectrum its square (both peak values)
                force = np.abs(fr.data) if fr.func_type == FUNC_SPECTRUM else np.sqrt(np.abs(fr.data))
        levels.append(ImportedLevel(level * lscale, ("record", rec.record), rec.f_Hz,
                                    to_compliance(rec.data * scale, rec.f_Hz, response), force))
    return Imported(path, "uff58", sorted(responses)[0] if responses else "disp", kind, levels)
