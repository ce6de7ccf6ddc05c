"""Figures (matplotlib ``Figure`` objects with the Agg canvas, never pyplot's global state).

Run report: compliance, accelerance, signal quality, modes vs force, model vs
measurement (simulated rig), online identification.  Analysis page: measured vs base and
final model per force level, hysteresis loops, residuals of the base model.  Each function
takes prepared data and returns a Figure; :func:`save_png` writes one, :func:`png_bytes`
gives the bytes to embed.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from procedures.kind import FORCE, Quantity

from ._analysis import FRF_QUANTITIES, level_groups, relative_error
from ._identification import ID_PARAMS, IdentificationData, finite, steps_of
from ._model import ModelComparison
from ._steps import UNSETTLED_RESIDUAL, control_error, phase_deg, residual_ratio

DIRECTION_STYLE = {"up": "-", "down": "--"}
DIRECTION_MARKER = {"up": "o", "down": "v"}
ID_LOG_SPAN = 2.0       # log axes show at most the final value /2 .. x2; estimates beyond are drawn at the edge
ID_LIN_SPAN = 0.3       # linear axes (n): at most the final value +- max(0.3, 20 %)


# ---------------------------------------------------------------------------- shared


def level_colours(levels: list[float]) -> dict[float, tuple]:
    from matplotlib import colormaps
    cmap = colormaps["viridis"]
    lv = sorted(levels)
    if len(lv) == 1:
        return {lv[0]: cmap(0.2)}
    lo, hi = math.log(lv[0]), math.log(lv[-1])
    return {v: cmap(0.9 * (math.log(v) - lo) / (hi - lo)) for v in lv}


def _legend(ax, colours: dict[float, tuple], directions: set[str], extra: list = (), level: Quantity = FORCE) -> None:
    handles = [Line2D([], [], color=c, lw=2, label=level.format(lv)) for lv, c in sorted(colours.items())]
    for d in ("up", "down"):
        if d in directions:
            handles.append(Line2D([], [], color="0.3", ls=DIRECTION_STYLE[d], marker=DIRECTION_MARKER[d],
                                  label=f"{d} sweep"))
    handles.extend(extra)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
              title=f"{level.name} level", title_fontsize=8, frameon=False)


def _plot_series(ax, series, colours, y, *, marker=True, **kw):
    for s in series:
        ax.plot(s.freq_Hz, y(s), ls=DIRECTION_STYLE.get(s.direction, ":"), color=colours[s.level_N],
                marker=DIRECTION_MARKER.get(s.direction, "s") if marker else None, ms=4, **kw)


def _plain_log_ticks(fig: Figure) -> None:
    """Log axes (frequency, force, compliance) get plain numbers (30, 50, 100; 2e-06), never
    mathtext such as 3x10^1; minor ones too (2, 3, 5 of each decade) when the axis spans
    less than two decades.  Major ticks at powers of ten outside 1e-3..1e5 keep 10^n."""
    from matplotlib.ticker import FuncFormatter, LogFormatterSciNotation, NullFormatter
    for ax in fig.axes:
        for axis, lim in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
            if axis.get_scale() != "log" or min(lim) <= 0:
                continue
            tiny = min(lim) < 1e-3 or max(lim) > 1e5
            axis.set_major_formatter(LogFormatterSciNotation() if tiny and max(lim) / min(lim) >= 100
                                     else FuncFormatter(plain_tick))
            axis.set_minor_formatter(FuncFormatter(sparse_tick) if math.log10(max(lim) / min(lim)) < 2
                                     else NullFormatter())


def plain_tick(v: float, _pos=None) -> str:
    """A log axis' tick label as a plain number: 60, 0.3, 2e-06."""
    return f"{v:g}"


def sparse_tick(v: float, _pos=None) -> str:
    """A minor tick's label on a short log axis: only 2, 3 and 5 of each decade."""
    return f"{v:g}" if f"{v:e}"[0] in "235" else ""


def _fit_titles(fig: Figure) -> bool:
    """Wrap the figure's title to the figure's width and each axes' title to its axes'
    width (a long title is otherwise cut at the figure's edges or runs into its neighbour),
    measured on the layout of the figure's last draw, each rewrapped until it fits.  True
    when a title changed (the figure then needs drawing again)."""
    import textwrap
    texts = [(fig._suptitle, fig.bbox)] if fig._suptitle is not None else []
    texts += [(t, ax.bbox) for ax in fig.axes for t in (ax.title, ax._left_title, ax._right_title)]
    changed = False
    for text, box in texts:
        for _ in range(4):
            s = text.get_text()
            if not s:
                break
            width = text.get_window_extent().width
            if width <= 0.98 * box.width:
                break
            per_line = max(len(line) for line in s.splitlines())
            text.set_text(textwrap.fill(" ".join(s.split()), max(10, int(per_line * 0.95 * box.width / width))))
            changed = True
    return changed


