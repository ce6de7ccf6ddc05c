"""The report of a run directory: PNG plots and ``report/report.md`` (read that first).

    <run>/report/report.md                what ran, on what, and what came out
    <run>/report/compliance.png           |X1/F1|, compliance_pp (x_max - x_min)/(2 F1) and phase vs frequency
    <run>/report/accelerance.png          |A1/F1| vs frequency
    <run>/report/quality.png              THD of displacement, force error, residual
    <run>/report/resonance.png            harmonic resonance frequency and compliance vs force
    <run>/report/model_vs_measurement.png simulated rigs only: the sim/ engine's prediction
    <run>/report/identification.png       online estimates of F_s, x_s, n, m vs steps completed

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
from matplotlib.patches import Patch

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


def legacy_pp(results: list[dict]) -> bool:
    """True for runs stored before compliance_pp came from the harmonic fit: their steps
    have no ``disp.raw_peak_to_peak`` and their compliance_pp is the raw record's."""
    return any("raw_peak_to_peak" not in r.get("disp", {}) for r in results)


def pp_source(results: list[dict]) -> str:
    """Where the stored compliance_pp of this run comes from, for the texts."""
    if legacy_pp(results):
        return ("the raw record (this run predates compliance_pp from the harmonic fit: it is biased high "
                "by noise and non-periodic motion, most at the flagged steps)")
    return "the periodic displacement of the harmonic fit"


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
    n_flagged: int               # steps with residual ratio > UNSETTLED_RESIDUAL
    median: float                # of the stored compliance_pp, all steps
    max: float
    max_unflagged: float         # unflagged steps only
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
        diff = []
        for s in steps:
            i = int(np.argmin(np.abs(f_model - s["freq_Hz"])))
            at_steps[s["key"]] = float(C[i])
            diff.append(s["compliance_pp_m_per_N"] / C[i] - 1.0)
        flagged = np.array([residual_ratio(s) > UNSETTLED_RESIDUAL for s in steps])
        diff = np.array(diff)
        levels.append(LevelComparison(level, gamma0, len(steps), int(flagged.sum()), _median(diff), _signed_max(diff),
                                      _signed_max(diff[~flagged]), notes))
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


def plot_compliance(series, colours, title, legacy: bool = False) -> Figure:
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
        measured = s.col(lambda st: st["compliance_pp_m_per_N"])
        diff = 100 * (measured / s.col(lambda st: cmp.at_steps.get(st["key"], math.nan)) - 1)
        flagged = s.col(residual_ratio) > UNSETTLED_RESIDUAL
        ax1.plot(s.freq_Hz, measured, ls="none", marker=DIRECTION_MARKER.get(s.direction, "s"), mfc="none",
                 mec=c, ms=7)
        ax2.plot(s.freq_Hz, diff, ls="none", marker=DIRECTION_MARKER.get(s.direction, "s"), mfc="none",
                 mec=c, ms=7)
        ax2.plot(s.freq_Hz[flagged], diff[flagged], ls="none", marker="x", color="r", ms=5)
    ax1.set(yscale="log", ylabel="compliance_pp (m/N)",
            title="lines: model (sim.shooting, rig's true parameters); markers: measured compliance_pp")
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


# ---------------------------------------------------------------------------- identification


@dataclass(frozen=True)
class IdParam:
    key: str            # as in the estimate's dicts (SI)
    label: str
    unit: str           # display unit
    scale: float        # SI -> display unit
    log_y: bool


ID_PARAMS = (IdParam("F_s_N", "F_s", "N", 1.0, True), IdParam("x_s_m", "x_s", "um", 1e6, True),
             IdParam("n", "n", "", 1.0, False), IdParam("mass_kg", "m", "kg", 1.0, True))
ID_LOG_SPAN = 2.0       # log axes show at most the final value /2 .. x2; estimates beyond are drawn at the edge
ID_LIN_SPAN = 0.3       # linear axes (n): at most the final value +- max(0.3, 20 %)


