"""The documentation names only what exists (issue 34 item 6): every `bench` command and option
in the README and the pages under docs/ is one the command line has, every plan and rig key in
their TOML examples is one the parser accepts, every file they point at is in the repository,
and the key reference is generated from the parser itself."""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib

import pytest

from bench.cli import build_parser
from bench.config import KEYS, model_schema
from benchtools import REPO

PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md")), *sorted((REPO / "docs" / "howto").glob("*.md")),
         REPO / "docs" / "reference" / "api.md", REPO / "examples" / "lab-ci" / "README.md"]


def subcommands() -> dict[str, set[str]]:
    """command -> its options (long and short), from the argparse tree."""
    import argparse
    parser = build_parser()
    out: dict[str, set[str]] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                opts = {o for a in sub._actions for o in a.option_strings}
                for a in sub._actions:                  # bench study map|mc ...
                    if isinstance(a, argparse._SubParsersAction):
                        for sname, ssub in a.choices.items():
                            out[f"{name} {sname}"] = {o for b in ssub._actions for o in b.option_strings}
                out[name] = opts
    top = {o for a in parser._actions for o in a.option_strings}
    out[""] = top
    return out


def command_lines(text: str) -> list[str]:
    """Every `bench ...` invocation written in a code block or inline code."""
    blocks = re.findall(r"```(?:sh|bash|console)?\n(.*?)```", text, re.S) + re.findall(r"`([^`\n]+)`", text)
    lines = []
    for b in blocks:
        for line in b.splitlines():
            line = line.split(" # ")[0].strip()
            m = re.search(r"(?:^|\s|/)bench\s+([a-z-]+.*)$", line)
            if m and not line.startswith(("import", "from", "#")):
                lines.append(m[1])
    return lines


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_command_and_option_a_page_names_exists(page):
    cmds = subcommands()
    text = page.read_text()
    problems = []
    for line in command_lines(text):
        words = line.split()
        name = words[0]
        if name.startswith("-"):
            options = cmds[""]
        elif len(words) > 1 and f"{name} {words[1]}" in cmds:
            options = cmds[f"{name} {words[1]}"]
        elif name in cmds:
            options = cmds[name] | cmds[""]
        else:
            problems.append(f"bench {name}: no such command ({line!r})")
            continue
        for w in words[1:]:
            opt = w.split("=")[0]
            if opt.startswith("-") and opt not in options and opt != "--":
                problems.append(f"bench {name} {opt}: no such option ({line!r})")
    assert not problems, "\n".join(problems)


def toml_blocks(text: str) -> list[dict]:
    out = []
    for b in re.findall(r"```toml\n(.*?)```", text, re.S):
        try:
            out.append(tomllib.loads(b))
        except tomllib.TOMLDecodeError:
            pass            # a fragment ("levels = [...]"): nothing whole to check
    return out


def unknown_keys(data: dict, path: str = "") -> list[str]:
    bad = []
    for k, v in data.items():
        full = f"{path}.{k}" if path else k
        if path in KEYS and k not in KEYS[path]:
            bad.append(full)
        elif path == "rig.model" and k not in model_schema():
            bad.append(full)
        elif isinstance(v, dict) and (full in KEYS or full == "rig.model"):
            bad += unknown_keys(v, full)
    return bad


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_key_in_a_pages_plan_or_rig_example_is_accepted(page):
    bad = [k for data in toml_blocks(page.read_text()) for k in unknown_keys(data)]
    assert not bad, f"{page.name}: keys the parser does not know: {bad}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_no_page_points_outside_the_repository(page):
    text = page.read_text()
    assert "../shared" not in text
    for target in re.findall(r"\]\(([^)#\s]+)\)", text):
        if "://" in target:
            continue
        assert (page.parent / target).resolve().exists() or (REPO / target).exists() or \
            (page.parent / target).with_suffix(".md").exists() or target.endswith(("keys.md",)), \
            f"{page.name}: link to {target}, which is not in the repository"


def test_the_key_reference_is_generated_from_the_parser_and_covers_every_key(tmp_path):
    out = tmp_path / "keys.md"
    proc = subprocess.run([sys.executable, str(REPO / "docs" / "gen_keys.py"), str(out)], capture_output=True,
                          text=True, cwd=REPO)
    assert proc.returncode == 0, proc.stderr
    text = out.read_text()
    for table, keys in KEYS.items():
        for k in keys:
            if f"{table}.{k}" not in KEYS and (table, k) != ("rig", "model"):
                assert re.search(rf"^\| `{re.escape(k)}` \| \S", text, re.M), f"[{table}] {k} missing"
    for k in model_schema():
        assert f"| `{k}` |" in text
    # a range that the parser checks is the one printed: the bench's force range for levels_N
    assert "| `levels_N` | list of numbers >= 0.1 and <= 100 | **required** |" in text
