"""`bench modes RUN [RUN ...] --out DIR` and the run report's modes: each run's modes per force level (sim.modal,
decision record 0043) in one ``modes.csv`` and the seed's Figs. 13 and 17 from the
measurements, one colour per run with its label, 95 % intervals as bars, the rig model's
prediction as lines (simulated rigs).

The rig model's prediction (decision record 0054) is the resonance of the same model the
report's model lines and the identification use (:mod:`sim.rig_response`: every declared
effect and the pitching mode), by the measurement's definitions: the feed mode the peak of
compliance_pp, the pitching mode the peak of |A1/F1|, each refined by golden-section search
on steady states.  A peak at the edge of the model's grid is no value ("at or beyond"),
never joined into the line.  A plain Masing rig's feed peak comes from the shooting engine.
"""

from __future__ import annotations

import csv
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from procedures.kind import FORCE, Quantity, of_stored_plan
from sim.modal import LevelData, ModeEstimate, pitch_band_Hz, track_modes
from sim.modal_flat import mark_overdamped
from sim.plant_effects import pitch_on

from ..storage import RunStore
from ._damping import DAMPING_COLUMNS, add_damping, damping_row
from ._earned import earned_pitch
from ._held import comparison_of
from ._model import ModelComparison
from ._refinement import mark_refinement

log = logging.getLogger(__name__)

# a run's levels are amplitudes of its procedure's quantity (decision 0052): `level` in
# `level_unit` (N, m, m/s^2); `level_N` stays for the readers of force levels and is empty
# for a level that is not a force (before, it held a response level's metres); damping
# ratios as fractions, each named by its definition (decision 0056)
COLUMNS = ("run", "label", "mode", "level", "level_unit", "level_N", "status", "curve", "resonance_Hz", "resonance_low_Hz",
           "resonance_high_Hz", *DAMPING_COLUMNS, "peak_compliance_m_per_N", "peak_accelerance_per_kg", "n_points",
           "model_resonance_Hz", "model_note", "note")


@dataclass
class RunModes:
    """One run's modes, with what the figures need."""

    path: Path
    label: str
    modes: list[ModeEstimate]
    model_feed: dict[float, tuple[float, float, str]] = field(default_factory=dict)   # level -> (Hz, m/N, note)
    pitch_band: tuple[float, float] | None = None
    kind: str = "stepped_sine"      # or "phase_resonance": one point per level, drawn with its own marker
    model_pitch: dict[float, tuple[float, float, str]] = field(default_factory=dict)  # level -> (Hz, 1/kg, note)
    level_quantity: Quantity = FORCE   # what the levels are amplitudes of (a response-controlled run: m or m/s^2)
    refinement: dict = field(default_factory=dict)   # (level_N, mode) -> how its refinement ended (_refinement)

    def rows(self) -> list[dict]:
        out = []
        for e in self.modes:
            mf = (self.model_feed if e.mode == "feed" else self.model_pitch).get(e.level_N)
            pk_c = e.peak if e.mode == "feed" else e.extra.get("compliance_pp", math.nan)
            pk_a = e.peak if e.mode == "pitch" else e.extra.get("accelerance", math.nan)
            q = self.level_quantity
            out.append(dict(run=str(self.path), label=self.label, mode=e.mode, level=e.level_N, level_unit=q.unit,
                            level_N=e.level_N if q == FORCE else math.nan, status=e.status,
                            curve=e.curve, resonance_Hz=e.resonance_Hz, resonance_low_Hz=e.resonance_low_Hz,
                            resonance_high_Hz=e.resonance_high_Hz, **damping_row(e), peak_compliance_m_per_N=pk_c,
                            peak_accelerance_per_kg=pk_a, n_points=e.n_points,
                            model_resonance_Hz=mf[0] if mf else math.nan,
                            model_note=mf[2] if mf else (f"model: above {self.pitch_band[0]:.4g} Hz (friction free)"
                                                         if e.mode == "pitch" and self.pitch_band else ""),
                            note=e.note))
        return out


def run_label(meta: dict, path: Path) -> str:
    """The run's label for legends: its ``labels`` (bench run --label k=v) or its directory's name."""
    labels = meta.get("labels") or {}
    label = ", ".join(f"{k}={v}" for k, v in labels.items()) if labels else Path(path).name
    origin = meta.get("origin")
    if isinstance(origin, dict) and origin.get("kind") == "imported":     # never passed off as a bench measurement
        label += f" (imported from {origin.get('name', '?')})"
    return label


