"""Export a run directory to CSV and universal files (UFF dataset 58).  UFF 58 is read
back by one reader, :func:`bench.sources.load_source` (decision 0059).

    <out>/steps.csv      one row per step (columns: CSV_COLUMNS)
    <out>/frf.uff        dataset 58, function type 4 (FRF): complex compliance X1/F1 (m/N)
                         and accelerance A1/F1 ((m/s^2)/N) over frequency, one function of
                         each per force level and sweep direction (tag q=X / q=A)
    <out>/modes.csv      the modes per level, as `bench modes` writes them (bench.reports)
    <out>/modes.uff      dataset 55 (data at nodes, normal mode): one record per mode and
                         level with a value (bench.export_modes)
    <out>/time.uff       dataset 58, function type 1 (time response): force (N),
                         acceleration (m/s^2) and displacement (m) of every step's measured
                         block, abscissa spacing 1/fs

UFF header conventions (so :func:`bench.sources.load_source` finds each step's identity): ID lines 4
and 5 carry ``key=value`` tags (``bench`` marks our files), e.g.
``bench step=00002-L00-F002-up ch=disp level=1 dir=up`` and
``bench f=94.8683 fs=25614.441 t0=4.42517 harmonics=5`` (t0: block start, s; the time
abscissa starts at 0 at the block start);
record 6 uses node 1 / direction +X (the carriage in the feed direction) for response
and reference; record 8-10 specific data types: 17 time, 18 frequency, 13 excitation
force, 12 acceleration, 8 displacement.  ASCII UFF writes abscissa values with 6
significant digits (format E13.5); the exact frequency and sample rate are in the tags.
"""

from __future__ import annotations

import csv
import logging
import math
from enum import StrEnum
from pathlib import Path

import numpy as np

from procedures.kind import FORCE, QUANTITIES, ProcedureKind, of_stored_plan

from .frf_import import origin_of
from .storage import RunStore
from .words import terminal_data as words

log = logging.getLogger(__name__)


class ExportSaid(StrEnum):
    """``bench export``'s log lines and the ID lines of frf.uff and time.uff (words:
    :data:`bench.words.terminal_data.EXPORT`; modes.uff's: :class:`bench.export_modes.ModeId`)."""

    ONE_STEP = "one_step"                   # level, direction, key: a level with one readable step
    PHASE_RESONANCE = "phase_resonance"     # run: no FRF along frequency
    NO_FRF = "no_frf"                       # run: no level has two readable steps
    NO_STEPS = "no_steps_to_export"         # run
    ID_TOO_LONG = "id_too_long"             # line
    FRF_ID1 = "frf_id1"                     # kind ("X" or "A"), level, direction
    FRF_ID2 = "frf_id2"                     # plan, rig: their names
    FRF_ID5 = "frf_id5"                     # kind, quantity: the level's, labels
    TIME_ID1 = "time_id1"                   # channel, unit, key

CSV_COLUMNS = (
    "key", "index", "level_index", "target_force_N", "direction", "freq_Hz", "force_N",
    "compliance_re_m_per_N", "compliance_im_m_per_N", "compliance_abs_m_per_N", "compliance_phase_rad",
    "compliance_pp_m_per_N", "accelerance_abs_kg_inv", "accelerance_phase_rad",
    "thd_force", "thd_accel", "thd_disp", "noise_force_N", "noise_accel_m_s2", "noise_disp_m",
    "force_error", "control_iterations", "force_converged",
    # the level in its quantity's unit and that quantity's control error (decision 0052): a
    # response-controlled step's target_force_N / force_error are the force it needed / 0
    "level", "level_unit", "control_error")

# channel -> (specific data type of UFF 58 record 9, unit label, raw key in steps/<key>.npz)
CHANNELS = {"force": (13, "N", "force_N"), "accel": (12, "m/s^2", "accel_m_s2"), "disp": (8, "m", "disp_m")}
TAG = "bench"
FUNC_TIME, FUNC_FRF = 1, 4
SDT_TIME, SDT_FREQ = 17, 18
SDT_LABEL = {8: "displacement", 12: "acceleration", 13: "force"}


