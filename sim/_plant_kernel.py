"""Compiled RK4 kernel for the simulated rig with its optional effects on.

The plain rig (Masing friction, viscous damping, a linear spring) runs on
:func:`sim._kernel.rk4_run`, which stays as fast as it is.  As soon as one of the effects
below is switched on, :class:`sim.rig.SimulatedRig` runs this kernel instead.  State:
feed displacement u = x / x_s and its rate v, pitch angle th (rad) and its rate w.

    m x'' + m e th'' = P - F(x, x') - c x' - c2 x'|x'| - k x - k3 x^3     (feed)
    m e x'' + J th'' = h P - k_th th - c_th th'                            (pitch)
    F(x, x')         = F_Masing(x) * (1 + alpha |x'| / v_ref) * (1 + a sign F_Masing)

Both right-hand sides are scaled by 1/F_s, r1 (dimensionless) and r2 (m); the constant
mass matrix [[m, m e], [m e, J]] is inverted once (:mod:`sim.plant_effects`), so
u'' = a11 r1 + a12 r2 and th'' = a21 r1 + a22 r2.  With the pitch off (J = 0) a12 = a21
= a22 = 0 and a11 = omega_s^2, so th stays 0.

Each effect is one small function here (:func:`rate_factor`, :func:`cubic_spring`,
:func:`pitch_moment`, :func:`accelerations`), tested on its own.  Reversals of the feed
motion are located inside the step exactly as in :mod:`sim._kernel` (the friction state
depends on u only).

``coef`` layout (float64 array, built by :func:`sim.plant_effects.coefficients`):
0 a11, 1 a12, 2 a21, 3 a22, 4 c x_s/F_s, 5 k x_s/F_s, 6 k3 x_s^3/F_s,
7 alpha x_s/v_ref, 8 h (m), 9 k_th/F_s, 10 c_th/F_s,
11 c2 x_s^2/F_s (quadratic damping), 12 a (friction asymmetry).
"""

from __future__ import annotations

import math

from numba import njit

from ._kernel import velocity_root
from .masing import active_depth, branch_force, friction, push_reversal

N_COEF = 13


@njit(cache=True, nogil=True, inline="always")
def rate_factor(v, alpha_v):
    """Velocity dependence of rolling friction: 1 + alpha |x'| / v_ref (alpha_v = alpha x_s / v_ref)."""
    return 1.0 + alpha_v * abs(v)


@njit(cache=True, nogil=True, inline="always")
def cubic_spring(u, k3):
    """Hardening spring force k3 x^3 / F_s (k3 here = k3 x_s^3 / F_s)."""
    return k3 * u * u * u


@njit(cache=True, nogil=True, inline="always")
def pitch_moment(Pn, th, w, coef):
    """Pitch right-hand side / F_s (m): h P - k_th th - c_th th'."""
    return coef[8] * Pn - coef[9] * th - coef[10] * w


@njit(cache=True, nogil=True, inline="always")
def accelerations(r1, r2, coef):
    """(u'', th'') from the scaled right-hand sides through the inverted mass matrix."""
    return coef[0] * r1 + coef[1] * r2, coef[2] * r1 + coef[3] * r2


@njit(cache=True, nogil=True, inline="always")
def _deriv(u, v, th, w, Pn, k, su, sF, d, lam, kind, p, coef):
    """(u'', th'', F_Masing/F_s) for the scaled drive force Pn = P / F_s."""
    F = friction(u, k, su, sF, d, lam, kind, p)
    r1 = (Pn - F * rate_factor(v, coef[7]) * (1.0 + coef[12] * math.copysign(1.0, F)) - coef[4] * v
          - coef[11] * v * abs(v) - coef[5] * u - cubic_spring(u, coef[6]))
    r2 = pitch_moment(Pn, th, w, coef)
    a, al = accelerations(r1, r2, coef)
    return a, al, F