def model_peaks(cmp: ModelComparison | None) -> tuple[dict, dict]:
    """(feed, pitch): level -> (frequency, peak value, note) of the rig model's resonances
    from the report's model comparison (simulated rigs with a stored model; empty
    otherwise).  On the compiled plant (:mod:`sim.rig_response`) the feed mode is the peak
    of compliance_pp below 0.8 x the pitching mode's friction-free frequency, the pitching
    mode the peak of |A1/F1| above it; on the shooting engine the feed peak of
    :func:`model_feed_peaks`."""
    if cmp is None:
        return {}, {}
    if not cmp.responses:
        return model_feed_peaks(cmp), {}
    from sim.rig_response import mode_split_Hz, resonance_Hz
    model = cmp.model
    split = mode_split_Hz(model)
    band = math.isfinite(split)
    feed, pitch = {}, {}
    for level, resp in cmp.responses.items():
        try:
            f, v, note = resonance_Hz(resp, model, "compliance_pp", below_Hz=split)
            feed[level] = (f, v, note)
            if band:
                f, v, note = resonance_Hz(resp, model, "accelerance", above_Hz=split)
                pitch[level] = (f, v, note)
        except Exception as e:  # noqa: BLE001 - the measured modes come out without the model's
            log.warning("model resonance at %g N failed: %s", level, e)
            feed.setdefault(level, (math.nan, math.nan, f"model failed: {e}"))
    return feed, pitch


def model_feed_peaks(cmp: ModelComparison | None) -> dict[float, tuple[float, float, str]]:
    """Level -> (frequency, compliance_pp, note) of the shooting engine's feed peak, from the
    report's model comparison: the curve's maximum refined by a parabola in log-log; a
    maximum at the engine grid's edge is NaN, noted."""
    if cmp is None:
        return {}
    out = {}
    for level, (f, c, _) in cmp.curves.items():
        ok = np.isfinite(c)
        if not ok.any():
            out[level] = (math.nan, math.nan, "no model value")
            continue
        i = int(np.nanargmax(np.where(ok, c, -np.inf)))
        if i in (0, f.size - 1) or not np.all(ok[i - 1:i + 2]):
            out[level] = (math.nan, math.nan, f"model peak at or beyond the edge of its grid, {f[i]:.4g} Hz")
            continue
        x, y = np.log(f[i - 1:i + 2]), np.log(c[i - 1:i + 2])
        a, b, cc = np.polyfit(x, y, 2)
        xv = -b / (2 * a) if a < 0 else x[1]
        out[level] = (float(math.exp(xv)), float(math.exp(a * xv * xv + b * xv + cc)), "")
    return out


BACKBONE_NOTE = ("phase resonance: one locked point, no interval (the frequency is where the loop held the "
                 "phase, the damping ratio the energy balance of one block)")


def backbone_modes(results: list[dict]) -> list[ModeEstimate]:
    """One estimate per point of a phase-resonance run (decision record 0044): its
    mode, the locked frequency as the resonance and the energy balance's damping ratio; a
    point that did not lock is "not locked" (no value). No intervals: one point at one
    frequency has no fit whose spread would give them."""
    out = []
    for r in sorted(results, key=lambda r: r["index"]):
        b = r.get("backbone")
        if not b:
            continue
        level = float(r["target_force_N"])
        if b["locked"]:
            out.append(ModeEstimate(b["mode"], level, "ok", f"phase resonance ({b['response']})",
                                    resonance_Hz=float(b["frequency_Hz"]), damping_ratio=float(b["damping_ratio"]),
                                    n_points=1, note=BACKBONE_NOTE, phase_resonance=True))
        else:
            out.append(ModeEstimate(b["mode"], level, "not locked", f"phase resonance ({b['response']})",
                                    n_points=1, note=f"phase resonance: not locked ({b['why']})",
                                    phase_resonance=True))
    return out


def backbone_model(meta: dict, results: list[dict]) -> tuple[dict, dict]:
    """(feed, other modes): level -> (frequency, nan, note) of the rig model's phase
    resonance at each locked point's force, searched from its measured frequency
    (:func:`sim.rig_response.phase_point`: the one model, the line backbone.png draws);
    empty unless the rig is simulated with a stored model."""
    rig = meta.get("rig") or {}
    feed: dict[float, tuple[float, float, str]] = {}
    other: dict[float, tuple[float, float, str]] = {}
    if not (rig.get("simulated") and rig.get("model")):
        return feed, other
    from sim.rig_response import phase_point
    for r in results:
        b = r.get("backbone")
        if not b or not b["locked"]:
            continue
        level = float(r["target_force_N"])
        p = phase_point(rig["model"], level, float(b["frequency_Hz"]), response=b["response"], mass_kg=b["mass_kg"])
        (feed if b["mode"] == "feed" else other)[level] = (
            p.frequency_Hz, math.nan, "model: the rig model's phase resonance at the level" if p.converged
            else "model: no phase resonance near the locked frequency")
    return feed, other