@dataclass
class IdentificationData:
    """The online identification of a run: what procedures.online_id stored."""

    history: list[dict]            # identification.jsonl: one estimate per completed step
    final: dict | None             # run.json "identification": the full fit at the end
    truth: dict | None             # simulated rig: the RigModel's parameters (SI)
    identifiability: list[str]     # run.json "identifiability_warnings" (judged before the run)
    unknown: object = None         # a run.json "identification" entry that is not an estimate

    @property
    def latest(self) -> dict | None:
        """The estimate to report: the final fit, else the last online one."""
        return self.final if self.final is not None else (self.history[-1] if self.history else None)


def _is_estimate(d) -> bool:
    return isinstance(d, dict) and isinstance(d.get("values"), dict)


def identification_data(run_dir: Path, meta: dict) -> IdentificationData:
    from procedures.online_id import history
    final = meta.get("identification")
    truth = None
    rig = meta.get("rig") or {}
    if rig.get("simulated") and rig.get("model"):
        from sim.rig import RigModel
        try:
            model = RigModel.from_dict(rig["model"])
            truth = {p.key: float(getattr(model, p.key)) for p in ID_PARAMS}
        except Exception as e:          # the report must come out even with a bad model entry
            log.warning("rig model unreadable: %s", e)
    return IdentificationData([h for h in history(Path(run_dir)) if _is_estimate(h)],
                              final if _is_estimate(final) else None, truth,
                              list(meta.get("identifiability_warnings") or []),
                              None if final is None or _is_estimate(final) else final)


def _finite(v) -> float:
    try:
        v = float(v)
    except (TypeError, ValueError):
        return math.nan
    return v if math.isfinite(v) else math.nan


def _steps_of(history: list[dict]) -> np.ndarray:
    return np.array([h.get("steps_used", i + 1) for i, h in enumerate(history)], dtype=float)


