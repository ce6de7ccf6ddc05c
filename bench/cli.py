"""Command line: `bench <command>`.  The application configures logging; libraries don't.

Exit codes (docs/reliability.md), chosen by the error's class in the tree of
sim/errors.py: 0 done; 1 runtime failure (an instrument error, a failed run, `bench check`
found problems; an unexpected exception is reported as an internal error); 2 usage or
configuration error (a bad argument, file or value: the message names it); 3 stopped by a
limit (a plan the rig's limits refuse, or a run aborted by the safety supervisor); 130
interrupted (Ctrl-C, SIGTERM).  Errors are one line on stderr; `--debug` adds the traceback.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from enum import IntEnum
from pathlib import Path

from sim.errors import BenchError, ConfigurationError, EnvelopeError, LimitError, RunDirectoryError

from . import __version__

log = logging.getLogger(__name__)


class ExitCode(IntEnum):
    OK = 0
    FAILURE = 1          # runtime failure; `bench check` found problems
    USAGE = 2            # bad argument, file or value
    LIMIT = 3            # refused or aborted by a limit
    INTERRUPTED = 130    # Ctrl-C or SIGTERM


class Progress:
    """One status line with a bar and an ETA, redrawn in place on a terminal."""

    def __init__(self, label: str, stream=sys.stderr):
        self.label, self.stream, self.t0 = label, stream, time.monotonic()
        self.tty = stream.isatty()
        self.t_start, self.done0 = self.t0, 0

    def restart(self, done: int = 0) -> None:
        """Count the ETA from now and from ``done`` steps (set-up and resumed steps excluded)."""
        self.t_start, self.done0 = time.monotonic(), done

    def __call__(self, done: int, total: int, note: str = "") -> None:
        frac = done / max(total, 1)
        now = time.monotonic()
        el = now - self.t0
        eta = (now - self.t_start) / (done - self.done0) * (total - done) if done > self.done0 else float("nan")
        bar = "#" * int(30 * frac)
        line = f"{self.label} [{bar:<30}] {done}/{total} {el:5.1f}s eta {eta:5.1f}s {note}"
        if self.tty:
            self.stream.write("\r" + line[:150].ljust(150))
            if done >= total:
                self.stream.write("\n")
        elif done >= total or done == 1 or done % max(1, total // 10) == 0:
            self.stream.write(line + "\n")
        self.stream.flush()


def cmd_paper(args) -> int:
    from sim.paper import reproduce

    out = Path(args.out)
    files = reproduce(out, quick=args.quick, progress=Progress("paper figures"))
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
    from .session import EnvelopeError, check_envelope, envelope, envelope_report

    plan, rig = _load_configs(args)
    steps = plan.schedule()
    print(f"plan '{plan.name}': {len(plan.levels_N)} levels x {len(plan.freqs_Hz)} frequencies "
          f"({plan.direction}) = {len(steps)} steps; rig '{rig.name}'{' (simulated)' if rig.simulated else ''}")
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
    for w in identifiability(runnable, rig):
        print(f"identifiability warning: {w}")
    return 0


def _run(args, resume: bool) -> int:
    from .session import run_plan
    from .storage import RunStatus, RunStore

    if resume:
        from .config import parse_plan, parse_rig, plan_toml, rig_toml
        meta = RunStore.open(Path(args.run)).metadata
        plan = parse_plan({"plan": plan_toml(meta["plan"])}, f"{args.run}/run.json")
        rig = parse_rig({"rig": rig_toml(meta["rig"])}, f"{args.run}/run.json")
        out, seed = Path(args.run), meta.get("sim_seed")
    else:
        plan, rig = _load_configs(args)
        out, seed = Path(args.out), args.seed
    if rig.simulated:
        _warm_up()
    watch = _start_watch(out, args)
    try:
        store = run_plan(plan, rig, out, resume=resume, progress=Progress("stepped sine"), sim_seed=seed)
    finally:
        if watch:
            watch.close()
    meta = store.metadata
    print(f"run {meta['status']}: {meta['steps_done']}/{meta['steps_total']} steps in {out}/")
    if meta["status"] == RunStatus.COMPLETED and not getattr(args, "no_report", False):
        from .reports import write_report
        print(f"report: {write_report(out)}")
    return {RunStatus.COMPLETED: ExitCode.OK, RunStatus.ABORTED: ExitCode.LIMIT}.get(meta["status"], ExitCode.FAILURE)


def _warm_up() -> None:
    """Compile the simulation kernels first if they are not (so compiling never counts in
    the progress line's ETA), with a one-line notice."""
    from .warmup import kernels_warm, warm_up
    if not kernels_warm():
        log.warning("compiling the simulation kernels (first run only; `make setup` does it ahead)")
        log.info("kernels compiled in %.0f s", warm_up())


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
    if not run_dir.is_dir():
        raise ConfigurationError(f"{run_dir}: no such run directory")
    if not (run_dir / "run.json").is_file():
        log.warning("%s has no run.json yet: the page waits for the run to start", run_dir)
    import signal

    from .signals import handling

    server = _watch_server(run_dir, args.host, args.port)
    # The page serves from its own thread; Ctrl-C and SIGTERM only raise a flag (no lock
    # the main thread might hold, no exception a finalizer could drop: bench/signals.py).
    ended = []
    with handling(lambda signum, frame: ended.append(signum), signal.SIGINT, signal.SIGTERM):
        server.start()
        print(f"watch: {server.url}  (Ctrl-C ends the page, not the run)", flush=True)
        try:
            while not ended:
                time.sleep(0.2)
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
    return _run(args, resume=True)


def cmd_demo(args) -> int:
    """The main job: the default plan on the simulated rig, then its report."""
    args.plan = args.rig = None
    args.seed = None
    out = Path(args.out)
    if out.exists() and any(out.iterdir()):
        import shutil
        shutil.rmtree(out)   # the demo always starts afresh
    return _run(args, resume=False)


def cmd_report(args) -> int:
    from .reports import write_report
    print(f"report: {write_report(Path(args.run))}")
    return 0


def cmd_export(args) -> int:
    from .export import export_run
    paths = export_run(Path(args.run), Path(args.out) if args.out else None, time_records=not args.no_time)
    for p in paths:
        print(p)
    return 0


def cmd_identify(args) -> int:
    """Offline identification of a stored run (result written into its run.json) or of
    UFF58 time records (guesses from --rig, default: the simulated rig's file)."""
    from procedures.online_id import MAX_HARMONICS
    from sim.identify import identify_results

    from .config import DEFAULTS, load_rig, parse_rig, rig_toml
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
    guess = dict(F_s_N=rig.expected_F_s_N, x_s_m=rig.expected_x_s_m, n=rig.expected_n,
                 mass_kg=rig.expected_mass_kg)
    est = identify_results([s.harmonics for s in src.steps], guess, MAX_HARMONICS).estimate
    if src.kind == "run":
        RunStore.open(source).update(identification=est.as_dict())
    print(f"{'parameter':>10} {'estimate':>12} {'95 % interval':>28}")
    for k, v in est.values.items():
        print(f"{k:>10} {v:12.5g} [{est.low[k]:12.5g}, {est.high[k]:12.5g}]")
    print(f"{len(src.steps)} steps ({len(src.rejected)} rejected), reduced chi^2 {est.cost:.3g}")
    for w in est.warnings:
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
    """Verify a run directory: every problem on one line, exit 1 if there is any."""
    from .storage import RunStore

    store = RunStore(Path(args.run))
    if not store.path.is_dir():
        RunStore.open(store.path)             # raises the one-line usage error
    problems = store.check()
    n = len(store.step_files())
    for p in problems:
        print(f"{p.kind:>9}  {p}")
    good = n - len({p.key for p in problems if p.key and p.kind != "unknown" and
                    (store.steps_dir / f"{p.key}.json").exists()})
    print(f"{store.path}: {n} step result files, {good} intact; "
          f"{len(problems)} problem{'s' if len(problems) != 1 else ''}"
          + (f" (bench resume {store.path} measures damaged steps again, keeping their files in damaged/)"
             if any(p.key and p.kind != "unknown" for p in problems) else ""))
    return ExitCode.FAILURE if problems else ExitCode.OK


def cmd_warmup(args) -> int:
    from .warmup import warm_up
    if not args.verbose:
        logging.getLogger().setLevel(logging.ERROR)     # the warm-up run's chatter is noise here
    print("compiling the simulation kernels (once per machine and change of sim/) ...", flush=True)
    print(f"kernels compiled and cached in {warm_up():.0f} s")
    return 0


def cmd_twins(args) -> int:
    from drivers import run_standalone
    from sim.rig import RigModel, SimulatedRig

    from .config import DEFAULTS, load_rig
    rig = load_rig(Path(args.rig) if args.rig else DEFAULTS / "sim_rig.toml")
    if not rig.simulated:
        raise ConfigurationError(f"{args.rig}: not a simulated rig (simulated = true is needed)")
    run_standalone(SimulatedRig(RigModel.from_dict(rig.model)), args.host, serial_ports=args.serial)
    return 0


class _Parser(argparse.ArgumentParser):
    """Usage errors in one line, naming the command, the problem and where to look."""

    def error(self, message):
        self.exit(ExitCode.USAGE, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="bench", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    p.add_argument("--debug", action="store_true", help="show the traceback of an error")
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("paper", help="redraw the seed paper's numerical figures (PNG + CSV)")
    s.add_argument("--out", default="out/paper")
    s.add_argument("--quick", action="store_true", help="coarse grids (seconds)")
    s.set_defaults(func=cmd_paper)

    s = sub.add_parser("demo", help="the main job: the default plan on the simulated rig, with its report")
    s.add_argument("--out", default="out/demo")
    _add_watch_options(s)
    s.set_defaults(func=cmd_demo)

    for name, func, hlp in (("run", cmd_run, "run a stepped-sine plan on a rig"),
                            ("dry-run", cmd_dry_run, "check a plan against the rig's limits; print the envelope")):
        s = sub.add_parser(name, help=hlp)
        s.add_argument("--plan", help="plan TOML (default: the demo plan)")
        s.add_argument("--rig", help="rig TOML (default: the simulated rig)")
        if name == "run":
            s.add_argument("--out", required=True, help="new run directory")
            s.add_argument("--seed", type=int, help="noise seed of a simulated rig")
            s.add_argument("--no-report", action="store_true")
            _add_watch_options(s)
        s.set_defaults(func=func)

    s = sub.add_parser("resume", help="continue an interrupted run without repeating completed steps")
    s.add_argument("run")
    s.add_argument("--no-report", action="store_true")
    _add_watch_options(s)
    s.set_defaults(func=cmd_resume)

    s = sub.add_parser("watch", help="serve a live page of a run directory (running, resumed or finished)")
    s.add_argument("run")
    s.add_argument("--port", type=int, default=0, help="port (default: any free one)")
    s.add_argument("--host", default="127.0.0.1", help="interface (default 127.0.0.1; others only when given)")
    s.set_defaults(func=cmd_watch)

    s = sub.add_parser("report", help="(re)write the report of a run directory")
    s.add_argument("run")
    s.set_defaults(func=cmd_report)

    s = sub.add_parser("export", help="write a run's steps as CSV and UFF 58 (FRFs and time records)")
    s.add_argument("run")
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
    s.add_argument("--host", default="127.0.0.1")
    s.add_argument("--serial", action="store_true", help="also serve SCPI and Modbus RTU on pty pairs")
    s.set_defaults(func=cmd_twins)

    s = sub.add_parser("warmup", help="compile and cache the simulation kernels (make setup runs it)")
    s.set_defaults(func=cmd_warmup)

    s = sub.add_parser("frf", help="compliance G(beta) of the model at one force level (CSV to stdout)")
    s.add_argument("--gamma0", type=float, default=0.6)
    s.add_argument("--n", type=float, default=1.5)
    s.add_argument("--beta-min", type=float, default=0.2)
    s.add_argument("--beta-max", type=float, default=2.0)
    s.add_argument("--points", type=int, default=200)
    s.add_argument("--engine", choices=("shooting", "rk4"), default="shooting")
    s.set_defaults(func=cmd_frf)

    s = sub.add_parser("check", help="verify a run directory: list missing, truncated, damaged and unknown steps")
    s.add_argument("run")
    s.set_defaults(func=cmd_check)

    from .studies.cli import add_parsers as add_study_parsers
    add_study_parsers(sub, Progress)
    return _with_debug(p)


def _with_debug(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """``--debug`` after any subcommand too (every subcommand, whoever added it)."""
    for action in p._actions:
        if isinstance(action, argparse._SubParsersAction):
            for s in action.choices.values():
                if "--debug" not in s._option_string_actions:
                    s.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                                   help="show the traceback of an error")
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
    if _exit_code(e) in (ExitCode.USAGE, ExitCode.LIMIT) and first:
        return first
    return named


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:               # usage error or --help: argparse has printed it
        return int(e.code or 0)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args))
    except (Exception, KeyboardInterrupt) as e:   # one line, a documented code; --debug: traceback
        code = _exit_code(e)
        if args.debug:
            log.exception("bench %s failed", args.command)
        hint = ("" if args.debug or code == ExitCode.INTERRUPTED else
                ", rerun with --debug for the traceback" if _internal(e) else " (--debug shows the traceback)")
        print(f"bench {args.command}: {'error: ' if code != ExitCode.INTERRUPTED else ''}{_one_line(e)}{hint}",
              file=sys.stderr)
        return code


if __name__ == "__main__":
    sys.exit(main())
