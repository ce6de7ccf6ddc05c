"""Command line: `bench <command>`.  The application configures logging; libraries don't.

Exit codes (docs/reliability.md), chosen by the error's class in the tree of
sim/errors.py: 0 done; 1 runtime failure (an instrument error, a failed run, `bench check`
found problems; an unexpected exception is reported as an internal error); 2 usage or
configuration error (a bad argument, file or value: the message names it); 3 stopped by a
limit (a plan the rig's limits refuse, or a run aborted by the safety supervisor); 130
interrupted (Ctrl-C, SIGTERM, SIGHUP, SIGQUIT before the work was done: the measuring and
the report; one after it leaves the code as it was, decision record 0051).  Errors are one
line on stderr; `--debug` adds the traceback.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from enum import IntEnum
from pathlib import Path

from procedures.kind import ProcedureKind
from sim.errors import BenchError, ConfigurationError, EnvelopeError, LimitError, RunDirectoryError

from .terminal import Progress, end_line, setup_logging, tolerant_streams

log = logging.getLogger(__name__)


class ExitCode(IntEnum):
    OK = 0
    FAILURE = 1          # runtime failure; `bench check` found problems
    USAGE = 2            # bad argument, file or value
    LIMIT = 3            # refused or aborted by a limit
    INTERRUPTED = 130    # Ctrl-C, SIGTERM, SIGHUP (terminal closed), SIGQUIT


def cmd_paper(args) -> int:
    from sim.paper import reproduce

    out = Path(args.out)
    pitch_model, measured, name, others = None, None, "", []
    if args.rig:
        from .config import load_rig
        from .rig_model import paper_model
        models = [(Path(r).stem, paper_model(load_rig(Path(r)), r)) for r in args.rig]
        (name, pitch_model), others = models[0], models[1:]
    if args.runs:
        from .reports import run_modes
        measured = []
        for r in args.runs:
            rm = run_modes(Path(r), model=False)
            measured.append({"label": rm.label, "rows": rm.rows()})
    files = reproduce(out, quick=args.quick, progress=Progress("paper figures"), pitch_model=pitch_model,
                      measured=measured, pitch_name=name, other_models=others)
    print(f"wrote {len(files)} files to {out}/ (start with {out}/README.md)")
    return 0


def cmd_frf(args) -> int:
    import numpy as np

    from sim.frf import find_peaks, frf_rk4
    from sim.shooting import frf_shooting

    if args.points < 1:
        raise ConfigurationError(f"--points must be >= 1, got {args.points}")
    betas = np.linspace(args.beta_min, args.beta_max, args.points)
    prog = Progress(f"FRF gamma0={args.gamma0} n={args.n} ({args.engine})")
    if args.engine == "shooting":
        fr, _ = frf_shooting(betas, args.gamma0, args.n, progress=prog)
    else:
        fr = frf_rk4(betas, args.gamma0, args.n, progress=prog)
    print("beta,G,converged")
    for b, G, c in zip(fr.beta, fr.G, fr.converged):
        print(f"{b:.6g},{G:.6g},{int(c)}")
    for p in find_peaks(fr):
        print(f"# {p.kind} resonance: beta={p.beta:.4f} G={p.G:.4f}", file=sys.stderr)
    return 0


def _load_configs(args):
    from .config import DEFAULTS, load_plan, load_rig

    plan = load_plan(Path(args.plan) if args.plan else DEFAULTS / "demo_plan.toml")
    rig = load_rig(Path(args.rig) if args.rig else DEFAULTS / "sim_rig.toml")
    return plan, rig


def cmd_dry_run(args) -> int:
    from .plan_time import planned_step_list
    from .session import EnvelopeError, check_envelope, envelope, envelope_report, planned_steps

    plan, rig = _load_configs(args)
    steps = plan.schedule()
    if plan.backbone:
        b = plan.backbone
        print(f"plan '{plan.name}': phase resonance, {len(plan.levels_N)} force levels (N) from {b.start_Hz:g} Hz in the window "
              f"{b.min_Hz:g}-{b.max_Hz:g} Hz (envelope at both ends); rig '{rig.name}'"
              f"{' (simulated)' if rig.simulated else ''}")
    else:
        n, refined, seconds = planned_steps(plan)
        runs = (f"{n} measured (adaptive: {plan.adaptive_per_sweep} per sweep, chosen online)"
                if plan.adaptive_per_sweep and n != len(steps) else f"{n} measured")
        if refined:
            runs += (f" + at most {refined} refinement steps ([plan.resonance]: {plan.refine_steps} per mode and level, "
                     f"modes {', '.join(plan.refine_modes)}, tolerance {100 * plan.refine_tolerance:g} %"
                     + (f"; with a dwell of {plan.dwell_cycles} cycles at each mode's resonance per level"
                        if plan.dwell_cycles else "") + ")")
        q = plan.level_quantity
        print(f"plan '{plan.name}': {plan.procedure.label}, {len(plan.levels_N)} levels x {len(plan.freqs_Hz)} frequencies "
              f"({plan.direction}) = {len(steps)} steps, {runs}; rig '{rig.name}'{' (simulated)' if rig.simulated else ''}")
        print(f"levels: {', '.join(q.format(v) for v in plan.levels_N)} ({q.name} amplitude"
              + (", the response fundamental held at each frequency)" if q.key != "force" else ")"))
        print(dry_run_time_line(plan, seconds, refined).replace("force control", f"{q.name} control"))
        if getattr(args, "steps", False):
            print("\n".join(["steps, in the order they run:"] + [p.line() for p in planned_step_list(plan)]))
    print(envelope_report(envelope(plan, rig)))
    from procedures.online_id import identifiability
    try:
        runnable = check_envelope(plan, rig)
    except EnvelopeError as e:
        print(f"REFUSED: {str(e).splitlines()[0]}")
        return ExitCode.LIMIT
    if runnable.skip:
        print(f"envelope: {len(runnable.schedule())} steps run, {len(steps) - len(runnable.schedule())} "
              f"skipped (infeasible = \"skip\")")
    else:
        print("envelope ok: the rig's limits hold every step")
    for w in identifiability(runnable, rig) if plan.procedure is ProcedureKind.STEPPED_SINE else []:
        print(f"identifiability warning: {w}")
    return 0


def dry_run_time_line(plan, typical_s: float, refined: int) -> str:
    """dry-run's rig time: the upper bound (bench.plan_time) and the typical figure."""
    from .plan_time import extra_block_seconds_max, rig_time_bound_s
    return (f"expected rig time: at most {_duration(rig_time_bound_s(plan))} (every step's force control and extra "
            f"settle blocks to the plan's limits, steps chosen online at the lowest frequency, refinement budget "
            f"used up); without the extra settle blocks at most {_duration(rig_time_bound_s(plan, extra_settle=False))}, "
            f"plus at most {extra_block_seconds_max(plan, min(plan.freqs_Hz)):.3g} s for each extra settle block a "
            f"step needs (at most {plan.max_extra_settle_blocks} a step); typically about {_duration(typical_s)}"
            + (" with the refinement budget used up" if refined else "")
            + " (a simulated rig runs faster or slower than real time)")