def _determined_from(history: list[dict]) -> int | None:
    """Steps completed from which on no estimate carried a warning (every relative
    standard error below 10 %); None if the last one still does."""
    if not history or history[-1].get("warnings"):
        return None
    i = len(history) - 1
    while i > 0 and not history[i - 1].get("warnings"):
        i -= 1
    return int(_steps_of(history)[i])


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
    x = _steps_of(ident.history)
    final = ident.final
    off_scale = False
    for ax, p in zip(axes, ID_PARAMS):
        def col(part, hist=ident.history, key=p.key):
            return np.array([_finite((h.get(part) or {}).get(key)) * p.scale for h in hist])   # floats: inf, no warning
        v, lo, hi = col("values"), col("low"), col("high")
        ref = _finite(final["values"].get(p.key)) * p.scale if final else math.nan
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
            fv, fl, fh = (_finite(final[k].get(p.key)) * p.scale if isinstance(final.get(k), dict) else math.nan
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


def _num(v, scale: float = 1.0) -> str:
    v = _finite(v)
    if math.isnan(v):
        return "n/a"
    v *= scale
    return "unbounded" if abs(v) > 1e100 else f"{v:.4g}"


def identification_md(ident: IdentificationData, plotted: bool) -> list[str]:
    md = ["## Identification of F_s, x_s, n and m", ""]
    est = ident.latest
    if ident.unknown is not None:
        md += [f"run.json holds an identification entry this report cannot read: `{ident.unknown!r}`", ""]
    if est is None:
        md += ["No identification data: this run has no `identification.jsonl` and no `identification` in "
               "`run.json` (run without online identification, or before it existed). "
               "`bench identify <run>` fits the stored steps offline.", ""]
    else:
        md += ["After every step the friction (Masing, F_s, x_s, n) and the moving mass m are refitted to the "
               "harmonics of all steps so far (procedures.online_id, warm-started); at the end a full fit over "
               "all steps is stored in run.json."
               + (" identification.png shows the estimates." if plotted else ""), ""]
        if est is ident.final:
            src = f"final fit over {est.get('steps_used', '?')} steps (run.json)"
        else:
            src = (f"last online estimate, after step {est.get('step', '?')} ({est.get('steps_used', '?')} steps); "
                   "there is no final fit (the run did not complete)")
        md += [f"Estimate: {src}.", ""]
        head = ["parameter", "unit", "estimate", "95 % low", "95 % high", "rel. std. error"]
        if ident.truth:
            head += ["truth (rig model)", "error", "truth in interval"]
        rows = []
        for p in ID_PARAMS:
            get = {k: (est.get(k) or {}).get(p.key) for k in ("values", "low", "high", "rel_std")}
            row = [p.label, p.unit or "-", _num(get["values"], p.scale), _num(get["low"], p.scale),
                   _num(get["high"], p.scale), _pct(_finite(get["rel_std"])).lstrip("+")]
            if ident.truth:
                t, v = ident.truth[p.key], _finite(get["values"])
                lo, hi = _finite(get["low"]), _finite(get["high"])
                row += [_num(t, p.scale), _pct(v / t - 1.0),
                        "n/a" if math.isnan(lo) or math.isnan(hi) else ("yes" if lo <= t <= hi else "**no**")]
            rows.append(row)
        md += _table(head, rows) + [""]
        times = [_finite(h.get("update_s")) * 1e3 for h in ident.history]
        times = [t for t in times if math.isfinite(t)]
        med = _finite((ident.final or {}).get("update_ms_median"))
        mx = _finite((ident.final or {}).get("update_ms_max"))
        if math.isnan(med) and times:
            med, mx = float(np.median(times)), float(np.max(times))
        md.append(f"- online update time per step: median {med:.3g} ms, max {mx:.3g} ms"
                  if math.isfinite(med) else "- online update time: n/a (no online updates stored)")
        md.append(f"- reduced chi^2: {_num(est.get('reduced_chi2'))} (about 1 when the residual is the "
                  "measurement noise the fit assumes; intervals are never scaled below it)")
        first = _determined_from(ident.history)
        if ident.history:
            md.append(f"- every parameter's relative standard error below 10 % from step {first} of "
                      f"{int(_steps_of(ident.history)[-1])} on" if first is not None else
                      "- the last online estimate still has a parameter with a relative standard error of 10 % "
                      "or more")
        warnings = est.get("warnings") or []
        md.append("- fit warnings: " + ("none" if not warnings else ""))
        md += [f"  - {w}" for w in warnings]
    md.append("- identifiability warnings (from the plan and the rig's expected parameters, before the run): "
              + ("none" if not ident.identifiability else ""))
    md += [f"  - {w}" for w in ident.identifiability]
    return md + [""]


# ---------------------------------------------------------------------------- markdown


def _pct(x: float) -> str:
    return "n/a" if not math.isfinite(x) else f"{100 * x:+.2f} %"


def _table(header: list[str], rows: list[list]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    out += ["| " + " | ".join(str(c).replace("|", "\\|").replace("\n", " ") for c in row) + " |" for row in rows]
    return out


def _level_starts(history: list[dict], results: list[dict]) -> list[tuple[float, float]]:
    """(steps completed, level N) where the online history first meets each new force level."""
    level_of = {r["key"]: r["target_force_N"] for r in results}
    out, last = [], None
    for x, h in zip(_steps_of(history), history):
        level = level_of.get(h.get("step"))
        if level is not None and level != last:
            out.append((float(x), float(level)))
            last = level
    return out


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
    ident = identification_data(store.path, meta)

    if not results:
        md += ["## Results", "", "No step was completed, so there is nothing to plot.", ""]
        md += identification_md(ident, plotted=False)
        path = out / "report.md"
        path.write_text("\n".join(md) + "\n")
        return path

    legacy = legacy_pp(results)
    files: list[tuple[str, str]] = []
    _save(plot_compliance(series, colours, title, legacy), out / "compliance.png")
    files.append(("compliance.png", "compliance vs frequency, log-log, one colour per force level, "
                  "solid = up sweep, dashed = down sweep. Top: |X1/F1| from the fundamentals of the harmonic "
                  "fits; middle: compliance_pp = (x_max - x_min)/(2 F1), the seed's Eq. 9 in SI, from "
                  f"{pp_source(results)}; bottom: phase of X1/F1 in degrees (0 = spring-like, -180 = mass-like)."))
    mass = rig.get("expected_mass_kg")
    _save(plot_accelerance(series, colours, title, mass), out / "accelerance.png")
    files.append(("accelerance.png", "|A1/F1| vs frequency per level; it tends to 1/m above the friction "
                  "resonance (dotted line: the rig file's expected mass)."))
    _save(plot_quality(series, colours, title, plan.get("force_tolerance")), out / "quality.png")
    files.append(("quality.png", "THD of the displacement (friction nonlinearity), force-control error "
                  "of the fundamental with the tolerance, and the displacement residual after the harmonic fit "
                  "relative to the fundamental (noise and non-periodic motion such as an unsettled free vibration; "
                  f"steps above {100 * UNSETTLED_RESIDUAL:g} % are flagged)."))

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
                      "relative differences (flagged steps marked)."))
    if ident.history:
        _save(plot_identification(ident, title, _level_starts(ident.history, results)), out / "identification.png")
        files.append(("identification.png", "online identification: the estimate of F_s, x_s, n and m after "
                      "each step with its 95 % interval (band)"
                      + (", the final fit (star) and the rig model's truth (dashed)" if ident.truth
                         else " and the final fit (star)") + "; dotted: the first step of each force level."))

    md += ["## Files", "", f"All in `{out}/` (raw data: `{store.path}/steps/`; "
           f"CSV and UFF: `bench export {store.path}`).", ""]
    md += _table(["file", "what it shows"], [[f"[{n}]({n})", d] for n, d in files])
    md += [""]

    md += ["## Harmonic resonance per level", "",
           "The step of largest compliance_pp (x_max - x_min)/(2 F1) at each level, either sweep direction "
           "(grid maximum: its accuracy is the grid spacing)."]
    if legacy:
        md += ["", f"compliance_pp of this run is from {pp_source(results)}."]
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
        md += ["- relative difference = measured / model - 1 of the stored compliance_pp (from "
               f"{pp_source(results)}), over all steps; max = the value of largest magnitude.",
               f"- flagged: steps whose displacement residual is above {100 * UNSETTLED_RESIDUAL:g} % of the "
               "fundamental (see quality.png and the steps needing attention).", ""]
        md += _table(["level (N)", "gamma0", "steps (flagged)", "median", "max", "max, unflagged steps", "notes"],
                     [[f"{c.level_N:g}", f"{c.gamma0:.3g}", f"{c.n_steps} ({c.n_flagged})", _pct(c.median),
                       _pct(c.max), _pct(c.max_unflagged), "; ".join(c.notes) or "ok"] for c in cmp.levels])
        md.append("")

    md += identification_md(ident, plotted=bool(ident.history))

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
    caveat = ("compliance_pp of these steps, from the raw record, is biased high; |X1/F1| much less affected"
              if legacy else "the record is not only the steady periodic response; the harmonic fit, from which "
              "compliance_pp and |X1/F1| come, rejects most of it, but treat these steps with care")
    md += ["", f"Displacement residual above {100 * UNSETTLED_RESIDUAL:g} % of the fundamental (noise or "
           f"non-periodic motion such as an unsettled free vibration; {caveat}):", ""]
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

    path = out / "report.md"
    path.write_text("\n".join(md) + "\n")
    log.info("report written to %s", path)
    return path
