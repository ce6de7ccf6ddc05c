"""``bench analyze RUN`` on an imported run (issue 42 item 3, decision 0084): the friction
models' describing functions fitted to the measured fundamentals across levels
(:func:`sim.describing_fit.fit_fundamentals`), a structural mode where BIC takes it.

The levels come from the run's steps: the receptance X1/F1 (``compliance_m_per_N``) per
frequency, the force amplitude per point (force-controlled) or the displacement amplitude
reached (response-controlled: |X1/F1| |F|; an acceleration held is a displacement
|A| / w^2 per point).

**The noise.**  An imported FRF carries none (decision 0081).  Unless the mapping gave one
(``origin.mapping.noise``: the FRF's relative standard deviation per real or imaginary
part), the rule is the residuals' own: each point's sigma is taken relative to |X1/F1|,
the model without a structure is fitted at a nominal 1e-3 and its residuals' rms then sets
the scale (sigma = 1e-3 sqrt(chi2/dof) |H|), and every model is fitted (and the structures
compared by BIC) in that scale.  So the simplest model's reduced chi-square is 1 by
construction, a mode is taken only when it lowers chi-square beyond BIC's charge against
that noise, and the intervals are the fit's, scaled by the reduced chi-square where it
exceeds 1 (decision 0082).

Nothing here makes words: the section's codes (:class:`~sim.describing_fit.ParameterStatus`,
:class:`~sim.describing_fit.Separation`) are rendered by :mod:`bench.words.terminal_data`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from sim.describing import Control, Level, Structure, receptance
from sim.describing_fit import FundamentalFit, fit_fundamentals

from .frf_import import origin_of
from .storage import RunStore


class FundamentalLine(StrEnum):
    """The lines of the fit's verdict (words: :data:`bench.words.terminal_data.FUNDAMENTALS`)."""

    MODEL = "fundamentals_model"            # model, structure, reduced_chi2, bic, parameters: the section's
    FAILED = "fundamentals_failed"          # model, error: a rival's fit that failed (its error's text)
    PREFERRED = "fundamentals_preferred"    # model, gap: the next model's BIC above it (None: one model)
    OPEN = "fundamentals_open"              # degenerate: names, separations: Separation codes
    NOISE = "fundamentals_noise"            # rule: mapping | residuals, sigma: relative


MODELS = ("masing", "dahl")          # the friction models fitted (the others of sim.friction: slow or untested)
NOMINAL_NOISE = 1e-3                 # the first fit's relative sigma, rescaled by its residuals (module doc)
FIGURE_POINTS = 60                   # frequencies of each level's fitted curve on the page


@dataclass(frozen=True)
class RunLevels:
    """The imported run's levels as the fit takes them, with each level's stored value."""

    levels: list[Level]
    values: list[float]              # the plan's level (N, m or m/s^2)
    level_kind: str                  # origin.level_kind: force | disp | accel
    noise: float                     # the relative sigma used
    noise_rule: str                  # "mapping" | "residuals"


def run_levels(path: Path) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray], list[float], dict]:
    """Per level: frequencies (Hz), X1/F1 (m/N), the held quantity per point (|F| N or |X| m);
    the levels' values; the run's origin."""
    store = RunStore.open(Path(path))
    meta = store.metadata
    origin = origin_of(meta) or {}
    kind = origin.get("level_kind", "force")
    levels = list((meta.get("plan") or {}).get("levels_N") or [])
    by: dict[int, list[tuple[float, complex, float]]] = {}
    for r in store.results(warn=False):
        c = r.get("compliance_m_per_N") or {}
        H = complex(float(c["re"]), float(c["im"]))
        F = float(r["force_N"])
        drive = F if kind == "force" else abs(H) * F
        by.setdefault(int(r["level_index"]), []).append((float(r["freq_Hz"]), H, drive))
    fs, Hs, ds, vals = [], [], [], []
    for li in sorted(by):
        pts = sorted(by[li])
        fs.append(np.array([p[0] for p in pts]))
        Hs.append(np.array([p[1] for p in pts]))
        ds.append(np.array([p[2] for p in pts]))
        vals.append(float(levels[li]) if li < len(levels) else math.nan)
    return fs, Hs, ds, vals, origin


def _levels(fs, Hs, ds, control: Control, noise: float) -> list[Level]:
    return [Level(f, H, control, d, noise * np.abs(H)) for f, H, d in zip(fs, Hs, ds, strict=True)]


def _values(fit: FundamentalFit) -> dict[str, Any]:
    return {**fit.friction_values, "mass_kg": fit.mass_kg, **fit.structure_values}


def _rival_guess(model: str, masing: FundamentalFit) -> dict[str, Any]:
    """A rival model's start from the Masing fit: its friction level F_s, its initial
    stiffness n F_s / ((n - 1) x_s) (F_s / x_s for n < 1) as Dahl's sigma, the mass and the
    structure's values (the automatic starts of a rival cost minutes on a 3 x 10 set)."""
    v = masing.friction_values
    n = float(v["n"])
    k0 = n * v["F_s_N"] / ((n - 1) * v["x_s_m"]) if n > 1 else v["F_s_N"] / v["x_s_m"]
    start = {"mass_kg": masing.mass_kg, **masing.structure_values}
    if model == "dahl":
        start.update(F_c_N=float(v["F_s_N"]), sigma_N_per_m=float(k0), exponent=1.0)
    return start