def _duration(seconds: float) -> str:
    m, s = divmod(int(round(seconds)), 60)
    h, m = divmod(m, 60)
    return f"{h} h {m:02d} min" if h else f"{m} min {s:02d} s" if m else f"{s} s"


def _latch():
    """The program's signal latch (installed first thing in :func:`main`), or, when the
    bench runs inside another program (a test), one of this command's own."""
    from .signals import SignalLatch, process_latch
    return process_latch() or SignalLatch()


def _run(args, resume: bool) -> int:
    latch = _latch()
    with latch.installed():       # SIGHUP, SIGQUIT, SIGTERM as Ctrl-C from the start
        return _session(args, resume, latch)


def _session(args, resume: bool, latch) -> int:
    from contextlib import ExitStack

    with ExitStack() as held:
        if resume:           # the run directory is ours before its steps are counted
            from . import runlock
            from .storage import RunStore
            RunStore.open(Path(args.run))
            held.enter_context(runlock.run_dir(Path(args.run)))
        return _session_held(args, resume, latch)


def _session_held(args, resume: bool, latch) -> int:
    from .api import execute, stored_configs
    from .storage import RunStatus, RunStore

    if resume:
        store = RunStore.open(Path(args.run))
        meta, acc = store.metadata, store.account()
        retry = bool(getattr(args, "retry_skipped", False)) and bool(acc.skipped)
        if acc.complete and not retry and meta.get("status") == RunStatus.COMPLETED:
            print("resume: nothing to do: the run completed and its steps are all there "
                  + ("or were skipped at run time as the plan allows (--retry-skipped measures them again) "
                     if acc.skipped else "") + f"({acc.summary()})")
            return ExitCode.OK
        print(f"resume: {acc.resume_text(retry)}" if acc.missing or acc.damaged or acc.owed or retry else
              f"resume: every planned step is there{' or was skipped at run time' if acc.skipped else ''}; "
              f"finishing the run (it ended '{meta.get('status', '?')}')",
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
        latch.hold(doing=REPORTING)
        begin_report = latch.reason is None    # decided before "run completed": a signal after it is one during the report
    print(f"run {meta['status']}: {meta['steps_done']}/{meta['steps_total']} steps in {out}/", flush=True)
    if wants_report:
        if begin_report:
            _report(out, latch)
        else:
            print(f"report not written: {latch.reason} before it began; `bench report {out}` writes it",
                  file=sys.stderr)
        latch.finish()
    if meta["status"] == RunStatus.COMPLETED:
        from .verdict import promise
        kept = promise(meta.get("plan") or {}, store.results(warn=False), meta.get("rig"))
        if kept.fatal:           # completed, but not what the procedure was run for (decision 0052)
            print(f"the {kept.kind.label} did not measure what it promised: {'; '.join(kept.short)}", file=sys.stderr)
            code = ExitCode.FAILURE
    if latch.reason is not None and code == ExitCode.OK:
        raise KeyboardInterrupt(latch.reason)     # a signal before the work was done: exit 130
    return code


REPORTING = "the report is written (the output is off)"


def _report(run: Path, latch, with_runs=()) -> None:
    """Write the run's report with ``latch`` held: a signal meanwhile is recorded, not
    raised into the numba kernels or the figures' finalizers where it could be swallowed,
    and is honoured once the report is complete (decision 0051)."""
    latch.hold(doing=REPORTING)
    from .api import open_run
    path = open_run(run).report(with_runs=tuple(with_runs))
    print(f"report: {path}" + (f" (complete; then {latch.reason})" if latch.reason else ""), flush=True)


def _event_count(out: Path) -> int:
    """Number of events a run directory holds now (0 when there is none yet)."""
    from .storage import RunStore
    try:
        return len(RunStore.open(out).events())
    except Exception:  # noqa: BLE001 - no run directory yet
        return 0


def _say_output_state(out: Path, since: int = 0) -> None:
    """On every ending (done, Ctrl-C, limit, error) say how this session left the output:
    the last ``output_off`` event among those written after the first ``since`` (the events
    of earlier sessions of a resumed run say nothing about this one).  No such event: this
    session never opened the generator far enough to switch the output on."""
    from .storage import RunStore
    try:
        events = RunStore.open(out).events()[since:]
    except Exception:  # noqa: BLE001 - no run directory: nothing was opened
        events = []
    offs = [e for e in events if e.get("event") == "output_off"]
    if not offs:
        print("output not switched on by this session (stopped before the generator was set up)",
              file=sys.stderr, flush=True)
    elif offs[-1].get("confirmed"):
        print("output off, confirmed by the generator", file=sys.stderr, flush=True)
    else:
        print("WARNING: output off NOT confirmed by the generator: switch the amplifier off by hand "
              "and check the generator", file=sys.stderr, flush=True)


def _start_watch(run_dir: Path, args):
    """The watch page beside the run (``--watch``), served from a thread of this process."""
    if not getattr(args, "watch", False):
        return None
    server = _watch_server(run_dir, args.watch_host, args.watch_port).start()
    print(f"watch: {server.url}", flush=True)
    return server


def _watch_server(run_dir: Path, host: str, port: int):
    from .watch import WatchServer
    try:
        return WatchServer(run_dir, host, port)
    except OSError as e:       # port taken, no such interface, privileged port
        raise ConfigurationError(f"cannot serve the watch page on {host}:{port}: {e}") from e


def cmd_watch(args) -> int:
    """Serve the live page of a run directory until Ctrl-C."""
    run_dir = Path(args.run)
    if run_dir.exists() and not run_dir.is_dir():
        raise ConfigurationError(f"{run_dir}: not a run directory (a file)")
    absent = not run_dir.is_dir()
    if absent and not run_dir.absolute().parent.is_dir():      # a mistyped path, not a run to come
        raise ConfigurationError(f"{run_dir}: no such run directory, nor its parent {run_dir.absolute().parent} "
                                 f"(bench watch waits for a run directory to appear inside an existing one)")
    if absent:        # started before the run: the page shows "waiting" until the run creates it
        print(f"waiting for {run_dir} to appear ... (Ctrl-C stops)", flush=True)
    elif not (run_dir / "run.json").is_file():
        log.warning("%s has no run.json yet: the page waits for the run to start", run_dir)
    from .signals import ENDING, handling

    server = _watch_server(run_dir, args.host, args.port)
    # The page serves from its own thread; the ending signals only raise a flag (no lock
    # the main thread might hold, no exception a finalizer could drop: bench/signals.py).
    ended = []
    with handling(lambda signum, frame: ended.append(signum), *ENDING):
        server.start()
        print(f"watch: {server.url}  (Ctrl-C ends the page, not the run)", flush=True)
        try:
            while not ended:
                time.sleep(0.2)
                if absent and run_dir.is_dir():
                    absent = False
                    print(f"{run_dir} appeared: the page follows the run", flush=True)
        finally:
            server.close()         # open pages get the last state and a goodbye
    return 0


def _add_watch_options(s) -> None:
    s.add_argument("--watch", action="store_true", help="serve the live page of the run (URL printed)")
    s.add_argument("--watch-port", type=int, default=0, help="port of the page (default: any free one)")
    s.add_argument("--watch-host", default="127.0.0.1",
                   help="interface of the page (default 127.0.0.1; others only when given)")


def cmd_run(args) -> int:
    return _run(args, resume=False)


def cmd_resume(args) -> int:
    from .sequence import is_sequence_dir
    if is_sequence_dir(Path(args.run)):
        return _sequence(args, resume=True)
    return _run(args, resume=True)


def cmd_sequence(args) -> int:
    """Every entry of SEQ.toml checked, then run one after the other into OUT/<name>/."""
    return _sequence(args, resume=False)


def _sequence(args, resume: bool) -> int:
    from .sequence import resume_sequence, run_sequence

    def progress(entry: str):
        return Progress(f"{entry}")
    with _latch().installed():    # between entries; each entry's session has its own (0051)
        res = (resume_sequence(Path(args.run), progress=progress, report=not args.no_report) if resume else
               run_sequence(Path(args.sequence), Path(args.out), progress=progress, report=not args.no_report))
    end_line()
    for e in res.entries:
        print(f"{e['name']}: {e['status']}" + (f" ({e['steps_done']}/{e['steps_total']} steps)"
                                                if e["status"] != "not started" else ""))
    print(f"sequence report: {res.path / 'report.md'}")
    statuses = [e["status"] for e in res.entries]
    if res.completed:
        return ExitCode.OK
    return ExitCode.LIMIT if "aborted" in statuses else ExitCode.FAILURE


def cmd_demo(args) -> int:
    """The main job: the default plan on the simulated rig, then its report."""
    from contextlib import nullcontext

    from . import runlock
    from .demo import check_out_dir, clear_earlier_demo, write_manifest

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


def cmd_report(args) -> int:
    latch = _latch()
    with latch.installed():
        _report(Path(args.run), latch, [Path(p) for p in args.with_runs or ()])
        latch.finish()
    if latch.reason is not None:
        raise KeyboardInterrupt(latch.reason)
    return 0


def cmd_export(args) -> int:
    from .api import open_run
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

    from .analyze import default_out_dir
    from .config import DEFAULTS, load_rig, parse_rig, rig_toml
    from .numbers import number
    from .sources import load_source
    from .storage import RunStore

    source = Path(args.source)
    if not source.exists():
        raise FileNotFoundError(2, "no such file or directory (expected a run directory or a UFF58 file)", str(source))
    src = load_source(source)
    if src.kind == "run":
        rig = parse_rig({"rig": rig_toml(src.metadata["rig"])}, f"{source}/run.json")
    else:
        rig = load_rig(Path(args.rig) if args.rig else DEFAULTS / "sim_rig.toml")
    for r in src.rejected:
        print(f"step {r.step} rejected: {r.reason}")
    if not src.steps:
        raise ConfigurationError(f"{source}: no steps with force, acceleration and displacement to identify from")
    guess = rig.guess()
    analysis_json = default_out_dir(source) / "analysis.json"
    extra: tuple[str, ...] = ()
    if analysis_json.is_file():
        try:
            extra = analysis_effects(json.loads(analysis_json.read_text()))
        except (OSError, ValueError) as e:
            print(f"warning: {analysis_json} cannot be read ({e}); the analysis' causes are not in the model")
    est = identify_steps(src.steps, guess, rig.model, extra, MAX_HARMONICS)
    check_finite(est)
    if src.kind == "run":
        RunStore.open(source).update(identification=est)
    effects = est.get("model", {}).get("effects") or []
    print(f"model: Masing friction and the moving mass{' with ' + ', '.join(effects) if effects else ''} "
          f"({est.get('source', 'final fit')})")
    print(f"{'parameter':>10} {'estimate':>12} {'95 % interval':>28}")
    for k, v in est["values"].items():
        print(f"{k:>10} {number(v, fmt='.6g'):>12} [{number(est['low'][k], fmt='.6g'):>12}, "
              f"{number(est['high'][k], fmt='.6g'):>12}]")
    for k, p in (est.get("model", {}).get("parameters") or {}).items():
        print(f"{k:>10} {number(p['value'], fmt='.6g'):>12} [{number(p['low'], fmt='.6g'):>12}, "
              f"{number(p['high'], fmt='.6g'):>12}]")
    print(f"{len(src.steps)} steps ({len(src.rejected)} rejected), reduced chi^2 {number(est['reduced_chi2'], fmt='.3g')}")
    for w in est["warnings"]:
        print(f"warning: {w}")
    return 0


def cmd_analyze(args) -> int:
    """Where the Masing model is wrong in SOURCE, the cause, the extended model and its gain."""
    from .analyze import analyze_source, default_out_dir
    from .studies.cli import cmd_analyze_batch, is_batch
    if is_batch(args):
        return cmd_analyze_batch(args, Progress)
    source = Path(args.sources[0])
    result = analyze_source(source, Path(args.out) if args.out else None, Path(args.rig) if args.rig else None)
    out = Path(args.out) if args.out else default_out_dir(source)
    print(result["verdict"])
    print(f"causes: {', '.join(c['id'] for c in result['causes']) or 'none'}; "
          f"unexplained: {'yes' if result['unexplained'] else 'no'}; written to {out}")
    return 0


def cmd_check(args) -> int:
    """Verify a run directory against its plan: every missing, damaged and orphan step on
    one line, and what a refined run still owes (a refinement whose end is not recorded, a
    dwell not measured: decision 0050), then the count; exit 1 if there is any problem.  A step skipped at run time
    (force unreachable) as the plan allows (``infeasible = "skip"``) is listed and counted,
    not a problem (exit 0 when it is the only gap) unless ``--strict`` (decision 0033)."""
    from .storage import NewerFormat, RunDirError, RunStatus, RunStore

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
        print(f"{'missing':>9}  interrupted after step {last or '(none)'}; {len(tail)} not yet measured "
              f"(the plan's steps after it; bench resume {store.path} measures them)")
    if acc is None:
        print(f"{store.path}: {len(store.step_files())} step result files; run.json unreadable or its plan not "
              f"valid, so the steps cannot be counted against the plan; {len(problems)} "
              f"problem{'s' if len(problems) != 1 else ''}")
        return ExitCode.FAILURE
    print(f"{store.path}: {acc.summary()}"
          + (f" (bench resume {store.path} measures missing and damaged steps again, keeping damaged "
             "files in damaged/)" if acc.missing or acc.damaged else "")
          + (f" (bench resume {store.path} measures what the refinement still owes)" if acc.owed and not
             (acc.missing or acc.damaged) else ""))
    from .verdict import promise
    meta = store.metadata
    kept = promise(meta.get("plan") or {}, store.results(warn=False), meta.get("rig"),
                   completed=meta.get("status") == RunStatus.COMPLETED)
    if kept.short:        # the steps are intact; what they say against the procedure's promise (decision 0052)
        print(f"{kept.kind.label}: {'; '.join(kept.short)}")
    if skipped:
        n = len(skipped)
        print(f"{n} step{'s' * (n != 1)} skipped at run time as the plan allows (infeasible = \"skip\"): "
              + ("counted as problems (--strict)" if args.strict else
                 "not a problem (--strict counts them); bench resume --retry-skipped measures them again"))
    return ExitCode.FAILURE if problems or (skipped and args.strict) else ExitCode.OK


def _not_yet_measured(store, acc) -> list:
    """The missing steps of a run that was stopped (not completed) that are simply the
    plan's steps after the last one stored, with no file at all: one line says so instead
    of one line each.  Any other missing step is listed by key."""
    from .storage import RunStatus, stored_plan
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
    tail = [p for p in acc.missing if p.reason.startswith("missing: neither") and p.key in order
            and order.index(p.key) > last]
    return tail if len(tail) > 1 else []


def cmd_warmup(args) -> int:
    from .warmup import warm_up
    if not args.verbose:
        logging.getLogger().setLevel(logging.ERROR)     # the warm-up run's chatter is noise here
    print("compiling the simulation kernels (once per machine and change of sim/) ...", flush=True)
    print(f"kernels compiled and cached in {warm_up():.0f} s")
    return 0


def cmd_twins(args) -> int:
    from drivers import run_standalone
    from sim.rig import SimulatedRig

    from .config import DEFAULTS, load_rig
    rig = load_rig(Path(args.rig) if args.rig else DEFAULTS / "sim_rig.toml")
    if not rig.simulated:
        raise ConfigurationError(f"{args.rig}: not a simulated rig (simulated = true is needed)")
    import threading

    from .signals import ENDING, handling
    stop = threading.Event()          # serving until a signal is this command's work: it ends it, exit 0
    with handling(lambda signum, frame: stop.set(), *ENDING):
        run_standalone(SimulatedRig(rig.model), args.host, serial_ports=args.serial, stop=stop)
    print("stopping twins")
    return 0


# ---------------------------------------------------------------------------- twin and compare (0026)


def cmd_twin(args) -> int:
    """rig.toml and plan.toml of a simulated twin of the rig that measured SOURCE."""
    from .twin import make_twin
    twin, paths = make_twin(Path(args.source), Path(args.analysis) if args.analysis else None,
                            Path(args.out) if args.out else None, plain=args.plain)
    v = twin.parameters
    print("twin: " + ", ".join(f"{k} {v[k]['value']:.4g}" for k in ("F_s_N", "x_s_m", "n", "m_kg")))
    for cid, keys in twin.applied.items():
        print(f"cause {cid} -> " + ", ".join(f"{k} = {x:.4g}" if isinstance(x, float) else f"{k} = {x}"
                                             for k, x in keys.items()))
    if twin.shaker.get("note"):
        print(twin.shaker["note"])
    for item in twin.not_in_plant:
        print(f"not in the plant: {item['cause']}: {item['reason']}")
    print(f"wrote {paths['rig']}, {paths['plan']} and {paths['twin']}")
    print(f"run it: bench run --plan {paths['plan']} --rig {paths['rig']} --out RUN")
    return ExitCode.OK


def cmd_compare(args) -> int:
    """Exit 0 when the two sources agree within the tolerance over enough of the reference, 1 when not."""
    from .compare import summary, write_compare
    result, out = write_compare(Path(args.reference), Path(args.other), Path(args.out) if args.out else None,
                                args.tolerance, args.min_coverage)
    print(summary(result), end="")
    print(f"written to {out}/compare.json and compare.html")
    return ExitCode.OK if result["overall"]["passed"] else ExitCode.FAILURE


def cmd_modes(args) -> int:
    """Each run's modes per level (in its quantity's unit) into OUT/modes.csv, with the seed's Figs. 13 and 17."""
    from .reports import write_modes
    runs, files = write_modes([Path(r) for r in args.runs], Path(args.out), model=not args.no_model)
    for r in runs:
        for e in r.modes:
            if e.ok:
                eb = e.extra.get("energy_balance")
                print(f"{r.label}: {e.mode} at {r.level_quantity.format(e.level_N)}: {e.resonance_Hz:.5g} Hz "
                      f"[{e.resonance_low_Hz:.5g}, {e.resonance_high_Hz:.5g}], damping ratio (single-mode fit) "
                      f"{100 * e.damping_ratio:.3g} % [{100 * e.damping_ratio_low:.3g}, {100 * e.damping_ratio_high:.3g}]"
                      + (f", (energy balance at resonance) {100 * eb.value:.3g} % [{100 * eb.low:.3g}, "
                         f"{100 * eb.high:.3g}]" if eb is not None else ""))
            else:
                print(f"{r.label}: {e.mode} at {r.level_quantity.format(e.level_N)}: {e.status}" + (f" ({e.note})" if e.note else ""))
    print("wrote " + ", ".join(str(f) for f in files))
    return ExitCode.OK


def parse_labels(items: list[str] | None) -> dict[str, str]:
    """``--label key=value`` (repeatable) -> {key: value}; a malformed one is a usage error."""
    out: dict[str, str] = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigurationError(f"--label {item!r}: expected KEY=VALUE, e.g. --label lubricant=\"ISO VG 32\"")
        out[key.strip()] = value.strip()
    return out


def _add_twin_parsers(sub) -> None:
    s = sub.add_parser("twin", help="write rig.toml and plan.toml of a simulated twin of the rig that measured "
                                    "SOURCE (identified friction, named causes, noise)")
    s.add_argument("source", help="run directory or UFF58 file of time records")
    s.add_argument("--analysis", help="directory (or file) of an existing analysis.json of SOURCE "
                                      "(default: analyse SOURCE into OUT/analysis)")
    s.add_argument("--out", help="output directory (default: SOURCE/twin, or <stem>_twin next to a file)")
    s.add_argument("--plain", action="store_true", help="a plain Masing twin: base F_s, x_s, n, m only")
    s.set_defaults(func=cmd_twin)

    s = sub.add_parser("compare", help="compare first-harmonic compliance and accelerance of two sources step "
                                       "by step; exit 1 when they differ by more than the tolerance or the other lacks steps "
                                       "of the reference")
    s.add_argument("reference", help="run directory or UFF58 file")
    s.add_argument("other", help="run directory or UFF58 file")
    s.add_argument("--tolerance", type=float, default=0.02,
                   help="largest rms relative difference accepted (fraction; default 0.02 = 2 %%)")
    s.add_argument("--min-coverage", type=float, default=1.0,
                   help="share of the reference's usable steps that must be matched in OTHER (fraction; default 1: "
                        "all of them; unmatched steps are named, the resonance ones as such)")
    s.add_argument("--out", help="output directory (default: OTHER/compare, or <stem>_compare next to a file)")
    s.set_defaults(func=cmd_compare)


DESCRIPTION = """\
Stepped-sine friction tests on the linear-guideway shaker rig, or on its simulated twin:
plan and run a test, watch it live, stop and resume it, then report, export and analyse
the measurements.  Start with `bench demo` (the default plan on the simulated rig), then
`bench dry-run --plan P --rig R` and `bench run --plan P --rig R --out DIR` with your own
plan and rig files (annotated examples in bench/defaults/).  Force levels 0.1-100 N,
frequencies 20-1000 Hz.  `bench COMMAND --help` explains each command."""

EPILOG = """\
exit codes: 0 done; 1 failure (an instrument error, a failed run, `bench check` found
problems); 2 usage or configuration error (the message names the file, key and allowed
values); 3 stopped by a limit (refused before the output went on, or aborted); 130
interrupted (Ctrl-C, SIGTERM, SIGHUP: the terminal closed, SIGQUIT) before the work
was done; a signal while the report is written is honoured once it is complete.  The
output is switched off on every exit.
-v, --debug and -vv may come before or after the command."""


class _Formatter(argparse.RawDescriptionHelpFormatter):
    """Every option's default shown after its help, unless it has none to show."""

    def _get_help_string(self, action):
        text = action.help or ""
        default = action.default
        if ("%(default)" in text or "default" in text or any(default is x for x in (None, False, argparse.SUPPRESS))
                or not action.option_strings or action.option_strings[0] in ("-v", "-h")):
            return text
        return f"{text} (default: %(default)s)"


class _Parser(argparse.ArgumentParser):
    """Usage errors in one line, naming the command, the problem and where to look; every
    (sub)command's help shows the defaults."""

    def __init__(self, *a, **k):
        k.setdefault("formatter_class", _Formatter)
        super().__init__(*a, **k)

    def error(self, message):
        self.exit(ExitCode.USAGE, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="bench", description=DESCRIPTION, epilog=EPILOG)
    _add_common(p, argparse.SUPPRESS)
    p.set_defaults(verbose=0, debug=False)
    from . import __version__
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("paper", help="redraw the seed paper's numerical figures (PNG + CSV)")
    s.add_argument("--out", default="out/paper", help="directory for the figures, their CSV and a README")
    s.add_argument("--quick", action="store_true", help="coarse grids (seconds instead of minutes)")
    s.add_argument("--rig", action="append", help="rig TOML with a pitching mode in [rig.model]: Figs. 15 and 17 "
                   "at its parameters (default: bench/defaults/sim_rig_pitch.toml's); repeat it for several "
                   "rigs, each model named by its file and drawn in the colour of the run of its position")
    s.add_argument("--runs", nargs="+", metavar="RUN", help="run directories whose measured modes are drawn over "
                                                             "Figs. 15 and 17 (legends: their --label)")
    s.set_defaults(func=cmd_paper)

    s = sub.add_parser("demo", help="the main job: the default plan on the simulated rig, with its report")
    s.add_argument("--out", default="out/demo", help="run directory (the files an earlier demo wrote there, listed in its "
                                           "demo-manifest.json, are deleted first; anything else is refused)")
    _add_watch_options(s)
    s.set_defaults(func=cmd_demo)

    for name, func, hlp in (("run", cmd_run, "run a stepped-sine plan on a rig"),
                            ("dry-run", cmd_dry_run, "check a plan against the rig's limits; print the envelope")):
        s = sub.add_parser(name, help=hlp)
        s.add_argument("--plan", help="plan TOML: force levels (0.1-100 N), frequencies (20-1000 Hz), control "
                                      "(default: the demo plan, bench/defaults/demo_plan.toml)")
        s.add_argument("--rig", help="rig TOML: instrument URLs, calibration, limits "
                                     "(default: the simulated rig, bench/defaults/sim_rig.toml)")
        if name == "run":
            s.add_argument("--out", required=True, help="new run directory (bench resume continues it)")
            s.add_argument("--seed", type=int, help="noise seed of a simulated rig (default: the rig file's)")
            s.add_argument("--no-report", action="store_true", help="do not write the report at the end")
            s.add_argument("--label", action="append", metavar="KEY=VALUE",
                           help="a label kept in run.json (repeatable), used by the legends of `bench modes`, "
                                "e.g. --label lubricant=\"ISO VG 32\"")
            _add_watch_options(s)
        else:
            s.add_argument("--steps", action="store_true", help="list the steps the plan will run (key, level, "
                           "frequency or \"refined, chosen online\")")
        s.set_defaults(func=func)

    s = sub.add_parser("resume", help="continue an interrupted run without repeating completed steps")
    s.add_argument("run", help="run directory of an interrupted, aborted or failed run")
    s.add_argument("--no-report", action="store_true", help="do not write the report at the end")
    s.add_argument("--retry-skipped", action="store_true",
                   help="also measure again the steps skipped at run time because their force was unreachable "
                        "(e.g. after raising drive_V in run.json's rig); by default they stay skipped")
    _add_watch_options(s)
    s.set_defaults(func=cmd_resume)

    s = sub.add_parser("sequence", help="run a sequence file's entries (plan, rig, labels) one after the other into "
                                        "OUT/<name>/, every entry checked first; bench resume OUT goes on with it")
    s.add_argument("sequence", help="sequence file (TOML: [sequence] name, [[sequence.entry]] name, plan, rig, labels)")
    s.add_argument("--out", required=True, help="new directory for the sequence (one run directory per entry)")
    s.add_argument("--no-report", action="store_true", help="do not write each entry's report")
    s.set_defaults(func=cmd_sequence)

    s = sub.add_parser("watch", help="serve a live page of a run directory (running, resumed or finished)")
    s.add_argument("run", help="run directory (it may not exist yet: the page waits for it)")
    s.add_argument("--port", type=int, default=0, help="port (default: any free one)")
    s.add_argument("--host", default="127.0.0.1", help="interface (default 127.0.0.1; others only when given)")
    s.set_defaults(func=cmd_watch)

    s = sub.add_parser("report", help="(re)write the report of a run directory")
    s.add_argument("run", help="run directory (the report goes to RUN/report/)")
    s.add_argument("--with", dest="with_runs", action="append", metavar="OTHER",
                   help="a stepped-sine run of the same rig whose modes the backbone figure of a phase-resonance "
                        "run overlays at their peaks' amplitudes (repeatable)")
    s.set_defaults(func=cmd_report)

    s = sub.add_parser("export", help="write a run's steps as CSV and UFF 58 (FRFs and time records)")
    s.add_argument("run", help="run directory")
    s.add_argument("--out", help="output directory (default: <run>/export)")
    s.add_argument("--no-time", action="store_true", help="skip the time records (time.uff)")
    s.set_defaults(func=cmd_export)

    s = sub.add_parser("identify", help="identify F_s, x_s, n and the mass from a stored run or a UFF58 file")
    s.add_argument("source", help="run directory, or a UFF file of time records (bench export)")
    s.add_argument("--rig", help="rig TOML whose [rig.expected] values start the fit (UFF input)")
    s.set_defaults(func=cmd_identify)

    s = sub.add_parser("analyze", help="find what the Masing model gets wrong in a run or UFF58 file, "
                                       "name the cause, extend the model, measure the gain")
    s.add_argument("sources", nargs="+", metavar="source",
                   help="run directory or UFF58 file of time records; several (or an archive directory) "
                        "run as a batch with one summary table")
    s.add_argument("--rig", help="rig TOML whose [rig.expected] values start the fit")
    s.add_argument("--out", help="output directory (default: SOURCE/analysis, or next to the file; "
                                 "required for a batch)")
    from .studies.cli import add_batch_options
    add_batch_options(s)
    s.set_defaults(func=cmd_analyze)

    s = sub.add_parser("twins", help="serve the simulated rig's instruments on loopback; print their URLs")
    s.add_argument("--rig", help="simulated rig TOML (default: bench/defaults/sim_rig.toml)")
    s.add_argument("--host", default="127.0.0.1", help="interface the twins listen on")
    s.add_argument("--serial", action="store_true", help="also serve SCPI and Modbus RTU on pty pairs")
    s.set_defaults(func=cmd_twins)

    s = sub.add_parser("warmup", help="compile and cache the simulation kernels (make setup runs it)")
    s.set_defaults(func=cmd_warmup)

    s = sub.add_parser("frf", help="compliance G(beta) of the model at one force level (CSV to stdout)")
    s.add_argument("--gamma0", type=float, default=0.6, help="force ratio P0/F_s")
    s.add_argument("--n", type=float, default=1.5, help="shape factor n of the virgin curve")
    s.add_argument("--beta-min", type=float, default=0.2, help="lowest frequency ratio beta")
    s.add_argument("--beta-max", type=float, default=2.0, help="highest frequency ratio beta")
    s.add_argument("--points", type=int, default=200, help="frequency ratios, linearly spaced")
    s.add_argument("--engine", choices=("shooting", "rk4"), default="shooting",
                   help="steady state by half-period shooting (fast) or by RK4 time stepping")
    s.set_defaults(func=cmd_frf)

    s = sub.add_parser("check", help="verify a run directory: list missing, truncated, damaged and unknown steps")
    s.add_argument("run", help="run directory")
    s.add_argument("--strict", action="store_true",
                   help="also fail (exit 1) on steps skipped at run time (force unreachable), which the plan's "
                        "infeasible = \"skip\" otherwise allows")
    s.set_defaults(func=cmd_check)

    _add_twin_parsers(sub)

    s = sub.add_parser("modes", help="each mode's resonance and damping ratio per force level of one or more runs: "
                                     "modes.csv and the seed's Figs. 13 and 17 from the measurements")
    s.add_argument("runs", nargs="+", metavar="RUN", help="run directories (legends use each run's --label)")
    s.add_argument("--out", required=True, help="output directory for modes.csv and the figures")
    s.add_argument("--no-model", action="store_true", help="leave out the rig model's prediction (simulated rigs)")
    s.set_defaults(func=cmd_modes)

    from .studies.cli import add_parsers as add_study_parsers
    add_study_parsers(sub, Progress)
    return _with_common(p)


def _add_common(p: argparse.ArgumentParser, default) -> None:
    p.add_argument("-v", "--verbose", action="count", default=default,
                   help="more detail on the terminal: -v the bench's INFO lines, -vv its DEBUG lines "
                        "(other libraries speak only for warnings)")
    p.add_argument("--debug", action="store_true", default=default, help="show the traceback of an error")


def _with_common(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """``-v`` and ``--debug`` after any subcommand too (every level of every subcommand,
    whoever added it): ``bench run -v`` is ``bench -v run``."""
    for action in p._actions:
        if isinstance(action, argparse._SubParsersAction):
            for s in action.choices.values():
                if "--debug" not in s._option_string_actions:
                    _add_common(s, argparse.SUPPRESS)
                _with_common(s)
    return p


# OSErrors about a path the user named (a missing file, a directory where a file goes):
# usage errors.  Any other OSError is a runtime failure (a full disk, a lost network).
_PATH_ERRORS = (FileNotFoundError, FileExistsError, IsADirectoryError, NotADirectoryError, PermissionError)


def _exit_code(e: BaseException) -> ExitCode:
    """The documented exit code of an exception, by its place in the error tree
    (sim/errors.py, decision record 0027)."""
    if isinstance(e, KeyboardInterrupt):
        return ExitCode.INTERRUPTED
    if isinstance(e, (LimitError, EnvelopeError)):
        return ExitCode.LIMIT
    if isinstance(e, (ConfigurationError, RunDirectoryError, _PATH_ERRORS)):
        return ExitCode.USAGE
    return ExitCode.FAILURE           # InstrumentError, another BenchError, a failure, a bug


def _internal(e: BaseException) -> bool:
    """A bug (or a library's error nobody translated), not an error raised on purpose."""
    return not isinstance(e, (BenchError, KeyboardInterrupt, OSError))


def _one_line(e: BaseException) -> str:
    if isinstance(e, KeyboardInterrupt):
        return f"interrupted{f' ({e})' if str(e) else ''}"
    if isinstance(e, OSError) and e.strerror:
        where = " -> ".join(str(f) for f in (e.filename, e.filename2) if f is not None)
        return f"{where}: {e.strerror}" if where else e.strerror
    text = str(e).strip().splitlines()
    first = text[0] if text else ""
    named = f"{type(e).__name__}: {first}" if first else type(e).__name__
    if _internal(e):
        return f"internal error ({named})"
    if isinstance(e, ConfigurationError) and len(text) > 1:    # a file's problems, one line each
        return f"{len(text)} problems:\n" + "\n".join(f"  {line}" for line in text)
    if _exit_code(e) in (ExitCode.USAGE, ExitCode.LIMIT) and first:
        return first
    return named


def main(argv: list[str] | None = None) -> int:
    """`bench ARGS`.  As the program (``argv`` None: the command line) the ending signals
    are caught from here, before the heavy imports, until the process is gone: a signal
    before the command's work is done gives 130, one after it changes nothing (0051)."""
    if argv is not None:                  # inside another program (a test): its signals stay its own
        return _parse_and_run(argv)
    from .signals import for_process, ignore_at_exit
    latch = for_process()
    with tolerant_streams():              # these lines too may meet a terminal that is gone
        try:
            code = _parse_and_run(argv)
        except KeyboardInterrupt as e:    # before or after the command (its errors are its own)
            print(f"bench: {_one_line(e)}", file=sys.stderr)
            code = ExitCode.INTERRUPTED
        latch.finish()
        if latch.reason is not None and code == ExitCode.OK:   # a signal a finalizer dropped: never 0
            code = ExitCode.INTERRUPTED
        elif latch.late is not None:
            print(f"bench: {latch.late} after the work was done: nothing left to stop", file=sys.stderr, flush=True)
    ignore_at_exit()
    return code


def _parse_and_run(argv: list[str] | None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:               # usage error or --help: argparse has printed it
        return int(e.code or 0)
    with tolerant_streams():            # a terminal that is gone changes nothing the bench does
        return _main(args)


def _main(args) -> int:
    handler = setup_logging(args.verbose)
    try:
        return int(args.func(args))
    except (Exception, KeyboardInterrupt) as e:   # one line, a documented code; --debug: traceback
        code = _exit_code(e)
        end_line()
        if args.debug:
            log.exception("bench %s failed", args.command)
        hint = ("" if args.debug or code == ExitCode.INTERRUPTED else
                ", rerun with --debug for the traceback" if _internal(e) else " (--debug shows the traceback)")
        print(f"bench {args.command}: {'error: ' if code != ExitCode.INTERRUPTED else ''}{_one_line(e)}{hint}",
              file=sys.stderr)
        return code
    finally:
        end_line()
        logging.getLogger().removeHandler(handler)


if __name__ == "__main__":
    sys.exit(main())
