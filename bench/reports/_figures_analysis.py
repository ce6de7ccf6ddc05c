"""The analysis page's figures (`bench analyze`): measured vs base and final model per level,
hysteresis loops, residuals of the base model, the overview and the restoring force (moved
from :mod:`._figures`; the shared helpers are there)."""

from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from ._analysis import FRF_QUANTITIES, level_groups, relative_error
from ._figures import (
    DIRECTION_MARKER,
    level_colours,
)
from ._steps import phase_deg

MODEL_STYLE = {"base": dict(ls="--", lw=1.3), "final": dict(ls="-", lw=1.6)}
MODEL_COLOUR = {"base": "C1", "final": "C0"}
MODEL_LABEL = {"base": "base model (Masing)", "final": "final model (with the causes named)"}
FRF_LABEL = {"compliance": ("compliance |x/P|  (m/N)", "phase of x/P  (deg)"),
             "accelerance": ("accelerance |a/P|  (m/s^2 per N)", "phase of a/P  (deg)")}


def _group_levels(steps) -> dict[int, list]:
    groups = level_groups([s.level_N for s in steps]) if steps else []
    out: dict[int, list] = {}
    for g, s in zip(groups, steps):
        out.setdefault(int(g), []).append(s)
    return out


def _level_name(steps) -> str:
    return f"{np.median([s.level_N for s in steps]):.3g} N"


def _phase(values: np.ndarray, quantity: str) -> np.ndarray:
    if quantity == "compliance":        # spring 0, mass -180: no wrap in between
        return phase_deg(np.angle(values))
    return (np.degrees(np.angle(values)) + 90.0) % 360.0 - 90.0    # accelerance: mass 0, spring 180


def plot_analysis_frf(steps, quantity: str) -> Figure:
    """Magnitude and phase of one first-harmonic FRF against frequency, one row per force
    level: measured (markers), base model (dashed), final model (solid)."""
    groups = sorted(_group_levels(steps).values(), key=lambda g: np.median([s.level_N for s in g]))
    fig = Figure(figsize=(10, 1.0 + 2.4 * max(len(groups), 1)), layout="constrained")
    axes = fig.subplots(max(len(groups), 1), 2, sharex=True, squeeze=False)
    models_drawn = set()
    for (ax_mag, ax_ph), g in zip(axes, groups):
        for direction in sorted({s.direction for s in g}):
            run = sorted((s for s in g if s.direction == direction), key=lambda s: s.freq_Hz)
            f = np.array([s.freq_Hz for s in run])
            meas = np.array([s.get("measured", quantity) for s in run])
            style = dict(ls="none", marker=DIRECTION_MARKER.get(direction, "o"), mfc="none", mec="k", ms=6)
            ax_mag.plot(f, np.abs(meas), **style)
            ax_ph.plot(f, _phase(meas, quantity), **style)
            base = np.array([s.get("base", quantity) for s in run])
            for model in ("base", "final"):
                v = np.array([s.get(model, quantity) for s in run])
                if model == "final" and np.allclose(v, base, rtol=1e-9, atol=0, equal_nan=True):
                    continue        # no cause named: the final model is the base model
                if np.isfinite(v).any():
                    models_drawn.add(model)
                    ax_mag.plot(f, np.abs(v), color=MODEL_COLOUR[model], **MODEL_STYLE[model])
                    ax_ph.plot(f, _phase(v, quantity), color=MODEL_COLOUR[model], **MODEL_STYLE[model])
        mag_label, phase_label = FRF_LABEL[quantity]
        ax_mag.set(xscale="log", yscale="log", ylabel=mag_label)
        ax_ph.set(xscale="log", ylabel=phase_label)
        ax_mag.set_title(f"force level {_level_name(g)}", loc="left", fontsize=10)
        for ax in (ax_mag, ax_ph):
            ax.grid(True, which="both", alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("frequency (Hz)")
    handles = [Line2D([], [], color="k", marker="o", mfc="none", ls="none", label="measured")]
    handles += [Line2D([], [], color=MODEL_COLOUR[m], label=MODEL_LABEL[m], **MODEL_STYLE[m])
                for m in ("base", "final") if m in models_drawn]
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=9, frameon=False)
    fig.suptitle(f"{quantity.capitalize()}: measured and simulated, per force level")
    return fig


