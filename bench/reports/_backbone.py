"""The backbone of a phase-resonance run (decision record 0044): natural frequency and
damping ratio against amplitude, measured points over the rig model's backbone, and its
table.

The model's backbone (decision record 0054): on a simulated rig whose model has more than
the Masing carriage with a spring and a damper (the pitching mode, speed-dependent
friction, ...), the phase resonance of that full model's steady state at forces spanning
the run's (:func:`sim.rig_response.phase_backbone`, the procedure's phase criterion and
energy balance), and the chart says that the rig has a second mode; otherwise the Masing
loop's single-harmonic balance (sim.backbone)."""

from __future__ import annotations

import logging
import math
import textwrap

import numpy as np
from matplotlib.figure import Figure

from ..backbone import backbone_rows, model_backbone
from ..config import parse_rig, rig_toml

log = logging.getLogger(__name__)

MODEL_FORCES = 7               # forces of the full model's backbone line, spanning the run's


def _model(rig: dict, amplitudes: np.ndarray):
    try:
        r = parse_rig({"rig": rig_toml(rig)}, "run.json")
    except Exception:  # noqa: BLE001 - an old or damaged rig entry: no model curve, the points stay
        return None
    return model_backbone(r, amplitudes)


def full_model_line(rig: dict, rows: list[dict], results: list[dict]) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                              str] | None:
    """(amplitude, frequency, damping ratio, label) of the rig model's phase-resonance
    backbone when the run is on a simulated rig whose model the single-harmonic balance
    leaves something out of; None otherwise (the harmonic balance is that model)."""
    from procedures.plan import stored_model
    stored = stored_model(rig)
    if stored is None or not rows:
        return None
    from sim.modal import pitch_band_Hz
    from sim.rig_response import line_model, phase_backbone, single_mode
    model = line_model(stored)
    band = pitch_band_Hz(model)
    if single_mode(model):
        return None
    b0 = next((r.get("backbone") or {} for r in results if r.get("backbone")), {})
    response, mode = b0.get("response", "disp"), rows[0].get("mode", "feed")
    locked = [r for r in rows if r["locked"]]
    start = float(locked[0]["frequency_Hz"]) if locked else float(rows[0]["frequency_Hz"])
    forces = np.array([float(r["force_N"]) for r in (locked or rows) if float(r["force_N"]) > 0])
    if not forces.size:
        return None
    lo, hi = (band[0], math.inf) if band and mode == "pitch" else (0.0, band[0] if band else math.inf)
    pts = phase_backbone(model, np.geomspace(forces.min() / 1.5, forces.max() * 1.5, MODEL_FORCES), start,
                         response=response, mass_kg=float(rows[0]["mass_kg"]), lo_Hz=lo, hi_Hz=hi)
    pts = [p for p in pts if p.converged and math.isfinite(p.frequency_Hz)]
    if not pts:
        return None
    second = (f"; the rig has a second (pitching) mode, above {band[0]:.4g} Hz with the friction free, "
              "so the one-mode harmonic balance does not hold here" if band else "")
    label = (f"rig model: phase resonance of its steady state ({'+90 deg accel' if response == 'accel' else '-90 deg'}"
             f", every declared effect{second})")
    return (np.array([p.amplitude_m for p in pts]), np.array([p.frequency_Hz for p in pts]),
            np.array([p.damping_ratio for p in pts]), label)


def stepped_points(others, mode: str = "feed") -> list[dict]:
    """The modes of stepped-sine runs (``bench.reports._modes.RunModes``) as points of a
    backbone: each level's resonance with its 95 % interval and its damping ratio, at the
    amplitude of the fitted peak, |X1| = peak compliance x level for the feed mode (the
    compliance_pp of seed Eq. 9) and peak accelerance x level / w^2 for the pitching mode;
    a response-controlled run's, the displacement it held (an acceleration held / w^2)."""
    out = []
    for run in others:
        if run.kind != "stepped_sine":
            continue
        for e in run.modes:
            if e.mode != mode or e.status != "ok" or not np.isfinite(e.peak):
                continue
            w2 = (2 * np.pi * e.resonance_Hz) ** 2
            held = getattr(getattr(run, "level_quantity", None), "key", "force")
            if held == "disp":          # a response-controlled level is the amplitude it held
                amp = e.level_N
            elif held == "accel":
                amp = e.level_N / w2
            else:
                amp = e.peak * e.level_N if mode == "feed" else e.peak * e.level_N / w2
            out.append(dict(label=run.label, level_N=e.level_N, amplitude_m=amp, frequency_Hz=e.resonance_Hz,
                            frequency_low_Hz=e.resonance_low_Hz, frequency_high_Hz=e.resonance_high_Hz,
                            damping_ratio=e.damping_ratio, damping_ratio_low=e.damping_ratio_low,
                            damping_ratio_high=e.damping_ratio_high))
    return out


