"""The bench as a Python library: the public API (decision record 0055).

    import bench
    rig = bench.load_rig("bench/defaults/sim_rig.toml")
    plan = bench.load_plan("bench/defaults/demo_plan.toml")
    run = bench.run(plan, rig, "runs/a", labels={"lubricant": "ISO VG 32"})
    run.steps()                    # pandas DataFrame, one row per step (STEP_COLUMNS)
    run.modes()                    # each mode's resonance and damping per level (modes.csv)
    bench.open_run("runs/a")       # any run directory: finished, interrupted or damaged

Everything here is also what the command line does, with the same checks, the same named
errors (``sim.errors``, all subclasses of ``bench.BenchError``) and the same safety: the plan is checked against the rig's limits
before anything is opened, and on every way out of a run (its end, a limit, an instrument
error, ``KeyboardInterrupt`` from a notebook's stop button or Ctrl-C, an exception raised
in the caller's ``progress`` callback) the output is ramped down and switched off, the
switch-off is confirmed in ``events.jsonl`` and the run directory stays resumable.
Everything not named in ``bench.__all__`` is private and free to change.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import replace
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

from procedures.plan import Plan, Rig
from sim.errors import ConfigurationError

from .words.terminal import refused
from .words.terminal_config import line

if TYPE_CHECKING:
    import pandas as pd

log = logging.getLogger(__name__)

PathLike = str | Path
Progress = Callable[[int, int, str], None]     # (steps done, steps planned, a note)

# run.steps()'s columns: those of `bench export`'s steps.csv (SI units in the names), then
# the step's kind: "sweep", "refine" or "dwell" (resonance search), "backbone" (a locked point)
STEP_COLUMNS: tuple[str, ...] = ()       # filled below from bench.export.CSV_COLUMNS


def _steps_columns() -> tuple[str, ...]:
    from .export import CSV_COLUMNS
    return (*CSV_COLUMNS, "kind", "refined_mode")


def load_rig(path: PathLike) -> Rig:
    """The rig of a rig file (TOML); every problem of it named in one `ConfigurationError`."""
    from .config import load_rig as _load
    return _load(Path(path))


def load_plan(path: PathLike) -> Plan:
    """The plan of a plan file (TOML); every problem of it named in one `ConfigurationError`."""
    from .config import load_plan as _load
    return _load(Path(path))


def rig_from_dict(data: Mapping[str, Any], source: str = "rig") -> Rig:
    """A rig built in code from the rig file's layout (``{"name": ..., "calibration": {...},
    "limits": {...}, ...}``, with or without the outer ``"rig"`` table), with the file's checks."""
    from .config import parse_rig
    return parse_rig(dict(data) if "rig" in data else {"rig": dict(data)}, source)


def plan_from_dict(data: Mapping[str, Any], source: str = "plan") -> Plan:
    """A plan built in code from the plan file's layout (``{"levels_N": [...], "frequencies":
    {...}, ...}``, with or without the outer ``"plan"`` table), with the file's checks."""
    from .config import parse_plan
    return parse_plan(dict(data) if "plan" in data else {"plan": dict(data)}, source)


class ApiRefusal(StrEnum):
    """What the Python API refuses (its words: bench.words.terminal_config.API)."""

    NOT_A_PLAN = "api_not_a_plan"       # got (the type's name)
    NOT_A_RIG = "api_not_a_rig"         # got (the type's name)
    BAD_LABEL = "api_bad_label"         # key
    IMPORTED_NO_RIG = "api_imported_no_rig"     # run, file: an imported run (bench import) has no rig


class ApiLine(StrEnum):
    """What the Python API logs (its words: bench.words.terminal_config.LOG)."""

    COMPILING = "kernels_compiling"
    COMPILED = "kernels_compiled"       # seconds


def _as_plan(plan: Plan | PathLike) -> Plan:
    if isinstance(plan, Plan):
        return plan
    if isinstance(plan, str | Path):
        return load_plan(plan)
    raise refused(TypeError, ApiRefusal.NOT_A_PLAN, got=type(plan).__name__)


def _as_rig(rig: Rig | PathLike) -> Rig:
    if isinstance(rig, Rig):
        return rig
    if isinstance(rig, str | Path):
        return load_rig(rig)
    raise refused(TypeError, ApiRefusal.NOT_A_RIG, got=type(rig).__name__)


