"""The report of a run directory: PNG plots and ``report/report.md`` (read that first).

    <run>/report/report.md                what ran, on what, and what came out
    <run>/report/compliance.png           |X1/F1|, (x_max - x_min)/(2 F1) and phase vs frequency
    <run>/report/accelerance.png          |A1/F1| vs frequency
    <run>/report/quality.png              THD of displacement, force error, residual
    <run>/report/resonance.png            harmonic resonance frequency and compliance vs force
    <run>/report/model_vs_measurement.png simulated rigs only: the sim/ engine's prediction

Works on partial runs (interrupted, aborted): whatever steps are stored are shown.
Plots use matplotlib ``Figure`` objects (Agg), never pyplot's global state.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from .storage import RunStore

log = logging.getLogger(__name__)

DIRECTION_STYLE = {"up": "-", "down": "--"}
DIRECTION_MARKER = {"up": "o", "down": "v"}
UNSETTLED_RESIDUAL = 0.02      # displacement residual rms / fundamental amplitude above which a step is flagged
MODEL_GRID_POINTS = 120        # dense frequency grid of the model curves
ROUTINE_EVENTS = {"start", "end", "sensor", "output_off"}


# ---------------------------------------------------------------------------- data


@dataclass
class Series:
    """One force level's sweep in one direction, sorted by frequency."""

    level_index: int
    level_N: float
    direction: str
    steps: list[dict]

    def col(self, getter) -> np.ndarray:
        return np.array([getter(s) for s in self.steps], dtype=float)

    @property
    def freq_Hz(self) -> np.ndarray:
        return self.col(lambda s: s["freq_Hz"])


def series_of(results: list[dict], levels_N) -> list[Series]:
    groups: dict[tuple[int, str], list[dict]] = {}
    for r in results:
        groups.setdefault((r["level_index"], r["direction"]), []).append(r)
    out = []
    for (li, d), steps in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1] != "up")):
        level = levels_N[li] if li < len(levels_N) else steps[0]["target_force_N"]
        out.append(Series(li, float(level), d, sorted(steps, key=lambda s: s["freq_Hz"])))
    return out


def fitted_half_pp(fit: dict, n: int = 2048) -> float:
    """Half the peak-to-peak of the periodic waveform rebuilt from a channel's harmonic
    fit: seed Eq. 9 without the noise and non-periodic residual the raw record carries."""
    amp, ph = np.asarray(fit["amplitude"]), np.asarray(fit["phase_rad"])
    wt = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    k = np.arange(1, amp.size + 1)
    x = (amp * np.sin(np.outer(wt, k) + ph)).sum(axis=1)
    return 0.5 * float(x.max() - x.min())


def fitted_compliance_pp(step: dict) -> float:
    return fitted_half_pp(step["disp"]) / step["force_N"]


def residual_ratio(step: dict) -> float:
    """Displacement residual rms (noise plus anything not periodic) / fundamental amplitude."""
    a1 = step["disp"]["amplitude"][0]
    return step["disp"]["noise_rms"] / a1 if a1 > 0 else math.inf


def phase_deg(phase_rad: np.ndarray) -> np.ndarray:
    """Compliance phase in degrees in (-270, 90]: a mass-spring-like lag runs 0 -> -180
    without wrapping at -180."""
    return (np.degrees(phase_rad) - 90.0) % 360.0 - 270.0


# ---------------------------------------------------------------------------- model


@dataclass
class LevelComparison:
    """Relative differences measured / model - 1 of one level; max = the one of largest magnitude."""

    level_N: float
    gamma0: float
    n_steps: int
    n_clean: int                 # steps with residual ratio <= UNSETTLED_RESIDUAL
    median_raw: float            # raw compliance_pp, clean steps only
    max_raw: float
    median_fit: float            # harmonic-fit compliance_pp, all steps
    max_fit: float
    notes: list[str]