def plot_backbone(results: list[dict], rig: dict, title: str, others=()) -> Figure:
    """``others``: the modes of stepped-sine runs of the same rig (``bench report RUN --with
    OTHER``), drawn at their peaks' amplitudes with their 95 % intervals."""
    rows = backbone_rows(results)
    X = np.array([r["amplitude_m"] for r in rows])
    f = np.array([r["frequency_Hz"] for r in rows])
    z = np.array([r["damping_ratio"] for r in rows])
    ok = np.array([bool(r["locked"]) for r in rows], dtype=bool)
    fig = Figure(figsize=(10, 4.5), layout="constrained")
    ax1, ax2 = fig.subplots(1, 2)
    grid = np.geomspace(X[X > 0].min() / 3, X.max() * 3, 80) if np.any(X > 0) else np.array([])
    try:
        full = full_model_line(rig, rows, results)
    except Exception as e:  # noqa: BLE001 - the points come out without the model's line; say why
        log.warning("the rig model's backbone failed: %s", e)
        full = None
    model = _model(rig, grid) if grid.size and full is None else None
    if full is not None:
        Xm, fm, zm, label = full
        for ax, y in ((ax1, fm), (ax2, 100 * zm)):
            ax.plot(Xm, y, "-", color="0.5", label=textwrap.fill(label, 60))
    if model:
        label = "model: Masing loop, single-harmonic balance" + ("" if rig.get("simulated") else " (expected values)")
        ax1.plot(grid, [p.frequency_Hz for p in model], "-", color="0.5", label=label)
        ax2.plot(grid, [100 * p.damping_ratio for p in model], "-", color="0.5", label=label)
    for ax, y in ((ax1, f), (ax2, 100 * z)) if rows else ():
        ax.plot(X[ok], y[ok], "o", color="C0", label="locked")
        if np.any(~ok):
            ax.plot(X[~ok], y[~ok], "x", color="C3", ms=9, label="not locked")
        for xi, yi, r in zip(X, y, rows):
            ax.annotate(f"{r['level_N']:g} N", (xi, yi), textcoords="offset points", xytext=(4, 4), fontsize=7)
    mode = rows[0].get("mode", "feed") if rows else "feed"
    pts = stepped_points(others, "pitch" if mode == "pitch" else "feed")
    for i, label in enumerate(dict.fromkeys(p["label"] for p in pts)):
        mine = [p for p in pts if p["label"] == label]
        a = np.array([p["amplitude_m"] for p in mine])
        for ax, key, k in ((ax1, "frequency", 1.0), (ax2, "damping_ratio", 100.0)):
            v = np.array([p[f"{key}_Hz" if key == "frequency" else key] for p in mine]) * k
            lo = np.array([p[f"{key}_low_Hz" if key == "frequency" else f"{key}_low"] for p in mine]) * k
            hi = np.array([p[f"{key}_high_Hz" if key == "frequency" else f"{key}_high"] for p in mine]) * k
            err = np.nan_to_num(np.vstack([v - lo, hi - v]), nan=0.0)
            ax.errorbar(a, v, yerr=err, fmt="s", color=f"C{i + 1}", ms=5, capsize=3,
                        label=f"{'stepped sine, ' if rows else ''}{label} (peak per level, 95 %)")
    for ax in (ax1, ax2):
        ax.set_xscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    if not rows:             # the modes per level alone (an imported run): no phase resonance drawn
        ax1.set(xlabel="displacement amplitude |X1| (m)", ylabel="resonance (Hz)", title="backbone: resonance per level")
        ax2.set(xlabel="displacement amplitude |X1| (m)", ylabel="damping ratio (%)",
                title="damping ratio (single-mode fit)")
        fig.suptitle(f"Backbone: {title}")
        return fig
    ax1.set(xlabel="displacement amplitude |X1| (m)", ylabel="natural frequency (Hz)",
            title="backbone: frequency at phase resonance")
    ax2.set(xlabel="displacement amplitude |X1| (m)", ylabel="damping ratio (%)",
            title="damping ratio (energy balance)")
    fig.suptitle(f"Backbone (phase resonance): {title}")
    return fig


def backbone_md(results: list[dict]) -> list[str]:
    rows = backbone_rows(results)
    md = ["## Backbone (phase resonance)", "",
          "One point per force level: the frequency where the response's fundamental was held at the target "
          "phase, the displacement amplitude there and the damping ratio of the energy balance "
          "|F1| sin(-phase) / (2 m w^2 |X1|) with m the rig file's expected mass (also in `backbone.csv`).", "",
          "| level N | force N | amplitude m | frequency Hz | phase deg | damping % | locked | periods |",
          "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        md.append(f"| {r['level_N']:g} | {r['force_N']:.4g} | {r['amplitude_m']:.4g} | {r['frequency_Hz']:.5g} | "
                  f"{r['phase_deg']:.2f} | {100 * r['damping_ratio']:.3g} | "
                  f"{'yes' if r['locked'] else 'no: ' + r['why']} | {r['periods']} |")
    return md + [""]
