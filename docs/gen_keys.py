"""Writes docs/reference/keys.md: every key of a plan and a rig file with its type, range and
default, taken from the validators themselves (bench/config.py, bench/rig_config.py), and its meaning from the
comment beside it in the annotated example files (bench/defaults/*.toml).  The [rig.model]
table is each sim.rig.RigModel field's own declaration (unit, range, default, meaning;
decision 0058), as bench.config.model_schema() reads it.

The parser is run on the example files with its accessors recording what they are asked
(key, default, bounds, choices), so the reference cannot drift from what the bench
accepts.  `make docs` runs it before `mkdocs build --strict`; `tests/bench/test_docs.py`
checks that every key the parser knows (config.KEYS) is in it.
"""

from __future__ import annotations

import math
import re
import sys
import tomllib
from pathlib import Path

import bench.config as config

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ["demo_plan.toml", "backbone_plan.toml", "response_plan.toml", "sim_rig.toml", "sim_rig_pitch.toml"]

# plans that reach the keys no example file holds (a frequency list, a plan's own limits)
EXTRA = [{"plan": {"levels_N": [1.0], "frequencies": {"list_Hz": [50.0, 80.0]},
                   "limits": {"drive_V": 5.0, "force_N": 50.0, "disp_m": 1e-3, "accel_m_s2": 500.0}}}]
# keys read by hand rather than through a typed accessor: (type and range, default)
SPECIAL = {("plan.resonance", "modes"): ("list of `\"feed\"`, `\"pitch\"`", '`["feed", "pitch"]`')}

seen: dict[tuple[str, str], dict] = {}


def _record(kind: str):
    original = getattr(config._Section, kind)

    def recording(self, key, *args, **kwargs):
        names = ("default", "lo", "hi") if kind in ("number", "numbers") else ("default", "allowed")
        info = dict(zip(names, args))
        info.update({k: v for k, v in kwargs.items() if k in ("default", "lo", "hi", "lo_open", "integer", "allowed")})
        seen.setdefault((self.path, re.sub(r"\[\d+\]$", "", key)), {"kind": kind, **info})
        return original(self, key, *args, **kwargs)
    setattr(config._Section, kind, recording)


for _kind in ("number", "numbers", "choice", "text", "flag"):
    _record(_kind)


def comments() -> dict[tuple[str, str], str]:
    """(table, key) -> the comment beside it in the example files."""
    out: dict[tuple[str, str], str] = {}
    for name in EXAMPLES:
        path = config.DEFAULTS / name
        if not path.is_file():
            continue
        table = ""
        for line in path.read_text().splitlines():
            m = re.match(r"\s*\[([\w.]+)\]\s*(#\s*(.*))?$", line)
            if m:
                table = m[1]
                continue
            m = re.match(r"\s*#?\s*(\w+)\s*=\s*[^#]*#\s*(.+)$", line)
            if m and (table, m[1]) not in out:
                out[(table, m[1])] = m[2].strip()
    return out


def bounds(info: dict) -> str:
    if info["kind"] == "choice":
        return "one of " + ", ".join(f"`{a}`" for a in info.get("allowed", ()))
    if info["kind"] == "flag":
        return "`true` / `false`"
    if info["kind"] == "text":
        return "text"
    lo, hi = info.get("lo", -math.inf), info.get("hi", math.inf)
    kind = "integer" if info.get("integer") else "number" if info["kind"] == "number" else "list of numbers"
    parts = []
    if math.isfinite(lo):
        parts.append(f"{'>' if info.get('lo_open') else '>='} {lo:g}")
    if math.isfinite(hi):
        parts.append(f"<= {hi:g}")
    return kind + (" " + " and ".join(parts) if parts else "")


def default(info: dict) -> str:
    d = info.get("default", None)
    if d is config._REQUIRED:
        return "**required**"
    if d is None:
        return "-"
    if isinstance(d, bool):
        return "`true`" if d else "`false`"
    if isinstance(d, float):
        return f"`{d:g}`"
    return f"`{d!r}`" if d != "" else "`\"\"`"


