"""`bench study map|mc` and the batch mode of `bench analyze` (argument parsing and
printing only; the work is in the sibling modules)."""

from __future__ import annotations

import logging
from enum import StrEnum
from pathlib import Path

from bench.words.terminal import refused
from bench.words.terminal_config import study_out
from sim.errors import ConfigurationError

log = logging.getLogger(__name__)


class StudyArgs(StrEnum):
    """What the study commands refuse of their arguments (their words: bench.words.terminal_config.STUDY)."""

    NOT_NUMBERS = "study_not_numbers"       # text
    NEEDS_OUT = "batch_needs_out"
    MC_RIG_NOT_SIMULATED = "study_mc_rig_not_simulated"     # path (the rig file)


class StudyOut(StrEnum):
    """What the study commands print and their progress labels (their words: bench.words.terminal_config.STUDY_OUT)."""

    FIGURE = "study_figure"                 # path
    OUTCOME = "study_outcome"               # computed, skipped, failed, seconds, workers, table
    FAILED = "study_failed"                 # task, shown (its inputs, or its source where they are long), error
    SUMMARY = "batch_summary"               # parquet, csv, reports
    MAP_LABEL = "study_map_label"           # rows
    MC_LABEL = "study_mc_label"             # samples
    BATCH_LABEL = "batch_label"


def _floats(text: str) -> tuple[float, ...]:
    """"0.5,1.5" or "0.1:0.9:9" (start:stop:count, linear)."""
    import numpy as np
    try:
        if text.count(":") == 2:
            a, b, k = text.split(":")
            return tuple(float(x) for x in np.round(np.linspace(float(a), float(b), int(k)), 12))
        return tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise refused(ConfigurationError, StudyArgs.NOT_NUMBERS, text=text) from None


def _dask_info(record: logging.LogRecord) -> bool:
    return not (record.name.split(".")[0] in ("distributed", "dask", "tornado") and record.levelno < logging.WARNING)


def _quiet_dask() -> None:
    """dask's own INFO lines (scheduler and nanny start/stop) would bury the progress line
    (dask sets its loggers' levels itself, so filter them at the application's handlers)."""
    if logging.getLogger().level > logging.DEBUG:
        for h in logging.getLogger().handlers:
            h.addFilter(_dask_info)


def _engine_args(s) -> None:
    s.add_argument("--scheduler", help="run on this dask scheduler (tcp://host:port) instead of local cores")
    s.add_argument("--workers", type=int, help="local worker processes (default: all cores)")


def _report(out) -> int:
    print(study_out(StudyOut.OUTCOME, computed=out.computed, skipped=out.skipped, failed=len(out.failures),
                    seconds=out.seconds, workers=out.workers, table=out.table_path))
    for f in out.failures:
        shown = f["inputs"] if len(str(f["inputs"])) < 300 else f["inputs"].get("source", f["task"])
        print(study_out(StudyOut.FAILED, task=f["task"], shown=shown, error=f["error"]))
    return 1 if out.failures else 0


def cmd_study_map(args, progress) -> int:
    _quiet_dask()
    from .maps import MapSpec, compliance_map
    spec = MapSpec(n=_floats(args.n), gamma0=_floats(args.gamma0), beta_min=args.beta_min,
                   beta_max=args.beta_max, beta_points=args.beta_points, engine=args.engine)
    out = compliance_map(spec, Path(args.out), scheduler=args.scheduler, workers=args.workers,
                         progress=progress(study_out(StudyOut.MAP_LABEL, rows=len(spec.tasks()))))
    if (Path(args.out) / "map.png").exists():
        print(study_out(StudyOut.FIGURE, path=Path(args.out) / "map.png"))
    return _report(out)