@dataclass
class ModelComparison:
    """The sim/ engine's compliance_pp for the rig's true parameters, per level."""

    params: dict                              # the RigModel used (defaults filled in)
    omega_s: float
    curves: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]]   # level -> (f, C_pp, flags)
    at_steps: dict[str, float]                # step key -> model compliance_pp (m/N)
    levels: list[LevelComparison]
    engine_notes: list[str] = field(default_factory=list)

    def resonance(self, level_N: float) -> tuple[float, float]:
        f, c, _ = self.curves[level_N]
        ok = np.isfinite(c)
        if not ok.any():
            return math.nan, math.nan
        i = int(np.nanargmax(np.where(ok, c, -np.inf)))
        return float(f[i]), float(c[i])


def _model_effects(model) -> list[str]:
    """Rig effects the dimensionless engine leaves out, when switched on."""
    names = {"viscous_N_s_per_m": "viscous damping", "spring_N_per_m": "linear spring",
             "disp_delay_s": "displacement-channel delay", "force_gain_error": "force gain error",
             "accel_gain_error": "acceleration gain error", "disp_gain_error": "displacement gain error"}
    return [f"{label} ({k} = {getattr(model, k):g})" for k, label in names.items() if getattr(model, k)]


def model_comparison(meta: dict, results: list[dict]) -> ModelComparison | None:
    """None unless the run is on a simulated rig with a stored model."""
    rig = meta.get("rig") or {}
    if not (rig.get("simulated") and rig.get("model")) or not results:
        return None
    from sim.rig import RigModel
    from sim.shooting import frf_shooting

    model = RigModel.from_dict(rig["model"])
    ws = model.omega_s
    scale = model.x_s_m / model.F_s_N                     # G (dimensionless) -> m/N
    plan = meta.get("plan") or {}
    levels_N = plan.get("levels_N") or sorted({r["target_force_N"] for r in results})
    freqs = np.array(sorted({r["freq_Hz"] for r in results}))
    dense = np.geomspace(freqs.min() / 1.1, freqs.max() * 1.1, MODEL_GRID_POINTS)
    engine_notes = [f"omega_s = sqrt(F_s/(x_s m)) = {ws:.4g} rad/s ({ws / (2 * math.pi):.4g} Hz); "
                    f"compliance = G x_s/F_s with G from sim.shooting.frf_shooting (n = {model.n:g})"]
    effects = _model_effects(model)
    if effects:
        engine_notes.append("the rig model has effects the engine leaves out, so differences are expected: "
                            + ", ".join(effects))

    curves, at_steps, levels = {}, {}, []
    by_level: dict[int, list[dict]] = {}
    for r in results:
        by_level.setdefault(r["level_index"], []).append(r)
    for li, steps in sorted(by_level.items()):
        level = float(levels_N[li]) if li < len(levels_N) else float(steps[0]["target_force_N"])
        gamma0 = level / model.F_s_N
        notes = []
        if level > model.amp_force_limit_N:
            notes.append(f"level above the amplifier's force limit {model.amp_force_limit_N:g} N")
        grid = np.union1d(dense, freqs)
        try:
            fr, fell_back = frf_shooting(2 * math.pi * grid / ws, gamma0, model.n)
            G = np.where(fr.converged, fr.G, np.nan)
            f_model = fr.beta * ws / (2 * math.pi)
            flags = np.array(fr.gross_rolling) | ~np.array(fr.converged)
            if (~fr.converged).any():
                notes.append(f"model: no steady state at {int((~fr.converged).sum())} of {grid.size} frequencies")
            if fell_back.any():
                notes.append(f"model: RK4 fallback at {int(fell_back.sum())} of {grid.size} frequencies")
            if np.any(fr.gross_rolling) or gamma0 >= 1:
                notes.append("gamma0 >= 1: gross rolling; model = centred periodic orbit, the rig's "
                             "carriage may drift: indicative only" if gamma0 >= 1
                             else "model: gross rolling at some frequencies")
        except Exception as e:          # the report must come out even if the engine fails
            log.warning("model FRF at %g N failed: %s", level, e)
            notes.append(f"model engine failed: {type(e).__name__}: {e}")
            f_model, G, flags = grid, np.full(grid.size, np.nan), np.ones(grid.size, bool)
        C = G * scale
        curves[level] = (f_model, C, flags)
        raw, fit = [], []
        for s in steps:
            i = int(np.argmin(np.abs(f_model - s["freq_Hz"])))
            at_steps[s["key"]] = float(C[i])
            raw.append(s["compliance_pp_m_per_N"] / C[i] - 1.0)
            fit.append(fitted_compliance_pp(s) / C[i] - 1.0)
        clean = np.array([residual_ratio(s) <= UNSETTLED_RESIDUAL for s in steps])
        raw, fit = np.array(raw)[clean], np.array(fit)
        levels.append(LevelComparison(level, gamma0, len(steps), int(clean.sum()), _median(raw), _signed_max(raw),
                                      _median(fit), _signed_max(fit), notes))
    return ModelComparison(model.__dict__.copy(), ws, curves, at_steps, levels, engine_notes)


