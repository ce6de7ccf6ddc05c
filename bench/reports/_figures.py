"""Figures (matplotlib ``Figure`` objects with the Agg canvas, never pyplot's global state).

Here: the shared helpers and the run report's figures (compliance, accelerance, signal
quality, model vs measurement on a simulated rig, online identification).  The analysis
page's are in :mod:`._figures_analysis`, the modes' (Figs. 13 and 17) in
:mod:`._figures_modes`.  Each function
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
