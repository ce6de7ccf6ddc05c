"""`bench demo --out DIR` starts afresh, but deletes only the files an earlier demo wrote.

Each demo leaves a manifest in DIR (``demo-manifest.json``): every file it wrote there,
with its size and SHA-256, and the directories it made.  A later demo deletes exactly
those files (then the directories, if that leaves them empty), and only when DIR holds
nothing else: a file the manifest does not list (a thesis in ``report/``, an export, a
resume's new steps), a listed file changed since, a link, or no manifest at all (an older
bench's demo, a run that is not a demo, ``--out .``) and the demo refuses in one line,
naming what it found, and deletes nothing (decision records 0040, 0051).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from enum import StrEnum
from pathlib import Path

from sim.errors import ConfigurationError

from .runlock import LOCK_NAME
from .words import say, terminal_run
from .words.terminal import refused

log = logging.getLogger(__name__)


class Writer(StrEnum):
    """Who wrote a manifest (``written_by``, stored as this string)."""

    DEMO = "bench demo"


class DemoLine(StrEnum):
    """The demo's words (:data:`bench.words.terminal_run.DEMO`): what it found in --out that
    it did not write, and what it deleted."""

    LINK = "link"                           # name: a link where the demo wrote a file
    CHANGED = "changed"                     # name: a file changed since the demo wrote it
    DELETED = "deleted"                     # out, files (the earlier demo's, deleted)


def _said(code: DemoLine, **fields) -> str:
    return say(terminal_run.DEMO, code, fields)

MANIFEST = "demo-manifest.json"
_OWN = {LOCK_NAME, MANIFEST}             # the session lock is never deleted (decision 0040)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _entries(out: Path) -> tuple[list[Path], list[Path], list[Path]]:
    """Files, directories and links under ``out`` (links not followed), the demo's own
    lock and manifest left out."""
    files, dirs, links = [], [], []
    for root, dnames, fnames in os.walk(out):
        for name in sorted(dnames) + sorted(fnames):
            p = Path(root) / name
            if p.is_symlink():
                links.append(p)
            elif p.is_dir():
                dirs.append(p)
            elif not (Path(root) == out and name in _OWN):
                files.append(p)
        dnames[:] = [d for d in dnames if not (Path(root) / d).is_symlink()]
    return files, dirs, links


def write_manifest(out: Path) -> None:
    """List what is in ``out`` as written by this demo (it was absent or emptied before the
    demo began).  Written atomically; nothing when this process did not start the run
    there (``out`` never made, another session's run)."""
    out = Path(out)
    try:
        process = json.loads((out / "run.json").read_bytes()).get("process") or {}
    except (OSError, ValueError, AttributeError):
        return
    if process.get("pid") != os.getpid():
        return
    files, dirs, _ = _entries(out)
    manifest = {"written_by": Writer.DEMO.value,
                "files": {p.relative_to(out).as_posix(): {"bytes": p.stat().st_size, "sha256": _sha256(p)}
                          for p in files},
                "dirs": [d.relative_to(out).as_posix() for d in dirs]}
    tmp = out / f".{MANIFEST}.{os.getpid()}.tmp"
    tmp.write_text(json.dumps(manifest, indent=1) + "\n")
    os.replace(tmp, out / MANIFEST)


def _manifest(out: Path) -> dict | None:
    try:
        m = json.loads((out / MANIFEST).read_bytes())
    except (OSError, ValueError):
        return None
    ok = (isinstance(m, dict) and isinstance(m.get("files"), dict) and isinstance(m.get("dirs"), list)
          and all(isinstance(v, dict) for v in m["files"].values()))
    return m if ok else None


def _foreign(out: Path, manifest: dict) -> list[str]:
    """What in ``out`` the earlier demo did not write, or changed since (relative names; a
    directory ends in /)."""
    files, dirs, links = _entries(out)
    listed, listed_dirs = manifest["files"], set(manifest["dirs"])

    def new_dir(p: Path) -> str | None:          # the outermost directory the demo did not make
        parts = p.relative_to(out).parts[:-1]
        return next((f"{'/'.join(parts[:k])}/" for k in range(1, len(parts) + 1)
                     if "/".join(parts[:k]) not in listed_dirs), None)

    found = set()
    for p in files + links + dirs:
        name = p.relative_to(out).as_posix()
        outer = new_dir(p) or (f"{name}/" if p in dirs and name not in listed_dirs else None)
        if outer:
            found.add(outer)
        elif p in links:
            found.add(_said(DemoLine.LINK, name=name))
        elif p in files and name not in listed:
            found.add(name)
        elif p in files and (p.stat().st_size != listed[name].get("bytes") or _sha256(p) != listed[name].get("sha256")):
            found.add(_said(DemoLine.CHANGED, name=name))
    return sorted(found)


class OutDirRefusal(StrEnum):
    """Why ``bench demo --out`` refused a directory (the error's ``code``; its words:
    :mod:`bench.words.terminal`)."""

    NOT_A_DIR = "demo_not_a_dir"        # out
    NOT_A_DEMO = "demo_not_a_demo"      # out, manifest (its file name)
    FOREIGN = "demo_foreign"            # out, foreign (what the demo did not write, sorted)


def check_out_dir(out: Path) -> bool:
    """True if ``out`` holds an earlier demo's files and nothing else, False if it is absent
    or empty; anything else raises :class:`ConfigurationError` naming what is there."""
    out = Path(out)
    if not out.exists() or (out.is_dir() and not any(p.name != LOCK_NAME for p in out.iterdir())):
        return False
    if not out.is_dir() or out.is_symlink():
        raise refused(ConfigurationError, OutDirRefusal.NOT_A_DIR, out=out)
    manifest = _manifest(out)
    if manifest is None:
        raise refused(ConfigurationError, OutDirRefusal.NOT_A_DEMO, out=out, manifest=MANIFEST)
    foreign = _foreign(out, manifest)
    if foreign:
        raise refused(ConfigurationError, OutDirRefusal.FOREIGN, out=out, foreign=foreign)
    return True


def clear_earlier_demo(out: Path) -> None:
    """Delete the files the earlier demo in ``out`` wrote, the directories it made once
    empty, then its manifest (see :func:`check_out_dir`, which refuses anything else,
    deleting nothing); the session lock stays (its holder is the caller)."""
    out = Path(out)
    if not check_out_dir(out):
        return
    files, dirs, _ = _entries(out)        # each one listed and unchanged (checked just now)
    for p in files:
        p.unlink()
    for d in sorted(dirs, key=lambda d: len(d.parts), reverse=True):
        d.rmdir()
    (out / MANIFEST).unlink()
    log.info(_said(DemoLine.DELETED, out=out, files=len(files)))
