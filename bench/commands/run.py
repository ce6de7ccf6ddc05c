"""`bench dry-run`, `run`, `resume`, `sequence`, `demo` and `watch`: plan, run and watch a test
(argument handling and printing; the work is in bench.session, bench.api and bench.sequence)."""

from __future__ import annotations

import logging
import sys
import time
from enum import StrEnum
from pathlib import Path

from procedures.kind import FORCE, ProcedureKind
from sim.errors import ConfigurationError

from ..signals import Doing
from ..terminal import Progress, end_line
from ..words import terminal, terminal_run
from . import ExitCode

log = logging.getLogger(__name__)


class RunLine(StrEnum):
    """The lines ``bench run`` and ``bench resume`` print at the end of a run (their words:
    :data:`bench.words.terminal.RUN`)."""

    ENDED = "ended"                         # status, done, total (steps), out
    NO_REPORT = "no_report"                 # reason (the signal's), out
    REPORT = "report"                       # path, then (a signal during the report, or None)
    PROMISE_BROKEN = "promise_broken"       # label (the procedure's), short: the shortfalls' words
    OUTPUT_NEVER_ON = "output_never_on"
    OUTPUT_OFF = "output_off"               # confirmed by the generator
    OUTPUT_OFF_UNCONFIRMED = "output_off_unconfirmed"


class DryRunLine(StrEnum):
    """``bench dry-run``'s lines (their words: :data:`bench.words.terminal_run.DRY_RUN`)."""

    BACKBONE_PLAN = "backbone_plan"         # name, levels (count), start_Hz, min_Hz, max_Hz, rig, simulated, friction
    BACKBONE_TIME = "backbone_time"         # bound_s, max_blocks
    PLAN = "plan"                           # name, procedure, levels, freqs, direction, steps, rig, simulated, friction,
    #                                         measured, per_sweep, refined, refine_steps, modes, tolerance, dwell_cycles
    LEVELS = "levels"                       # levels, unit, quantity, held (a response's level)
    TIME = "time"                           # quantity, bound_s, without_extra_s, block_s, blocks, typical_s, refined
    STEPS = "steps"                         # lines: the planned steps', in order
    REFUSED = "refused"                     # first: the refusal's first line
    RUNS_SOME = "runs_some"                 # run, skipped (steps)
    ENVELOPE_OK = "envelope_ok"
    IDENTIFIABILITY = "identifiability"     # warning


class ResumeLine(StrEnum):
    """What ``bench resume`` says before it measures (:data:`bench.words.terminal_run.RESUME`)."""

    NOTHING_TO_DO = "nothing_to_do"         # skipped (any), summary
    MEASURES = "measures"                   # text: what it measures again
    FINISHING = "finishing"                 # skipped (any), status (the run's end)


class WatchLine(StrEnum):
    """The watch page's lines (:data:`bench.words.terminal_run.WATCH`)."""

    URL = "url"                             # url (beside a run)
    SERVING = "serving"                     # url (bench watch)
    WAITING = "waiting"                     # path
    NO_RUN_JSON = "no_run_json"             # path
    APPEARED = "appeared"                   # path


class SequenceEndLine(StrEnum):
    """``bench sequence``'s lines at its end (:data:`bench.words.terminal_run.SEQUENCE`)."""

    ENTRY = "entry"                         # name, status, done, total
    REPORT = "report"                       # path


class RunRefusal(StrEnum):
    """The one-line errors of these commands (:data:`bench.words.terminal_run.REFUSAL`)."""

    WATCH_PORT = "watch_port"               # host, port, error
    WATCH_A_FILE = "watch_a_file"           # path
    WATCH_NO_PARENT = "watch_no_parent"     # path, parent
    LABEL = "label"                         # item


def say(code: RunLine, **fields) -> str:
    return terminal.say(terminal.RUN, code, fields)


def _said(words: terminal.Words, code: StrEnum, **fields) -> str:
    return terminal.say(words, code, fields)


def _load_configs(args):
    from ..config import DEFAULTS, load_plan, load_rig

    plan = load_plan(Path(args.plan) if args.plan else DEFAULTS / "demo_plan.toml")
    rig = load_rig(Path(args.rig) if args.rig else DEFAULTS / "sim_rig.toml")
    return plan, rig