@njit(cache=True, nogil=True)
def _step(u, v, th, w, h, P0, Ph, P1, k, su, sF, d, lam, kind, p, coef):
    """One classic RK4 step of the 4-state system; returns the new state and u'' at the start."""
    a1, b1, _ = _deriv(u, v, th, w, P0, k, su, sF, d, lam, kind, p, coef)
    u2, v2, t2, w2 = u + 0.5 * h * v, v + 0.5 * h * a1, th + 0.5 * h * w, w + 0.5 * h * b1
    a2, b2, _ = _deriv(u2, v2, t2, w2, Ph, k, su, sF, d, lam, kind, p, coef)
    u3, v3, t3, w3 = u + 0.5 * h * v2, v + 0.5 * h * a2, th + 0.5 * h * w2, w + 0.5 * h * b2
    a3, b3, _ = _deriv(u3, v3, t3, w3, Ph, k, su, sF, d, lam, kind, p, coef)
    u4, v4, t4, w4 = u + h * v3, v + h * a3, th + h * w3, w + h * b3
    a4, b4, _ = _deriv(u4, v4, t4, w4, P1, k, su, sF, d, lam, kind, p, coef)
    un = u + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
    vn = v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    tn = th + h / 6.0 * (w + 2.0 * w2 + 2.0 * w3 + w4)
    wn = w + h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
    return un, vn, tn, wn, a1


@njit(cache=True, nogil=True)
def _step_at(u, v, th, w, t, h, k, su, sF, d, lam, kind, p, gamma, omega, phase, bias, coef):
    """RK4 step of arbitrary size from time t (used to split a step at a reversal)."""
    P0 = gamma * math.sin(omega * t + phase) + bias
    Ph = gamma * math.sin(omega * (t + 0.5 * h) + phase) + bias
    P1 = gamma * math.sin(omega * (t + h) + phase) + bias
    return _step(u, v, th, w, h, P0, Ph, P1, k, su, sF, d, lam, kind, p, coef)


@njit(cache=True, nogil=True)
def plant_run(u, v, th, w, t0, k, d, su, sF, lam, kind, p, gamma, omega, phase, bias, coef,
              h, nsteps, rec_every, rec):
    """Integrate ``nsteps`` RK4 steps of size ``h`` from time ``t0``.

    ``gamma``, ``bias``: drive amplitude and static force over F_s.  ``rec`` is an (m, 6)
    array receiving (t, u, u', u'', th'', F_Masing/F_s) every ``rec_every`` steps, starting
    with the initial state.  Returns (u, v, th, w, k, d, su, sF).
    """
    nrec = rec.shape[0]
    j = 0
    for i in range(nsteps + 1):
        t = t0 + i * h
        if j < nrec and i % rec_every == 0:
            Pn = gamma * math.sin(omega * t + phase) + bias
            a, al, F = _deriv(u, v, th, w, Pn, k, su, sF, d, lam, kind, p, coef)
            rec[j, 0] = t
            rec[j, 1] = u
            rec[j, 2] = v
            rec[j, 3] = a
            rec[j, 4] = al
            rec[j, 5] = F
            j += 1
        if i == nsteps:
            break
        un, vn, tn, wn, a0 = _step_at(u, v, th, w, t, h, k, su, sF, d, lam, kind, p,
                                      gamma, omega, phase, bias, coef)
        if d == 0.0:
            if vn > 0.0:
                d = 1.0
            elif vn < 0.0:
                d = -1.0
            u, v, th, w = un, vn, tn, wn
        elif d * vn < 0.0:
            # The feed motion reverses inside this step: split it at the zero of u'.
            if d * v > 0.0:
                Pe = gamma * math.sin(omega * (t + h) + phase) + bias
                a_end, _, _ = _deriv(un, vn, tn, wn, Pe, k, su, sF, d, lam, kind, p, coef)
                theta = velocity_root(v, vn, a0 * h, a_end * h)
            else:
                theta = 0.0
            h1 = theta * h
            if h1 > 0.0:
                u, v, th, w, _ = _step_at(u, v, th, w, t, h1, k, su, sF, d, lam, kind, p,
                                          gamma, omega, phase, bias, coef)
            k = active_depth(u, k, su, d)
            F_r = branch_force(u, k, su, sF, lam, kind, p)
            k, su, sF = push_reversal(u, F_r, k, su, sF)
            d = -d
            u, v, th, w, _ = _step_at(u, v, th, w, t + h1, h - h1, k, su, sF, d, lam, kind, p,
                                      gamma, omega, phase, bias, coef)
        else:
            u, v, th, w = un, vn, tn, wn
        k = active_depth(u, k, su, d)
    return u, v, th, w, k, d, su, sF