def plot_analysis_loops(loops) -> Figure:
    """Friction force against displacement over one period, measured vs the models."""
    cols = 2 if len(loops) == 4 else min(3, max(1, len(loops)))
    rows = math.ceil(len(loops) / cols) if loops else 1
    fig = Figure(figsize=(10, 3.6 * rows + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False).ravel())
    style = {"meas": dict(color="k", lw=2.2, label="measured (P - m a)"),
             "base": dict(color=MODEL_COLOUR["base"], label=MODEL_LABEL["base"], **MODEL_STYLE["base"]),
             "final": dict(color=MODEL_COLOUR["final"], label=MODEL_LABEL["final"], **MODEL_STYLE["final"])}
    drawn = set()
    for ax, loop in zip(axes, loops):
        x_um = 1e6 * loop.disp_m
        f = loop.friction_N
        for name in ("meas", "base", "final"):
            if name == "final" and "base" in f and "final" in f and np.allclose(f["final"], f["base"], rtol=1e-9,
                                                                                  atol=0):
                continue            # no cause named: the final model is the base model
            if name in f:
                drawn.add(name)
                ax.plot(np.append(x_um, x_um[:1]), np.append(f[name], f[name][:1]), **style[name])
        ax.set(xlabel="displacement (um)", ylabel="friction force (N)", title=loop.title)
        ax.grid(True, alpha=0.3)
    for ax in axes[len(loops):]:
        ax.set_axis_off()
    handles = [Line2D([], [], **style[n]) for n in ("meas", "base", "final") if n in drawn]
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=8, frameon=False)
    fig.suptitle("Hysteresis loops over one period: measured and modelled friction")
    return fig


def plot_analysis_residuals(steps) -> Figure:
    """Relative error of the base model's compliance and accelerance against frequency and
    force level, and its residual per harmonic."""
    fig = Figure(figsize=(10, 8), layout="constrained")
    top = fig.subfigures(2, 1, height_ratios=(1, 1))
    ax_f, ax_l = top[0].subplots(1, 2)
    ax_h = top[1].subplots()
    groups = _group_levels(steps)
    colours = level_colours([float(np.median([s.level_N for s in g])) for g in groups.values()] or [1.0])
    marker = {"compliance": "o", "accelerance": "s"}
    for g in groups.values():
        level = float(np.median([s.level_N for s in g]))
        for q in FRF_QUANTITIES:
            err = 100 * np.array([relative_error(s.get("base", q), s.get("measured", q)) for s in g])
            ax_f.plot([s.freq_Hz for s in g], err, ls="none", marker=marker[q], mfc="none" if q == "accelerance"
                      else colours[level], mec=colours[level], ms=5)
            ax_l.plot([s.level_N for s in g], err, ls="none", marker=marker[q],
                      mfc="none" if q == "accelerance" else colours[level], mec=colours[level], ms=5)
    for ax, xl in ((ax_f, "frequency (Hz)"), (ax_l, "force level (N)")):
        ax.set(xscale="log", yscale="log", xlabel=xl, ylabel="|base - measured| / |measured|  (%)")
        ax.grid(True, which="both", alpha=0.3)
    ax_f.set_title("base model error against frequency")
    ax_l.set_title("against force level")
    ax_f.legend(handles=[Line2D([], [], color="0.3", marker="o", ls="none", label="compliance"),
                         Line2D([], [], color="0.3", marker="s", mfc="none", ls="none", label="accelerance")],
                fontsize=8)
    ax_l.legend(handles=[Line2D([], [], color=c, marker="o", ls="none", label=f"{lv:.3g} N")
                         for lv, c in sorted(colours.items())], fontsize=8, title="force level", title_fontsize=8)
    K = max((s.residual_by_harmonic.size for s in steps), default=0)
    if K:
        R = np.full((len(steps), K), np.nan)
        for i, s in enumerate(steps):
            R[i, :s.residual_by_harmonic.size] = s.residual_by_harmonic
        k = np.arange(1, K + 1)
        level_of = {id(s): float(np.median([t.level_N for t in g])) for g in groups.values() for s in g}
        for i, s in enumerate(steps):
            ax_h.plot(k + 0.08 * (i / max(len(steps) - 1, 1) - 0.5), R[i], ls="none", marker=".", ms=4,
                      color=colours[level_of[id(s)]], alpha=0.6)
        with np.errstate(all="ignore"):
            ax_h.plot(k, np.nanmedian(R, axis=0), "k_-", ms=18, mew=2, lw=1, label="median over steps")
        positive = R[np.isfinite(R) & (R > 0)]
        if positive.size:
            ax_h.set_yscale("log")
        ax_h.set_xticks(k)
        ax_h.legend(fontsize=8)
    else:
        ax_h.text(0.5, 0.5, "no residual per harmonic in the analysis", ha="center", va="center",
                  transform=ax_h.transAxes)
    ax_h.set(xlabel="harmonic", ylabel="base model residual",
             title="base model residual per harmonic (dots: steps, coloured by level)")
    ax_h.grid(True, which="both", alpha=0.3)
    for ax in (ax_f, ax_l, ax_h):
        _plain_log_y(ax)
    fig.suptitle("Residuals of the base model")
    return fig