def cmd_dry_run(args) -> int:
    from ..plan_time import planned_step_list
    from ..session import EnvelopeError, check_envelope, envelope, envelope_report, planned_steps

    plan, rig = _load_configs(args)
    steps = plan.schedule()
    named = dict(name=plan.name, rig=rig.name, simulated=rig.simulated, friction=_rival_friction(rig))
    if plan.backbone:
        b = plan.backbone
        _dry(DryRunLine.BACKBONE_PLAN, levels=len(plan.levels_N), start_Hz=b.start_Hz, min_Hz=b.min_Hz,
             max_Hz=b.max_Hz, **named)
        from ..plan_time import backbone_time_bound_s
        _dry(DryRunLine.BACKBONE_TIME, bound_s=backbone_time_bound_s(plan), max_blocks=b.max_blocks)
    else:
        n, refined, seconds = planned_steps(plan)
        q = plan.level_quantity
        _dry(DryRunLine.PLAN, procedure=plan.procedure.label, levels=len(plan.levels_N), freqs=len(plan.freqs_Hz),
             direction=plan.direction, steps=len(steps), measured=n,
             per_sweep=plan.adaptive_per_sweep if plan.adaptive_per_sweep and n != len(steps) else None,
             refined=refined, refine_steps=plan.refine_steps, modes=list(plan.refine_modes),
             tolerance=plan.refine_tolerance, dwell_cycles=plan.dwell_cycles, **named)
        _dry(DryRunLine.LEVELS, levels=list(plan.levels_N), unit=q.unit, quantity=q.name, held=q.key != FORCE.key)
        print(dry_run_time_line(plan, seconds, refined))
        if getattr(args, "steps", False):
            _dry(DryRunLine.STEPS, lines=[p.line() for p in planned_step_list(plan)])
    print(envelope_report(envelope(plan, rig)))
    from procedures.online_id import identifiability
    try:
        runnable = check_envelope(plan, rig)
    except EnvelopeError as e:
        _dry(DryRunLine.REFUSED, first=str(e).splitlines()[0])
        return ExitCode.LIMIT
    if runnable.skip:
        _dry(DryRunLine.RUNS_SOME, run=len(runnable.schedule()), skipped=len(steps) - len(runnable.schedule()))
    else:
        _dry(DryRunLine.ENVELOPE_OK)
    for w in identifiability(runnable, rig) if plan.procedure is ProcedureKind.STEPPED_SINE else []:
        _dry(DryRunLine.IDENTIFIABILITY, warning=w)
    return 0


def _rival_friction(rig) -> str:
    """The label of a simulated rig's friction model when it is not Masing, else ""."""
    from sim.friction import MODELS
    from sim.rig_friction import MASING
    m = rig.model
    return MODELS[m.friction].label if rig.simulated and m is not None and m.friction != MASING else ""


def _dry(code: DryRunLine, **fields) -> None:
    print(_said(terminal_run.DRY_RUN, code, **fields))


def dry_run_time_line(plan, typical_s: float, refined: int) -> str:
    """dry-run's rig time: the upper bound (bench.plan_time) and the typical figure."""
    from ..plan_time import extra_block_seconds_max, rig_time_bound_s
    return terminal.say(terminal_run.DRY_RUN, DryRunLine.TIME, dict(
        quantity=plan.level_quantity.name, bound_s=rig_time_bound_s(plan),
        without_extra_s=rig_time_bound_s(plan, extra_settle=False),
        block_s=extra_block_seconds_max(plan, min(plan.freqs_Hz)), blocks=plan.max_extra_settle_blocks,
        typical_s=typical_s, refined=refined))


def _latch():
    """The program's signal latch (installed first thing in :func:`main`), or, when the
    bench runs inside another program (a test), one of this command's own."""
    from ..signals import SignalLatch, process_latch
    return process_latch() or SignalLatch()


def _run(args, resume: bool) -> int:
    latch = _latch()
    with latch.installed():       # SIGHUP, SIGQUIT, SIGTERM as Ctrl-C from the start
        return _session(args, resume, latch)


def _session(args, resume: bool, latch) -> int:
    from contextlib import ExitStack

    with ExitStack() as held:
        if resume:           # the run directory is ours before its steps are counted
            from .. import runlock
            from ..storage import RunStore
            RunStore.open(Path(args.run))
            held.enter_context(runlock.run_dir(Path(args.run)))
        return _session_held(args, resume, latch)