def step_row(r: dict) -> dict:
    """One step result flattened to the CSV columns."""
    return {
        "key": r["key"], "index": r["index"], "level_index": r["level_index"],
        "target_force_N": r["target_force_N"], "direction": r["direction"], "freq_Hz": r["freq_Hz"],
        "force_N": r["force_N"],
        "compliance_re_m_per_N": r["compliance_m_per_N"]["re"], "compliance_im_m_per_N": r["compliance_m_per_N"]["im"],
        "compliance_abs_m_per_N": r["compliance_abs_m_per_N"], "compliance_phase_rad": r["compliance_phase_rad"],
        "compliance_pp_m_per_N": r["compliance_pp_m_per_N"],
        "accelerance_abs_kg_inv": r["accelerance_abs_kg_inv"], "accelerance_phase_rad": r["accelerance_phase_rad"],
        "thd_force": r["force"]["thd"], "thd_accel": r["accel"]["thd"], "thd_disp": r["disp"]["thd"],
        "noise_force_N": r["force"]["noise_rms"], "noise_accel_m_s2": r["accel"]["noise_rms"],
        "noise_disp_m": r["disp"]["noise_rms"],
        "force_error": r["force_error"], "control_iterations": r["control_iterations"],
        "force_converged": int(bool(r["force_converged"])),
        **_level_of(r),
    }


def _level_of(r: dict) -> dict:
    """The level a step held in its quantity's unit (decision 0052): a response-controlled
    step's target response (m or m/s^2) and its control error, else the force level (N)."""
    rc = r.get("response_control")
    if isinstance(rc, dict) and "target" in rc:
        unit = QUANTITIES[rc["quantity"]].unit if rc.get("quantity") in QUANTITIES else "?"
        return {"level": rc["target"], "level_unit": unit, "control_error": rc.get("error", math.nan)}
    return {"level": r["target_force_N"], "level_unit": "N", "control_error": r["force_error"]}


def write_csv(results: list[dict], path: Path) -> Path:
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=CSV_COLUMNS)
        w.writeheader()
        for r in results:
            w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in step_row(r).items()})
    return path


# ---------------------------------------------------------------------------- UFF writing


def _tags(**kw) -> str:
    s = " ".join([TAG] + [f"{k}={v}" for k, v in kw.items()])
    if len(s) > 80:
        raise words.refused(ValueError, ExportSaid.ID_TOO_LONG, line=s)
    return s


def _id(text: str) -> str:
    return (text or "NONE")[:80]


def _dset58(*, func_type, func_id, x, data, id1, id2, id3, id4, id5, abscissa, ordinate, denominator=None):
    """A dataset-58 dict for pyuff (node 1, +X, single-point excitation)."""
    a_sdt, a_unit = abscissa
    o_sdt, o_unit = ordinate
    d = dict(type=58, func_type=func_type, func_id=func_id, id1=_id(id1), id2=_id(id2), id3=_id(id3), id4=_id(id4), id5=_id(id5),
             rsp_node=1, rsp_dir=1, ref_node=1, ref_dir=1, load_case_id=0,
             abscissa_spacing=1 if func_type == FUNC_TIME else 0,
             abscissa_spec_data_type=a_sdt, abscissa_axis_lab="time" if a_sdt == SDT_TIME else "frequency",
             abscissa_axis_units_lab=a_unit,
             ordinate_spec_data_type=o_sdt, ordinate_axis_units_lab=o_unit,
             ordinate_axis_lab=SDT_LABEL.get(o_sdt, "NONE"),
             x=np.asarray(x, dtype=float), data=np.asarray(data))
    den_sdt, den_unit = denominator or (0, "NONE")      # record 10 unused: data type 0
    d.update(orddenom_spec_data_type=den_sdt, orddenom_axis_units_lab=den_unit)
    return d