def run(plan: Plan | PathLike, rig: Rig | PathLike, out: PathLike, *, labels: Mapping[str, str] | None = None,
        progress: Progress | None = None, seed: int | None = None, identify: bool = True,
        report: bool = True) -> Run:
    """Run ``plan`` on ``rig`` into the new run directory ``out`` and return it as a `Run`.

    ``plan`` and ``rig`` are the typed values (`load_plan`, `plan_from_dict`) or
    the paths of their files.  ``progress(done, total, note)`` is called after each step.
    ``seed`` seeds a simulated rig's noise.  ``report`` writes ``out/report/report.md`` when
    the run completed.  A run stopped by a limit returns normally (its ``status`` says
    ``aborted``); ``KeyboardInterrupt`` and every other exception propagate once the output
    is off and confirmed (the run is then ``interrupted`` or ``failed`` and
    `Run.resume` goes on with it)."""
    plan, rig = _as_plan(plan), _as_rig(rig)
    execute(plan, rig, Path(out), progress=progress, seed=seed, identify=identify,
            labels=_checked_labels(labels) if labels is not None else None)
    done = Run(out)
    if report and done.status == "completed":
        done.report()
    return done


def execute(plan: Plan, rig: Rig, out: Path, *, resume: bool = False, progress: Progress | None = None,
            seed: int | None = None, identify: bool = True, retry_skipped: bool = False,
            labels: dict[str, str] | None = None, latch: Any = None):
    """The one way every caller (`run`, `Run.resume`, ``bench run``, ``bench resume``,
    ``bench sequence``) measures: the kernels compiled first for a simulated rig (so the
    compile never counts in a progress ETA), then ``bench.session.run_plan`` with its safety
    path.  Returns the run's store.  ``latch``: the command line's process-wide signal
    latch (decision 0051); a script's run makes its own."""
    from .session import run_plan
    warm_if_simulated(rig)
    return run_plan(plan, rig, Path(out), resume=resume, progress=progress, sim_seed=seed, identify=identify,
                    retry_skipped=retry_skipped, labels=labels, latch=latch)


def stored_configs(meta: Mapping[str, Any], where: str) -> tuple[Plan, Rig]:
    """The plan and the rig stored in a run's ``run.json`` (``meta``), validated as the files
    are; the envelope's skips are left to be worked out again (the limits may have changed)."""
    from .config import parse_rig, rig_toml
    from .storage import stored_plan
    return replace(stored_plan(dict(meta), where), skip=()), parse_rig({"rig": rig_toml(meta["rig"])}, where)


def open_run(path: PathLike) -> Run:
    """An existing run directory as a `Run` (finished, interrupted or with damaged
    steps: the readers skip a damaged step with a warning naming its file)."""
    return Run(path)


def _checked_labels(labels: Mapping[str, str]) -> dict[str, str]:
    out = {}
    for k, v in labels.items():
        if not isinstance(k, str) or not k.strip():
            raise refused(ConfigurationError, ApiRefusal.BAD_LABEL, key=k)
        out[k.strip()] = str(v).strip()
    return out


def warm_if_simulated(rig: Rig) -> None:
    """Compile the simulation kernels first if a simulated rig needs them and they are not,
    with a one-line notice."""
    if rig.simulated:
        from .warmup import kernels_warm, warm_up
        if not kernels_warm():
            log.warning(line(ApiLine.COMPILING))
            log.info(line(ApiLine.COMPILED, seconds=warm_up()))


def _frame(rows: list[dict], columns: tuple[str, ...]) -> pd.DataFrame:
    import pandas as pd
    return pd.DataFrame(rows, columns=list(columns))


