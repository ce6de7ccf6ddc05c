"""Batch analysis: one per-source function over a lab's archive, on the study engine.

Sources are run directories (holding run.json) and UFF58 files (.uff, .unv), given one by
one or found under archive directories.  One task per source calls the per-source
function ``fn(source: Path, out_dir: Path | None, rig: Path | None) -> dict`` (by
default :func:`bench.analyze.analyze_source`, which writes analysis.json and a report)
with ``out_dir = <batch>/sources/<name>``; the dict is flattened into one summary row:

    <batch>/summary.parquet, summary.csv   one row per source (parameters, verdict, ...)
    <batch>/sources/<name>/                 each source's own report
    <batch>/study.json, parts/              the engine's manifest and parts (resumable)

A source that fails is reported with its path; the others complete.  Workers read the
sources and write the reports, so on a cluster the paths must be on a shared file system.
"""

from __future__ import annotations

import csv
import importlib
import logging
import re
from collections.abc import Callable
from enum import StrEnum
from pathlib import Path

import pyarrow.parquet as pq

from sim.errors import ConfigurationError

from ..words import terminal_data as words
from .engine import Engine, Outcome, Study

log = logging.getLogger(__name__)


class BatchSaid(StrEnum):
    """A batch's bad paths and a source whose modes could not be estimated (words:
    :data:`bench.words.terminal_data.STUDIES`)."""

    NO_SUCH_PATH = "no_such_path"           # path
    NO_SOURCES_IN = "no_sources_in"         # path: a directory with no run or UFF58 file
    NO_MODES = "no_modes"                   # path, detail (a log line)

ANALYZE = "bench.analyze:analyze_source"
IDENTIFY = "bench.studies.batch:identify_source"
UFF_SUFFIXES = (".uff", ".unv")


def find_sources(paths: list[Path]) -> list[Path]:
    """Run directories and UFF58 files among ``paths`` and under archive directories."""
    out: list[Path] = []
    for p in map(Path, paths):
        if not p.exists():
            raise words.refused(ConfigurationError, BatchSaid.NO_SUCH_PATH, path=p)
        if p.is_file() or (p / "run.json").exists():
            out.append(p)
            continue
        runs = {q.parent for q in p.rglob("run.json")}
        # a run's own export (<run>/export/*.uff) is the same data again: the run counts
        uffs = {q for q in p.rglob("*") if q.is_file() and q.suffix.lower() in UFF_SUFFIXES
                and not runs.intersection(q.parents)}
        found = sorted(runs | uffs)
        if not found:
            raise words.refused(ConfigurationError, BatchSaid.NO_SOURCES_IN, path=p)
        out.extend(found)
    seen, unique = set(), []
    for s in out:
        if s.resolve() not in seen:
            seen.add(s.resolve())
            unique.append(s)
    return unique


def _resolve(spec: str) -> Callable:
    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr)