def fit_run(path: Path, models: tuple[str, ...] = MODELS) -> tuple[RunLevels, dict[str, FundamentalFit | str]]:
    """Every model of ``models`` (the first ``masing``) fitted to the run's fundamentals
    (module doc): Masing with the structures none and mode, BIC choosing; each rival with
    the structure Masing's fit chose, from a start made of Masing's fit."""
    fs, Hs, ds, vals, origin = run_levels(path)
    kind = origin.get("level_kind", "force")
    control = Control.FORCE if kind == "force" else Control.RESPONSE
    given = (origin.get("mapping") or {}).get("noise")
    first = None
    if isinstance(given, (int, float)) and math.isfinite(given) and given > 0:
        noise, rule = float(given), "mapping"
    else:
        first = fit_fundamentals(_levels(fs, Hs, ds, control, NOMINAL_NOISE), models[0], structures=(Structure.NONE,))
        noise, rule = NOMINAL_NOISE * math.sqrt(max(first.reduced_chi2, 1e-12)), "residuals"
    levels = _levels(fs, Hs, ds, control, noise)
    main = fit_fundamentals(levels, models[0], guess=_values(first) if first is not None else None)
    fits: dict[str, FundamentalFit | str] = {models[0]: main}
    for m in models[1:]:
        try:
            # Masing's mode (when BIC took one) held in the rival's: a free mode in Dahl's fit
            # cost 120 s on the how-to's 3 x 41 points (226 evaluations)
            fits[m] = fit_fundamentals(levels, m, structures=tuple(dict.fromkeys((Structure.NONE, main.structure))),
                                       guess=_rival_guess(m, main), fixed=dict(main.structure_values) or None)
        except (ArithmeticError, ValueError) as e:
            # a rival's fit run into a parameter's end (Dahl's F_c -> 0 on one held level divides by
            # zero in its kernel): the rival is reported failed, Masing's fit stands
            fits[m] = f"{type(e).__name__}: {e}"
    return RunLevels(levels, vals, kind, noise, rule), fits


def _estimate(e) -> dict:
    return {"value": e.value, "low": e.low if math.isfinite(e.low) else None,
            "high": e.high if math.isfinite(e.high) else None, "unit": e.unit, "status": str(e.status)}


def _curve(fit: FundamentalFit, lv: Level) -> tuple[np.ndarray, np.ndarray]:
    """The fitted receptance along a fine grid of the level's band (the held quantity
    interpolated in ln between the measured points)."""
    f = np.geomspace(lv.frequency_Hz.min(), lv.frequency_Hz.max(), FIGURE_POINTS)
    d = np.exp(np.interp(np.log(f), np.log(lv.frequency_Hz), np.log(lv.drive)))
    fine = Level(f, np.interp(f, lv.frequency_Hz, lv.receptance_m_per_N.real)
                 + 1j * np.interp(f, lv.frequency_Hz, lv.receptance_m_per_N.imag), lv.control, d, 1.0)
    H, _ = receptance(fit.model, fit.friction_values, fit.mass_kg, fine, fit.structure, fit.structure_values)
    return f, H


def fundamentals_section(rl: RunLevels, every: dict[str, FundamentalFit | str]) -> dict[str, Any]:
    """analysis.json's ``fundamentals`` section (schema in docs/analysis.md); a model whose
    fit failed (the error's text in ``every``) is listed in ``failed``."""
    fits = {m: f for m, f in every.items() if isinstance(f, FundamentalFit)}
    failed = {m: f for m, f in every.items() if isinstance(f, str)}
    models = {}
    for name, fit in fits.items():
        models[name] = {
            "structure": str(fit.structure), "parameters": {e.name: _estimate(e) for e in fit.estimates},
            "reduced_chi2": fit.reduced_chi2, "chi2": fit.chi2, "dof": fit.dof, "bic": fit.bic,
            "bic_by_structure": dict(fit.bic_by_structure), "separations": [str(s) for s in fit.separations],
            "identified": list(fit.identified), "degenerate": list(fit.degenerate),
            "force_reach": fit.force_reach, "loop_reach": fit.loop_reach,
            "directions": [{"exponents": d.exponents, "half_width": d.half_width, "identified": d.identified}
                           for d in fit.directions],
            "seconds": fit.seconds, "nfev": fit.nfev}
    preferred = min(fits, key=lambda m: fits[m].bic)
    best = fits[preferred]
    levels = []
    for lv, value in zip(rl.levels, rl.values, strict=True):
        entry: dict[str, Any] = {"level": value, "control": str(lv.control), "freq_Hz": lv.frequency_Hz.tolist(),
                                 "measured": [[h.real, h.imag] for h in lv.receptance_m_per_N], "fitted": {}}
        for name, fit in fits.items():
            f, H = _curve(fit, lv)
            entry["fitted"][name] = {"freq_Hz": f.tolist(), "receptance": [[h.real, h.imag] for h in H]}
        levels.append(entry)
    return {"models": models, "failed": failed, "preferred": preferred, "separations": [str(s) for s in best.separations],
            "level_kind": rl.level_kind, "noise": {"relative_sigma": rl.noise, "rule": rl.noise_rule},
            "n_levels": len(rl.levels), "n_points": int(sum(lv.frequency_Hz.size for lv in rl.levels)),
            "levels": levels}
