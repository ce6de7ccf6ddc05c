"""The house's bars (issue 35, decisions 0057, 0059 and 0067), read from the source tree: no
branch on the words of a message, the values converted to codes carry no sentence (their words
are made in bench/words/), one kernel that fits harmonics to a record, rooms of at most 600
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

# the values whose words are made by the renderers of bench/words/ (decision 0067): their
# codes' enum, the modules that make them, and each constructor (or helper that builds one)
# with the position of its code argument
# (None: an exception that must not be raised with words there)
CODED = {"Problem": (("bench/step_files.py", "bench/storage.py", "bench/accounting.py", "bench/commands/results.py"),
                     {"StepProblem": 3, "bad": 1}),
         "LockRefusal": (("bench/runlock.py",), {"refused": 1, "InUse": None}),
         "OutDirRefusal": (("bench/demo.py",), {"refused": 1, "ConfigurationError": None}),
         "RunDirRefusal": (("bench/storage.py",), {"refused": 1, "RunDirError": None, "NewerFormat": None,
                                                   "FileExistsError": None, "StorageError": None}),
         "CheckLine": (("bench/commands/results.py",), {"say": 0}),
         "PageWarning": (("bench/watch/snapshot.py",), {"page.warning": 0}),
         "RunLine": (("bench/commands/run.py",), {"say": 0}),
         "ModeLine": (("bench/commands/results.py",), {"say_mode": 0}),
         "ConfigProblem": (("bench/toml_tables.py",), {"refused": 1, "self._bad": 0, "self.coded": 0,
                                                          "ConfigError": None}),
         "ConfigRule": (("bench/config.py", "bench/rig_config.py"), {"ConfigError": None}),
         "SequenceProblem": (("bench/sequence.py",), {"refused": 1, "bad": 0, "ConfigurationError": None,
                                                      "RunDirectoryError": None}),
         "PaperRule": (("bench/rig_model.py",), {"refused": 1, "ConfigurationError": None}),
         "ApiRefusal": (("bench/api.py",), {"refused": 1, "TypeError": None, "ConfigurationError": None}),
         "PluginRefusal": (("bench/testing.py",), {"refused": 1, "ValueError": None}),
         "_Missing": (("bench/__init__.py",), {"refused": 1, "AttributeError": None}),
         "StudyArgs": (("bench/studies/cli.py",), {"refused": 1, "ConfigurationError": None})}

# modules converted whole: they decide and make no sentence (docstrings aside); their words are
# made by a renderer (bench/words/, or sim/artefacts/sentences.py for the words a step file stores)
WORDLESS = ("bench/step_files.py", "bench/runlock.py", "sim/artefacts/causes.py", "sim/artefacts/cleaning.py",
            "sim/artefacts/decision.py", "sim/artefacts/quality.py", "bench/verdict.py", "bench/reports/_overall.py",
            "bench/toml_tables.py", "bench/commands/run.py", "bench/session.py", "bench/durable.py", "bench/signals.py",
            "bench/storage.py", "bench/files.py", "bench/accounting.py",
            "bench/warmup.py", "bench/demo.py", "bench/cli.py", "bench/watch/server.py", "bench/watch/stop.py",
            "bench/watch/snapshot.py", "bench/sources.py", "bench/twin.py", "bench/compare.py", "bench/export.py",
            "bench/export_modes.py", "bench/analyze.py", "bench/commands/tools.py", "bench/commands/results.py",
            "bench/studies/engine.py", "bench/studies/montecarlo.py", "bench/studies/maps.py", "bench/studies/batch.py",
            "bench/studies/__init__.py", "bench/config.py", "bench/rig_config.py", "bench/sequence.py",
            "bench/plan_time.py", "bench/rig_model.py",
            "bench/api.py", "bench/testing.py", "bench/numbers.py", "bench/backbone.py", "bench/__init__.py",
            "bench/studies/cli.py", "bench/__main__.py", "bench/commands/__init__.py", "bench/terminal.py",
            "bench/watch/__init__.py", "bench/frf_import.py", "bench/frf_run.py", "bench/fundamentals.py",
            "bench/mat73.py")

# the renderers (decision 0071): the modules that make the words of an output from values and
# decide nothing that is stored or acted upon; every other module of bench/ is WORDLESS
RENDERERS = ("bench/words/", "bench/reports/", "bench/studies/figures.py")


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


def _sentence(node: ast.AST) -> str | None:
    """A string literal or f-string whose literal text holds a space between words: words for
    a person (a file name such as ``f"{key}.json"`` is not)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        text = node.value
    elif isinstance(node, ast.JoinedStr):
        text = "".join(v.value for v in node.values if isinstance(v, ast.Constant) and isinstance(v.value, str))
    else:
        return None
    return text if re.search(r"[A-Za-z]\w* [A-Za-z(]", text) else None


