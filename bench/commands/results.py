"""`bench report`, `export`, `identify`, `analyze`, `check`, `compare` and `modes`: what a
stored run says (argument handling and printing; the work is in the modules they call)."""

from __future__ import annotations

import logging
from enum import StrEnum
from pathlib import Path

from sim.errors import ConfigurationError

from ..terminal import Progress
from ..words import terminal
from ..words import terminal_data as words
from . import ExitCode
from .run import _latch, _report

log = logging.getLogger(__name__)


def cmd_report(args) -> int:
    latch = _latch()
    with latch.installed():
        _report(Path(args.run), latch, [Path(p) for p in args.with_runs or ()])
        latch.finish()
    if latch.reason is not None:
        raise KeyboardInterrupt(latch.reason)
    return 0


def cmd_export(args) -> int:
    from ..api import open_run
    for p in open_run(args.run).export(args.out, time_records=not args.no_time):
        print(p)
    return 0


def cmd_identify(args) -> int:
    """Offline identification of a stored run (result written into its run.json) or of
    UFF58 time records (guesses from --rig, default: the simulated rig's file), with the
    model of the rig: the modes its file declares and, once `bench analyze` has run, the
    causes it named (decision 0042)."""
    import json

    from procedures.online_id import MAX_HARMONICS, check_finite
    from sim.discrepancy.rigfit import analysis_effects, identify_steps

    from ..analyze import default_out_dir
    from ..config import DEFAULTS, load_rig, parse_rig, rig_toml
    from ..sources import SourceProblem, load_source
    from ..storage import RunStore
    from ..words.numbers import number

    source = Path(args.source)
    if not source.exists():
        raise FileNotFoundError(2, say_result(ResultLine.NO_SOURCE), str(source))
    from ..analyze import refuse_imported
    refuse_imported(source)               # fundamentals only: nothing to identify the friction from yet
    src = load_source(source)
    if src.kind == "run":
        rig = parse_rig({"rig": rig_toml(src.metadata["rig"])}, f"{source}/run.json")
    else:
        rig = load_rig(Path(args.rig) if args.rig else DEFAULTS / "sim_rig.toml")
    for r in src.rejected:
        print(say_result(ResultLine.STEP_REJECTED, step=r.step, reason=r.reason))
    if not src.steps:
        raise words.refused(ConfigurationError, SourceProblem.NO_STEPS_TO_IDENTIFY, path=source)
    guess = rig.guess()
    analysis_json = default_out_dir(source) / "analysis.json"
    extra: tuple[str, ...] = ()
    analysis = None
    if analysis_json.is_file():
        try:
            analysis = json.loads(analysis_json.read_text())
            extra = analysis_effects(analysis)
        except (OSError, ValueError) as e:
            analysis = None
            print(say_result(ResultLine.ANALYSIS_UNREADABLE, path=analysis_json, detail=str(e)))
    est = identify_steps(src.steps, guess, rig.model, extra, MAX_HARMONICS)
    check_finite(est)
    friction = preferred_friction(analysis, analysis_json)
    if friction is not None:
        est["friction_model"] = friction
    if src.kind == "run":
        RunStore.open(source).update(identification=est)
    if friction is None:
        print(say_result(ResultLine.FRICTION_NOT_COMPARED, source=source))
    else:
        print(say_result(ResultLine.FRICTION_PREFERRED, **friction))
    effects = est.get("model", {}).get("effects") or []
    print(say_result(ResultLine.MODEL, effects=effects, source=est.get("source"), named="source" in est))
    print(say_result(ResultLine.TABLE_HEAD))
    for k, v in est["values"].items():
        print(f"{k:>10} {number(v, fmt='.6g'):>12} [{number(est['low'][k], fmt='.6g'):>12}, "
              f"{number(est['high'][k], fmt='.6g'):>12}]")
    for k, p in (est.get("model", {}).get("parameters") or {}).items():
        print(f"{k:>10} {number(p['value'], fmt='.6g'):>12} [{number(p['low'], fmt='.6g'):>12}, "
              f"{number(p['high'], fmt='.6g'):>12}]")
    print(say_result(ResultLine.FIT, steps=len(src.steps), rejected=len(src.rejected),
                     chi2=number(est["reduced_chi2"], fmt=".3g")))
    for w in est["warnings"]:
        print(say_result(ResultLine.WARNING, text=w))
    return 0


def preferred_friction(analysis, path: Path) -> dict | None:
    """The friction model an analysis of the source prefers (issue 41 item 5): ``model``,
    ``label``, its ``parameters`` ({name: {value, low, high, unit}}, 95 %) and the file
    (``analysis``); None without an analysis that compared the models (decision 0087)."""
    from sim.friction import MODELS
    if not isinstance(analysis, dict) or not isinstance(analysis.get("friction_models"), dict):
        return None
    name = str(analysis.get("friction_model") or "masing")
    rows = [r for r in analysis["friction_models"].get("table") or [] if isinstance(r, dict) and r.get("model") == name]
    params = rows[0].get("parameters") if rows and isinstance(rows[0].get("parameters"), dict) else {}
    return dict(model=name, label=MODELS[name].label if name in MODELS else name, analysis=str(path),
                parameters={k: v for k, v in params.items() if isinstance(v, dict)})