def cmd_study_mc(args, progress) -> int:
    _quiet_dask()
    from bench.config import DEFAULTS, parse_plan, parse_rig, read_toml
    from sim.errors import ConfigurationError

    from .montecarlo import McSpec, identification_mc
    plan_path, rig_path = Path(args.plan or DEFAULTS / "demo_plan.toml"), Path(args.rig or DEFAULTS / "sim_rig.toml")
    plan, rig = read_toml(plan_path), read_toml(rig_path)
    parse_plan(plan, str(plan_path))          # errors name the file (McSpec checks again, unnamed)
    if not parse_rig(rig, str(rig_path)).simulated:
        raise refused(ConfigurationError, StudyArgs.MC_RIG_NOT_SIMULATED, path=rig_path)
    spec = McSpec(plan=plan, rig=rig, samples=args.samples, spread=args.spread, n_spread=args.n_spread,
                  noise_scale=args.noise_scale, seed=args.seed)
    out = identification_mc(spec, Path(args.out), scheduler=args.scheduler, workers=args.workers,
                            progress=progress(study_out(StudyOut.MC_LABEL, samples=spec.samples)))
    if (Path(args.out) / "errors.png").exists():
        print(study_out(StudyOut.FIGURE, path=Path(args.out) / "errors.png"))
    return _report(out)


def is_batch(args) -> bool:
    """`bench analyze` in batch mode: several sources, an archive directory (one without
    run.json), an engine option or --identify-only."""
    if len(args.sources) != 1 or any(getattr(args, k, None) for k in ("scheduler", "workers", "identify_only")):
        return True
    p = Path(args.sources[0])
    return p.is_dir() and not (p / "run.json").exists()


def cmd_analyze_batch(args, progress) -> int:
    _quiet_dask()
    if not args.out:
        raise refused(ConfigurationError, StudyArgs.NEEDS_OUT)
    from .batch import ANALYZE, IDENTIFY, analyze_batch
    out = analyze_batch([Path(s) for s in args.sources], Path(args.out), rig=Path(args.rig) if args.rig else None,
                        function=IDENTIFY if args.identify_only else ANALYZE, scheduler=args.scheduler,
                        workers=args.workers, progress=progress(study_out(StudyOut.BATCH_LABEL)))
    print(study_out(StudyOut.SUMMARY, parquet=Path(args.out) / "summary.parquet", csv=Path(args.out) / "summary.csv",
                    reports=Path(args.out) / "sources"))
    return _report(out)


def add_parsers(sub, progress) -> None:
    """Register `study` on ``sub`` (the batch options of `analyze`: :func:`add_batch_options`)."""
    s = sub.add_parser("study", help="parameter studies on all local cores or a dask cluster (resumable)")
    ss = s.add_subparsers(dest="study", required=True)
    m = ss.add_parser("map", help="compliance map G(beta, gamma0) for one or more n (Parquet + map.png)")
    m.add_argument("--n", default="1.5", help="shape factors: '0.5,1.5' or 'start:stop:count'")
    m.add_argument("--gamma0", default="0.1:0.9:9", help="force ratios P0/F_s in (0, 1)")
    m.add_argument("--beta-min", type=float, default=0.2, help="lowest frequency ratio beta")
    m.add_argument("--beta-max", type=float, default=3.0, help="highest frequency ratio beta")
    m.add_argument("--beta-points", type=int, default=200, help="log-spaced frequency ratios per row")
    m.add_argument("--engine", choices=("shooting", "rk4"), default="shooting",
                   help="steady state by half-period shooting (fast) or by RK4 time stepping")
    m.add_argument("--out", required=True, help="study directory (run again to resume)")
    _engine_args(m)
    m.set_defaults(func=lambda a: cmd_study_map(a, progress))
    c = ss.add_parser("mc", help="Monte-Carlo study of identification for a plan (Parquet + errors.png)")
    c.add_argument("--plan", help="plan TOML (default: the demo plan)")
    c.add_argument("--rig", help="simulated rig TOML; [rig.expected] centres the random rigs")
    c.add_argument("--samples", type=int, default=20, help="random rigs to run the plan on")
    c.add_argument("--spread", type=float, default=2.0, help="F_s, x_s, m within this factor of expected")
    c.add_argument("--n-spread", type=float, default=0.5, help="n within +- this of expected")
    c.add_argument("--noise-scale", type=float, default=1.0, help="multiplies the rig model's sensor noise")
    c.add_argument("--seed", type=int, default=0, help="study seed (task seeds derive from it)")
    c.add_argument("--out", required=True, help="study directory (run again to resume)")
    _engine_args(c)
    c.set_defaults(func=lambda a: cmd_study_mc(a, progress))


def add_batch_options(a) -> None:
    """The options that only the batch mode of `bench analyze` has."""
    a.add_argument("--identify-only", action="store_true",
                   help="only identify F_s, x_s, n, m per source (no model-vs-measurement analysis)")
    _engine_args(a)