def model_rows() -> list[str]:
    """One row per [rig.model] key, from the model's own declaration."""
    from sim.rig import RigModel
    defaults = RigModel()
    rows = []
    for key, spec in config.model_schema().items():
        if spec.choices:
            typ = "one of " + ", ".join(f"`{c}`" if c else '`""`' for c in spec.choices)
        else:
            typ = (f"{'integer' if spec.integer else 'number'} {'>' if spec.lo_open else '>='} {spec.lo:g} "
                   f"and <= {spec.hi:g}" + (f" ({spec.unit})" if spec.unit else ""))
        meaning = spec.meaning.replace("|", "\\|") + ("" if spec.in_plant else " (not in the plant yet)")
        rows.append(f"| `{key}` | {typ} | {default(dict(default=getattr(defaults, key)))} | {meaning} |")
    return rows


def friction_rows() -> list[str]:
    """One row per parameter of each friction model other than Masing (whose parameters are
    the [rig.model] keys F_s_N, x_s_m, n above), from the model's own declaration (decision 0075)."""
    from sim.friction import MODELS
    rows = []
    for name, model in MODELS.items():
        for p in model.parameters if name != "masing" else ():
            rows.append(f"| `{name}` | `{p.name}` | number {'>' if p.lo_open else '>='} {p.lo:g} and <= {p.hi:g} "
                        f"({p.unit}) | {p.meaning.replace('|', chr(92) + '|')} |")
    return rows


def main(out: Path) -> int:
    for name in EXAMPLES:
        path = config.DEFAULTS / name
        if path.is_file():
            data = tomllib.loads(path.read_text())
            (config.parse_plan if "plan" in data else config.parse_rig)(data, name)
    for data in EXTRA:
        config.parse_plan(data, "extra")
    notes = comments()
    lines = ["# Plan and rig keys", "",
             "Every key a plan file (`[plan...]`) and a rig file (`[rig...]`) may hold, with its type, range "
             "and default as the bench checks them (generated by `docs/gen_keys.py` from the validators in "
             "`bench/config.py` and `bench/rig_config.py`; the meaning is the comment beside the key in the annotated examples in "
             "`bench/defaults/`). Units are in the key's name (`_N`, `_Hz`, `_s`, `_m`, `_V`, ...). An unknown "
             "key is refused with the close valid one; every problem of a file is named in one go.", ""]
    for table in config.KEYS:
        keys = [k for k in config.KEYS[table] if f"{table}.{k}" not in config.KEYS]
        if not keys:
            continue
        lines += [f"## `[{table}]`", "", "| key | type and range | default | meaning (from the example files) |", "|---|---|---|---|"]
        for k in keys:
            info = seen.get((table, k))
            if info is None and table == "rig" and k == "model":
                continue
            typ, dflt = (bounds(info), default(info)) if info else SPECIAL.get((table, k), ("", "-"))
            lines.append(f"| `{k}` | {typ} | {dflt} | {notes.get((table, k), '')} |")
        lines.append("")
    lines += ["## `[rig.model]` (simulated rigs)", "",
              "SI units; each key is a field of `sim.rig.RigModel`, which declares its unit, range, default and "
              "meaning (decision record 0058); the equations are in decision record 0013.", "",
              "| key | type and range | default | meaning |", "|---|---|---|---|", *model_rows(), "",
              "### Friction models' parameters (`[rig.model]`, with `friction` = the model)", "",
              "Each model of `sim.friction.MODELS` declares its parameters (decision records 0073, 0075); with "
              "`friction` naming it they are keys of `[rig.model]`, every one required; a parameter of another "
              "model than the one named is refused. Masing's are `F_s_N`, `x_s_m`, `n` above.", "",
              "| friction | key | type and range | meaning |", "|---|---|---|---|", *friction_rows(), ""]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")
    missing = [(t, k) for t in config.KEYS for k in config.KEYS[t] if f"{t}.{k}" not in config.KEYS
               and (t, k) not in seen and (t, k) not in SPECIAL and (t, k) != ("rig", "model")]
    if missing:
        print(f"error: keys no example reaches (their range unknown): {missing}", file=sys.stderr)
        return 1
    print(f"wrote {out} ({sum(len(v) for v in config.KEYS.values())} keys, {len(config.model_schema())} model keys)")
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "reference" / "keys.md"))