def cmd_analyze(args) -> int:
    """Where the Masing model is wrong in SOURCE, the cause, the extended model and its gain."""
    from ..analyze import analyze_source, default_out_dir
    from ..studies.cli import cmd_analyze_batch, is_batch
    if is_batch(args):
        return cmd_analyze_batch(args, Progress)
    source = Path(args.sources[0])
    result = analyze_source(source, Path(args.out) if args.out else None, Path(args.rig) if args.rig else None)
    out = Path(args.out) if args.out else default_out_dir(source)
    print(result["verdict"])
    if "fundamentals" in result:          # an imported run: the fit to fundamentals (decision 0084)
        print(say_result(ResultLine.FUNDAMENTALS_WRITTEN, out=out))
        return 0
    print(say_result(ResultLine.ANALYZED, causes=[c["id"] for c in result["causes"]], unexplained=result["unexplained"],
                     friction_model=str(result.get("friction_model") or "masing"),
                     out=out))
    return 0


def cmd_check(args) -> int:
    """Verify a run directory against its plan: every missing, damaged and orphan step on
    one line, and what a refined run still owes (a refinement whose end is not recorded, a
    dwell not measured: decision 0050), then the count; exit 1 if there is any problem.  A step skipped at run time
    (force unreachable) as the plan allows (``infeasible = "skip"``) is listed and counted,
    not a problem (exit 0 when it is the only gap) unless ``--strict`` (decision 0033)."""
    from ..storage import NewerFormat, RunDirError, RunStatus, RunStore

    store = RunStore(Path(args.run))
    if not store.path.is_dir():
        RunStore.open(store.path)             # raises the one-line usage error
    try:
        acc = store.account()
    except NewerFormat:
        raise                                 # refused by name (exit 2), as report and resume do
    except RunDirError:                       # run.json damaged or its plan not valid: the files alone
        acc = None
    problems = store.check() if acc is None else acc.missing + acc.damaged + acc.orphan + acc.owed
    skipped = [] if acc is None else acc.skipped
    for p in skipped:
        print(f"{p.kind:>9}  {p.key}: {p.reason}")
    tail = _not_yet_measured(store, acc) if acc is not None else []
    for p in problems:
        if p not in tail:
            print(f"{p.kind:>9}  {p.key}: {p.reason}" if p.kind == "owed" else f"{p.kind:>9}  {p}")
    if tail:
        last = max((k for k in acc.intact), default=None)
        print(f"{'missing':>9}  " + say(CheckLine.UNMEASURED_TAIL, last=last, count=len(tail), run=store.path))
    if acc is None:
        print(say(CheckLine.NO_PLAN, run=store.path, files=len(store.step_files()), problems=len(problems)))
        return ExitCode.FAILURE
    print(f"{store.path}: {acc.summary()}"
          + (say(CheckLine.RESUME_MEASURES, run=store.path) if acc.missing or acc.damaged else "")
          + (say(CheckLine.RESUME_OWES, run=store.path) if acc.owed and not (acc.missing or acc.damaged) else ""))
    from ..verdict import promise
    meta = store.metadata
    kept = promise(meta.get("plan") or {}, store.results(warn=False), meta.get("rig"),
                   completed=meta.get("status") == RunStatus.COMPLETED)
    if kept.short:        # the steps are intact; what they say against the procedure's promise (decision 0052)
        print(say(CheckLine.PROMISE_SHORT, label=kept.kind.label, short=[terminal.promised(s) for s in kept.short]))
    if skipped:
        print(say(CheckLine.SKIPPED, count=len(skipped), strict=args.strict))
    return ExitCode.FAILURE if problems or (skipped and args.strict) else ExitCode.OK


class CheckLine(StrEnum):
    """The lines ``bench check`` prints besides each problem's (their words:
    :data:`bench.words.terminal.CHECK`)."""

    UNMEASURED_TAIL = "unmeasured_tail"     # last (the last step stored, or None), count, run
    NO_PLAN = "no_plan"                     # run, files (step result files), problems
    RESUME_MEASURES = "resume_measures"     # run: what bench resume measures again
    RESUME_OWES = "resume_owes"             # run: what it measures of a refinement's debt
    PROMISE_SHORT = "promise_short"         # label (the procedure's), short: the shortfalls' words
    SKIPPED = "skipped_allowed"             # count, strict


