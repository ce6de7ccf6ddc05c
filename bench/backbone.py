"""A phase-resonance run on the session's supervised instruments, and its backbone.csv.

Each backbone point is stored as the level's step (``steps/<key>.json`` + ``.npz``, written
atomically, with a ``backbone`` record: decision record 0044), so resume, accounting,
export and damage checks work as for a stepped sine; ``backbone.csv`` is rewritten
(atomically) from the stored steps after each point.
"""

from __future__ import annotations

import csv
import io
import logging
from enum import StrEnum
from pathlib import Path

from procedures.factory import procedure_for
from procedures.plan import GUESS_KEYS, Plan, StepSpec
from sim.backbone import backbone_point
from sim.step_result import StepResult

from .config import Rig
from .storage import RunStore, atomic_write
from .words.terminal_config import line

log = logging.getLogger(__name__)

COLUMNS = ("mode", "level_N", "force_N", "amplitude_m", "frequency_Hz", "phase_deg", "phase_error_deg",
           "damping_ratio", "locked", "periods", "mass_kg", "why")


def backbone_rows(results: list[StepResult]) -> list[dict]:
    """One row per stored backbone point, in level order."""
    rows = []
    for r in sorted(results, key=lambda r: r["index"]):
        b = r.get("backbone")
        if not b:
            continue
        rows.append({"mode": b["mode"], "level_N": r["target_force_N"], "force_N": r["force_N"],
                     "amplitude_m": b["amplitude_m"], "frequency_Hz": b["frequency_Hz"], "phase_deg": b["phase_deg"],
                     "phase_error_deg": b["phase_error_deg"], "damping_ratio": b["damping_ratio"],
                     "locked": b["locked"], "periods": b["periods"], "mass_kg": b["mass_kg"], "why": b["why"]})
    return rows


def write_backbone_csv(store: RunStore) -> Path:
    """``backbone.csv`` in the run directory from its stored points (atomic)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, COLUMNS, lineterminator="\n")
    w.writeheader()
    for row in backbone_rows(store.results(warn=False)):
        w.writerow({k: (f"{v:.9g}" if isinstance(v, float) else str(v).lower() if isinstance(v, bool) else v)
                    for k, v in row.items()})
    path = store.path / "backbone.csv"
    text = buf.getvalue().encode()
    atomic_write(path, lambda fh: fh.write(text))
    return path


def model_backbone(rig: Rig, amplitudes_m) -> list:
    """The single-harmonic-balance backbone of the rig's model (simulated rigs; the
    expected parameters otherwise) at the given amplitudes."""
    m = rig.model
    p = {k: getattr(m, k) for k in GUESS_KEYS} if m else rig.guess()
    linear = dict(spring_N_per_m=m.spring_N_per_m, viscous_N_s_per_m=m.viscous_N_s_per_m) if m else {}
    return [backbone_point(X, p["mass_kg"], p["F_s_N"], p["x_s_m"], p["n"], **linear) for X in amplitudes_m]


class BackboneLine(StrEnum):
    """What a phase-resonance run says of its lock (its words: bench.words.terminal_config.LOG)."""

    LOCKING = "locking"     # level_N, freq_Hz, phase_error_deg, periods (settled in the band)


def run_backbone(plan: Plan, rig: Rig, store: RunStore, gen, daq, sensor_check, *, marker, drive_limit_V: float,
                 noise_floor_m: float, progress=None) -> None:
    """The phase-resonance test: each point stored as it completes, backbone.csv after each."""
    total = len(plan.schedule())

    def on_block(state: dict) -> None:
        store.event("lock_block", level_N=state["level_N"], freq_Hz=state["freq_Hz"],   # the watch page's lock panel
                    phase_error_deg=state["phase_error_deg"], amplitude=state["amplitude"],
                    response=plan.backbone.response, force_N=state["force_N"],
                    settled_periods=state["settled_periods"])
        if progress:
            progress(len(store.done_keys()), total,
                     line(BackboneLine.LOCKING, level_N=state["level_N"], freq_Hz=state["freq_Hz"],
                          phase_error_deg=state["phase_error_deg"], periods=state["settled_periods"]))

    proc = procedure_for(plan, gen, daq, amp_gain_N_per_V=rig.amp_gain_N_per_V, mass_kg=rig.expected_mass_kg,
                         sensor_check=sensor_check, marker=marker, drive_limit_V=drive_limit_V,
                         on_event=store.event, on_block=on_block)
    proc.preload(store.results())
    proc.disp_noise_floor_m = noise_floor_m
    if progress and hasattr(progress, "restart"):
        progress.restart(len(store.done_keys()))

    def record(step: StepSpec, res: StepResult, raw: dict) -> None:
        store.write_step(step.key, res, raw)
        b = res["backbone"]
        store.event("backbone_point", key=step.key, level_N=step.force_N, freq_Hz=b["frequency_Hz"],
                    amplitude_m=b["amplitude_m"], phase_error_deg=b["phase_error_deg"],
                    damping_ratio=b["damping_ratio"], locked=b["locked"],
                    periods=b["periods"])
        write_backbone_csv(store)

    proc.run(store.done_keys(), record, progress)
    write_backbone_csv(store)
