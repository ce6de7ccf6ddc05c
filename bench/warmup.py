"""Compile the simulation kernels ahead of the first run (``bench warmup``, run by ``make setup``).

numba compiles a kernel on its first call and caches the machine code beside the source
(``sim/__pycache__``), so only the very first run on a machine pays for it (about 45 s on
two cores).  The warm-up pays it during set-up instead: it drives the plain plant and the
plant with every effect on, and runs a two-step plan through the twins with online
identification, so every kernel the bench calls is compiled and cached.  numba keys its
cache on the jitted function's own file only, so first the cache is cleared if any
``sim/*.py`` changed since it was built (:mod:`sim.kernel_cache`, a hash of the sources).
A stamp records the hash of the sources it compiled; :func:`kernels_warm` compares
against it, so a run can say "compiling the simulation kernels (first run only)" when the
cache will be rebuilt.
"""

from __future__ import annotations

import logging
import tempfile
import time
from enum import StrEnum
from pathlib import Path

import numpy as np

from sim.kernel_cache import invalidate_stale_kernels, sources_hash

from .terminal import PROJECT
from .words import say, terminal_run

log = logging.getLogger(__name__)


class WarmupLine(StrEnum):
    """The warm-up's words (:data:`bench.words.terminal_run.WARMUP`)."""

    SOURCE = "source"                       # the warm-up plan's name where a plan's file name goes
    ENDED = "ended"                         # status (a run that did not complete: an error)
    STAMP_UNWRITTEN = "stamp_unwritten"     # path, error


def _said(code: WarmupLine, **fields) -> str:
    return say(terminal_run.WARMUP, code, fields)

SIM_DIR = Path(__file__).resolve().parents[1] / "sim"
STAMP = SIM_DIR / "__pycache__" / "kernels.warm"

_PLAN = {"plan": {"name": "warm-up", "levels_N": [1.0],
                  "frequencies": {"list_Hz": [150.0, 200.0], "direction": "up"},
                  "control": {"settle_cycles": 2, "measure_cycles": 4, "ramp_s": 0.0,
                              "max_extra_settle_blocks": 0}}}


def kernels_warm() -> bool:
    """True when a warm-up compiled the present sim/ sources (the cache will load)."""
    try:
        return STAMP.read_text() == sources_hash(SIM_DIR)
    except OSError:
        return False


def warm_up() -> float:
    """Compile and cache every kernel; returns the seconds it took."""
    from sim.friction import MODELS
    from sim.friction.iwan import design_matrix
    from sim.rig import RigModel, SimulatedRig

    from .config import DEFAULTS, load_rig, parse_plan
    from .session import run_plan
    from .storage import RunStatus

    t0 = time.perf_counter()
    invalidate_stale_kernels(SIM_DIR)
    compiled = sources_hash(SIM_DIR)
    effects = dict(friction_alpha=0.1, friction_v_ref_m_per_s=1e-2, pitch_inertia_kg_m2=0.3,
                   pitch_stiffness_N_m_per_rad=3e5, cg_height_m=0.1, drive_height_m=0.2,
                   cubic_spring_N_per_m3=1e12)
    for model in (RigModel(), RigModel(**effects)):
        rig = SimulatedRig(model)
        rig.set_generator(freq_Hz=100.0, amplitude_Vpp=0.2, output_on=True)
        rig.run(256, 25600.0)
    path = 1e-6 * np.sin(np.linspace(0.0, 2 * np.pi, 64, endpoint=False))[None, :]
    for friction in MODELS.values():          # the analysis fits every friction model
        friction.periodic_force(friction.typical(), path, np.array([300.0]))
    design_matrix(path, np.array([1e-5]))      # the Iwan elements' linear fit (its own loop)
    # the warm-up's own two steps say what a user's run would of them (identifiability, an
    # unsettled step, poorly determined parameters): warnings about a plan nobody asked for,
    # printed before the user's run as if they were its; errors still pass
    # (the project's loggers only: a script's own warnings meanwhile still pass)
    loggers = [logging.getLogger(name) for name in PROJECT]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.ERROR)
    try:
        with tempfile.TemporaryDirectory(prefix="bench-warmup-") as tmp:
            store = run_plan(parse_plan(_PLAN, _said(WarmupLine.SOURCE)), load_rig(DEFAULTS / "sim_rig.toml"),
                             Path(tmp) / "run", identify=True)
            if store.metadata["status"] != RunStatus.COMPLETED:
                raise RuntimeError(_said(WarmupLine.ENDED, status=store.metadata["status"]))
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)
    try:
        STAMP.parent.mkdir(exist_ok=True)
        STAMP.write_text(compiled)
    except OSError as e:         # a read-only install: numba caches elsewhere or not at all
        log.warning(_said(WarmupLine.STAMP_UNWRITTEN, path=STAMP, error=e))
    return time.perf_counter() - t0