def _slug(path: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", path.strip("/"))[-120:]


def flatten(result: dict) -> dict:
    """One summary row from an analysis dict (analysis.json schema, or a subset of it)."""
    from sim.discrepancy.analysis import stored_analysis
    result = stored_analysis(result)
    row = dict(schema=result.get("schema", ""))
    for name, p in (result.get("parameters") or {}).items():
        for part in ("value", "low", "high"):
            row[f"{name}_{part}"] = p.get(part) if isinstance(p, dict) else None
    base = result.get("base") or {}
    row["reduced_chi2"] = base.get("reduced_chi2", result.get("reduced_chi2"))
    causes = result.get("causes")
    row["causes"] = (",".join(c.get("id", "") for c in causes if c.get("kind") != "artefact")
                     if causes is not None else None)
    row["artefacts"] = (",".join(dict.fromkeys(c.get("id", "") for c in causes if c.get("kind") == "artefact"))
                        if causes is not None else None)
    row["unexplained"] = result.get("unexplained")
    row["friction_model"] = result.get("friction_model")
    row["verdict"] = result.get("verdict")
    used = result.get("steps_used")
    row["steps_used"] = len(used) if isinstance(used, list) else used
    rejected = result.get("steps_rejected")
    row["steps_rejected"] = len(rejected) if isinstance(rejected, list) else rejected
    return row


def source_task(inputs: dict, seed: int = 0) -> list[dict]:
    """One source (a task): run the per-source function, return its summary row."""
    fn = _resolve(inputs["function"])
    out_dir = Path(inputs["out_dir"]) if inputs.get("out_dir") else None
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    rig = Path(inputs["rig"]) if inputs.get("rig") else None
    result = fn(Path(inputs["source"]), out_dir, rig)
    return [dict(source=inputs["source"], report_dir=inputs.get("out_dir"), **flatten(result),
                 **mode_columns(Path(inputs["source"])))]


MODE_COLUMNS = tuple(f"{m}_{k}" for m in ("feed", "pitch") for k in ("resonance_Hz", "damping_ratio", "status"))


def mode_columns(source: Path) -> dict:
    """The run's modes per level (decision 0043) as fixed text columns, one per mode and
    quantity, ``level:value`` pairs joined by ``;`` (``feed_resonance_Hz = "0.3:74.77;1:67.98"``;
    NaN where a level has no value, its status says why); empty for a source that is not a
    run directory.  `bench modes` gives the same as one row per run, mode and level."""
    out = dict.fromkeys(MODE_COLUMNS, "")
    if not (source.is_dir() and (source / "run.json").is_file()):
        return out
    try:
        from bench.reports import run_modes
        modes = run_modes(source, model=False).modes
    except Exception as e:  # noqa: BLE001 - the summary row comes out without the modes
        log.warning("%s", words.said(BatchSaid.NO_MODES, path=source, detail=e))
        return out
    for mode in ("feed", "pitch"):
        ms = [e for e in modes if e.mode == mode]
        out[f"{mode}_resonance_Hz"] = ";".join(f"{e.level_N:g}:{e.resonance_Hz:.6g}" for e in ms)
        out[f"{mode}_damping_ratio"] = ";".join(f"{e.level_N:g}:{e.damping_ratio:.4g}" for e in ms)
        out[f"{mode}_status"] = ";".join(f"{e.level_N:g}:{e.status}" for e in ms)
    return out


def identify_source(source: Path, out_dir: Path | None = None, rig: Path | None = None) -> dict:
    """Identification of one run directory or UFF58 file (:func:`bench.sources.load_source`,
    :func:`sim.identify.identify_results`) as a subset of the analysis.json schema
    (parameters, reduced_chi2, steps_used, steps_rejected): a cheap per-source function
    where the full analysis is not needed.  Guesses from the run's rig, else from ``rig``
    (default: the simulated rig's file); writes identification.json into ``out_dir``."""
    from bench.config import DEFAULTS, load_rig, stored_rig
    from bench.sources import SourceProblem, load_source
    from bench.storage import write_json
    from procedures.online_id import MAX_HARMONICS
    from sim.discrepancy.rigfit import identify_steps

    src = load_source(source)
    rr = (stored_rig(src.metadata["rig"], f"{source}/run.json") if src.kind == "run"
          else load_rig(rig or DEFAULTS / "sim_rig.toml"))
    if not src.steps:
        raise words.refused(ConfigurationError, SourceProblem.NO_STEPS_TO_IDENTIFY, path=source)
    est = identify_steps(src.steps, rr.guess(), rr.model, harmonics=MAX_HARMONICS)
    out = dict(schema="guideway-bench/identification/1", source=str(source), kind=src.kind,
               parameters={k: dict(value=est["values"][k], low=est["low"][k], high=est["high"][k])
                           for k in est["values"]},
               reduced_chi2=est["reduced_chi2"], steps_used=[s.key for s in src.steps],
               steps_rejected=[dict(step=r.step, reason=r.reason) for r in src.rejected],
               warnings=list(est["warnings"]), misfit=bool(est.get("misfit")), estimate_source=est.get("source"),
               model=est.get("model"))
    if out_dir is not None:
        write_json(Path(out_dir) / "identification.json", out)
    return out


def analyze_batch(sources: list[Path], out_dir: Path, *, rig: Path | None = None, function: str = ANALYZE,
                  scheduler: str | None = None, workers: int | None = None, engine: Engine | None = None,
                  progress=None) -> Outcome:
    """Run ``function`` ("module:name") over every source; summary.parquet + summary.csv."""
    out_dir = Path(out_dir)
    srcs = find_sources(sources)
    tasks = [dict(source=str(s.resolve()), out_dir=str((out_dir / "sources" / _slug(str(s.resolve()))).resolve()),
                  rig=str(Path(rig).resolve()) if rig else None, function=function) for s in srcs]
    study = Study(out_dir, "batch-analysis", dict(function=function, rig=tasks[0]["rig"] if tasks else None,
                                                  sources=[t["source"] for t in tasks]), tasks)
    if engine is None:
        with Engine(scheduler, workers) as eng:
            out = study.run(source_task, eng, progress=progress)
    else:
        out = study.run(source_task, engine, progress=progress)
    if out.table_path.exists():
        table = pq.read_table(out.table_path)
        pq.write_table(table, out_dir / "summary.parquet")
        with open(out_dir / "summary.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(table.column_names)
            w.writerows(zip(*(table.column(c).to_pylist() for c in table.column_names)))
    return out


def map_cases(fn: Callable, args: list, *, scheduler: str | None = None, workers: int | None = None,
              progress=None) -> list:
    """``[fn(a) for a in args]`` on the study engine (local cores or a cluster), in order.

    ``fn`` must be importable on the workers (a module-level function); for example the
    analysis benchmark's ``run_case(seed)``: ``map_cases(run_case, list(range(40)))``."""
    with Engine(scheduler, workers) as eng:
        return eng.map(fn, list(args), progress=progress, label=getattr(fn, "__name__", "case"))
