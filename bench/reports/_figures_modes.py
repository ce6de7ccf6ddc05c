"""The modes' figures (`bench modes` and the run report): the seed's Figs. 13 and 17 from the
measured modes per level (moved from :mod:`._figures`; the shared helpers are there)."""

from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from procedures.kind import FORCE

RUN_COLOURS = ("C0", "C3", "C2", "C1", "C4", "C5", "C6", "C7", "C8", "C9")
EDGE_MARKER = {"below grid": "v", "above grid": "^"}


def _mode_points(ax, modes: list, colour, label: str, y, lo=None, hi=None, marker: str = "o") -> None:
    """One run's estimates of one mode against force: points with 95 % bars, lines joining
    consecutive levels found inside the grid only; a mode at the grid's edge is an open
    triangle at the edge frequency (y = None: not drawn), never joined."""
    ok = [e for e in modes if e.ok and math.isfinite(y(e))]
    F = np.array([e.level_N for e in ok])
    v = np.array([y(e) for e in ok])
    if ok:
        err = None
        if lo is not None and hi is not None:
            low, high = np.array([lo(e) for e in ok]), np.array([hi(e) for e in ok])
            err = np.vstack([np.clip(v - low, 0, None), np.clip(high - v, 0, None)])
            err = np.where(np.isfinite(err), err, 0.0)
        ax.errorbar(F, v, yerr=err, color=colour, marker=marker, ms=5, capsize=3, lw=0, elinewidth=1.2, label=label)
        levels = [e.level_N for e in modes]
        run: list[int] = []
        for k, e in enumerate(ok):       # join only levels that follow each other in the run
            if run and levels.index(e.level_N) != levels.index(ok[run[-1]].level_N) + 1:
                ax.plot(F[run], v[run], color=colour, lw=1.2)
                run = []
            run.append(k)
        if run:
            ax.plot(F[run], v[run], color=colour, lw=1.2)


MODEL_LINE_LABEL = ("rig model: its resonance per level, as measured\n(every declared effect and mode; "
                    "decision 0054)")


def _energy_balance_points(ax, modes: list, colour) -> bool:
    """The energy-balance damping ratios (per cent, 95 % bars) of one run's estimates of one
    mode (bench.reports._damping); True when any was drawn."""
    pts = [(e.level_N, eb) for e in modes if (eb := e.extra.get("energy_balance")) is not None
           and math.isfinite(eb.value)]
    if not pts:
        return False
    F = np.array([p[0] for p in pts])
    v = np.array([100 * p[1].value for p in pts])
    err = np.vstack([np.clip(v - [100 * p[1].low for p in pts], 0, None),
                     np.clip(np.array([100 * p[1].high for p in pts]) - v, 0, None)])
    ax.errorbar(F * 1.03, v, yerr=np.where(np.isfinite(err), err, 0.0), color=colour, marker="*", ms=7, capsize=2,
                lw=0, elinewidth=0.8)
    return True


def _run_marker(run) -> str:
    """A phase-resonance run's points (bench modes, decision 0044) are diamonds, a stepped sine's circles."""
    return "D" if getattr(run, "kind", "") == "phase_resonance" else "o"


def _pr_handle() -> Line2D:
    return Line2D([], [], color="0.3", marker="D", lw=0, label="phase resonance: locked point (no interval)")


def _edge_points(ax, modes: list, colour) -> bool:
    edge = [e for e in modes if e.status in EDGE_MARKER and math.isfinite(e.edge_Hz)]
    for e in edge:
        ax.plot([e.level_N], [e.edge_Hz], ls="none", marker=EDGE_MARKER[e.status], mfc="none", mec=colour, ms=9)
    return bool(edge)


def plot_fig13(runs: list) -> Figure:
    """Seed Fig. 13 from measurements: the feed mode's resonance frequency (the peak of
    compliance_pp) and the compliance at it against the force amplitude, per run."""
    fig = Figure(figsize=(11, 4.8), layout="constrained")
    ax1, ax2 = fig.subplots(1, 2)
    edge = model = pr = False
    for r, colour in zip(runs, RUN_COLOURS * 10):
        feed = [e for e in r.modes if e.mode == "feed"]
        mk = _run_marker(r)
        pr |= mk != "o"
        _mode_points(ax1, feed, colour, r.label, lambda e: e.resonance_Hz, lambda e: e.resonance_low_Hz,
                     lambda e: e.resonance_high_Hz, marker=mk)
        _mode_points(ax2, feed, colour, r.label, lambda e: e.peak, lambda e: e.peak_low, lambda e: e.peak_high,
                     marker=mk)
        edge |= _edge_points(ax1, feed, colour)
        pts = sorted((lv, v) for lv, v in r.model_feed.items() if math.isfinite(v[0]))
        if pts:
            model = True
            ax1.plot([p[0] for p in pts], [p[1][0] for p in pts], color=colour, ls="--", lw=1)
            peaks = [p for p in pts if math.isfinite(p[1][1])]     # a backbone's model has no peak value
            if peaks:
                ax2.plot([p[0] for p in peaks], [p[1][1] for p in peaks], color=colour, ls="--", lw=1)
    ax1.set(xscale="log", xlabel=level_axis(runs), ylabel="resonance frequency (Hz)",
            title="(a) feed mode: peak of compliance_pp")
    ax2.set(xscale="log", yscale="log", xlabel=level_axis(runs), ylabel="compliance_pp at the resonance (m/N)",
            title="(b) compliance at the resonance")
    extra = [Line2D([], [], color="0.3", marker="o", lw=0, label="measured, 95 % interval")]
    if pr:
        extra.append(_pr_handle())
    if model:
        extra.append(Line2D([], [], color="0.3", ls="--", label=MODEL_LINE_LABEL))
    if edge:
        extra.append(Line2D([], [], color="0.3", marker="v", mfc="none", ls="none",
                            label="no peak inside the grid:\nat or beyond this edge"))
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
    h, _ = ax1.get_legend_handles_labels()
    ax1.legend(handles=h + extra, fontsize=8)
    fig.suptitle("Seed Fig. 13 from measurements: the feed mode against force")
    return fig


