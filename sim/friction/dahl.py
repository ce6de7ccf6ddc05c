"""Dahl's friction model (Dahl 1968, 1976): rate independent, local memory.

    dF/dx = sigma |1 - F/F_c sgn(v)|^i sgn(1 - F/F_c sgn(v))

F_c the Coulomb (sliding) force, sigma the rest stiffness (dF/dx at F = 0), i the shape
exponent (1 the common form).  Along a monotone segment of travel s = |dx| in the direction
sg = sgn(dx), y = 1 - sg F / F_c obeys dy/ds = -(sigma / F_c) |y|^i sgn(y), which has a
closed form (:func:`dahl_advance`), so a sampled path is followed exactly whatever its
step: y0 exp(-sigma s / F_c) for i = 1, (|y0|^(1-i) + (i - 1) sigma s / F_c)^(1/(1-i)) for
i > 1, and the same with (1 - i) for i < 1, which reaches y = 0 (F = sg F_c, sliding) in a
finite travel.  What sets it apart from Masing in stepped-sine data: the branch after a
reversal depends on the force at the reversal (local memory), so loops at different
amplitudes are not scaled copies of one virgin curve; in steady symmetric oscillation of
amplitude X with i = 1 the reversal force is F_c tanh(sigma X / F_c).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from numba import njit

from ._base import FrictionModel, Parameter
from ._periodic import one_period, secant_state


@njit(cache=True, nogil=True)
def dahl_advance(p, state, dx, dt, v_end):
    """Dahl's force after a travel ``dx`` (m) from the force ``state[0]`` (N); updates it
    (rate independent: ``dt`` and ``v_end`` unused)."""
    if dx == 0.0:
        return state[0]
    F_c, sigma, i = p[0], p[1], p[2]
    sg = 1.0 if dx > 0.0 else -1.0
    y = 1.0 - sg * state[0] / F_c
    s = sigma * abs(dx) / F_c
    ay = abs(y)
    if ay > 0.0:
        if i == 1.0:
            ay = ay * math.exp(-s)
        elif i > 1.0:
            ay = (ay ** (1.0 - i) + (i - 1.0) * s) ** (1.0 / (1.0 - i))
        else:
            t = ay ** (1.0 - i) - (1.0 - i) * s
            ay = t ** (1.0 / (1.0 - i)) if t > 0.0 else 0.0
    F = sg * F_c * (1.0 - (ay if y >= 0.0 else -ay))
    state[0] = F
    return F


@njit(cache=True, nogil=True)
def _runs(x):
    """The signed travels of the monotone runs of one period ``x`` (the last sample
    followed by the first), in order, from sample 0."""
    M = x.shape[0]
    travel = np.empty(M)
    k, start, sg_prev = 0, x[0], 0.0
    for j in range(M):
        jn = j + 1 if j + 1 < M else 0
        dx = x[jn] - x[j]
        if dx == 0.0:
            continue
        sg = 1.0 if dx > 0.0 else -1.0
        if sg_prev != 0.0 and sg != sg_prev:
            travel[k] = x[j] - start
            k += 1
            start = x[j]
        sg_prev = sg
    travel[k] = x[0] - start
    return travel[:k + 1]


@njit(cache=True, nogil=True, inline="always")
def _period(advance, p, state, travel, v, dt, out):
    """The period map taken a run at a time (``v``, ``dt``, ``out`` unused: the signature of
    :func:`~sim.friction._periodic.one_period`)."""
    for t in travel:
        advance(p, state, t, math.inf, 0.0)


@njit(cache=True, nogil=True)
def dahl_rows(p, paths, vel, dts, state_size, scale, out):
    """:func:`sim.friction._periodic.periodic_row` for Dahl, its period map taken a monotone
    run at a time: the closed form of :func:`dahl_advance` over a run's whole travel is the
    same as over its samples (a flow: exp(-s) multiplies, |y|^(1 - i) adds), so the fixed
    point costs a few operations a period instead of one per sample; the forces then come
    from one period sample by sample, as before (decision 0091)."""
    worst = 0
    for i in range(paths.shape[0]):
        x = paths[i]
        travel = _runs(x)
        s = np.zeros(1)
        dahl_advance(p, s, x[0], math.inf, 0.0)      # virgin, quasi-static, to the first sample
        used = secant_state(_period, dahl_advance, p, s, travel, travel, 0.0, travel, scale)
        one_period(dahl_advance, p, s, x, vel[i], dts[i], out[i])
        worst = max(worst, used)
    return worst


class Dahl(FrictionModel):
    name = "dahl"
    label = "Dahl"
    reference = "P. R. Dahl, A solid friction model, Aerospace Corp. TOR-0158(3107-18)-1, 1968; AIAA J. 14(9), 1976"
    rate_dependent = False
    advance = staticmethod(dahl_advance)
    rows = staticmethod(dahl_rows)
    parameters = (
        Parameter("F_c_N", "N", 0.0, 1e6, "Coulomb (sliding) friction force", 10.0),
        Parameter("sigma_N_per_m", "N/m", 0.0, 1e12, "rest stiffness: dF/dx at zero force", 1e6),
        Parameter("exponent", "1", 0.05, 10.0, "shape exponent i (1: the common form)", 1.0),
    )

    def friction_level(self, values: Mapping[str, float]) -> float:
        return float(values["F_c_N"])
