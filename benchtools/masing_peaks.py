"""Brute-force resonances of a simulated pitching rig, computed outside the code under test
(issue 32): the steady state of benchtools/independent_masing.py (scipy's DOP853, written from
the physics notes, no code shared with sim/) at one frequency at a time, from rest, and a
golden-section search on it:

- the feed mode: the peak of compliance_pp = (x_max - x_min) / (2 |F1|) (the seed's Eq. 9);
- the pitching mode: the peak of the drive point's |A1/F1| (the fundamentals).

The rig is given as the ``[rig.model]`` mapping of a rig file (mass, F_s, x_s, n, viscous
damping, speed-dependent friction, the pitching column); the force is an ideal sine (the
twin's shaker is not modelled here: compare against a rig without one).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np

from benchtools.independent_masing import simulate_level

GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


def steady_response(model: Mapping, force_N: float, f_Hz: float, settle: int = 60, measure: int = 4,
                    rtol: float = 1e-9) -> tuple[float, float, float]:
    """(compliance_pp in m/N, |A1/F1| in 1/kg, the energy balance's damping ratio) of the
    steady state at ``f_Hz`` and force amplitude ``force_N``, from rest, after ``settle``
    periods.  The energy balance: |F1| sin(-phase) / (2 m w^2 |X1|) = -Im(H) / (2 m w^2 |H|^2)
    with H = X1/F1 and m the carriage's mass (the feed mode's definition, decision 0056)."""
    pp, acc, H = steady_state(model, force_N, f_Hz, settle, measure, rtol)
    w = 2 * math.pi * f_Hz
    return pp, acc, float(-H.imag / (2 * model["mass_kg"] * w * w * abs(H) ** 2))


def steady_state(model: Mapping, force_N: float, f_Hz: float, settle: int = 60, measure: int = 4,
                 rtol: float = 1e-9) -> tuple[float, float, complex]:
    """(compliance_pp in m/N, |A1/F1| in 1/kg, X1/F1 in m/N) of the steady state at ``f_Hz``
    and force amplitude ``force_N``, from rest, after ``settle`` periods."""
    F_s, x_s, mass = model["F_s_N"], model["x_s_m"], model["mass_kg"]
    ws = math.sqrt(F_s / (x_s * mass))
    pitch = None
    if model.get("pitch_inertia_kg_m2"):
        J, h, e = model["pitch_inertia_kg_m2"], model["drive_height_m"], model["cg_height_m"]
        pitch = (mass * h * h / J, e / h, model["pitch_stiffness_N_m_per_rad"] / (J * ws * ws),
                 model.get("pitch_damping_N_m_s_per_rad", 0.0) / (J * ws))
    speed = model.get("friction_alpha", 0.0) * x_s * ws / model.get("friction_v_ref_m_per_s", 1.0)
    beta = 2 * math.pi * f_Hz / ws
    ((t, u, a, P),) = list(simulate_level(
        model["n"], force_N / F_s, [beta], settle, measure, 128 * beta / (2 * math.pi), rtol=rtol, pitch=pitch,
        viscous=model.get("viscous_N_s_per_m", 0.0) * x_s * ws / F_s, speed=speed))
    # the fundamentals through a Hann window: a free vibration of the other mode (the feed
    # mode barely damped at small amplitude) is not a whole number of the drive's periods and
    # leaks into a plain DFT (0.1 % of |A1/F1| over 4 periods at 0.3 N)
    e1 = np.exp(-1j * beta * t) * np.hanning(t.size)
    p1 = abs(P @ e1)
    pp = 0.5 * (_extremum(u, 1) - _extremum(u, -1)) * x_s / force_N      # the force is an exact sine
    acc = abs(a @ e1) / p1 / mass                     # dimensionless a = x'' / (F_s / m), P = F / F_s
    H = (u @ e1) * x_s / ((P @ e1) * F_s)
    return pp, float(acc), complex(H)


def _extremum(u: np.ndarray, sign: int) -> float:
    """The largest (``sign`` 1) or smallest (-1) value of a smooth sampled record: the vertex
    of the parabola through the extreme sample and its neighbours (the samples' own maximum
    is low by up to 1 - cos(pi / 128) = 3e-4 of the amplitude, as much as the curve falls
    0.2 % off a 8 %-damped peak)."""
    v = sign * u
    i = int(np.argmax(v[1:-1])) + 1
    a, b, c = v[i - 1], v[i], v[i + 1]
    den = a - 2 * b + c
    return sign * float(b - (a - c) ** 2 / (8 * den) if den < 0 else b)


def golden_max(fun: Callable[[float], float], lo: float, hi: float, rel_tol: float = 2e-5) -> float:
    """The maximiser of a unimodal ``fun`` on [lo, hi] (golden-section search, to ``rel_tol``
    of the abscissa)."""
    a, b = lo, hi
    c, d = b - GOLDEN * (b - a), a + GOLDEN * (b - a)
    fc, fd = fun(c), fun(d)
    while (b - a) > rel_tol * (a + b) / 2:
        if fc >= fd:
            b, d, fd = d, c, fc
            c = b - GOLDEN * (b - a)
            fc = fun(c)
        else:
            a, c, fc = c, d, fd
            d = a + GOLDEN * (b - a)
            fd = fun(d)
    return (a + b) / 2


def peak_Hz(model: Mapping, force_N: float, mode: str, lo_Hz: float, hi_Hz: float, scan: int = 9,
            rel_tol: float = 2e-4) -> tuple[float, float, float]:
    """(frequency, value, energy-balance damping ratio there) of the peak of the mode's curve (``mode`` "feed": compliance_pp;
    "pitch": |A1/F1|) in [lo_Hz, hi_Hz]: the largest of ``scan`` log-spaced points, then a
    golden-section search between its neighbours.  Each point from rest, 40 periods settled and
    4 measured (the feed mode, damped >= 4 %: e^-11 of its transient left), or 100 and 40 (the
    pitching mode, ~2 %: 50 periods left 0.1 % of its transient in |A1/F1|, 100 leave e^-12)."""
    k = 0 if mode == "feed" else 1
    settle, measure = (40, 4) if mode == "feed" else (100, 40)
    cache: dict[float, tuple[float, float, float]] = {}

    def fun(f: float) -> float:
        if f not in cache:
            cache[f] = steady_response(model, force_N, f, settle=settle, measure=measure, rtol=1e-7)
        return cache[f][k]
    grid = np.geomspace(lo_Hz, hi_Hz, scan)
    vals = [fun(float(f)) for f in grid]
    i = int(np.argmax(vals))
    if i in (0, scan - 1):
        raise ValueError(f"{mode} peak at the scan's edge {grid[i]:.4g} Hz ({lo_Hz:g}-{hi_Hz:g} Hz)")
    f = golden_max(fun, float(grid[i - 1]), float(grid[i + 1]), rel_tol)
    # finish with the parabola through the three best points (the bracket's width is
    # rel_tol: the vertex is good to a small fraction of it)
    best = sorted(cache, key=lambda x: cache[x][k])[-3:]
    a, b, _ = np.polyfit(np.array(best) - f, [cache[x][k] for x in best], 2)
    if a < 0 and abs(b / (2 * a)) < rel_tol * f:
        f = f - b / (2 * a)
    return f, fun(f), cache[f][2]


# The campaign's rigs (issue 32: two pitching rigs standing in for two lubricants), without the
# twin's shaker (an ideal force source: the integrator above drives an exact sine).
SHAKER_KEYS = ("shaker_force_constant_N_per_A", "shaker_resistance_ohm", "shaker_inductance_H",
               "shaker_armature_mass_kg", "shaker_suspension_N_per_m", "shaker_damping_N_s_per_m")
OIL_B = dict(F_s_N=12.0, x_s_m=7e-6, n=1.2, viscous_N_s_per_m=60.0, pitch_damping_N_m_s_per_rad=25.0,
             friction_alpha=0.8)
OILS = ("A", "B")
LEVELS_N = (0.3, 1.0, 3.0, 10.0)
BOUNDS_HZ = {"feed": (30.0, 140.0), "pitch": (190.0, 260.0)}     # the plan's grid starts at 30 Hz


def oil_model(oil: str) -> dict:
    """The ``[rig.model]`` of bench/defaults/sim_rig_pitch.toml ("A": speed-dependent friction)
    or its variant "B" (viscous damping, a stiffer, rounder friction, a more damped pitch),
    without the shaker."""
    import tomllib
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / "bench" / "defaults" / "sim_rig_pitch.toml"
    with open(path, "rb") as fh:
        model = tomllib.load(fh)["rig"]["model"]
    model = {k: v for k, v in model.items() if k not in SHAKER_KEYS}
    return dict(model, **OIL_B) if oil == "B" else model


def plain_model() -> dict:
    """The ``[rig.model]`` of bench/defaults/sim_rig.toml (the demo's plain rig: no pitching
    mode, no viscous or speed-dependent effects), without the shaker."""
    import tomllib
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / "bench" / "defaults" / "sim_rig.toml"
    with open(path, "rb") as fh:
        model = tomllib.load(fh)["rig"]["model"]
    return {k: v for k, v in model.items() if k not in SHAKER_KEYS}


# (oil, mode, level N) -> (the brute-force peak in Hz, the feed energy balance's ratio there:
# a damping ratio of the feed mode only; the pitch rows' number is no ratio of the pitching
# mode), printed by ``python -m benchtools.masing_peaks`` (golden section to 0.02 %, then a
# parabola; about 80 s a feed value, 130 s a pitch value on a loaded core).
# None: no peak inside the bounds (the curve rises to the grid's lowest frequency).
REFERENCES: dict[tuple[str, str, float], tuple[float, float] | None] = {
    ('A', 'feed', 0.3): (72.4656, 0.04454),   # peak 5.3889e-06
    ('A', 'feed', 1.0): (68.5332, 0.07990),   # peak 3.4113e-06
    ('A', 'feed', 3.0): (59.5208, 0.16573),   # peak 2.1811e-06
    ('A', 'feed', 10.0): (40.8283, 0.49584),   # peak 1.5498e-06
    ('B', 'feed', 0.3): (102.6016, 0.06216),   # peak 1.9341e-06
    ('B', 'feed', 1.0): (94.3419, 0.09341),   # peak 1.5167e-06
    ('B', 'feed', 3.0): (83.9633, 0.15767),   # peak 1.1378e-06
    ('B', 'feed', 10.0): (70.4171, 0.34761),   # peak 7.5726e-07
    ('A', 'pitch', 0.3): (206.1669, -0.04478),   # peak 0.79532
    ('A', 'pitch', 1.0): (205.5479, -0.04762),   # peak 0.7733
    ('A', 'pitch', 3.0): (204.8376, -0.05273),   # peak 0.73308
    ('A', 'pitch', 10.0): (203.9368, -0.06493),   # peak 0.65273
    ('B', 'pitch', 0.3): (237.4567, -0.22396),   # peak 0.23164
    ('B', 'pitch', 1.0): (232.1001, -0.20578),   # peak 0.24271
    ('B', 'pitch', 3.0): (226.5913, -0.19417),   # peak 0.25633
    ('B', 'pitch', 10.0): (220.5698, -0.19314),   # peak 0.27294
}


# A first pass (the same search to 0.05 %, 9 points over BOUNDS_HZ): where the second starts.
PRIOR_HZ = {("A", "feed", 0.3): 72.456, ("A", "feed", 1.0): 68.468, ("A", "feed", 3.0): 59.485,
            ("A", "feed", 10.0): 40.908, ("A", "pitch", 0.3): 206.05, ("A", "pitch", 1.0): 205.52,
            ("A", "pitch", 3.0): 204.83, ("A", "pitch", 10.0): 203.94, ("B", "feed", 3.0): 83.772,
            ("B", "feed", 10.0): 70.605, ("B", "pitch", 0.3): 238.0, ("B", "pitch", 1.0): 232.1,
            ("B", "pitch", 3.0): 226.7, ("B", "pitch", 10.0): 220.52}


if __name__ == "__main__":
    import sys
    import time
    for oil in OILS:
        for mode in [m for m in ("feed", "pitch") if m in sys.argv or not {"feed", "pitch"} & set(sys.argv)]:
            for level in LEVELS_N:
                if (oil, mode, level) in REFERENCES and "--all" not in sys.argv:
                    continue
                t0 = time.perf_counter()
                prior = PRIOR_HZ.get((oil, mode, level))
                try:
                    if prior:
                        f, v, z = peak_Hz(oil_model(oil), level, mode, 0.99 * prior, 1.01 * prior, scan=5)
                    else:
                        f, v, z = peak_Hz(oil_model(oil), level, mode, *BOUNDS_HZ[mode])
                except ValueError as e:
                    print(f"    ({oil!r}, {mode!r}, {level!r}): None,   # {e}", flush=True)
                    continue
                print(f"    ({oil!r}, {mode!r}, {level!r}): ({f:.4f}, {z:.5f}),   # peak {v:.5g}, "
                      f"{time.perf_counter() - t0:.0f} s", flush=True)
    sys.exit(0)