def _session_held(args, resume: bool, latch) -> int:
    from ..api import execute, stored_configs
    from ..storage import RunStatus, RunStore

    if resume:
        store = RunStore.open(Path(args.run))
        meta, acc = store.metadata, store.account()
        retry = bool(getattr(args, "retry_skipped", False)) and bool(acc.skipped)
        if acc.complete and not retry and meta.get("status") == RunStatus.COMPLETED:
            print(_said(terminal_run.RESUME, ResumeLine.NOTHING_TO_DO, skipped=bool(acc.skipped), summary=acc.summary()))
            return ExitCode.OK
        print(_said(terminal_run.RESUME, ResumeLine.MEASURES, text=acc.resume_text(retry))
              if acc.missing or acc.damaged or acc.owed or retry else
              _said(terminal_run.RESUME, ResumeLine.FINISHING, skipped=bool(acc.skipped), status=meta.get("status", "?")),
              flush=True)
        plan, rig = stored_configs(meta, f"{args.run}/run.json")     # validated as account() did
        out, seed = Path(args.run), meta.get("sim_seed")
        labels = None
    else:
        plan, rig = _load_configs(args)
        out, seed = Path(args.out), args.seed
        labels = parse_labels(getattr(args, "label", None))
    before = _event_count(out)
    watch = _start_watch(out, args)
    try:
        store = execute(plan, rig, out, resume=resume, progress=Progress(plan.procedure.label), seed=seed,
                        retry_skipped=bool(getattr(args, "retry_skipped", False)), labels=labels, latch=latch)
    finally:
        if watch:
            watch.close()
        end_line()                 # an interrupted run's progress line ends where it stood
        _say_output_state(out, before)
    meta = store.metadata
    code = {RunStatus.COMPLETED: ExitCode.OK, RunStatus.ABORTED: ExitCode.LIMIT}.get(meta["status"], ExitCode.FAILURE)
    wants_report = meta["status"] == RunStatus.COMPLETED and not getattr(args, "no_report", False)
    begin_report = False
    if wants_report:
        latch.reopen()             # the report is work too; held: nothing raises inside it (0051)
        latch.hold(doing=Doing.REPORT)
        begin_report = latch.reason is None    # decided before "run completed": a signal after it is one during the report
    print(say(RunLine.ENDED, status=meta["status"], done=meta["steps_done"], total=meta["steps_total"], out=out),
          flush=True)
    if wants_report:
        if begin_report:
            _report(out, latch)
        else:
            print(say(RunLine.NO_REPORT, reason=latch.reason, out=out), file=sys.stderr)
        latch.finish()
    if meta["status"] == RunStatus.COMPLETED:
        from ..verdict import promise
        kept = promise(meta.get("plan") or {}, store.results(warn=False), meta.get("rig"))
        if kept.fatal:           # completed, but not what the procedure was run for (decision 0052)
            print(say(RunLine.PROMISE_BROKEN, label=kept.kind.label, short=[terminal.promised(s) for s in kept.short]),
                  file=sys.stderr)
            code = ExitCode.FAILURE
    if latch.reason is not None and code == ExitCode.OK:
        raise KeyboardInterrupt(latch.reason)     # a signal before the work was done: exit 130
    return code


def _report(run: Path, latch, with_runs=()) -> None:
    """Write the run's report with ``latch`` held: a signal meanwhile is recorded, not
    raised into the numba kernels or the figures' finalizers where it could be swallowed,
    and is honoured once the report is complete (decision 0051)."""
    latch.hold(doing=Doing.REPORT)
    from ..api import open_run
    path = open_run(run).report(with_runs=tuple(with_runs))
    print(say(RunLine.REPORT, path=path, then=latch.reason), flush=True)


def _event_count(out: Path) -> int:
    """Number of events a run directory holds now (0 when there is none yet)."""
    from ..storage import RunStore
    try:
        return len(RunStore.open(out).events())
    except Exception:  # noqa: BLE001 - no run directory yet
        return 0


def _say_output_state(out: Path, since: int = 0) -> None:
    """On every ending (done, Ctrl-C, limit, error) say how this session left the output:
    the last ``output_off`` event among those written after the first ``since`` (the events
    of earlier sessions of a resumed run say nothing about this one).  No such event: this
    session never opened the generator far enough to switch the output on."""
    from ..storage import RunStore
    try:
        events = RunStore.open(out).events()[since:]
    except Exception:  # noqa: BLE001 - no run directory: nothing was opened
        events = []
    offs = [e for e in events if e.get("event") == "output_off"]
    if not offs:
        print(say(RunLine.OUTPUT_NEVER_ON), file=sys.stderr, flush=True)
    elif offs[-1].get("confirmed"):
        print(say(RunLine.OUTPUT_OFF), file=sys.stderr, flush=True)
    else:
        print(say(RunLine.OUTPUT_OFF_UNCONFIRMED), file=sys.stderr, flush=True)


def _start_watch(run_dir: Path, args):
    """The watch page beside the run (``--watch``), served from a thread of this process."""
    if not getattr(args, "watch", False):
        return None
    server = _watch_server(run_dir, args.watch_host, args.watch_port).start()
    print(_said(terminal_run.WATCH, WatchLine.URL, url=server.url), flush=True)
    return server