def _render(fig: Figure, save) -> None:
    """``save()`` the figure (savefig: a full draw with the constrained layout), then fit its
    titles to that layout; saved again only if a title was rewrapped.  A draw of a figure of
    ten log axes costs about a second: a figure whose titles fit is drawn once, not once to
    measure and once to save, nor once per title (decision 0048)."""
    _plain_log_ticks(fig)
    for _ in range(4):
        save()
        if not _fit_titles(fig):
            return


def save_png(fig: Figure, path: Path) -> Path:
    _render(fig, lambda: fig.savefig(path, dpi=110))
    return path


def png_bytes(fig: Figure, dpi: int = 96) -> bytes:
    buf = io.BytesIO()

    def save():
        buf.seek(0)
        buf.truncate()
        fig.savefig(buf, format="png", dpi=dpi)
    _render(fig, save)
    return buf.getvalue()


# ---------------------------------------------------------------------------- run report


def plot_compliance(series, colours, title, legacy: bool = False, level: Quantity = FORCE) -> Figure:
    fig = Figure(figsize=(10, 10), layout="constrained")
    ax1, ax2, ax3 = fig.subplots(3, 1, sharex=True)
    _plot_series(ax1, series, colours, lambda s: s.col(lambda st: st["compliance_abs_m_per_N"]))
    ax1.set(yscale="log", ylabel="|X1/F1|  (m/N)", title="fundamental: |X1/F1| (harmonic fit)")
    _plot_series(ax2, series, colours, lambda s: s.col(lambda st: st["compliance_pp_m_per_N"]))
    ax2.set(yscale="log", ylabel="(x_max - x_min)/(2 F1)  (m/N)",
            title="peak-to-peak compliance (seed Eq. 9 in SI), "
                  + ("from the raw record (run stored before the harmonic-fit compliance_pp)" if legacy
                     else "from the fitted periodic displacement"))
    _plot_series(ax3, series, colours, lambda s: phase_deg(s.col(lambda st: st["compliance_phase_rad"])))
    ax3.set(xscale="log", xlabel="frequency (Hz)", ylabel="phase of X1/F1  (deg)",
            title="phase (displacement behind force: 0 = spring, -180 = mass)")
    ax3.set_yticks([-270, -180, -90, 0, 90])
    ax3.set_ylim(-280, 100)
    for ax in (ax1, ax2, ax3):
        ax.grid(True, which="both", alpha=0.3)
    _legend(ax1, colours, {s.direction for s in series}, level=level)
    fig.suptitle(f"Compliance: {title}")
    return fig


def plot_accelerance(series, colours, title, mass_kg: float | None, level: Quantity = FORCE) -> Figure:
    fig = Figure(figsize=(10, 5.5), layout="constrained")
    ax = fig.subplots()
    _plot_series(ax, series, colours, lambda s: s.col(lambda st: st["accelerance_abs_kg_inv"]))
    extra = []
    if mass_kg:
        ax.axhline(1.0 / mass_kg, color="k", lw=1, ls=":")
        extra.append(Line2D([], [], color="k", ls=":", label=f"1/m, m = {mass_kg:g} kg\n(expected; free mass)"))
    ax.set(xscale="log", yscale="log", xlabel="frequency (Hz)", ylabel="|A1/F1|  (1/kg = m/s^2 per N)",
           title=f"Accelerance |A1/F1| (tends to 1/m above the friction resonance): {title}")
    ax.grid(True, which="both", alpha=0.3)
    _legend(ax, colours, {s.direction for s in series}, extra, level=level)
    return fig


def plot_quality(series, colours, title, tolerance: float | None, level: Quantity = FORCE) -> Figure:
    """THD, the control error of the quantity the levels hold (``level``) and the residual."""
    fig = Figure(figsize=(10, 10), layout="constrained")
    ax1, ax2, ax3 = fig.subplots(3, 1, sharex=True)
    _plot_series(ax1, series, colours, lambda s: 100 * s.col(lambda st: st["disp"]["thd"]))
    ax1.set(yscale="log", ylabel="THD of displacement (%)",
            title="displacement THD: sqrt(sum A_k^2, k >= 2) / A_1 (friction nonlinearity)")
    _plot_series(ax2, series, colours, lambda s: 100 * s.col(control_error))
    if tolerance:
        for sgn in (-1, 1):
            ax2.axhline(100 * sgn * tolerance, color="r", lw=1, ls=":")
    ax2.set(ylabel=f"{level.name} error {level.symbol}/target - 1 (%)",
            title=f"{level.name} control: error of the {level.name} fundamental (red: tolerance)")
    _plot_series(ax3, series, colours, lambda s: 100 * s.col(residual_ratio))
    ax3.axhline(100 * UNSETTLED_RESIDUAL, color="r", lw=1, ls=":")
    ax3.set(xscale="log", yscale="log", xlabel="frequency (Hz)", ylabel="residual rms / A_1 (%)",
            title="displacement residual after the harmonic fit / fundamental\n"
                  "(noise + non-periodic motion; red: flag level)")
    for ax in (ax1, ax2, ax3):
        ax.grid(True, which="both", alpha=0.3)
    _legend(ax1, colours, {s.direction for s in series}, level=level)
    fig.suptitle(f"Signal quality: {title}")
    return fig


