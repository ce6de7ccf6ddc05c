"""Scale-out engine: map a task function over a list of tasks on dask.distributed.

A *task* is a dict of JSON-able inputs (a row of a map, one Monte-Carlo sample, one
source).  ``fn(inputs, seed) -> list[dict]`` runs on a worker and returns rows; the
client adds the task's inputs and the software version to every row and writes them as
one Parquet part per task (temporary name, then rename: all or nothing; no fsync, a part
lost to a power cut is recomputed):

    <study>/study.json              kind, spec, software version, tasks, failures
    <study>/parts/<task key>.parquet one task's rows
    <study>/results.parquet         every part, concatenated, when the study ends

A task's key is a hash of its inputs; a part that exists is never computed again, so an
interrupted or failed study is resumed by running it again.  The seed of a task comes
from the study seed and the task's inputs (never from the order or the worker), so a
local run and a cluster run give the same numbers.

Where it runs: ``scheduler=None`` starts a LocalCluster (one single-threaded worker
process per core; the numba kernels release the GIL but the identification and the
shooting Newton loops are Python); ``scheduler="tcp://host:port"`` connects to a running
cluster.  Each worker compiles (or loads from numba's cache) the kernels once, in a
worker plugin, before its first task.  Workers that die are replaced by dask, which
reruns their tasks elsewhere; a task that raises is reported with its inputs and the
rest goes on.  Ctrl-C cancels the pending futures and closes the cluster.

Rows are computed on the workers and written by the client, so workers need no shared
file system (the batch analysis, which reads sources and writes reports, does).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
from distributed import Client, LocalCluster, WorkerPlugin, as_completed

from bench.signals import SignalLatch
from bench.storage import atomic_write, now_iso
from bench.words import terminal_data as words
from sim.errors import ConfigurationError

log = logging.getLogger(__name__)


class StudySaid(StrEnum):
    """A study's refusals, log lines and progress notes, and the software version it stores
    (words: :data:`bench.words.terminal_data.STUDIES`)."""

    VERSION = "version"                     # version: the installed package's
    NOT_INSTALLED = "not_installed"
    NO_SCHEDULER = "no_scheduler"           # scheduler, detail: the connection's error
    SAME_INPUTS = "same_inputs"             # kind
    DIFFERENT_STUDY = "different_study"     # path, kind, seed, spec: the study the directory holds
    ALREADY_DONE = "already_done"           # path, done, total, todo
    RESUMED = "resumed"                     # the progress line's note
    FAILED_SO_FAR = "failed_so_far"         # count (the progress line's note)
    TASK_FAILED = "task_failed"             # key, inputs, error
    CANCELLING = "cancelling"               # path, count

SCHEMA = "guideway-bench/study/1"


def software_version() -> str:
    from importlib import metadata
    try:
        return words.said(StudySaid.VERSION, version=metadata.version("guideway-bench"))
    except metadata.PackageNotFoundError:
        return words.said(StudySaid.NOT_INSTALLED)


def task_key(inputs: dict) -> str:
    """Stable id of a task: a hash of its inputs (order of keys does not matter)."""
    blob = json.dumps(inputs, sort_keys=True, default=float).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def task_seed(study_seed: int, inputs: dict) -> int:
    """A task's random seed, from the study seed and the task's inputs alone."""
    blob = json.dumps([int(study_seed), inputs], sort_keys=True, default=float).encode()
    return int.from_bytes(hashlib.sha256(blob).digest()[:8], "little") >> 1


class WarmKernels(WorkerPlugin):
    """Compile (or load from numba's on-disk cache) the kernels once per worker."""

    name = "guideway-bench-warm-kernels"

    def setup(self, worker=None):
        warm_kernels()


def warm_kernels() -> None:
    from sim.dynamics import FrictionState, Integrator
    from sim.identify import Identifier  # noqa: F401  (imports compile-cached kernels)
    from sim.shooting import solve_half_period
    it = Integrator(n=1.5, steps_per_period=100)
    it.run(FrictionState(), 0.5, 1.5, 1)
    solve_half_period(1.5, 0.5, it.curve, 0.3, 4.7, steps=100, max_iter=1)


@dataclass
class Outcome:
    """What a study run did: rows written, tasks skipped (already done), failures."""

    study_dir: Path
    computed: int = 0
    skipped: int = 0
    failures: list[dict] = field(default_factory=list)
    seconds: float = 0.0
    workers: int = 0

    @property
    def table_path(self) -> Path:
        return self.study_dir / "results.parquet"

    def table(self) -> pa.Table:
        return pq.read_table(self.table_path)


class Engine:
    """A dask client on a LocalCluster (default) or on a running scheduler.

    Use as a context manager; ``workers`` is the LocalCluster's size (default: all cores).
    """

    def __init__(self, scheduler: str | None = None, workers: int | None = None, warm: bool = True,
                 connect_timeout_s: float = 20.0):
        self.scheduler, self.workers, self.warm = scheduler, workers, warm
        self.connect_timeout_s = connect_timeout_s
        self.cluster: LocalCluster | None = None
        self.client: Client | None = None

    def __enter__(self) -> Engine:
        try:
            if self.scheduler:
                try:
                    self.client = Client(self.scheduler, timeout=f"{self.connect_timeout_s}s")
                except OSError as e:
                    raise words.refused(ConfigurationError, StudySaid.NO_SCHEDULER, scheduler=self.scheduler,
                                        detail=str(e)) from e
            else:
                n = self.workers or os.cpu_count() or 1
                self.cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                            dashboard_address="127.0.0.1:0", host="127.0.0.1")
                self.client = Client(self.cluster)
            if self.warm:
                self.client.register_plugin(WarmKernels())
        except BaseException:          # Ctrl-C or a failure while starting: no stray workers
            self.close()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None
        if self.cluster is not None:
            self.cluster.close()
            self.cluster = None

    @property
    def n_workers(self) -> int:
        return len(self.client.scheduler_info(n_workers=-1)["workers"]) if self.client else 0

    def map(self, fn: Callable, items: list, *, progress=None, label: str = "") -> list:
        """``[fn(item) for item in items]`` on the cluster, in order; failures raise."""
        futures = self.client.map(fn, items, pure=False)
        out: dict = {}
        try:
            for i, fut in enumerate(as_completed(futures)):
                out[fut.key] = fut.result()
                if progress:
                    progress(i + 1, len(futures), label)
        except BaseException:
            self.client.cancel(futures)
            raise
        return [out[f.key] for f in futures]


