"""Run directory: crash-safe storage of a stepped-sine test, step by step.

    <run>/run.json          metadata: plan, rig, identities, versions, start/end, status
    <run>/events.jsonl      start, resume, interruption, abort, end (append-only)
    <run>/steps/<key>.json  one step's results   } written to a temporary name, fsynced,
    <run>/steps/<key>.npz   one step's raw block }   then renamed: all or nothing
    <run>/bench.log         the application's log

A step counts as done when its .json exists; the .npz is written first, so a .json never
points at a missing block.  A kill -9 at any moment leaves every completed step readable;
a torn last line of events.jsonl is skipped on reading.
"""

from __future__ import annotations

import json
import logging
import os
import tempfile
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)


def now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _atomic_write(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        _fsync_dir(path.parent)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, complex):
        return {"re": o.real, "im": o.imag}
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def write_json(path: Path, obj) -> None:
    data = json.dumps(obj, indent=1, default=_json_default).encode()
    _atomic_write(path, lambda fh: fh.write(data))


class RunStore:
    def __init__(self, path: Path):
        self.path = Path(path)
        self.steps_dir = self.path / "steps"

    # ------------------------------------------------------------------ life cycle
    @classmethod
    def create(cls, path: Path, metadata: dict) -> "RunStore":
        path = Path(path)
        if path.exists() and any(path.iterdir()):
            raise FileExistsError(f"run directory {path} exists and is not empty; "
                                  f"use 'bench resume {path}' or choose another --out")
        (path / "steps").mkdir(parents=True, exist_ok=True)
        store = cls(path)
        write_json(path / "run.json", dict(metadata, status="running", started=now_iso()))
        store.event("start")
        return store

    @classmethod
    def open(cls, path: Path) -> "RunStore":
        store = cls(path)
        if not (store.path / "run.json").is_file():
            raise FileNotFoundError(f"{path} is not a run directory (no run.json)")
        return store

    @property
    def metadata(self) -> dict:
        return json.loads((self.path / "run.json").read_text())

    def update(self, **fields) -> None:
        write_json(self.path / "run.json", dict(self.metadata, **fields))

    def finish(self, status: str, **fields) -> None:
        self.update(status=status, ended=now_iso(), **fields)
        self.event("end", status=status)

    # ------------------------------------------------------------------ events
    def event(self, kind: str, **fields) -> None:
        line = json.dumps(dict(time=now_iso(), event=kind, **fields), default=_json_default)
        with open(self.path / "events.jsonl", "a") as fh:
            fh.write(line + "\n")
            fh.flush()
            os.fsync(fh.fileno())

    def events(self) -> list[dict]:
        out = []
        p = self.path / "events.jsonl"
        if not p.exists():
            return out
        for line in p.read_text().splitlines():
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError:
                log.warning("skipping a torn line in %s", p)
        return out

    # ------------------------------------------------------------------ steps
    def done_keys(self) -> set[str]:
        return {p.stem for p in self.steps_dir.glob("*.json")}

    def write_step(self, key: str, result: dict, raw: dict[str, np.ndarray]) -> None:
        _atomic_write(self.steps_dir / f"{key}.npz", lambda fh: np.savez(fh, **raw))
        write_json(self.steps_dir / f"{key}.json", result)

    def results(self) -> list[dict]:
        """Completed steps' results, in schedule order."""
        return [json.loads(p.read_text()) for p in sorted(self.steps_dir.glob("*.json"))]

    def raw(self, key: str) -> dict[str, np.ndarray]:
        with np.load(self.steps_dir / f"{key}.npz") as z:
            return {k: z[k] for k in z.files}