class Run:
    """One run directory: its metadata, its steps as a table, its modes, backbone points and
    identification, and what the command line does with a run (resume, report, export,
    analyze, check).  Reads go to the directory each time (a run that is still going shows
    its latest steps)."""

    def __init__(self, path: PathLike):
        from .storage import RunStore
        self.path = Path(path)
        self._store = RunStore.open(self.path)      # a one-line RunDirectoryError if it is not a run directory

    def __repr__(self) -> str:
        meta = self.metadata
        return (f"Run({str(self.path)!r}, status={meta.get('status')!r}, "
                f"steps={meta.get('steps_done', len(self._store.done_keys()))}/{meta.get('steps_total', '?')})")

    # ------------------------------------------------------------------ what it is

    @property
    def metadata(self) -> dict:
        """run.json as a dict (docs/run-format.md)."""
        return self._store.metadata

    @property
    def status(self) -> str:
        """``running``, ``completed``, ``interrupted``, ``aborted`` (a limit), ``failed`` or
        ``instrument error`` (run.json's ``status``)."""
        return str(self.metadata.get("status", "unknown"))

    @property
    def plan(self) -> Plan:
        from .storage import stored_plan
        return stored_plan(self.metadata, self.path / "run.json")

    @property
    def rig(self) -> Rig:
        """The rig the run was measured on; an imported run (``bench import``) has none."""
        from .frf_import import origin_of
        if (origin := origin_of(self.metadata)) is not None:
            raise refused(ConfigurationError, ApiRefusal.IMPORTED_NO_RIG, run=self.path, file=origin.get("file", "?"))
        return stored_configs(self.metadata, f"{self.path}/run.json")[1]

    @property
    def labels(self) -> dict[str, str]:
        return dict(self.metadata.get("labels") or {})

    @property
    def identification(self) -> dict | None:
        """The final identification (values, 95 % intervals, warnings) when the run made one."""
        return self.metadata.get("identification")

    def results(self) -> list[dict]:
        """Every intact step's full record (sim.step_result.StepResult), in the order measured."""
        return sorted(self._store.results(), key=lambda r: (r["index"], r["key"]))

    # ------------------------------------------------------------------ tables

    def steps(self) -> pd.DataFrame:
        """One row per intact step, in SI units: the columns of ``bench export``'s steps.csv
        (``key``, ``level_index``, ``target_force_N``, ``freq_Hz``, ``force_N``, complex
        compliance, accelerance, THD and noise per channel, force error, control iterations;
        ``bench.STEP_COLUMNS`` lists them), then ``kind`` (``sweep``, ``refine``, ``dwell`` or
        ``backbone``) and ``refined_mode`` (the mode a refinement or dwell step is at)."""
        from procedures.plan import REFINED_KEY

        from .export import step_row
        rows = []
        for r in self.results():
            row = step_row(r)
            m = REFINED_KEY.fullmatch(r["key"])
            row["kind"] = ("backbone" if r.get("backbone") else "sweep" if m is None
                           else "dwell" if m["kind"] == "W" else "refine")
            row["refined_mode"] = {"F": "feed", "P": "pitch"}[m["mode"]] if m else ""
            rows.append(row)
        return _frame(rows, _steps_columns())

    def modes(self, *, model: bool = True) -> pd.DataFrame:
        """Each mode's resonance and damping ratio per level with their intervals: the rows
        of ``bench modes``' modes.csv for this run (with the rig model's prediction when
        ``model`` and the rig is simulated)."""
        from .reports import MODES_COLUMNS, run_modes
        return _frame(run_modes(self.path, model=model).rows(), MODES_COLUMNS)

    def backbone(self) -> pd.DataFrame:
        """A phase-resonance run's points (backbone.csv's columns); empty for other procedures."""
        from .backbone import COLUMNS, backbone_rows
        return _frame(backbone_rows(self._store.results(warn=False)), COLUMNS)

    # ------------------------------------------------------------------ what the CLI does with a run

    def resume(self, *, progress: Progress | None = None, retry_skipped: bool = False, report: bool = True) -> Run:
        """Go on with an interrupted, aborted or damaged run (``bench resume``): the missing and
        damaged steps are measured (damaged files kept in ``damaged/``), the limits checked
        again first.  Returns this run, re-read."""
        plan, rig = stored_configs(self.metadata, f"{self.path}/run.json")
        execute(plan, rig, self.path, resume=True, progress=progress, seed=self.metadata.get("sim_seed"),
                retry_skipped=retry_skipped)
        again = Run(self.path)
        if report and again.status == "completed":
            again.report()
        return again

    def report(self, *, with_runs: tuple[PathLike, ...] = ()) -> Path:
        """(Re)write ``report/report.md`` and its figures; returns its path."""
        from .reports import write_report
        return Path(write_report(self.path, [Path(p) for p in with_runs]))

    def export(self, out: PathLike | None = None, *, time_records: bool = True) -> list[Path]:
        """steps.csv, frf.uff and time.uff (``bench export``); returns the files written."""
        from .export import export_run
        return [Path(p) for p in export_run(self.path, Path(out) if out else None, time_records=time_records)]

    def analyze(self, out: PathLike | None = None, *, rig: PathLike | None = None) -> dict:
        """What the Masing model gets wrong, the cause and the gain (``bench analyze``):
        writes ``analysis/analysis.json`` and ``analysis.html``, returns the analysis."""
        from .analyze import analyze_source
        return analyze_source(self.path, Path(out) if out else None, Path(rig) if rig else None)

    def check(self) -> list[str]:
        """Every problem of the directory against its plan (``bench check``), one sentence
        each: missing, damaged and orphan steps; empty when the run is whole."""
        acc = self._store.account()
        return [str(p) for p in acc.missing + acc.damaged + acc.orphan]


STEP_COLUMNS = _steps_columns()
"""The columns of `Run.steps()`: bench export's steps.csv columns, then ``kind`` and ``refined_mode``."""

__all__ = ["STEP_COLUMNS", "Plan", "Rig", "Run", "load_plan", "load_rig", "open_run",
           "plan_from_dict", "rig_from_dict", "run"]