def frf_datasets(meta: dict, results: list[dict]) -> list[dict]:
    """One FRF (compliance X1/F1, m/N) per force level and sweep direction."""
    plan = meta.get("plan") or {}
    levels = plan.get("levels_N") or []
    q = of_stored_plan(plan)[1]
    groups: dict[tuple[int, str], list[dict]] = {}
    for r in results:
        groups.setdefault((r["level_index"], r["direction"]), []).append(r)
    out = []
    for (li, d), steps in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1] != "up")):
        steps = sorted(steps, key=lambda s: s["freq_Hz"])
        level = levels[li] if li < len(levels) else steps[0]["target_force_N"]
        if len(steps) < 2:        # an FRF record needs two abscissa values (pyuff, and the format)
            log.warning("%s", words.said(ExportSaid.ONE_STEP, level=q.format(level), direction=d, key=steps[0]["key"]))
            continue
        H = np.array([complex(s["compliance_m_per_N"]["re"], s["compliance_m_per_N"]["im"]) for s in steps])
        A = np.array([s["accelerance_abs_kg_inv"] * np.exp(1j * s["accelerance_phase_rad"]) for s in steps])
        unit_tag = {} if q == FORCE else {"unit": q.unit}
        for kind, data, sdt, unit in (("X", H, 8, "m"), ("A", A, 12, "m/s^2")):
            out.append(_dset58(
                func_type=FUNC_FRF, func_id=len(out) + 1, x=[s["freq_Hz"] for s in steps], data=data,
                id1=words.said(ExportSaid.FRF_ID1, kind=kind, level=q.format(level), direction=d),
                id2=words.said(ExportSaid.FRF_ID2, plan=plan.get("name", ""), rig=(meta.get("rig") or {}).get("name", ""),
                               origin=(origin_of(meta) or {}).get("name", "")),
                id3=str(meta.get("started", "")),
                id4=_tags(level=f"{level:g}", L=li, dir=d, n=len(steps), q=kind, **unit_tag),
                id5=words.said(ExportSaid.FRF_ID5, kind=kind, quantity=q.name, labels=meta.get("labels") or {}),
                abscissa=(SDT_FREQ, "Hz"), ordinate=(sdt, unit), denominator=(13, "N")))
    return out


def time_datasets(store: RunStore, meta: dict, results: list[dict]) -> list[dict]:
    """Force, acceleration and displacement of each step's measured block."""
    out = []
    for case, (r, raw) in enumerate(store.with_raw(results), start=1):
        fs = float(raw["fs_Hz"])
        t0 = float(raw["t0_s"])
        for ch, (sdt, unit, rk) in CHANNELS.items():
            x = raw[rk]
            out.append(_dset58(
                func_type=FUNC_TIME, func_id=len(out) + 1, x=np.arange(x.size) / fs, data=np.asarray(x, dtype=float),
                id1=words.said(ExportSaid.TIME_ID1, channel=ch, unit=unit, key=r["key"]),
                id2=f"{(meta.get('plan') or {}).get('name', '')}",
                id3=str(meta.get("started", "")),
                id4=_tags(step=r["key"], ch=ch, level=f"{r['target_force_N']:g}", dir=r["direction"]),
                id5=_tags(f=f"{r['freq_Hz']:.10g}", fs=f"{fs:.10g}", t0=f"{t0:.10g}",
                          harmonics=len(r[ch]["amplitude"])),
                abscissa=(SDT_TIME, "s"), ordinate=(sdt, unit)))
            out[-1]["load_case_id"] = case          # one load case per step (docs/uff58-input.md)
    return out


def _write_uff(path: Path, dsets: list[dict]) -> Path:
    import pyuff
    if path.exists():
        path.unlink()
    pyuff.UFF(str(path)).write_sets(dsets, mode="add")
    return path


def export_run(run_dir: Path, out_dir: Path | None = None, *, time_records: bool = True) -> list[Path]:
    """Write steps.csv, frf.uff and (unless ``time_records`` is False) time.uff into
    ``out_dir`` (default ``<run>/export``); returns the paths written."""
    store = RunStore.open(Path(run_dir))
    meta, results = store.metadata, store.results()
    out = Path(out_dir) if out_dir else store.path / "export"
    out.mkdir(parents=True, exist_ok=True)
    paths = [write_csv(results, out / "steps.csv")]
    if results:
        if of_stored_plan(meta.get("plan") or {})[0] is ProcedureKind.PHASE_RESONANCE:
            log.warning("%s", words.said(ExportSaid.PHASE_RESONANCE, run=run_dir))
        elif dsets := frf_datasets(meta, results):
            paths.append(_write_uff(out / "frf.uff", dsets))
        else:
            log.warning("%s", words.said(ExportSaid.NO_FRF, run=run_dir))
        from .export_modes import export_modes
        paths += export_modes(store.path, out, _write_uff)
        if time_records and origin_of(meta) is None:     # an imported run holds no time records
            paths.append(_write_uff(out / "time.uff", time_datasets(store, meta, results)))
    else:
        log.warning("%s", words.said(ExportSaid.NO_STEPS, run=run_dir))
    return paths