def modes_of(path: Path, meta: dict, results: list[dict], cmp: ModelComparison | None) -> RunModes:
    """The modes of a run's stored steps (every level; tracked as sim.modal.track_modes
    does, the feed mode by the model's peak when ``cmp`` has one); a phase-resonance run's
    are its locked points (:func:`backbone_modes`), beside the model's phase resonance
    when ``cmp`` is given (:func:`backbone_model`)."""
    if any(r.get("backbone") for r in results):
        run = RunModes(Path(path), run_label(meta, path), backbone_modes(results), kind="phase_resonance")
        if cmp is not None:         # the model asked for: its phase resonance beside each point
            run.model_feed, run.model_pitch = backbone_model(meta, results)
        return run
    plan, rig = meta.get("plan") or {}, meta.get("rig") or {}
    level = of_stored_plan(plan)[1]
    levels_N = plan.get("levels_N") or sorted({r["target_force_N"] for r in results})
    by_level: dict[int, list[dict]] = {}
    for r in results:
        by_level.setdefault(r["level_index"], []).append(r)
    data = [LevelData.from_steps(float(levels_N[li]) if li < len(levels_N) else steps[0]["target_force_N"], steps)
            for li, steps in sorted(by_level.items()) if len(steps) >= 3]
    feed_model, pitch_model = model_peaks(cmp)
    from procedures.plan import stored_model
    model = stored_model(rig)
    band = pitch_band_Hz(model) if model else None
    pred = {lv: v[0] for lv, v in feed_model.items()}
    model_without_pitch = model is not None and band is None and not pitch_on(model)
    modes = track_modes(data, feed_predicted_Hz=pred, pitch=not model_without_pitch, pitch_band_Hz=band)
    if band is None and model is None:
        modes = earned_pitch(modes, data)                  # no model: a second peak must earn its place
    if band is None and not any(e.mode == "pitch" and e.ok for e in modes):
        modes = [e for e in modes if e.mode != "pitch"]    # no pitching mode in the data nor the model
    data_at = {d.level_N: d for d in data}
    for e in modes:                                        # a plateau is not a point (decision 0056)
        if e.level_N in data_at:
            d = data_at[e.level_N]
            mark_overdamped(e, d.f_Hz, d.compliance_pp if e.mode == "feed" else np.abs(d.accelerance))
    add_damping(modes, results, meta, [float(x) for x in levels_N])
    refinement = mark_refinement(modes, meta, results, data, levels_N, band)
    return RunModes(Path(path), run_label(meta, path), modes, feed_model, band, model_pitch=pitch_model,
                    level_quantity=level, refinement=refinement)


def run_modes(path: Path, *, model: bool = True) -> RunModes:
    """The modes of a run directory (with the rig model's prediction when ``model`` and
    the rig is simulated with a stored model)."""
    store = RunStore.open(Path(path))
    meta, results = store.metadata, store.results()
    cmp = None
    if any(r.get("backbone") for r in results):
        run = modes_of(Path(path), meta, results, None)
        if model:
            try:
                run.model_feed, run.model_pitch = backbone_model(meta, results)
            except Exception as e:  # noqa: BLE001 - the measured points come out without the model
                log.warning("model phase resonance failed: %s", e)
        return run
    if model:
        try:
            cmp = comparison_of(meta, results)
        except Exception as e:  # noqa: BLE001 - the measured modes come out without the model
            log.warning("model prediction failed: %s", e)
    return modes_of(Path(path), meta, results, cmp)


def write_csv(runs: list[RunModes], path: Path) -> Path:
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        for r in runs:
            for row in r.rows():
                w.writerow({k: ("" if k == "level_N" and math.isnan(v) else f"{v:.6g}" if isinstance(v, float) else v)
                            for k, v in row.items()})
    return path


def write_modes(sources: list[Path], out: Path, *, model: bool = True) -> tuple[list[RunModes], list[Path]]:
    """modes.csv, fig13_feed.png and fig17_modes.png of ``sources`` into ``out``."""
    from . import _figures as figures
    from . import _figures_modes as mode_figures
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    runs = [run_modes(p, model=model) for p in sources]
    files = [write_csv(runs, out / "modes.csv")]
    figures.save_png(mode_figures.plot_fig13(runs), out / "fig13_feed.png")
    figures.save_png(mode_figures.plot_fig17(runs), out / "fig17_modes.png")
    files += [out / "fig13_feed.png", out / "fig17_modes.png"]
    return runs, files