def _watch_server(run_dir: Path, host: str, port: int):
    from ..watch import WatchServer
    try:
        return WatchServer(run_dir, host, port)
    except OSError as e:       # port taken, no such interface, privileged port
        raise terminal_run.refused(ConfigurationError, RunRefusal.WATCH_PORT, host=host, port=port, error=e) from e


def cmd_watch(args) -> int:
    """Serve the live page of a run directory until Ctrl-C."""
    run_dir = Path(args.run)
    if run_dir.exists() and not run_dir.is_dir():
        raise terminal_run.refused(ConfigurationError, RunRefusal.WATCH_A_FILE, path=run_dir)
    absent = not run_dir.is_dir()
    if absent and not run_dir.absolute().parent.is_dir():      # a mistyped path, not a run to come
        raise terminal_run.refused(ConfigurationError, RunRefusal.WATCH_NO_PARENT, path=run_dir,
                                   parent=run_dir.absolute().parent)
    if absent:        # started before the run: the page shows "waiting" until the run creates it
        print(_said(terminal_run.WATCH, WatchLine.WAITING, path=run_dir), flush=True)
    elif not (run_dir / "run.json").is_file():
        log.warning(_said(terminal_run.WATCH, WatchLine.NO_RUN_JSON, path=run_dir))
    from ..signals import ENDING, handling

    server = _watch_server(run_dir, args.host, args.port)
    # The page serves from its own thread; the ending signals only raise a flag (no lock
    # the main thread might hold, no exception a finalizer could drop: bench/signals.py).
    ended = []
    with handling(lambda signum, frame: ended.append(signum), *ENDING):
        server.start()
        print(_said(terminal_run.WATCH, WatchLine.SERVING, url=server.url), flush=True)
        try:
            while not ended:
                time.sleep(0.2)
                if absent and run_dir.is_dir():
                    absent = False
                    print(_said(terminal_run.WATCH, WatchLine.APPEARED, path=run_dir), flush=True)
        finally:
            server.close()         # open pages get the last state and a goodbye
    return 0


def cmd_run(args) -> int:
    return _run(args, resume=False)


def cmd_resume(args) -> int:
    from ..sequence import is_sequence_dir
    if is_sequence_dir(Path(args.run)):
        return _sequence(args, resume=True)
    return _run(args, resume=True)


def cmd_sequence(args) -> int:
    """Every entry of SEQ.toml checked, then run one after the other into OUT/<name>/."""
    return _sequence(args, resume=False)


def _sequence(args, resume: bool) -> int:
    from ..sequence import resume_sequence, run_sequence

    def progress(entry: str):
        return Progress(f"{entry}")
    with _latch().installed():    # between entries; each entry's session has its own (0051)
        res = (resume_sequence(Path(args.run), progress=progress, report=not args.no_report) if resume else
               run_sequence(Path(args.sequence), Path(args.out), progress=progress, report=not args.no_report))
    end_line()
    for e in res.entries:
        print(_said(terminal_run.SEQUENCE, SequenceEndLine.ENTRY, name=e["name"], status=e["status"], done=e["steps_done"],
                    total=e["steps_total"]))
    print(_said(terminal_run.SEQUENCE, SequenceEndLine.REPORT, path=res.path / "report.md"))
    statuses = [e["status"] for e in res.entries]
    if res.completed:
        return ExitCode.OK
    return ExitCode.LIMIT if "aborted" in statuses else ExitCode.FAILURE


def cmd_demo(args) -> int:
    """The main job: the default plan on the simulated rig, then its report."""
    from contextlib import nullcontext

    from .. import runlock
    from ..demo import check_out_dir, clear_earlier_demo, write_manifest

    args.plan = args.rig = None
    args.seed = None
    out = Path(args.out)
    earlier = check_out_dir(out)     # refuses (deleting nothing) unless out holds only an earlier demo's files
    with runlock.run_dir(out) if earlier else nullcontext():      # not while another session uses it
        if earlier:
            clear_earlier_demo(out)
        try:
            return _run(args, resume=False)
        finally:
            _latch().hold()          # the manifest is written whole (a signal is honoured after it)
            write_manifest(out)      # what this demo wrote: what the next one may delete (0051)


def parse_labels(items: list[str] | None) -> dict[str, str]:
    """``--label key=value`` (repeatable) -> {key: value}; a malformed one is a usage error."""
    out: dict[str, str] = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise terminal_run.refused(ConfigurationError, RunRefusal.LABEL, item=item)
        out[key.strip()] = value.strip()
    return out
