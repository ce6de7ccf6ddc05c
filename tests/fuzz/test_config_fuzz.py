"""Fuzzing plan and rig TOML: mutations of the shipped default files.

Text mutations (characters deleted, inserted, replaced; lines dropped or repeated) and
value mutations (any leaf replaced by a value of another type or out of range: NaN, inf,
negatives, huge numbers, strings, lists, tables) must give a Plan/Rig or a ConfigError
naming the file; nothing else.  A plan that loads must also give its schedule.
"""

from __future__ import annotations

import math
import tomllib

from hypothesis import given
from hypothesis import strategies as st

from bench.config import DEFAULTS, ConfigError, load_plan, load_rig, parse_plan, parse_rig
from procedures.plan import Plan, Rig

from ._settings import fuzz

FILES = {"plan": (DEFAULTS / "demo_plan.toml", load_plan, parse_plan, Plan),
         "rig": (DEFAULTS / "sim_rig.toml", load_rig, parse_rig, Rig)}
TEXT = {k: v[0].read_text() for k, v in FILES.items()}

odd_values = st.one_of(
    st.integers(-10**20, 10**20), st.floats(allow_nan=True, allow_infinity=True), st.booleans(),
    st.text(max_size=10), st.sampled_from([0, -1, 1e308, 1e-308, "", "up", "skip", "refuse", "both"]),
    st.lists(st.one_of(st.floats(), st.integers(), st.text(max_size=3)), max_size=5),
    st.dictionaries(st.text(max_size=5), st.integers(), max_size=2),
)


@st.composite
def text_mutations(draw, kind):
    lines = TEXT[kind].splitlines(keepends=True)
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["char", "drop line", "repeat line", "insert"]))
        i = draw(st.integers(0, max(0, len(lines) - 1)))
        if op == "drop line" and lines:
            del lines[i]
        elif op == "repeat line" and lines:
            lines.insert(i, lines[i])
        elif op == "insert":
            lines.insert(i, draw(st.text(alphabet="[]=.\"'#abcdefgnz_0123456789 -+e\n", max_size=30)) + "\n")
        elif lines:
            s = lines[i]
            j = draw(st.integers(0, len(s)))
            c = draw(st.sampled_from(list("=[]\"'.,#0123456789-+eE ") + ["", "\x00", "\u00e9"]))
            lines[i] = s[:j] + c + s[j + 1:]
    return "".join(lines)


def _leaves(d, path=()):
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _leaves(v, path + (k,))
        else:
            yield path + (k,)


@st.composite
def value_mutations(draw, kind):
    data = tomllib.loads(TEXT[kind])
    leaves = list(_leaves(data))
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(leaves))
        node = data
        for k in path[:-1]:
            node = node[k]
        if draw(st.booleans()) and path[-1] in node:
            node[path[-1]] = draw(odd_values)
        else:
            node.pop(path[-1], None)
    return data


def _check(kind, result):
    cls = FILES[kind][3]
    assert isinstance(result, cls)
    if isinstance(result, Plan):
        steps = result.schedule()
        assert steps and all(math.isfinite(s.freq_Hz) and s.freq_Hz > 0 for s in steps)


@given(st.sampled_from(sorted(FILES)).flatmap(lambda k: st.tuples(st.just(k), text_mutations(k))))
@fuzz(150)
def test_text_mutations_give_a_config_or_a_config_error_naming_the_file(tmp_path_factory, case):
    kind, text = case
    path = tmp_path_factory.mktemp("cfg") / f"mutated_{kind}.toml"
    path.write_text(text, encoding="utf-8")
    try:
        result = FILES[kind][1](path)
    except ConfigError as e:
        assert str(e).startswith(str(path)), e
    else:
        _check(kind, result)


@given(st.sampled_from(sorted(FILES)).flatmap(lambda k: st.tuples(st.just(k), value_mutations(k))))
@fuzz(250)
def test_value_mutations_give_a_config_or_a_config_error_naming_the_key(case):
    kind, data = case
    try:
        result = FILES[kind][2](data, f"fuzzed-{kind}.toml")
    except ConfigError as e:
        assert str(e).startswith(f"fuzzed-{kind}.toml"), e
    else:
        _check(kind, result)


@given(st.sampled_from(sorted(FILES)), st.sampled_from(["utf-8", "utf-8-sig", "utf-16", "utf-16-le", "utf-16-be",
                                                        "latin-1", "cp1252"]),
       st.sampled_from(["\u00e9", "\u00b5", "\u00b1", ""]), st.integers(0, 5000))
@fuzz(60)
def test_any_encoding_or_nesting_gives_a_config_or_an_error_naming_the_file_and_the_encoding(
        tmp_path_factory, kind, encoding, char, depth):
    """A file saved as UTF-16 or Latin-1 (issue 24, item 7), or nested thousands deep: a
    Plan/Rig or a ConfigError naming the file and what is wrong, never an internal error."""
    text = TEXT[kind].replace("\n", f"  # {char}\n", 1) + (f"deep = {'[' * depth}{']' * depth}\n" if depth else "")
    path = tmp_path_factory.mktemp("enc") / f"{kind}.toml"
    path.write_bytes(text.encode(encoding))
    try:
        result = FILES[kind][1](path)
    except ConfigError as e:
        assert str(e).startswith(str(path)), e
        if encoding.startswith("utf-16"):
            assert "UTF-16" in str(e)
        elif encoding in ("latin-1", "cp1252") and char:
            assert "not UTF-8" in str(e) and "another encoding" in str(e)
        elif depth > 500:
            assert "nested too deeply" in str(e) or "deep: unknown key" in str(e) or "unknown table" in str(e)
    else:
        assert encoding.startswith("utf-8") or not char, (encoding, char)
        _check(kind, result)


@given(value_mutations("plan"))
@fuzz(150)
def test_a_stored_plan_mutated_gives_a_plan_or_an_error_naming_run_json(data):
    """The plan stored in run.json (Plan.to_dict) goes through the plan file's validator
    (issue 24, item 6): a Plan or a ConfigError naming run.json and the key."""
    from bench.config import parse_stored_plan
    try:
        stored = parse_plan(data).to_dict()
    except ConfigError:
        return
    try:
        plan = parse_stored_plan(stored, "RUN/run.json")
    except ConfigError as e:
        raise AssertionError(f"a valid plan's stored form refused: {e}") from e
    assert plan == parse_plan(data)
    for key, value in (("levels_N", "abc"), ("freqs_Hz", []), ("direction", "sideways"), ("harmonics", -1)):
        try:
            parse_stored_plan(dict(stored, **{key: value}), "RUN/run.json")
        except ConfigError as e:
            assert str(e).startswith("RUN/run.json: [plan"), e
        else:
            raise AssertionError(f"{key} = {value!r} passed")