def _run_task(fn: Callable, inputs: dict, seed: int) -> list[dict]:
    return list(fn(inputs, seed))


def _rows_table(rows: list[dict], inputs: dict, key: str, version: str) -> pa.Table:
    cols: dict[str, list] = {}
    extra = {f"in_{k}": v for k, v in inputs.items() if not isinstance(v, (list, dict))}
    extra.update(task=key, software_version=version)
    for r in rows:
        for k in {**r, **extra}:
            cols.setdefault(k, [])
    for r in rows:
        full = {**extra, **r}
        for k in cols:
            cols[k].append(full.get(k))
    return pa.table(cols)


def _write_part(path: Path, table: pa.Table) -> None:
    """All or nothing (temporary name, then rename), without fsync: a part lost to a power
    cut is only recomputed, and fsync would cost more than dask's own per-task overhead."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        pq.write_table(table, tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


class Study:
    """One study directory: its spec, its tasks, the parts done so far."""

    def __init__(self, study_dir: Path, kind: str, spec: dict, tasks: list[dict], seed: int = 0):
        self.dir = Path(study_dir)
        self.kind, self.spec, self.seed = kind, spec, int(seed)
        self.tasks = tasks
        self.keys = [task_key(t) for t in tasks]
        if len(set(self.keys)) != len(self.keys):
            raise words.refused(ConfigurationError, StudySaid.SAME_INPUTS, kind=kind)
        self.parts = self.dir / "parts"
        self.manifest = self.dir / "study.json"

    def _check_or_create(self) -> dict:
        self.parts.mkdir(parents=True, exist_ok=True)
        if self.manifest.exists():
            old = json.loads(self.manifest.read_text())
            if old.get("kind") != self.kind or old.get("spec") != json.loads(json.dumps(self.spec)) \
                    or old.get("seed") != self.seed:
                raise words.refused(ConfigurationError, StudySaid.DIFFERENT_STUDY, path=self.dir, kind=old.get("kind"),
                                    seed=old.get("seed"), spec=old.get("spec"))
            return old
        return dict(schema=SCHEMA, kind=self.kind, spec=self.spec, seed=self.seed,
                    software_version=software_version(), created=now_iso(),
                    tasks=[dict(key=k, inputs=t) for k, t in zip(self.keys, self.tasks)], runs=[])

    def done(self) -> set[str]:
        return {p.stem for p in self.parts.glob("*.parquet")}

    def _write_manifest(self, m: dict) -> None:
        atomic_write(self.manifest, lambda fh: fh.write(json.dumps(m, indent=1, default=float).encode()))

    def run_on(self, fn: Callable, engine: Engine | None = None, scheduler: str | None = None,
               workers: int | None = None, *, progress=None) -> Outcome:
        """:meth:`run` on ``engine``, or on one started (and closed) for this study."""
        if engine is not None:
            return self.run(fn, engine, progress=progress)
        with Engine(scheduler, workers) as eng:
            return self.run(fn, eng, progress=progress)

    def run(self, fn: Callable, engine: Engine, *, progress=None) -> Outcome:
        """Compute every task whose part is missing; returns the outcome (never raises for
        a failed task: it is in ``outcome.failures`` and ``study.json``)."""
        t0 = time.perf_counter()
        manifest = self._check_or_create()
        self._write_manifest(manifest)
        version = software_version()
        done = self.done()
        todo = [(k, t) for k, t in zip(self.keys, self.tasks) if k not in done]
        out = Outcome(self.dir, skipped=len(self.tasks) - len(todo), workers=engine.n_workers)
        if out.skipped:
            log.info("%s", words.said(StudySaid.ALREADY_DONE, path=self.dir, done=out.skipped, total=len(self.tasks),
                                      todo=len(todo)))
        client = engine.client
        futures = {}
        for k, t in todo:
            fut = client.submit(_run_task, fn, t, task_seed(self.seed, t), key=f"{self.kind}-{k}",
                                pure=False, retries=0)
            futures[fut] = (k, t)
        total, finished = len(self.tasks), out.skipped
        if progress and finished:
            progress(finished, total, words.said(StudySaid.RESUMED))
        latch = SignalLatch()       # SIGTERM as Ctrl-C; one dropped in a finalizer acts after the next task
        try:
            with latch.installed():
                for fut in as_completed(list(futures)):
                    latch.check()
                    k, t = futures[fut]
                    try:
                        rows = fut.result()
                    except Exception as e:  # noqa: BLE001 - one task's failure must not stop the study
                        msg = f"{type(e).__name__}: {e}"
                        log.error("%s", words.said(StudySaid.TASK_FAILED, key=k, inputs=t, error=msg))
                        out.failures.append(dict(task=k, inputs=t, error=msg))
                    else:
                        _write_part(self.parts / f"{k}.parquet", _rows_table(rows, t, k, version))
                        out.computed += 1
                    finished += 1
                    if progress:
                        progress(finished, total,
                                 words.said(StudySaid.FAILED_SO_FAR, count=len(out.failures)) if out.failures else "")
        except BaseException:
            log.warning("%s", words.said(StudySaid.CANCELLING, path=self.dir, count=sum(not f.done() for f in futures)))
            client.cancel(list(futures))
            raise
        finally:
            out.seconds = time.perf_counter() - t0
            manifest["runs"].append(dict(ended=now_iso(), computed=out.computed, skipped=out.skipped,
                                         failed=len(out.failures), seconds=out.seconds,
                                         workers=out.workers, scheduler=engine.scheduler or "local"))
            manifest["failures"] = out.failures
            manifest["complete"] = not out.failures and len(self.done()) == len(self.tasks)
            self._write_manifest(manifest)
        self.collect()
        return out

    def collect(self) -> Path:
        """Concatenate the parts, in task order, into results.parquet."""
        tables = [pq.read_table(self.parts / f"{k}.parquet") for k in self.keys
                  if (self.parts / f"{k}.parquet").exists()]
        path = self.dir / "results.parquet"
        if tables:
            table = pa.concat_tables(tables, promote_options="default")
            atomic_write(path, lambda fh: pq.write_table(table, fh))
        return path