def level_axis(runs: list) -> str:
    """The x label of a figure against the runs' levels: their quantity and unit; runs of
    different quantities (a force and a response-controlled run) each named with theirs."""
    qs = list(dict.fromkeys(getattr(r, "level_quantity", FORCE) for r in runs)) or [FORCE]
    if len(qs) == 1:
        return f"{qs[0].name} amplitude ({qs[0].unit})"
    return "level: " + ", ".join(f"{q.name} ({q.unit})" for q in qs) + " (one axis, see each run's label)"


def plot_fig17(runs: list, title: str = "") -> Figure:
    """Seed Fig. 17 (and 15) from measurements: each mode's resonance frequency and
    damping ratio against the force amplitude, per run (one colour each)."""
    fig = Figure(figsize=(11, 8), layout="constrained")
    axes = fig.subplots(2, 2)
    edge = model = band = hp = pr = eb = False
    for r, colour in zip(runs, RUN_COLOURS * 10):
        mk = _run_marker(r)
        pr |= mk != "o"
        for row, mode in enumerate(("feed", "pitch")):
            ms = [e for e in r.modes if e.mode == mode]
            a_f, a_z = axes[row]
            _mode_points(a_f, ms, colour, r.label, lambda e: e.resonance_Hz, lambda e: e.resonance_low_Hz,
                         lambda e: e.resonance_high_Hz, marker=mk)
            _mode_points(a_z, ms, colour, r.label, lambda e: 100 * e.damping_ratio,
                         lambda e: 100 * e.damping_ratio_low, lambda e: 100 * e.damping_ratio_high, marker=mk)
            okz = [e for e in ms if e.ok and math.isfinite(e.half_power_damping_ratio)]
            if okz:
                hp = True
                a_z.plot([e.level_N for e in okz], [100 * e.half_power_damping_ratio for e in okz], ls="none",
                         marker="s", mfc="none", mec=colour, ms=6)
            eb |= _energy_balance_points(a_z, ms, colour)
            edge |= _edge_points(a_f, ms, colour)
        for row, peaks in ((0, r.model_feed), (1, getattr(r, "model_pitch", {}))):
            pts = sorted((lv, v[0]) for lv, v in peaks.items() if math.isfinite(v[0]))
            if pts:
                model = True
                axes[row][0].plot([p[0] for p in pts], [p[1] for p in pts], color=colour, ls="--", lw=1)
        if r.pitch_band and not getattr(r, "model_pitch", None):
            band = True
            axes[1][0].axhline(r.pitch_band[0], color=colour, ls=":", lw=1)
    titles = (("(a) feed mode: resonance (peak of compliance_pp)", "(b) feed mode: damping ratio"),
              ("(c) pitching mode: resonance (peak of |A1/F1|)", "(d) pitching mode: damping ratio"))
    for row in range(2):
        for col in range(2):
            ax = axes[row][col]
            ax.set(xscale="log", xlabel=level_axis(runs), title=titles[row][col],
                   ylabel="resonance frequency (Hz)" if col == 0 else "damping ratio (%)")
            ax.grid(True, which="both", alpha=0.3)
    extra = [Line2D([], [], color="0.3", marker="o", lw=0,
                    label="measured: single-mode fit, 95 % interval\n(damping: the fit's zeta)")]
    if pr:
        extra.append(_pr_handle())
    if eb:
        extra.append(Line2D([], [], color="0.3", marker="*", lw=0, label="damping: energy balance at resonance,\n"
                            "|F1| sin(-phase) / (2 m w^2 |X1|), 95 %\n(pitch: m the model's modal mass)"))
    if hp:
        extra.append(Line2D([], [], color="0.3", marker="s", mfc="none", ls="none",
                            label="damping: half-power bandwidth"))
    if model:
        extra.append(Line2D([], [], color="0.3", ls="--", label=MODEL_LINE_LABEL))
    if band:
        extra.append(Line2D([], [], color="0.3", ls=":", label="rig model: pitching mode with the friction free\n(its large-force limit; friction raises it)"))
    if edge:
        extra.append(Line2D([], [], color="0.3", marker="v", mfc="none", ls="none",
                            label="no peak inside the grid:\nat or beyond this edge"))
    h, _ = axes[0][0].get_legend_handles_labels()
    axes[0][0].legend(handles=h + extra, fontsize=7)
    fig.suptitle(title or "Seed Fig. 17 from measurements: each mode's resonance and damping against force")
    return fig