class ModeLine(StrEnum):
    """The lines ``bench modes`` prints (their words: :data:`bench.words.terminal.MODES`);
    each mode's with run, mode and level (formatted in its quantity)."""

    LOCKED = "locked"                   # f_Hz, zeta (phase resonance: the locked point's energy balance)
    FITTED = "fitted"                   # f_Hz, zeta: (value, low, high); balance: (value, low, high) or None
    NOT_ESTIMATED = "not_estimated"     # status, note
    WROTE = "wrote"                     # files


class ResultLine(StrEnum):
    """The lines ``bench identify``, ``analyze`` and ``compare`` print, and their refusals
    (words: :data:`bench.words.terminal_data.RESULTS`)."""

    NO_SOURCE = "no_source"                 # the FileNotFoundError's strerror
    STEP_REJECTED = "step_rejected_here"    # step, reason
    ANALYSIS_UNREADABLE = "analysis_unreadable"     # path, detail: the reader's error
    MODEL = "model"                         # effects, source, named: whether the estimate names its source
    TABLE_HEAD = "table_head"
    FIT = "fit"                             # steps, rejected, chi2: formatted
    WARNING = "warning"                     # text: the identification's warning
    ANALYZED = "analyzed"                   # causes: ids, unexplained, friction_model (the preferred id), out
    FRICTION_PREFERRED = "friction_preferred"   # model, label, parameters, analysis: preferred_friction()
    FRICTION_NOT_COMPARED = "friction_not_compared"     # source: no analysis compared the friction models
    COMPARED = "compared"                   # out
    FUNDAMENTALS_WRITTEN = "fundamentals_written"   # out: an imported run's fit to fundamentals


def say_result(code: ResultLine, **fields) -> str:
    return words.said(code, **fields)


def say_mode(code: ModeLine, **fields) -> str:
    return terminal.say(terminal.MODES, code, fields)


def say(code: CheckLine, **fields) -> str:
    return terminal.say(terminal.CHECK, code, fields)


def _not_yet_measured(store, acc) -> list:
    """The missing steps of a run that was stopped (not completed) that are simply the
    plan's steps after the last one stored, with no file at all: one line says so instead
    of one line each.  Any other missing step is listed by key."""
    from ..storage import RunStatus, stored_plan
    try:
        meta = store.metadata
        plan = stored_plan(meta, store.path / "run.json")
    except Exception:  # noqa: BLE001 - no plan to judge against: list every step
        return []
    if meta.get("status") == RunStatus.COMPLETED or plan.adaptive_per_sweep:
        return []
    order = [s.key for s in plan.schedule()]
    present = {k for k in acc.intact} | {p.key for p in acc.damaged} | {p.key for p in acc.skipped}
    last = max((order.index(k) for k in present if k in order), default=-1)
    tail = [p for p in acc.missing if p.files == (".json", ".npz") and p.key in order
            and order.index(p.key) > last]
    return tail if len(tail) > 1 else []


def cmd_compare(args) -> int:
    """Exit 0 when the two sources agree within the tolerance over enough of the reference, 1 when not."""
    from ..compare import summary, write_compare
    result, out = write_compare(Path(args.reference), Path(args.other), Path(args.out) if args.out else None,
                                args.tolerance, args.min_coverage)
    print(summary(result), end="")
    print(say_result(ResultLine.COMPARED, out=out))
    return ExitCode.OK if result["overall"]["passed"] else ExitCode.FAILURE


def cmd_import(args) -> int:
    """Measured FRFs into a new run directory (bench.frf_run); every problem at once, exit 2."""
    from ..frf_run import import_frfs, imported_line
    out, imp = import_frfs(Path(args.source), Path(args.out), Path(args.mapping) if args.mapping else None)
    print(imported_line(out, imp))
    return ExitCode.OK


def cmd_modes(args) -> int:
    """Each run's modes per level (in its quantity's unit) into OUT/modes.csv, with the seed's Figs. 13 and 17."""
    from ..reports import write_modes
    runs, files = write_modes([Path(r) for r in args.runs], Path(args.out), model=not args.no_model)
    for r in runs:
        for e in r.modes:
            at = {"run": r.label, "mode": e.mode, "level": r.level_quantity.format(e.level_N)}
            if e.ok and e.phase_resonance:     # one locked point: its energy balance, no fit, no interval
                print(say_mode(ModeLine.LOCKED, **at, f_Hz=e.resonance_Hz, zeta=e.damping_ratio))
            elif e.ok:
                eb = e.extra.get("energy_balance")
                print(say_mode(ModeLine.FITTED, **at, f_Hz=(e.resonance_Hz, e.resonance_low_Hz, e.resonance_high_Hz),
                               zeta=(e.damping_ratio, e.damping_ratio_low, e.damping_ratio_high),
                               balance=(eb.value, eb.low, eb.high) if eb is not None else None))
            else:
                print(say_mode(ModeLine.NOT_ESTIMATED, **at, status=e.status, note=e.note))
    print(say_mode(ModeLine.WROTE, files=[str(f) for f in files]))
    return ExitCode.OK