def _plain_log_y(ax) -> None:
    """Plain numbers (2, 5, 10, 0.01) on a log y axis of errors and residuals."""
    from matplotlib.ticker import FuncFormatter, NullFormatter
    if ax.yaxis.get_scale() != "log":
        return
    lo, hi = ax.get_ylim()
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:g}" if f"{v:e}"[0] in "25" else "")
                                 if lo > 0 and hi / lo < 100 else NullFormatter())


def plot_analysis_overview(steps) -> Figure:
    """One figure: compliance magnitude against frequency, every force level on one axis
    (colour by level): measured (markers), base model (dashed), extended model (solid)."""
    groups = sorted(_group_levels(steps).values(), key=lambda g: np.median([s.level_N for s in g]))
    fig = Figure(figsize=(8, 4.2), layout="constrained")
    ax = fig.subplots()
    colours = level_colours([float(np.median([s.level_N for s in g])) for g in groups])
    drawn = set()
    for g in groups:
        c = colours[float(np.median([s.level_N for s in g]))]
        run = sorted(g, key=lambda s: s.freq_Hz)
        f = np.array([s.freq_Hz for s in run])
        ax.plot(f, np.abs([s.get("measured", "compliance") for s in run]), ls="none", marker="o", mfc="none",
                mec=c, ms=5)
        base = np.array([s.get("base", "compliance") for s in run])
        for model in ("base", "final"):
            v = np.array([s.get(model, "compliance") for s in run])
            if model == "final" and np.allclose(v, base, rtol=1e-9, atol=0, equal_nan=True):
                continue
            if np.isfinite(v).any():
                drawn.add(model)
                ax.plot(f, np.abs(v), color=c, ls="--" if model == "base" else "-", lw=1.4)
    ax.set(xscale="log", yscale="log", xlabel="frequency (Hz)", ylabel="compliance |x/P|  (m/N)")
    ax.grid(True, which="both", alpha=0.3)
    handles = [Line2D([], [], color="k", marker="o", mfc="none", ls="none", label="measured")]
    handles += [Line2D([], [], color="k", ls="--" if m == "base" else "-",
                       label="base model (Masing)" if m == "base" else "extended model (causes named)")
                for m in ("base", "final") if m in drawn]
    handles += [Patch(color=c, label=f"{lv:.3g} N") for lv, c in colours.items()]
    ax.legend(handles=handles, fontsize=8, loc="best", frameon=False)
    ax.set_title("Compliance: measured, base model and extended model, all force levels", fontsize=10)
    return fig