def default_lines(cmp: ModelComparison) -> str:
    """What a comparison's lines are: the rig's full model on the compiled plant (decision
    0054) or the plain Masing carriage by shooting."""
    return ("the rig's model (every effect its file declares, compiled plant)" if cmp.responses
            else "model (sim.shooting, rig's true parameters)")


def plot_model(series, colours, title, cmp: ModelComparison, level: Quantity = FORCE,
               lines: str = "") -> Figure:
    fig = Figure(figsize=(10, 9), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    gamma0 = {c.level_N: c.gamma0 for c in cmp.levels}
    for lv, (f, C, flags) in sorted(cmp.curves.items()):
        ax1.plot(f, C, color=colours.get(lv, "k"), lw=1.5, alpha=0.8, ls=":" if gamma0.get(lv, 0) >= 1 else "-")
        bad = ~np.isfinite(C)
        if bad.any():
            ax1.plot(f[bad], np.full(bad.sum(), np.nanmin(C) if np.isfinite(C).any() else 1e-9), ls="none",
                     marker="|", ms=8, color="r")
    for s in series:
        c = colours[s.level_N]
        measured = s.col(lambda st: st["compliance_pp_m_per_N"])
        diff = 100 * (measured / s.col(lambda st: cmp.at_steps.get(st["key"], math.nan)) - 1)
        flagged = s.col(residual_ratio) > UNSETTLED_RESIDUAL
        ax1.plot(s.freq_Hz, measured, ls="none", marker=DIRECTION_MARKER.get(s.direction, "s"), mfc="none",
                 mec=c, ms=7)
        ax2.plot(s.freq_Hz, diff, ls="none", marker=DIRECTION_MARKER.get(s.direction, "s"), mfc="none",
                 mec=c, ms=7)
        ax2.plot(s.freq_Hz[flagged], diff[flagged], ls="none", marker="x", color="r", ms=5)
    ax1.set(yscale="log", ylabel="compliance_pp (m/N)",
            title=f"lines: {lines or default_lines(cmp)}; markers: measured compliance_pp")
    ax2.axhline(0, color="k", lw=0.8)
    ax2.set(xscale="log", xlabel="frequency (Hz)", ylabel="measured / model - 1 (%)",
            title=f"relative difference (red x: displacement residual > {100 * UNSETTLED_RESIDUAL:g} % of the "
                  "fundamental, see quality.png)")
    ax2.set_yscale("symlog", linthresh=1)
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
    extra = [Line2D([], [], color="0.3", lw=1.5, label="model"),
             Line2D([], [], color="0.3", lw=1.5, ls=":", label="model, gamma0 >= 1\n(gross rolling)"),
             Line2D([], [], color="r", marker="x", ls="none", label="flagged step (residual)"),
             Line2D([], [], color="r", marker="|", ls="none", label="model: no steady state")]
    handles = [Line2D([], [], color=c, lw=2, label=level.format(lv)) for lv, c in sorted(colours.items())]
    handles += [Line2D([], [], color="0.3", marker=DIRECTION_MARKER[d], mfc="none", ls="none",
                       label=f"measured, {d} sweep") for d in ("up", "down") if d in {s.direction for s in series}]
    ax1.legend(handles=handles + extra, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    fig.suptitle(f"Model vs measurement (simulated rig): {title}")
    return fig


def _id_caps(ref: float, log_y: bool) -> tuple[float, float]:
    if log_y:
        return ref / ID_LOG_SPAN, ref * ID_LOG_SPAN
    w = max(ID_LIN_SPAN, 0.2 * abs(ref))
    return ref - w, ref + w


def plot_identification(ident: IdentificationData, title: str, level_starts: list[tuple[float, float]]) -> Figure:
    """Estimate vs steps completed, one panel per parameter, 95 % interval as a band."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator, NullFormatter
    fig = Figure(figsize=(10, 8), layout="constrained")
    axes = fig.subplots(2, 2, sharex=True).ravel()
    x = steps_of(ident.history)
    final = ident.final
    off_scale = False
    for ax, p in zip(axes, ID_PARAMS):
        def col(part, hist=ident.history, key=p.key):
            return np.array([finite((h.get(part) or {}).get(key)) * p.scale for h in hist])   # floats: inf, no warning
        v, lo, hi = col("values"), col("low"), col("high")
        ref = finite(final["values"].get(p.key)) * p.scale if final else math.nan
        if not math.isfinite(ref) or (p.log_y and ref <= 0):
            good = v[np.isfinite(v) & ((v > 0) if p.log_y else True)]
            ref = float(good[-1]) if good.size else (1.0 if p.log_y else 0.0)
        cap_lo, cap_hi = _id_caps(ref, p.log_y)
        # an undetermined bound fills the axis; the band is clipped to it
        band_lo = np.clip(np.where(np.isfinite(lo) & ((lo > 0) if p.log_y else True), lo, cap_lo), cap_lo, cap_hi)
        band_hi = np.clip(np.where(np.isfinite(hi), hi, cap_hi), cap_lo, cap_hi)
        ax.fill_between(x, band_lo, band_hi, color="C0", alpha=0.2, lw=0)
        inside = (v >= cap_lo) & (v <= cap_hi)
        ax.plot(x[inside], v[inside], "o-", color="C0", ms=3, lw=1)
        for sel, edge, mk in ((v > cap_hi, cap_hi, "^"), (v < cap_lo, cap_lo, "v")):
            if sel.any():
                off_scale = True
                ax.plot(x[sel], np.full(sel.sum(), edge), ls="none", marker=mk, color="C0", mfc="none", ms=6,
                        clip_on=False)
        shown = list(v[inside]) + list(band_lo[np.isfinite(lo)]) + list(band_hi[np.isfinite(hi)])
        if final:
            fv, fl, fh = (finite(final[k].get(p.key)) * p.scale if isinstance(final.get(k), dict) else math.nan
                          for k in ("values", "low", "high"))
            xf = final.get("steps_used", x[-1] if x.size else 1)
            if math.isfinite(fv):
                err = [[max(fv - fl, 0.0) if math.isfinite(fl) else 0.0],
                       [max(fh - fv, 0.0) if math.isfinite(fh) else 0.0]]
                ax.errorbar([xf], [fv], yerr=err, fmt="*", color="C3", ms=11, capsize=4, zorder=5)
                shown += [fv]
        if ident.truth:
            t = ident.truth[p.key] * p.scale
            ax.axhline(t, color="k", ls="--", lw=1.2)
            shown.append(t)
        shown = np.clip([s for s in shown if math.isfinite(s) and (s > 0 or not p.log_y)], cap_lo, cap_hi)
        a, b = (float(shown.min()), float(shown.max())) if shown.size else (cap_lo, cap_hi)
        if p.log_y:
            pad = max((b / a) ** 0.06, 1.002)
            ax.set_ylim(a / pad, b * pad)
            ax.set_yscale("log")
            ax.yaxis.set_major_formatter(FuncFormatter(lambda val, _: f"{val:g}"))
            ax.yaxis.set_minor_formatter(FuncFormatter(lambda val, _: f"{val:g}") if b / a < 30 else NullFormatter())
        else:
            pad = max(0.06 * (b - a), 0.002 * max(abs(a), abs(b), 1e-12))
            ax.set_ylim(a - pad, b + pad)
        for i, (xs, level) in enumerate(level_starts):
            if i:       # the first level starts with the plot
                ax.axvline(xs - 0.5, color="0.6", lw=0.8, ls=":")
            if ax in axes[:2]:
                ax.text(xs - 0.5, 1.0, f" {level:g} N", transform=ax.get_xaxis_transform(), fontsize=7,
                        color="0.4", va="bottom", ha="left")
        unit = f" ({p.unit})" if p.unit else ""
        ax.set_ylabel(f"{p.label}{unit}{', log scale' if p.log_y else ''}")
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes[2:]:
        ax.set_xlabel("steps completed")
    axes[0].xaxis.set_major_locator(MaxNLocator(integer=True))
    handles = [Line2D([], [], color="C0", marker="o", ms=3, label="online estimate"),
               Patch(color="C0", alpha=0.2, label="95 % interval")]
    if off_scale:
        handles.append(Line2D([], [], color="C0", marker="^", mfc="none", ls="none", label="estimate off scale"))
    if final:
        handles.append(Line2D([], [], color="C3", marker="*", ms=10, ls="none", label="final fit (95 %)"))
    if ident.truth:
        handles.append(Line2D([], [], color="k", ls="--", label="truth (rig model)"))
    handles.append(Line2D([], [], color="0.6", ls=":", label="first step of a level"))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=8, frameon=False)
    fig.suptitle(f"Online identification: estimate vs steps completed: {title}")
    return fig


# ---------------------------------------------------------------------------- analysis page

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


# ---------------------------------------------------------------------------- modes (bench modes)

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
