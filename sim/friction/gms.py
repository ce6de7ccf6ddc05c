"""The Generalized Maxwell-Slip (GMS) friction model (Al-Bender, Lampaert, Swevers, IEEE TAC
50(11), 1883-1887, 2005; Chaos 14(2), 446-460, 2004).

N elements in parallel, element i of stiffness k_i and share alpha_i of the Stribeck curve
s(v) = F_c + (F_s - F_c) exp(-|v/v_s|^delta) (the shares sum to 1).  An element **sticks**,
dF_i/dt = k_i v, until its force reaches its share in the direction of motion,
F_i sgn(v) = alpha_i s(v); it then **slides** by the attraction law of the TAC paper,

    dF_i/dt = sgn(v) C (alpha_i - F_i / s(v))      (s taken with the sign of v)

i.e. F_i is drawn towards alpha_i s(v) sgn(v) with the time constant s(v)/C (C, in N/s,
the attraction parameter: the frictional lag), and slides until the velocity goes through
zero, where it sticks again.  F = sum_i F_i + sigma_2 v.  (The 2003/2004 papers write the
rate C (1 - F_i / (alpha_i s(v))): the same attractor, 1/alpha_i faster per element; the
2005 form is the one used, as in benchtools/independent_friction.py and the open
implementations that read it the same way.)

Time-domain update (:func:`gms_advance`): the state is the N element forces, the N modes
(0 sticking, 1 sliding) and the direction of the last motion (0 before any).  Over a
segment of travel dx in time dt the velocity is taken linear in time, from
2 dx/dt - v_end to v_end; a reversal (dx against the last direction) makes every element
stick; a sticking element moves by k_i dx and, if that takes it past its share at the
segment's end (alpha_i s(v_end): the share rises as the motion slows, and an element
creeping up to a rising share must not be declared sliding early), slides from where its
guard F_i sgn(v) - alpha_i s(v) crossed zero (interpolated linearly) for the rest of the
segment; a sliding element relaxes exactly with s frozen at the mean velocity of the time it
slides, F = a + (F_i - a) exp(-C t / s), a = alpha_i s sgn(dx) (second order in the
segment's length).  The force is taken at the segment's end with its velocity v_end.
The steady periodic force is that update run period by period to a periodic state
(:func:`~sim.friction._periodic.periodic_row`): an element that slides in a period reaches
its attractor and forgets its past, one that sticks throughout keeps the offset of where
the path started (no harmonics).

Special cases: with F_s = F_c the attractor is constant and an element that reaches it
stays there: the GMS is then the Maxwell-slip / Iwan model (:mod:`sim.friction.iwan`) with
slip forces alpha_i F_c, for any C (one element: a spring k in series with a Coulomb
slider, the Jenkins element).  What sets it apart in stepped-sine data: non-local memory
like Masing (the Maxwell-slip structure) with a Stribeck curve and a frictional lag, so the
loops depend on the rate once elements slide; in gross sliding at a steady speed v the
force is s(v) + sigma_2 v.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numba import njit

from ._base import FrictionModel, Parameter, ParameterProblem, Problem, stribeck_order
from ._periodic import periodic_row

SCALARS = 6         # F_c, F_s, v_s, delta, C, sigma_2 before the elements' k and alpha in the kernels' array
SHARES_SUM_TOL = 1e-6


@njit(cache=True, nogil=True, inline="always")
def _stribeck(F_c, F_s, v_s, delta, v):
    return F_c + (F_s - F_c) * math.exp(-abs(v / v_s) ** delta)


@njit(cache=True, nogil=True)
def gms_advance(p, state, dx, dt, v_end):
    """The GMS force at the end of a travel ``dx`` (m) in ``dt`` (s), velocity ``v_end``
    (m/s) there; ``state`` = N element forces (N), N modes, the last direction; updated."""
    F_c, F_s, v_s, delta, C, s2 = p[0], p[1], p[2], p[3], p[4], p[5]
    N = (p.shape[0] - SCALARS) // 2
    if dx != 0.0:
        sg = 1.0 if dx > 0.0 else -1.0
        if state[2 * N] != sg:                  # the velocity went through zero: every element sticks
            for i in range(N):
                state[N + i] = 0.0
            state[2 * N] = sg
        v_mean = dx / dt if dt > 0.0 else 0.0
        v_start = 2.0 * v_mean - v_end          # the velocity taken linear in time over the segment
        s = _stribeck(F_c, F_s, v_s, delta, v_mean)
        s_end = _stribeck(F_c, F_s, v_s, delta, v_end)
        s_start = _stribeck(F_c, F_s, v_s, delta, v_start)
        for i in range(N):
            k = p[SCALARS + i]
            alpha = p[SCALARS + N + i]
            Fi = state[i]
            t_slide = dt
            s_slide = s
            if state[N + i] == 0.0:
                Fn = Fi + k * dx
                after = sg * Fn - alpha * s_end     # the share's guard at the segment's end
                if after <= 0.0:
                    state[i] = Fn
                    continue
                before = sg * Fi - alpha * s_start
                frac = before / (before - after) if before < 0.0 else 0.0   # where the guard crossed zero
                Fi = Fi + frac * k * dx
                t_slide = (1.0 - frac) * dt
                s_slide = _stribeck(F_c, F_s, v_s, delta, v_start + (v_end - v_start) * 0.5 * (1.0 + frac))
                state[N + i] = 1.0
            a = sg * alpha * s_slide            # the attractor in the direction of motion
            # t_slide is nan (0 x inf) only in the virgin call at an element just reaching its share
            state[i] = a + (Fi - a) * (math.exp(-C * t_slide / s_slide) if t_slide > 0.0 else 1.0)
    total = s2 * v_end
    for i in range(N):
        total += state[i]
    return total


@njit(cache=True, nogil=True)
def gms_rows(p, paths, vel, dts, state_size, scale, out):
    worst = 0
    for i in range(paths.shape[0]):
        worst = max(worst, periodic_row(gms_advance, p, paths[i], vel[i], dts[i], state_size, scale, out[i]))
    return worst


class GMS(FrictionModel):
    name = "gms"
    label = "Generalized Maxwell-Slip"
    reference = ("F. Al-Bender, V. Lampaert, J. Swevers, The generalized Maxwell-slip model: a novel model for "
                 "friction simulation and compensation, IEEE Trans. Automatic Control 50(11), 1883-1887, 2005")
    rate_dependent = True
    advance = staticmethod(gms_advance)
    rows = staticmethod(gms_rows)
    parameters = (
        Parameter("F_c_N", "N", 0.0, 1e6, "Coulomb (sliding) friction force", 10.0),
        Parameter("F_s_N", "N", 0.0, 1e6, "breakaway (static) friction force, at least F_c", 12.0),
        Parameter("v_s_m_per_s", "m/s", 0.0, 10.0, "Stribeck velocity", 5e-3),
        Parameter("delta", "1", 0.0, 10.0, "Stribeck shape exponent (2: LuGre's Gaussian)", 2.0, log=False),
        Parameter("C_N_per_s", "N/s", 0.0, 1e12, "attraction parameter: the sliding elements' rate", 1e4),
        Parameter("sigma2_N_s_per_m", "N s/m", 0.0, 1e8, "viscous friction sigma_2", 20.0, log=False, lo_open=False),
        Parameter("k_N_per_m", "N/m", 0.0, 1e12, "stiffness k_i of element i", 2.5e5, elements=True,
                  typical_elements=(3.3e5, 3.1e5, 2.1e5, 1.3e5)),
        Parameter("alpha", "1", 0.0, 1.0, "share alpha_i of the Stribeck curve of element i (they sum to 1)", 0.25,
                  lo_open=True, elements=True, typical_elements=(0.1, 0.2, 0.3, 0.4)),
    )

    def friction_level(self, values: Mapping[str, Any]) -> float:
        return float(values["F_s_N"])        # s(0)

    @property
    def state_size(self) -> int:
        raise NotImplementedError(f"{self.name}: the state grows with the number of elements; use state_length(values)")

    def state_length(self, values: Mapping[str, Any]) -> int:
        return 2 * self.n_elements(values) + 1

    def constraints(self, values: Mapping[str, Any]) -> list[Problem]:
        out = stribeck_order(self.name, values)
        total = float(np.sum(np.asarray(values["alpha"], dtype=np.float64)))
        if abs(total - 1.0) > SHARES_SUM_TOL:
            out.append(Problem(self.name, "alpha", ParameterProblem.SUM, total, 1.0, 1.0))
        return out
