"""The house's bars (issue 35, decisions 0057 and 0059), read from the source tree: no branch
on the words of a message, one kernel that fits harmonics to a record, rooms of at most 600
lines or a reason at their top, benchmarks that import no test module, one helper that
starts `bench` in a process, one UFF58 reader."""

from __future__ import annotations

import ast
import re

from benchtools import REPO

PRODUCT = ("bench", "procedures", "sim", "drivers")
MAX_LINES = 600
REASON = "Longer than 600 lines:"       # the phrase a long module's docstring gives its reason with

# the branches that read a message's words (issue 35 item 1); none may come back
KNOWN_TEXT_BRANCHES = ('startswith("not periodic enough")', 'failed.startswith("harmonic ")',
                       '.endswith("mains")', 'family.split()[0]', 'base.split()[0]', '.startswith(f"{base:g} Hz")',
                       'startswith("missing: neither")', 'reason.startswith("truncated")', 'e.msg.startswith(',
                       '"shaker" in e', '"interference" in e', '"reached the bound" in', 'curve.startswith(',
                       '"refine" in self.note', '"dwell" in self.note', '"harmonic" not in src', 'src.split(" (")')
# any other test of a message's text: a string compared with a reason, a message, a note ...
TEXT_BRANCH = re.compile(r'\.(reason|msg|message|why|note|text|curve|detail|warning)s?\.(startswith|endswith)\('
                         r'|"[^"]*" (not )?in (str\(e\)|[a-z_.]*(reason|msg|message|note|warning|why|text)s?\b)')
# argparse's help formatter reads the help text it formats (the words themselves, not a decision)
TEXT_ALLOWED = {("bench/cli.py", '"default" in text')}


# modules that start `bench` in a process of their own on purpose (decision 0057)
OWN_SPAWN = {"test_house.py", "test_packaging.py", "test_run_dir_files.py", "test_demo_out.py", "test_api.py", "test_terminal.py",
             "test_studies.py"}


def _sources(*tops: str):
    for top in tops:
        for p in sorted((REPO / top).rglob("*.py")):
            if ".venv" not in p.parts:
                yield p.relative_to(REPO).as_posix(), p.read_text()


def test_no_branch_reads_the_words_of_a_message():
    found = []
    for rel, text in _sources("bench", "procedures", "sim"):
        for i, line in enumerate(text.splitlines(), 1):
            code = line.split("#", 1)[0]
            hits = [k for k in KNOWN_TEXT_BRANCHES if k in code]
            m = TEXT_BRANCH.search(code)
            if m and not any(r == rel and a in code for r, a in TEXT_ALLOWED):
                hits.append(m.group(0))
            found += [f"{rel}:{i}: {h}" for h in hits]
    assert not found, "branches on a message's words (make the decision a value, decision 0059):\n" + "\n".join(found)


def _fits_harmonics(node: ast.FunctionDef, src: str) -> bool:
    """A function that fits harmonics to a record itself: a least-squares fit on sine and
    cosine columns, or a single-bin Fourier sum at the drive frequency."""
    said = f"{node.name} {ast.get_docstring(node) or ''}".lower()
    if "harmonic" not in said and "fundamental" not in said:
        return False                          # a line's or a transient's sinusoid, not the drive's harmonics
    body = ast.get_source_segment(src, node) or ""
    lsq = "lstsq" in body and "np.sin" in body and "np.cos" in body
    dft = re.search(r"np\.dot\(.*np\.exp\(-2j", body) is not None or "np.fft.rfft(x)" in body
    return lsq or dft


def test_one_kernel_fits_harmonics_to_a_record():
    found = set()
    for rel, text in _sources(*PRODUCT):
        if rel == "sim/records.py":          # the kernel, and the frequency fit beside it
            continue
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef) and _fits_harmonics(node, text):
                found.add((rel, node.name))
    assert not found, f"harmonics fitted outside sim.records.lsq_harmonics: {sorted(found)}"
    src = (REPO / "procedures/analysis.py").read_text()
    assert "lsq_harmonics(" in src, "procedures.analysis.fit_harmonics is the kernel's wrapper"


def test_a_module_over_600_lines_says_why_at_its_top():
    long = []
    for rel, text in _sources(*PRODUCT, "benchtools", "benchmarks"):
        lines = text.splitlines()
        if len(lines) > MAX_LINES and REASON not in "\n".join(lines[:40]):
            long.append(f"{rel}: {len(lines)} lines")
    assert not long, f"split by job, or say why in the module docstring ({REASON!r}): {long}"


def test_benchmarks_and_benchtools_import_no_test_module():
    bad = [rel for rel, text in _sources("benchmarks", "benchtools")
           if re.search(r"^\s*(import tests\b|from tests\b)", text, re.M)]
    assert not bad, bad


def test_one_helper_starts_bench_in_a_process():
    spawn = re.compile(r'"-m", "bench|bench\.cli"\]|bin/bench"|def _bench\(|def bench_main\(')
    bad = [rel for rel, text in _sources("tests")
           if spawn.search(text) and rel.rsplit("/", 1)[-1] not in OWN_SPAWN]
    assert not bad, f"start bench with benchtools.procs (bench_process, bench_done, bench_main): {bad}"


def test_one_uff58_reader():
    readers = [rel for rel, text in _sources(*PRODUCT) if re.search(r"\.read_sets\(|\.get_set_types\(", text)]
    assert readers == ["bench/sources.py"], f"UFF58 is read by bench.sources.load_source only: {readers}"
