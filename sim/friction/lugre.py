"""The LuGre friction model (Canudas de Wit, Olsson, Astrom, Lischinsky, IEEE TAC 40(3), 1995).

    dz/dt = v - sigma_0 |v| z / g(v),   g(v) = F_c + (F_s - F_c) exp(-(v/v_s)^2),
    F = sigma_0 z + sigma_1 dz/dt + sigma_2 v

z is the bristles' mean deflection (m), sigma_0 their stiffness, sigma_1 their
(micro-)damping, sigma_2 the viscous friction, g the Stribeck curve from the breakaway
force F_s at rest to the Coulomb force F_c, v_s the Stribeck velocity.  (The paper writes
g as a length, F_c/sigma_0 + ...; here g is a force and sigma_0 divides it: the same law.)

Time-domain update (:func:`lugre_advance`): over a segment of travel dx in time dt the
velocity is taken as its mean dx/dt, and with g frozen at that velocity the bristle law
is linear in z along the travel, dz/dx = 1 - sgn(dx) sigma_0 z / g, so

    z_end = z_ss + (z - z_ss) exp(-sigma_0 |dx| / g),   z_ss = sgn(dx) g / sigma_0,

exact for a segment of constant velocity (an exponential integrator; second order in the
segment's length for a varying one, the mean being the midpoint velocity); the force is
then taken at the segment's end with its velocity v_end.  A stiff bristle (a relaxation
length g/sigma_0 much shorter than a segment) is no harder: the update is unconditionally
stable.  The steady periodic force is that update run to the periodic z (one float,
:func:`~sim.friction._periodic.periodic_row`'s secant).

What sets it apart in stepped-sine data: at low speed (|v| << v_s, and sigma_1 |dz/dt|,
sigma_2 |v| small against F_s) it is Dahl's model with exponent 1, F_c -> F_s and sigma ->
sigma_0 (local memory: the branch after a reversal depends on the reversal force); above
that the loops depend on the rate (the Stribeck curve, the damping terms), and in gross
sliding at a steady speed v the force is g(v) + sigma_2 v.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from numba import njit

from ._base import FrictionModel, Parameter, Problem, stribeck_order
from ._periodic import periodic_row


@njit(cache=True, nogil=True)
def lugre_advance(p, state, dx, dt, v_end):
    """LuGre's force at the end of a travel ``dx`` (m) in ``dt`` (s), velocity ``v_end``
    (m/s) there; ``state[0]`` is the bristles' deflection z (m), updated."""
    s0, s1, s2, F_c, F_s, v_s = p[0], p[1], p[2], p[3], p[4], p[5]
    z = state[0]
    if dx != 0.0:
        sg = 1.0 if dx > 0.0 else -1.0
        g = F_c
        if dt > 0.0:
            r = dx / (dt * v_s)
            g = F_c + (F_s - F_c) * math.exp(-r * r)
        z_ss = sg * g / s0
        z = z_ss + (z - z_ss) * math.exp(-s0 * abs(dx) / g)
        state[0] = z
    r = v_end / v_s
    g_end = F_c + (F_s - F_c) * math.exp(-r * r)
    z_dot = v_end - s0 * abs(v_end) * z / g_end
    return s0 * z + s1 * z_dot + s2 * v_end


@njit(cache=True, nogil=True)
def lugre_rows(p, paths, vel, dts, state_size, scale, out):
    worst = 0
    for i in range(paths.shape[0]):
        worst = max(worst, periodic_row(lugre_advance, p, paths[i], vel[i], dts[i], state_size, scale, out[i]))
    return worst


class LuGre(FrictionModel):
    name = "lugre"
    label = "LuGre"
    reference = ("C. Canudas de Wit, H. Olsson, K. J. Astrom, P. Lischinsky, A new model for control of systems "
                 "with friction, IEEE Trans. Automatic Control 40(3), 419-425, 1995")
    rate_dependent = True
    advance = staticmethod(lugre_advance)
    rows = staticmethod(lugre_rows)
    parameters = (
        Parameter("sigma0_N_per_m", "N/m", 0.0, 1e12, "bristle stiffness sigma_0: dF/dx at rest", 4e5),
        Parameter("sigma1_N_s_per_m", "N s/m", 0.0, 1e8, "bristle (micro-)damping sigma_1", 200.0, log=False,
                  lo_open=False),
        Parameter("sigma2_N_s_per_m", "N s/m", 0.0, 1e8, "viscous friction sigma_2", 20.0, log=False, lo_open=False),
        Parameter("F_c_N", "N", 0.0, 1e6, "Coulomb (sliding) friction force", 10.0),
        Parameter("F_s_N", "N", 0.0, 1e6, "breakaway (static) friction force, at least F_c", 13.0),
        Parameter("v_s_m_per_s", "m/s", 0.0, 10.0, "Stribeck velocity", 2e-3),
    )

    def friction_level(self, values: Mapping[str, Any]) -> float:
        return float(values["F_s_N"])        # g(0): what it saturates at in slow sliding

    def state_scale(self, values: Mapping[str, Any]) -> float:
        return float(values["F_s_N"]) / float(values["sigma0_N_per_m"])       # z is a length

    def constraints(self, values: Mapping[str, Any]) -> list[Problem]:
        return stribeck_order(self.name, values)