def _called(node: ast.Call) -> str | None:
    """The name a call calls: ``f`` or ``module.f``."""
    f = node.func
    if isinstance(f, ast.Name):
        return f.id
    return f"{f.value.id}.{f.attr}" if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) else None


def test_a_coded_value_carries_no_sentence():
    """Where a value's words moved to the renderers, its constructor gets a code of its enum
    and fields, never words: a new problem is a new code and its words in bench/words/."""
    found = []
    for enum, (modules, makers) in CODED.items():
        for rel in modules:
            text = (REPO / rel).read_text()
            for node in ast.walk(ast.parse(text)):
                cls = _called(node) if isinstance(node, ast.Call) else None
                if cls not in makers:
                    continue
                at = makers[cls]
                code = (node.args[at] if len(node.args) > at else
                        next((k.value for k in node.keywords if k.arg == "code"), None)) if at is not None else None
                if at is not None and not (isinstance(code, ast.Attribute) and getattr(code.value, "id", None) == enum
                                           or isinstance(code, ast.Name)):
                    found.append(f"{rel}:{node.lineno}: {cls}(...) without a {enum} code")
                parts = {id(v) for sub in ast.walk(node) if isinstance(sub, ast.JoinedStr) for v in sub.values}
                for sub in ast.walk(node):
                    if id(sub) not in parts and (said := _sentence(sub)) is not None:
                        found.append(f"{rel}:{sub.lineno}: {cls}(...) given words {said!r}")
    assert not found, "a coded value carries words (give it a code and its words in bench/words/):\n" + "\n".join(found)


# the command line's declaration: argparse's help, description and epilog (words, not messages)
DECLARING = {"add_argument", "add_parser", "ArgumentParser", "_Parser"}     # _Parser: bench.cli's ArgumentParser
DECLARED = {"help", "description", "epilog"}


def _declared(tree: ast.AST) -> set[int]:
    """The nodes of the ``help=``, ``description=`` and ``epilog=`` arguments of argparse's
    ``add_argument``, ``add_parser`` and ``ArgumentParser``."""
    out = set()
    for call in ast.walk(tree):
        if isinstance(call, ast.Call) and (getattr(call.func, "attr", None) or getattr(call.func, "id", None)) in DECLARING:
            out |= {id(n) for k in call.keywords if k.arg in DECLARED for n in ast.walk(k.value)}
    return out


def test_every_module_of_the_application_is_a_renderer_or_makes_no_sentence():
    """Issue 35 item 1: all wording lives in one renderer per output. A new module of bench/
    is either a renderer (RENDERERS) or WORDLESS (and then held by the test below)."""
    unsorted = [rel for rel, _ in _sources("bench") if rel not in WORDLESS and not rel.startswith(RENDERERS)]
    assert not unsorted, "modules neither a renderer nor WORDLESS (decision 0071): " + ", ".join(unsorted)


def test_a_converted_module_makes_no_sentence():
    found = []
    for rel in WORDLESS:
        tree = ast.parse((REPO / rel).read_text())
        docs = {id(n.body[0].value) for n in ast.walk(tree)
                if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                and n.body and isinstance(n.body[0], ast.Expr)}
        # an attribute's docstring: a string statement right after a module's or a class's assignment
        docs |= {id(b.value) for n in ast.walk(tree) if isinstance(n, (ast.Module, ast.ClassDef))
                 for a, b in zip(n.body, n.body[1:]) if isinstance(a, (ast.Assign, ast.AnnAssign))
                 and isinstance(b, ast.Expr) and isinstance(b.value, ast.Constant)}
        parts = {id(v) for n in ast.walk(tree) if isinstance(n, ast.JoinedStr) for v in n.values}
        # a StrEnum member's value is a code, stored as it is (RunStatus.INSTRUMENT_ERROR = "instrument error")
        codes = {id(a.value) for n in ast.walk(tree) if isinstance(n, ast.ClassDef)
                 and any(ast.unparse(b).endswith("StrEnum") for b in n.bases)
                 for a in n.body if isinstance(a, ast.Assign)}
        skip = docs | parts | codes | _declared(tree)
        found += [f"{rel}:{n.lineno}: {said!r}" for n in ast.walk(tree)
                  if id(n) not in skip and (said := _sentence(n)) is not None]
    assert not found, "words made outside the renderers (move them to bench/words/ or the module's sentences):\n" + \
        "\n".join(found)


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
