"""The cases of issue 41: data from the rival friction models, made by the independent
simulators (benchtools/independent_friction.py, benchtools/independent_masing.py; no code
shared with sim/), for the tests and benchmarks of the model comparison.

Every case is a stepped-sine up-sweep per force level, written as UFF58 time records:
6 levels from 0.1 to 1.5 times the friction level (geometric: 0.1, 0.17, 0.30, 0.51,
0.87, 1.5; the top one above it, in gross sliding), 15 frequencies from 0.3 to 3 times the
case's friction resonance (geometric), 25 settle and 8 measured periods, the noise of
benchtools/independent_masing.py (force 0.3 % of the friction level, acceleration 0.5 % of
its rms, displacement 0.2 % of the pre-rolling length), so 90 steps.  The friction level is
the force at which the carriage slides: Dahl's F_c, the Iwan elements' sum of slip forces,
LuGre's and GMS's F_s (the breakaway), Masing's F_s.  The friction resonance is the
small-amplitude one, sqrt(K0/m)/(2 pi) with K0 the initial stiffness (Masing: the seed's
omega_s = sqrt(F_s/(x_s m)), its beta = 1), so the harmonic resonance of every level below
gross sliding lies in the grid.

The values are the rig's scale (physics.md: carriage and column 5-15 kg, friction 5-30 N,
pre-rolling length 5-50 um, friction resonance 20-100 Hz), different per case so that no
two cases are copies of each other:

- ``dahl``: F_c 12 N, sigma 6e5 N/m (pre-rolling length F_c/sigma = 20 um), i = 1, 8 kg:
  43.6 Hz.  The common form; the reversal force of a loop of amplitude X is F_c tanh(sigma X/F_c).
- ``dahl_i2``: F_c 15 N, sigma 5e5 N/m (30 um), i = 2, 10 kg: 35.6 Hz.  An n > 1 like shape:
  the branch approaches F_c slowly (F = F_c s/(s + 30 um) on the virgin curve).
- ``dahl_i05``: F_c 10 N, sigma 8e5 N/m (12.5 um), i = 0.5, 6 kg: 58.1 Hz.  An n < 1 like
  shape: the branch reaches F_c after a finite travel, 2 F_c/sigma = 25 um.
- ``lugre``: sigma_0 4e5 N/m, F_c 10 N, F_s 13 N (F_s/sigma_0 = 32.5 um), v_s 2 mm/s
  (below the carriage's speeds in pre-rolling at resonance, a few mm/s, so the Stribeck
  curve shapes the loops), sigma_1 200 N s/m (5 % of the bristles' critical damping
  2 sqrt(sigma_0 m)), sigma_2 20 N s/m (0.26 N at 13 mm/s), 10 kg: 31.8 Hz.
- ``masing_iwan``: six elasto-plastic elements, slip displacements 2, 4, 8, 14, 24, 40 um
  and slip forces 1.2, 1.6, 2.0, 2.4, 2.4, 2.4 N (12 N in all; k_i = f_i / slip_i), 12 kg:
  57.8 Hz.  Masing's rules exactly, a piecewise-linear virgin curve; linear (undamped)
  below 2 um.
- ``gms``: four elements, alpha 0.1, 0.2, 0.3, 0.4, slip displacements at F_c 3, 6.5, 14,
  30 um (k_i = alpha_i F_c / slip_i), F_c 10 N, F_s 12 N, v_s 5 mm/s, delta 1.5, C 1e4 N/s
  (the attraction's time constant s/C = 1-1.2 ms, a tenth of a period at resonance: a
  visible frictional lag in gross sliding), sigma_2 75 N s/m (1 % of critical at small
  amplitude), 14 kg: 42.3 Hz.
- ``masing_n15``, ``masing_n05``: the control, Sakai's Masing model by
  benchtools/independent_masing.py: F_s 10 N, x_s 20 um, 10 kg (35.6 Hz), n = 1.5 and 0.5.

Each case function writes ``out_dir/NAME.uff`` and returns (path, truth): the truth is the
model (``friction_model``: the name analysis.json would give, one of masing, masing_iwan,
dahl, lugre, gms), its parameters, the mass, the grid, the noise and its scales, the steps
written and the generation time (process seconds).  ``levels`` and ``freqs`` (fractions of
the friction level and of the friction resonance) select a smaller grid; :func:`small_grid`
draws a seeded one for a test.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchtools import independent_friction as rival

LEVELS = tuple(float(v) for v in np.geomspace(0.1, 1.5, 6))     # x the friction level
FREQS = tuple(float(v) for v in np.geomspace(0.3, 3.0, 15))     # x the friction resonance
NOISE = (0.003, 0.005, 0.002)                                    # force, accel, disp (relative)
SETTLE, MEASURE = 25, 8


@dataclass(frozen=True)
class FrictionCase:
    name: str
    model: str              # "masing" (independent_masing) or a model of independent_friction
    params: dict
    mass_kg: float


def _iwan(slip_m, f_N):
    return dict(k_N_per_m=[f / s for f, s in zip(f_N, slip_m)], f_N=list(f_N))


def _gms(alpha, slip_m, F_c_N, **rest):
    return dict(k_N_per_m=[a * F_c_N / s for a, s in zip(alpha, slip_m)], alpha=list(alpha), F_c_N=F_c_N, **rest)


CASES = {c.name: c for c in (
    FrictionCase("dahl", "dahl", dict(F_c_N=12.0, sigma_N_per_m=6e5, exponent=1.0), 8.0),
    FrictionCase("dahl_i2", "dahl", dict(F_c_N=15.0, sigma_N_per_m=5e5, exponent=2.0), 10.0),
    FrictionCase("dahl_i05", "dahl", dict(F_c_N=10.0, sigma_N_per_m=8e5, exponent=0.5), 6.0),
    FrictionCase("lugre", "lugre", dict(sigma0_N_per_m=4e5, sigma1_N_s_per_m=200.0, sigma2_N_s_per_m=20.0,
                                        F_c_N=10.0, F_s_N=13.0, v_s_m_per_s=2e-3), 10.0),
    FrictionCase("masing_iwan", "masing_iwan", _iwan([2e-6, 4e-6, 8e-6, 14e-6, 24e-6, 40e-6],
                                                     [1.2, 1.6, 2.0, 2.4, 2.4, 2.4]), 12.0),
    FrictionCase("gms", "gms", _gms([0.1, 0.2, 0.3, 0.4], [3e-6, 6.5e-6, 14e-6, 30e-6], 10.0, F_s_N=12.0,
                                    v_s_m_per_s=5e-3, delta=1.5, C_N_per_s=1e4, sigma2_N_s_per_m=75.0), 14.0),
    FrictionCase("masing_n15", "masing", dict(F_s_N=10.0, x_s_m=20e-6, n=1.5), 10.0),
    FrictionCase("masing_n05", "masing", dict(F_s_N=10.0, x_s_m=20e-6, n=0.5), 10.0),
)}


def friction_level_N(case: FrictionCase) -> float:
    return case.params["F_s_N"] if case.model == "masing" else rival.scales(case.model, case.params)[0]


def length_scale_m(case: FrictionCase) -> float:
    return case.params["x_s_m"] if case.model == "masing" else rival.scales(case.model, case.params)[1]


def friction_resonance_Hz(case: FrictionCase | str) -> float:
    """The case's friction resonance, the centre of its frequency grid (see the module)."""
    c = CASES[case] if isinstance(case, str) else case
    if c.model == "masing":
        return math.sqrt(c.params["F_s_N"] / (c.params["x_s_m"] * c.mass_kg)) / (2 * math.pi)
    return rival.friction_resonance_Hz(c.model, c.params, c.mass_kg)


