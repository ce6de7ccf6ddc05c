"""Measured and modelled hysteresis loops: one period of friction force against displacement
at one step of every force level, for the analysis's Masing fits (``loops``) and for every
fitted friction model (``friction_models.table[].loops``, issue 41 item 3; decision 0087).

The step of a level is its most compliant one (largest |X/P|: nearest its resonance, the
widest loop).  The measured friction is P - m a from the step's averaged period of time
records (or, without them, its harmonics), with the mass of the model it is compared with.
A rival model's friction is its own steady periodic force
(:meth:`sim.friction.FrictionModel.periodic_force`) along the displacement the fit uses (both
motion channels' harmonics, :meth:`~sim.discrepancy.models.Model._displacement`), taken back
to the step's time grid through its harmonics, so a model added to :mod:`sim.friction` and
fitted gets its loops without code here.
"""

from __future__ import annotations

import math

import numpy as np

from ..friction import MODELS
from ..identify import path_harmonics, period_paths, synthesize
from .models import Data, Model

LOOP_POINTS = 64                 # samples per stored loop of a friction model (analysis.json's size)
SYNTH_POINTS = 256               # samples of a period rebuilt from harmonics (steps without time records)


def loop_steps(d: Data, count: int | None = None) -> list[int]:
    """The most compliant step of each force level (of ``count`` levels spread from the lowest
    to the highest; every level when None), in level order."""
    C = np.abs(d.X[:, 0] / d.P[:, 0])
    levels = np.unique(d.level)
    if count is not None:
        levels = np.array(list(dict.fromkeys(levels[int(round(i))]
                                             for i in np.linspace(0, levels.size - 1, min(count, levels.size)))))
    out = []
    for lv in levels:
        idx = np.flatnonzero(d.level == lv)
        out.append(int(idx[np.argmax(C[idx])]))
    return out


def measured_period(step, d: Data, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(displacement, force, acceleration) over one period of step ``i``: its averaged time
    records, or synthesized from its harmonics."""
    disp = getattr(step, "disp_m", None)
    if disp is None or np.size(disp) < 8:
        row = slice(i, i + 1)
        return (synthesize(d.X[row], SYNTH_POINTS)[0], synthesize(d.P[row], SYNTH_POINTS)[0],
                synthesize(d.A[row], SYNTH_POINTS)[0])
    return np.asarray(disp, float), np.asarray(step.force_N, float), np.asarray(step.accel_m_s2, float)


def model_friction(name: str, values: dict, d: Data, i: int, samples: int) -> np.ndarray:
    """Model ``name``'s steady friction (N) with parameters ``values`` over one period of step
    ``i``, at ``samples`` points of the step's time grid (no mean: the harmonics have none)."""
    sub = d.subset(np.arange(d.X.shape[0]) == i)
    m0 = Model((), d.X.shape[1])
    x = m0._displacement({}, sub)
    paths, starts = period_paths(x, m0.M)
    F = MODELS[name].periodic_force(values, paths, sub.omega)
    K = min(x.shape[1], samples // 2 - 1, m0.M // 2 - 1)
    return synthesize(path_harmonics(F, starts, K), samples)[0]


def _mass(fit, fallback: float) -> float:
    p = fit.parameters.get("mass_kg") if isinstance(fit.parameters, dict) else None
    v = p.get("value") if isinstance(p, dict) else None
    return float(v) if isinstance(v, int | float) and math.isfinite(v) else fallback


def _short(a: np.ndarray) -> list[float]:
    """Six significant digits: the loops are for drawing and comparing, not refitting."""
    return [float(f"{v:.6g}") for v in a]


def friction_model_loops(steps, d: Data, fits: dict, mass_kg: float, points: int = LOOP_POINTS) -> dict[str, list[dict]]:
    """Model name -> its loops at every level (:func:`loop_steps`): ``key, level_N, freq_Hz,
    disp_m, friction_meas_N`` (P - m a with the model's mass), ``friction_model_N`` (its
    periodic force plus the measured mean), ``points`` samples each, and
    ``rms_difference_N`` (measured minus model over the full period).  Models not fitted (or
    without ``values``) get none; ``mass_kg``: the mass of a model that gives none."""
    rows = loop_steps(d)
    periods = {i: measured_period(steps[i], d, i) for i in rows}
    out: dict[str, list[dict]] = {}
    for name, f in fits.items():
        if not f.fitted or not f.values or name not in MODELS:
            continue
        m = _mass(f, mass_kg)
        loops = []
        for i in rows:
            disp, force, accel = periods[i]
            meas = force - m * accel
            model = model_friction(name, f.values, d, i, disp.size) + float(np.mean(meas))
            pick = np.round(np.linspace(0, disp.size, min(points, disp.size), endpoint=False)).astype(int)
            s = steps[i]
            loops.append(dict(key=s.key, level_N=float(s.level_N), freq_Hz=float(s.freq_Hz), mass_kg=m,
                              disp_m=_short(disp[pick]), friction_meas_N=_short(meas[pick]),
                              friction_model_N=_short(model[pick]),
                              rms_difference_N=float(np.sqrt(np.mean((meas - model) ** 2)))))
        out[name] = loops
    return out