def plot_restoring_force(rf) -> Figure:
    """The force the base model leaves out against displacement and velocity, coloured by
    force level: a stiffness term is a curve in x, a damping term a curve in v, an
    asymmetry shows as a shift between the two signs."""
    fig = Figure(figsize=(10, 4.0), layout="constrained")
    ax_x, ax_v = fig.subplots(1, 2, sharey=True)
    lv = rf.level_index
    levels = sorted(set(lv.tolist()))
    colours = level_colours([float(x) + 1.0 for x in levels])      # by level number 1, 2, ...
    for g in levels:
        sel = lv == g
        c = colours[float(g) + 1.0]
        ax_x.plot(1e6 * rf.x_m[sel], rf.force_N[sel], ls="none", marker=".", ms=2, color=c)
        ax_v.plot(1e3 * rf.v_m_s[sel], rf.force_N[sel], ls="none", marker=".", ms=2, color=c)
    ax_x.set(xlabel="displacement x  (um)", ylabel="force the base model leaves out  (N)")
    ax_v.set(xlabel="velocity v  (mm/s)")
    for ax in (ax_x, ax_v):
        ax.axhline(0, color="0.5", lw=0.8)
        ax.grid(True, alpha=0.3)
    ax_v.legend(handles=[Patch(color=colours[float(g) + 1.0], label=f"level {int(g) + 1}") for g in levels],
                fontsize=8, frameon=False)
    fig.suptitle("Restoring force: P - m a - F_Masing(x) of the base model, over one period of every step")
    return fig




def plot_friction_model_loops(loops: dict, preferred: str, labels: dict[str, str] | None = None) -> Figure:
    """Every fitted friction model's loop at every level against the measured one, one panel
    per level (``loops``: model -> its :class:`~._analysis.ModelLoop` s, level by level).  The
    measured loop is drawn with the preferred model's mass; each model's curve is its
    prediction of that P - m a (its friction, plus the inertia its own mass differs by), so
    every curve meets the measured one where that model fits.  The preferred model is the
    thick line."""
    labels = labels or {}
    ref = loops.get(preferred) or next(iter(loops.values()), [])
    cols = min(3, max(1, len(ref)))
    rows = math.ceil(len(ref) / cols) if ref else 1
    fig = Figure(figsize=(10, 3.6 * rows + 0.8), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False).ravel())
    handles = [Line2D([], [], color="k", lw=2.4, label="measured (P - m a)")]
    for ax, r in zip(axes, ref):
        x_um = 1e6 * np.append(r.disp_m, r.disp_m[:1])
        ax.plot(x_um, np.append(r.measured_N, r.measured_N[:1]), color="k", lw=2.4)
        ax.set(xlabel="displacement (um)", ylabel="friction force (N)", title=f"{r.key} ({r.level_N:.3g} N)")
        ax.grid(True, alpha=0.3)
    for j, (name, ls) in enumerate(loops.items()):
        best = name == preferred
        style = dict(color=f"C{j}", lw=1.8 if best else 1.1, ls="-" if best else "--")
        for ax, r in zip(axes, ref):
            own = next((q for q in ls if q.key == r.key and q.disp_m.shape == r.disp_m.shape), None)
            if own is None:
                continue
            y = own.model_N + (r.measured_N - own.measured_N)      # into the preferred model's mass
            ax.plot(1e6 * np.append(r.disp_m, r.disp_m[:1]), np.append(y, y[:1]), **style)
        handles.append(Line2D([], [], label=f"{labels.get(name, name)}{' (preferred)' if best else ''}", **style))
    for ax in axes[len(ref):]:
        ax.set_axis_off()
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 3), fontsize=8, frameon=False)
    fig.suptitle("Hysteresis loops of every fitted friction model against the measured loop")
    return fig
