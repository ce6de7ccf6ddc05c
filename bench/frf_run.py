"""`bench import SOURCE --out RUN [--mapping MAP]`: measured frequency responses
(:mod:`bench.frf_import`) into a run directory every reader reads (decision record 0081).

The imported run is a plain run directory: its plan holds the levels (``levels_N``, in the
level kind's unit: a response-controlled source's plan is ``response_controlled``), the
union of the levels' frequencies and, as ``skip``, the (level, frequency) pairs a level
lacks; each point is a step whose result holds the fundamental only: the compliance X1/F1,
the accelerance -w^2 X1/F1, ``compliance_pp`` = |X1/F1| (no harmonics: half the fundamental's
peak-to-peak), the force amplitude (the source's force spectrum or column; else the level,
or the level over |X1/F1| at a held response), the response's amplitude, and for a held
response its ``response_control`` record.  The raw block of each step is empty (no time
record was imported).  run.json says where it came from::

    "origin": {"kind": "imported", "file": ..., "sha256": ..., "format": ..., "mapping": {...},
               "response": "disp" | "vel" | "accel", "level_kind": ..., "force": bool}

and its rig is the default rig's layout, not simulated, no instruments (``bench identify``
refuses an imported run before it reads it; ``bench analyze`` fits its fundamentals, decision 0084), ``expected_mass_kg`` the
mapping's ``mass_kg`` when given.  The energy balance's mass is ``origin.mass_kg``, used only
where the source holds the force beside the response (``origin.force``).  Nothing is written until every problem is known.
"""

from __future__ import annotations

import hashlib
import math
import os
import shutil
from dataclasses import replace
from enum import StrEnum
from pathlib import Path

import numpy as np

from procedures.kind import ProcedureKind

from .durable import _fsync_dir, deferred_sync
from .frf_import import IMPORTED, Imported, ImportProblem, _Problems, read_frfs
from .storage import RunStatus, RunStore
from .words import terminal_data as words

PERIOD_SAMPLES = 64       # the fundamental's period synthesized at 64 points (loop plots, bench compare)


class ImportLine(StrEnum):
    """What ``bench import`` prints (words: :data:`bench.words.terminal_data.IMPORT`)."""

    IMPORTED = "imported"           # path, out, levels, points, kind, response


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _fit(amplitude: float, phase: float) -> dict:
    """One channel's summary holding its fundamental only (no harmonics, no noise estimate)."""
    return {"amplitude": [float(amplitude)], "phase_rad": [float(phase)], "offset": 0.0, "thd": 0.0,
            "noise_rms": math.nan, "peak_to_peak": 2 * float(amplitude), "raw_peak_to_peak": math.nan}


def _channel(amplitude: float, phase: float) -> dict:
    """The ``harmonics`` record of one channel: its fundamental C_1 alone, the noise not known."""
    C = amplitude * np.exp(1j * phase)
    return {"re": [float(C.real)], "im": [float(C.imag)], "offset": 0.0, "noise_rms": math.nan, "sigma": math.nan}


def _steps(imp: Imported, freqs: list[float]) -> tuple[list[dict], list[list[int]]]:
    """Each point's step result, and the plan's ``skip``: the pairs a level lacks."""
    index = {f: i for i, f in enumerate(freqs)}
    results, skip = [], []
    n = len(freqs)
    from procedures.plan import StepSpec
    for li, lv in enumerate(imp.levels):
        have = {index[float(f)] for f in lv.f_Hz}
        skip += [[li, fi] for fi in range(n) if fi not in have]
        for k, (f, X) in enumerate(zip(lv.f_Hz, lv.H, strict=True)):
            f = float(f)
            w2 = (2 * math.pi * f) ** 2
            A = -w2 * X
            if lv.force_N is not None:
                F = float(lv.force_N[k])
            elif imp.level_kind == "force":
                F = lv.level
            else:
                F = lv.level / (abs(X) if imp.level_kind == "disp" else abs(A))
            fi = index[f]
            spec = StepSpec(li * n + fi, li, fi, "up", lv.level, f)
            r = {"key": spec.key, "index": spec.index, "level_index": li, "freq_index": fi, "direction": "up",
                 "freq_Hz": f, "target_force_N": lv.level if imp.level_kind == "force" else F, "force_N": F,
                 "force_error": F / lv.level - 1 if imp.level_kind == "force" else 0.0,
                 "force_converged": True, "control_iterations": 0, "drive_Vpp": math.nan,
                 "compliance_m_per_N": {"re": float(X.real), "im": float(X.imag)},
                 "compliance_abs_m_per_N": float(abs(X)), "compliance_phase_rad": float(np.angle(X)),
                 "accelerance_abs_kg_inv": float(abs(A)), "accelerance_phase_rad": float(np.angle(A)),
                 "compliance_pp_m_per_N": float(abs(X)),
                 "force": _fit(F, 0.0), "disp": _fit(abs(X) * F, np.angle(X)), "accel": _fit(abs(A) * F, np.angle(A)),
                 "fs_Hz": math.nan, "t0_s": 0.0, "block_id": 0, "resends": 0, "settle_extra_blocks": 0,
                 "quality": {"status": "usable", "reason": "", "notes": [], "freq_Hz": f, "level_N": lv.level,
                             "record_s": None, "artefacts": []},
                 "harmonics": {"freq_Hz": f, "fs_Hz": PERIOD_SAMPLES * f, "periods": 0, "samples": 0, "start": 0,
                               "drift_sigma": 0.0, "drift_detail": "",
                               "force": _channel(F, 0.0), "disp": _channel(abs(X) * F, np.angle(X)),
                               "accel": _channel(abs(A) * F, np.angle(A))}}
            if imp.level_kind != "force":
                held = abs(X) * F if imp.level_kind == "disp" else abs(A) * F
                r["response_control"] = {"quantity": imp.level_kind, "target": lv.level, "measured": held,
                                         "error": held / lv.level - 1}
            results.append(r)
    return results, skip


