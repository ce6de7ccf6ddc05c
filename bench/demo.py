"""`bench demo --out DIR` starts afresh, but deletes only an earlier demo run.

DIR is cleared only when it is recognisably what an earlier `bench demo` left: its
run.json names the demo plan on the simulated rig, and every entry in it is one the demo
(or a resume of it) writes: the run's own files, ``steps/`` holding step files only,
``report/`` holding the report's pictures and text, ``damaged/`` of a resume.  Anything
else (a thesis, another run, an export or analysis made from the demo, ``--out .``) and
nothing is deleted: the demo refuses, naming what it found (decision record 0040).
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

from sim.errors import ConfigurationError

from .config import DEFAULTS, load_plan, load_rig
from .runlock import LOCK_NAME

RUN_FILES = {"run.json", "events.jsonl", "bench.log", "identification.jsonl", "stop.request", LOCK_NAME}
STEP_FILE = re.compile(r"(\d{5}-L\d{2}-F\d{3}-(up|down)\.(json|npz)|\..+\.tmp)")
REPORT_FILE = re.compile(r"[\w.-]+\.(png|md|html)")


def is_demo_run(meta: object) -> bool:
    """run.json of a demo: the demo plan on the simulated rig."""
    if not isinstance(meta, dict):
        return False
    plan, rig = meta.get("plan"), meta.get("rig")
    return (isinstance(plan, dict) and isinstance(rig, dict) and rig.get("simulated") is True
            and plan.get("name") == load_plan(DEFAULTS / "demo_plan.toml").name
            and rig.get("name") == load_rig(DEFAULTS / "sim_rig.toml").name)


def _foreign(out: Path) -> list[str]:
    """What in ``out`` the demo did not write (relative names; a directory ends in /)."""
    found = []
    for p in sorted(out.iterdir()):
        if p.is_symlink():
            found.append(p.name + " (a link)")
        elif p.is_file() and p.name in RUN_FILES:
            continue
        elif p.is_dir() and p.name in ("steps", "report", "damaged"):
            pattern = {"steps": STEP_FILE, "report": REPORT_FILE}.get(p.name)
            for q in sorted(p.rglob("*") if p.name == "damaged" else p.iterdir()):
                ok = (q.is_dir() or (q.is_file() and STEP_FILE.fullmatch(q.name))) if p.name == "damaged" else \
                    (q.is_file() and not q.is_symlink() and pattern.fullmatch(q.name))
                if q.is_symlink() or not ok:
                    found.append(f"{q.relative_to(out)}{'/' if q.is_dir() else ''}")
        else:
            found.append(p.name + ("/" if p.is_dir() else ""))
    return found


def check_out_dir(out: Path) -> bool:
    """True if ``out`` holds an earlier demo run and nothing else, False if it is absent or
    empty; anything else raises :class:`ConfigurationError` naming what is there."""
    out = Path(out)
    if not out.exists() or (out.is_dir() and not any(p.name != LOCK_NAME for p in out.iterdir())):
        return False
    how = "bench demo --out: choose a new or empty directory, or remove"
    if not out.is_dir():
        raise ConfigurationError(f"{out}: not a directory; {how} it")
    try:
        meta = json.loads((out / "run.json").read_bytes())
    except (OSError, ValueError):
        meta = None
    if not is_demo_run(meta):
        raise ConfigurationError(f"{out} is not empty and holds no earlier demo run (no run.json of the demo plan "
                                 f"on the simulated rig); the demo deletes nothing else: {how} its contents")
    foreign = _foreign(out)
    if foreign:
        shown = ", ".join(foreign[:6]) + (f" (+{len(foreign) - 6} more)" if len(foreign) > 6 else "")
        raise ConfigurationError(f"{out} holds an earlier demo run and files the demo did not write ({shown}); "
                                 f"the demo deletes nothing it did not write: {how} them")
    return True


def clear_earlier_demo(out: Path) -> None:
    """Delete the earlier demo run in ``out`` (see :func:`check_out_dir`, which refuses
    anything else, deleting nothing); the session lock stays (its holder is the caller)."""
    if not check_out_dir(out):
        return
    for p in Path(out).iterdir():
        if p.name == LOCK_NAME:
            continue                      # held by this session
        if p.is_dir():
            shutil.rmtree(p)
        else:
            p.unlink()