def small_grid(seed: int, n_levels: int = 3, n_freqs: int = 7) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(level fractions, frequency fractions): a seeded sample of the full grid for a test,
    always with the top level (gross sliding) and frequencies spread over the whole range
    (one drawn from each of ``n_freqs`` equal slices of the grid)."""
    rng = np.random.default_rng(seed)
    levels = sorted(rng.choice(LEVELS[:-1], n_levels - 1, replace=False).tolist()) + [LEVELS[-1]]
    slices = np.array_split(np.arange(len(FREQS)), n_freqs)
    freqs = [FREQS[int(rng.choice(s))] for s in slices]
    return tuple(levels), tuple(freqs)


def write_case(name: str, out_dir, *, levels=LEVELS, freqs=FREQS, settle: int = SETTLE, measure: int = MEASURE,
               noise=NOISE, seed: int = 0) -> tuple[Path, dict]:
    """Write case ``name`` to ``out_dir/name.uff``; (path, truth)."""
    case = CASES[name]
    path = Path(out_dir) / f"{name}.uff"
    f_r = friction_resonance_Hz(case)
    levels_N = [lv * friction_level_N(case) for lv in levels]
    freqs_Hz = [fr * f_r for fr in freqs]
    t0 = time.process_time()
    if case.model == "masing":
        from benchtools.independent_masing import generate_uff

        steps = generate_uff(path, **case.params, mass_kg=case.mass_kg, levels_N=levels_N, freqs_Hz=freqs_Hz,
                             settle=settle, measure=measure, noise=noise, seed=seed)
    else:
        steps = rival.generate_uff(path, case.model, case.params, case.mass_kg, levels_N, freqs_Hz, settle=settle,
                                   measure=measure, noise=noise, seed=seed)
    truth = dict(case=name, friction_model=case.model, params=case.params, mass_kg=case.mass_kg,
                 friction_level_N=friction_level_N(case), length_scale_m=length_scale_m(case),
                 friction_resonance_Hz=f_r, levels_N=levels_N, freqs_Hz=freqs_Hz, settle=settle, measure=measure,
                 noise=tuple(noise), seed=seed, steps=steps, generation_s=time.process_time() - t0)
    return path, truth


def dahl_case(out_dir, **kw):
    """Dahl, i = 1 (F_c 12 N, sigma 6e5 N/m, 8 kg)."""
    return write_case("dahl", out_dir, **kw)


def dahl_exponent2_case(out_dir, **kw):
    """Dahl, i = 2 (F_c 15 N, sigma 5e5 N/m, 10 kg): an n > 1 like shape."""
    return write_case("dahl_i2", out_dir, **kw)


def dahl_exponent05_case(out_dir, **kw):
    """Dahl, i = 0.5 (F_c 10 N, sigma 8e5 N/m, 6 kg): an n < 1 like shape."""
    return write_case("dahl_i05", out_dir, **kw)


def lugre_case(out_dir, **kw):
    """LuGre (sigma_0 4e5 N/m, F_c 10 N, F_s 13 N, v_s 2 mm/s, sigma_1 200, sigma_2 20 N s/m, 10 kg)."""
    return write_case("lugre", out_dir, **kw)


def maxwell_slip_case(out_dir, **kw):
    """Maxwell-slip / Iwan, six elements (12 N, slip 2-40 um, 12 kg)."""
    return write_case("masing_iwan", out_dir, **kw)


def gms_case(out_dir, **kw):
    """Generalized Maxwell-slip, four elements (F_c 10 N, F_s 12 N, C 1e4 N/s, 14 kg)."""
    return write_case("gms", out_dir, **kw)


def masing_case(out_dir, n: float = 1.5, **kw):
    """The Masing control (Sakai's virgin curve, F_s 10 N, x_s 20 um, 10 kg), n = 1.5 or 0.5."""
    name = {1.5: "masing_n15", 0.5: "masing_n05"}.get(n)
    if name is None:
        raise ValueError(f"masing_case: n = {n}: the cases are n = 1.5 and n = 0.5")
    return write_case(name, out_dir, **kw)