def _median(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else math.nan


def _signed_max(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(x[np.argmax(np.abs(x))]) if x.size else math.nan


# ---------------------------------------------------------------------------- resonance


@dataclass
class Resonance:
    level_N: float
    freq_Hz: float
    compliance_pp_m_per_N: float
    direction: str
    at_grid_edge: bool
    model_freq_Hz: float = math.nan
    model_compliance_pp_m_per_N: float = math.nan


def resonances(series: list[Series], comparison: ModelComparison | None) -> list[Resonance]:
    """Per level: the step of largest compliance_pp (either sweep direction)."""
    out = []
    for level in sorted({s.level_N for s in series}):
        steps = [st for s in series if s.level_N == level for st in s.steps]
        best = max(steps, key=lambda st: st["compliance_pp_m_per_N"])
        fs = sorted({st["freq_Hz"] for st in steps})
        r = Resonance(level, best["freq_Hz"], best["compliance_pp_m_per_N"], best["direction"],
                      best["freq_Hz"] in (fs[0], fs[-1]))
        if comparison and level in comparison.curves:
            r.model_freq_Hz, r.model_compliance_pp_m_per_N = comparison.resonance(level)
        out.append(r)
    return out


# ---------------------------------------------------------------------------- plots


def _colours(levels: list[float]) -> dict[float, tuple]:
    from matplotlib import colormaps
    cmap = colormaps["viridis"]
    lv = sorted(levels)
    if len(lv) == 1:
        return {lv[0]: cmap(0.2)}
    lo, hi = math.log(lv[0]), math.log(lv[-1])
    return {v: cmap(0.9 * (math.log(v) - lo) / (hi - lo)) for v in lv}


def _legend(ax, colours: dict[float, tuple], directions: set[str], extra: list = ()) -> None:
    handles = [Line2D([], [], color=c, lw=2, label=f"{lv:g} N") for lv, c in sorted(colours.items())]
    for d in ("up", "down"):
        if d in directions:
            handles.append(Line2D([], [], color="0.3", ls=DIRECTION_STYLE[d], marker=DIRECTION_MARKER[d],
                                  label=f"{d} sweep"))
    handles.extend(extra)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
              title="force level", title_fontsize=8, frameon=False)


def _plot_series(ax, series, colours, y, *, marker=True, **kw):
    for s in series:
        ax.plot(s.freq_Hz, y(s), ls=DIRECTION_STYLE.get(s.direction, ":"), color=colours[s.level_N],
                marker=DIRECTION_MARKER.get(s.direction, "s") if marker else None, ms=4, **kw)


def _plain_log_ticks(fig: Figure) -> None:
    """Log x axes (frequency, force) get plain numbers (30, 50, 100), not 3x10^1; minor
    ones too when the axis spans less than two decades."""
    from matplotlib.ticker import FuncFormatter, NullFormatter
    plain = FuncFormatter(lambda v, _: f"{v:g}")
    sparse = FuncFormatter(lambda v, _: f"{v:g}" if f"{v:e}"[0] in "235" else "")
    for ax in fig.axes:
        lim = ax.get_xlim()
        if ax.xaxis.get_scale() != "log" or min(lim) <= 0:
            continue
        ax.xaxis.set_major_formatter(plain)
        ax.xaxis.set_minor_formatter(sparse if math.log10(max(lim) / min(lim)) < 2 else NullFormatter())


def _save(fig: Figure, path: Path) -> Path:
    _plain_log_ticks(fig)
    fig.savefig(path, dpi=110)
    return path


def plot_compliance(series, colours, title) -> Figure:
    fig = Figure(figsize=(10, 10), layout="constrained")
    ax1, ax2, ax3 = fig.subplots(3, 1, sharex=True)
    _plot_series(ax1, series, colours, lambda s: s.col(lambda st: st["compliance_abs_m_per_N"]))
    ax1.set(yscale="log", ylabel="|X1/F1|  (m/N)", title="fundamental: |X1/F1| (harmonic fit)")
    _plot_series(ax2, series, colours, lambda s: s.col(lambda st: st["compliance_pp_m_per_N"]))
    ax2.set(yscale="log", ylabel="(x_max - x_min)/(2 F1)  (m/N)",
            title="peak-to-peak compliance (seed Eq. 9 in SI), from the raw record")
    _plot_series(ax3, series, colours, lambda s: phase_deg(s.col(lambda st: st["compliance_phase_rad"])))
    ax3.set(xscale="log", xlabel="frequency (Hz)", ylabel="phase of X1/F1  (deg)",
            title="phase (displacement behind force: 0 = spring, -180 = mass)")
    ax3.set_yticks([-270, -180, -90, 0, 90])
    ax3.set_ylim(-280, 100)
    for ax in (ax1, ax2, ax3):
        ax.grid(True, which="both", alpha=0.3)
    _legend(ax1, colours, {s.direction for s in series})
    fig.suptitle(f"Compliance: {title}")
    return fig


def plot_accelerance(series, colours, title, mass_kg: float | None) -> Figure:
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
    _legend(ax, colours, {s.direction for s in series}, extra)
    return fig


def plot_quality(series, colours, title, tolerance: float | None) -> Figure:
    fig = Figure(figsize=(10, 10), layout="constrained")
    ax1, ax2, ax3 = fig.subplots(3, 1, sharex=True)
    _plot_series(ax1, series, colours, lambda s: 100 * s.col(lambda st: st["disp"]["thd"]))
    ax1.set(yscale="log", ylabel="THD of displacement (%)",
            title="displacement THD: sqrt(sum A_k^2, k >= 2) / A_1 (friction nonlinearity)")
    _plot_series(ax2, series, colours, lambda s: 100 * s.col(lambda st: st["force_error"]))
    if tolerance:
        for sgn in (-1, 1):
            ax2.axhline(100 * sgn * tolerance, color="r", lw=1, ls=":")
    ax2.set(ylabel="force error F1/target - 1 (%)",
            title="force control: error of the force fundamental (red: tolerance)")
    _plot_series(ax3, series, colours, lambda s: 100 * s.col(residual_ratio))
    ax3.axhline(100 * UNSETTLED_RESIDUAL, color="r", lw=1, ls=":")
    ax3.set(xscale="log", yscale="log", xlabel="frequency (Hz)", ylabel="residual rms / A_1 (%)",
            title="displacement residual after the harmonic fit / fundamental\n"
                  "(noise + non-periodic motion; red: flag level)")
    for ax in (ax1, ax2, ax3):
        ax.grid(True, which="both", alpha=0.3)
    _legend(ax1, colours, {s.direction for s in series})
    fig.suptitle(f"Signal quality: {title}")
    return fig


def plot_model(series, colours, title, cmp: ModelComparison) -> Figure:
    fig = Figure(figsize=(10, 9), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    gamma0 = {c.level_N: c.gamma0 for c in cmp.levels}
    for level, (f, C, flags) in sorted(cmp.curves.items()):
        ax1.plot(f, C, color=colours.get(level, "k"), lw=1.5, alpha=0.8, ls=":" if gamma0.get(level, 0) >= 1 else "-")
        bad = ~np.isfinite(C)
        if bad.any():
            ax1.plot(f[bad], np.full(bad.sum(), np.nanmin(C) if np.isfinite(C).any() else 1e-9), ls="none",
                     marker="|", ms=8, color="r")
    for s in series:
        c = colours[s.level_N]
        ax1.plot(s.freq_Hz, s.col(lambda st: st["compliance_pp_m_per_N"]), ls="none",
                 marker=DIRECTION_MARKER.get(s.direction, "s"), mfc="none", mec=c, ms=7)
        model = s.col(lambda st: cmp.at_steps.get(st["key"], math.nan))
        ax2.plot(s.freq_Hz, 100 * (s.col(lambda st: st["compliance_pp_m_per_N"]) / model - 1),
                 ls="none", marker=DIRECTION_MARKER.get(s.direction, "s"), mfc="none", mec=c, ms=7)
        ax2.plot(s.freq_Hz, 100 * (s.col(fitted_compliance_pp) / model - 1), ls="none", marker="x",
                 color=c, ms=6)
    ax1.set(yscale="log", ylabel="compliance_pp (m/N)",
            title="lines: model (sim.shooting, rig's true parameters); open markers: measured (raw)")
    ax2.axhline(0, color="k", lw=0.8)
    ax2.set(xscale="log", xlabel="frequency (Hz)", ylabel="measured / model - 1 (%)",
            title="relative difference: open = raw peak-to-peak, x = from the harmonic fit")
    ax2.set_yscale("symlog", linthresh=1)
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
    extra = [Line2D([], [], color="0.3", lw=1.5, label="model"),
             Line2D([], [], color="0.3", lw=1.5, ls=":", label="model, gamma0 >= 1\n(gross rolling)"),
             Line2D([], [], color="0.3", marker="x", ls="none", label="harmonic-fit pp"),
             Line2D([], [], color="r", marker="|", ls="none", label="model: no steady state")]
    handles = [Line2D([], [], color=c, lw=2, label=f"{lv:g} N") for lv, c in sorted(colours.items())]
    handles += [Line2D([], [], color="0.3", marker=DIRECTION_MARKER[d], mfc="none", ls="none",
                       label=f"measured, {d} sweep") for d in ("up", "down") if d in {s.direction for s in series}]
    ax1.legend(handles=handles + extra, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    fig.suptitle(f"Model vs measurement (simulated rig): {title}")
    return fig


def plot_resonance(res: list[Resonance], title) -> Figure:
    fig = Figure(figsize=(10, 5), layout="constrained")
    ax1, ax2 = fig.subplots(1, 2)
    F = np.array([r.level_N for r in res])
    ax1.plot(F, [r.freq_Hz for r in res], "o-", label="measured (grid maximum)")
    ax2.plot(F, [r.compliance_pp_m_per_N for r in res], "o-", label="measured (grid maximum)")
    if any(math.isfinite(r.model_freq_Hz) for r in res):
        ax1.plot(F, [r.model_freq_Hz for r in res], "s--", mfc="none", label="model (dense grid)")
        ax2.plot(F, [r.model_compliance_pp_m_per_N for r in res], "s--", mfc="none", label="model (dense grid)")
    edge = [r for r in res if r.at_grid_edge]
    if edge:
        ax1.plot([r.level_N for r in edge], [r.freq_Hz for r in edge], "rx", ms=10,
                 label="at the edge of the grid (not a peak)")
    ax1.set(xscale="log", yscale="log", xlabel="force amplitude (N)", ylabel="resonance frequency (Hz)",
            title="harmonic resonance frequency")
    ax2.set(xscale="log", yscale="log", xlabel="force amplitude (N)", ylabel="compliance_pp at resonance (m/N)",
            title="compliance at the resonance")
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"Resonance vs force (largest compliance_pp per level): {title}")
    return fig


# ---------------------------------------------------------------------------- markdown


def _pct(x: float) -> str:
    return "n/a" if not math.isfinite(x) else f"{100 * x:+.2f} %"


def _table(header: list[str], rows: list[list]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    out += ["| " + " | ".join(str(c).replace("|", "\\|").replace("\n", " ") for c in row) + " |" for row in rows]
    return out


def _identification(ident) -> list[str]:
    """Render whatever the identification entry holds, without interpreting it.

    Dict-valued entries become one table: either {"parameters": {name: {value, low, ...}}}
    (a row per parameter, a column per field) or {"values": {name: v}, "low": {...}, ...}
    (a row per parameter, a column per entry).  Everything else is listed below it."""
    lines = ["## Identification", ""]
    if not isinstance(ident, dict):
        return lines + [f"`{ident!r}`", ""]
    if isinstance(ident.get("parameters"), dict):
        table = ident["parameters"]
        rest = {k: v for k, v in ident.items() if k != "parameters"}
        cols = list(dict.fromkeys(c for v in table.values() if isinstance(v, dict) for c in v))
        rows = [[name] + ([_fmt(v.get(c, "")) for c in cols] if isinstance(v, dict) else [v] + [""] * max(0, len(cols) - 1))
                for name, v in table.items()]
        lines += _table(["parameter"] + (cols or ["value"]), rows)
    else:
        cols = [k for k, v in ident.items() if isinstance(v, dict)]
        rest = {k: v for k, v in ident.items() if k not in cols}
        names = list(dict.fromkeys(n for c in cols for n in ident[c]))
        if cols:
            lines += _table(["parameter"] + cols, [[n] + [_fmt(ident[c].get(n, "")) for c in cols] for n in names])
    lines.append("")
    lines += [f"- {k}: {_fmt(v)}" for k, v in rest.items()]
    return lines + [""]


def _fmt(v) -> str:
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def write_report(run_dir: Path) -> Path:
    """Write ``<run>/report/`` (plots and report.md); returns the path of report.md."""
    store = RunStore.open(Path(run_dir))
    meta, results, events = store.metadata, store.results(), store.events()
    out = store.path / "report"
    out.mkdir(exist_ok=True)
    plan, rig = meta.get("plan") or {}, meta.get("rig") or {}
    levels_N = plan.get("levels_N") or sorted({r["target_force_N"] for r in results})
    series = series_of(results, levels_N)
    colours = _colours(sorted({s.level_N for s in series}) or [1.0])
    title = f"{plan.get('name', '?')} on {rig.get('name', '?')}"

    md = [f"# Stepped-sine report: {plan.get('name', '?')}", ""]
    md += _table(["", ""], [
        ["run directory", f"`{store.path}`"],
        ["plan", plan.get("name", "?")],
        ["rig", f"{rig.get('name', '?')}{' (simulated)' if rig.get('simulated') else ''}"],
        ["status", f"**{meta.get('status', '?')}**"],
        ["steps done / total", f"{meta.get('steps_done', len(results))} / {meta.get('steps_total', '?')}"],
        ["started / ended (UTC)", f"{meta.get('started', '?')} / {meta.get('ended', '?')}"],
        ["levels (N)", ", ".join(f"{v:g}" for v in levels_N)],
        ["frequencies", f"{len(plan.get('freqs_Hz', []))} from {min(plan.get('freqs_Hz', [math.nan])):g} to "
                        f"{max(plan.get('freqs_Hz', [math.nan])):g} Hz, direction {plan.get('direction', '?')}"],
    ])
    md += ["", "## Instruments", ""]
    ids = meta.get("identities") or {}
    md += _table(["instrument", "identity"], [[k, ", ".join(f"{a}: {b}" for a, b in v.items())
                                               if isinstance(v, dict) else v] for k, v in ids.items()]) \
        if ids else ["(no identities stored: the instruments were never opened)"]
    md += ["", "## Software", ""]
    md += _table(["package", "version"], [[k, v] for k, v in (meta.get("versions") or {}).items()])
    md += ["", "## Interruptions and aborts", ""]
    notable = [e for e in events if e.get("event") not in ROUTINE_EVENTS]
    if notable:
        md += _table(["time (UTC)", "event", "details"],
                     [[e.get("time", ""), e.get("event", ""),
                       "; ".join(f"{k}={v}" for k, v in e.items() if k not in ("time", "event"))] for e in notable])
    else:
        md.append("none (events.jsonl records only start, sensor checks, output off and end)")
    md.append("")

    if not results:
        md += ["## Results", "", "No step was completed, so there is nothing to plot."]
        path = out / "report.md"
        path.write_text("\n".join(md) + "\n")
        return path

    files: list[tuple[str, str]] = []
    _save(plot_compliance(series, colours, title), out / "compliance.png")
    files.append(("compliance.png", "compliance vs frequency, log-log, one colour per force level, "
                  "solid = up sweep, dashed = down sweep. Top: |X1/F1| from the fundamentals of the harmonic "
                  "fits; middle: (x_max - x_min)/(2 F1), the seed's Eq. 9 in SI, from the raw record; "
                  "bottom: phase of X1/F1 in degrees (0 = spring-like, -180 = mass-like)."))
    mass = rig.get("expected_mass_kg")
    _save(plot_accelerance(series, colours, title, mass), out / "accelerance.png")
    files.append(("accelerance.png", "|A1/F1| vs frequency per level; it tends to 1/m above the friction "
                  "resonance (dotted line: the rig file's expected mass)."))
    _save(plot_quality(series, colours, title, plan.get("force_tolerance")), out / "quality.png")
    files.append(("quality.png", "THD of the displacement (friction nonlinearity), force-control error "
                  "of the fundamental with the tolerance, and the displacement residual after the harmonic fit "
                  "relative to the fundamental (noise and non-periodic motion such as an unsettled free vibration)."))

    cmp = None
    if rig.get("simulated") and rig.get("model"):
        try:
            cmp = model_comparison(meta, results)
        except Exception as e:
            log.warning("model comparison failed: %s", e)
            md += [f"Model comparison failed: {type(e).__name__}: {e}", ""]
    res = resonances(series, cmp)
    _save(plot_resonance(res, title), out / "resonance.png")
    files.append(("resonance.png", "frequency and compliance_pp of the largest compliance_pp per level "
                  "(the harmonic resonance) against force; the seed's result is that the frequency falls "
                  "as the force rises."))
    if cmp:
        _save(plot_model(series, colours, title, cmp), out / "model_vs_measurement.png")
        files.append(("model_vs_measurement.png", "simulated rig only: the sim/ engine's compliance_pp for "
                      "the rig's true parameters (lines) over the measured compliance_pp (markers), and the "
                      "relative differences (raw peak-to-peak and harmonic-fit peak-to-peak)."))

    md += ["## Files", "", f"All in `{out}/` (raw data: `{store.path}/steps/`; "
           f"CSV and UFF: `bench export {store.path}`).", ""]
    md += _table(["file", "what it shows"], [[f"[{n}]({n})", d] for n, d in files])
    md += [""]

    md += ["## Harmonic resonance per level", "",
           "The step of largest compliance_pp (x_max - x_min)/(2 F1) at each level, either sweep direction "
           "(grid maximum: its accuracy is the grid spacing)."]
    rows = []
    for r in res:
        row = [f"{r.level_N:g}", f"{r.freq_Hz:.4g}{' (grid edge)' if r.at_grid_edge else ''}",
               f"{r.compliance_pp_m_per_N:.4g}", r.direction]
        if cmp:
            row += [f"{r.model_freq_Hz:.4g}", f"{r.model_compliance_pp_m_per_N:.4g}"]
        rows.append(row)
    head = ["level (N)", "resonance (Hz)", "compliance_pp (m/N)", "sweep"]
    if cmp:
        head += ["model resonance (Hz)", "model compliance_pp (m/N)"]
    md += [""] + _table(head, rows) + [""]
    inner = [r for r in res if not r.at_grid_edge]
    if len(inner) >= 2:
        falls = all(b.freq_Hz <= a.freq_Hz for a, b in zip(inner, inner[1:]))
        md.append(f"Resonance frequency {'falls' if falls else 'does not fall monotonically'} as the force rises "
                  f"({inner[0].freq_Hz:.4g} Hz at {inner[0].level_N:g} N to {inner[-1].freq_Hz:.4g} Hz at "
                  f"{inner[-1].level_N:g} N; the seed: it falls).")
        md.append("")

    if cmp:
        p = cmp.params
        md += ["## Model vs measurement (simulated rig)", "",
               f"Rig model (true parameters, defaults filled in): F_s = {p['F_s_N']:g} N, x_s = {p['x_s_m']:g} m, "
               f"n = {p['n']:g}, m = {p['mass_kg']:g} kg.", ""]
        md += [f"- {n}" for n in cmp.engine_notes]
        md += ["- relative difference = measured / model - 1; max = the value of largest magnitude.",
               "- raw: the stored compliance_pp, over the *clean* steps only (displacement residual <= "
               f"{100 * UNSETTLED_RESIDUAL:g} % of the fundamental). The peak-to-peak of a noisy record is biased "
               "high by about 3 noise sigma / amplitude, and a non-periodic residual (an unsettled free vibration "
               "at the small-amplitude natural frequency, or a displacement below the sensor noise at high "
               "frequency) inflates it further: see quality.png.",
               "- fit: peak-to-peak of the periodic waveform rebuilt from the displacement's harmonic fit, "
               "over all steps (free of most of the noise and residual).", ""]
        md += _table(["level (N)", "gamma0", "clean / all steps", "median raw", "max raw", "median fit", "max fit",
                      "notes"],
                     [[f"{c.level_N:g}", f"{c.gamma0:.3g}", f"{c.n_clean} / {c.n_steps}", _pct(c.median_raw),
                       _pct(c.max_raw), _pct(c.median_fit), _pct(c.max_fit), "; ".join(c.notes) or "ok"]
                      for c in cmp.levels])
        md.append("")

    md += ["## Steps needing attention", ""]
    failed = [r for r in results if not r.get("force_converged", True)]
    if failed:
        md.append("Force control did not reach the tolerance:")
        md.append("")
        md += _table(["step", "level (N)", "freq (Hz)", "force error", "iterations"],
                     [[r["key"], f"{r['target_force_N']:g}", f"{r['freq_Hz']:g}", _pct(r["force_error"]),
                       r["control_iterations"]] for r in failed])
    else:
        md.append("Force control reached the tolerance at every step.")
    md += ["", f"Displacement residual above {100 * UNSETTLED_RESIDUAL:g} % of the fundamental (noise or "
           "non-periodic motion; compliance_pp of these steps is unreliable, |X1/F1| much less affected):", ""]
    rows = []
    for s in series:
        bad = [st for st in s.steps if residual_ratio(st) > UNSETTLED_RESIDUAL]
        if bad:
            worst = max(bad, key=residual_ratio)
            rows.append([f"{s.level_N:g}", s.direction, f"{len(bad)} / {len(s.steps)}",
                         ", ".join(f"{st['freq_Hz']:.4g}" for st in bad),
                         f"{100 * residual_ratio(worst):.3g} % at {worst['freq_Hz']:.4g} Hz"])
    md += _table(["level (N)", "sweep", "steps", "frequencies (Hz)", "worst"], rows) if rows else ["none"]
    md.append("")

    if "identification" in meta:
        md += _identification(meta["identification"])

    path = out / "report.md"
    path.write_text("\n".join(md) + "\n")
    log.info("report written to %s", path)
    return path