def _plan(imp: Imported, freqs: list[float], skip: list[list[int]]) -> dict:
    from .config import DEFAULTS, load_plan
    plan = load_plan(DEFAULTS / "demo_plan.toml")
    kind = ProcedureKind.STEPPED_SINE if imp.level_kind == "force" else ProcedureKind.RESPONSE_CONTROLLED
    plan = replace(plan, name=imp.path.name, levels_N=tuple(lv.level for lv in imp.levels), freqs_Hz=tuple(freqs),
                   direction="up", refine=False, dwell_cycles=0, adaptive_per_sweep=0, procedure=kind,
                   response="" if imp.level_kind == "force" else imp.level_kind, backbone=None, skip=())
    return dict(plan.to_dict(), skip=skip), plan


def _rig(imp: Imported) -> dict:
    from .config import DEFAULTS, load_rig
    rig = load_rig(DEFAULTS / "sim_rig.toml")
    rig = replace(rig, name=imp.path.name, notes=IMPORTED, simulated=False, model=None,
                  expected_mass_kg=imp.mass_kg if math.isfinite(imp.mass_kg) else rig.expected_mass_kg)
    return rig.to_dict()


def import_frfs(source: Path, out: Path, mapping: Path | None = None) -> tuple[Path, Imported]:
    """Read ``source`` and write the run directory ``out``; :class:`ConfigurationError` with
    every problem of the file, the mapping and the run directory, nothing written then."""
    source, out = Path(source), Path(out)
    imp = read_frfs(source, mapping)
    problems = _Problems()
    try:
        RunStore.check_new(out)
    except FileExistsError:
        problems.add(ImportProblem.OUT_NOT_NEW, path=out)
    freqs = sorted({float(f) for lv in imp.levels for f in lv.f_Hz})
    results, skip = _steps(imp, freqs)
    plan_dict, plan = _plan(imp, freqs, skip)
    from .accounting import stored_plan
    try:
        stored_plan({"plan": plan_dict}, out / "run.json")
    except Exception as e:  # noqa: BLE001 - the stored plan's validator names the key; the import says so
        problems.add(ImportProblem.PLAN_RANGE, path=source, detail=str(e))
    problems.raise_any()
    origin = {"kind": IMPORTED, "file": str(source.resolve()), "name": source.name, "sha256": _sha256(source),
              "format": imp.format, "mapping": imp.mapping, "mapping_file": str(mapping) if mapping else "",
              "response": imp.response, "level_kind": imp.level_kind,
              "force": all(lv.force_N is not None for lv in imp.levels),
              "mass_kg": imp.mass_kg if math.isfinite(imp.mass_kg) else None}
    # written whole into a hidden directory beside OUT, synced once, then renamed into place:
    # an import cut short leaves no half run directory (and 2 x 500 fsyncs cost seconds)
    staging = out.parent / f".{out.name}.importing-{os.getpid()}"
    shutil.rmtree(staging, ignore_errors=True)
    try:
        with deferred_sync():
            store = RunStore.create(staging, {"plan": plan_dict, "procedure": plan.describe(), "rig": _rig(imp),
                                              "versions": _versions(), "sim_seed": None,
                                              "identifiability_warnings": [], "origin": origin})
            empty = {"force_N": np.zeros(0), "accel_m_s2": np.zeros(0), "disp_m": np.zeros(0),
                     "fs_Hz": np.array(math.nan), "t0_s": np.array(0.0)}
            for r in results:
                store.write_step(r["key"], r, empty)      # type: ignore[arg-type]
            store.finish(RunStatus.COMPLETED, steps_done=len(results), steps_total=len(results))
        os.sync()
        os.replace(staging, out)                          # OUT absent or empty (checked above)
        _fsync_dir(out.parent)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out, imp


def _versions() -> dict:
    from .session import versions
    return versions()


def imported_line(out: Path, imp: Imported) -> str:
    return words.said(ImportLine.IMPORTED, path=imp.path, out=out, levels=len(imp.levels),
                      points=sum(lv.f_Hz.size for lv in imp.levels), kind=imp.level_kind, response=imp.response)
