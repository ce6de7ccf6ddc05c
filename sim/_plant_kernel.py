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
:func:`pitch_moment`, :func:`accelerations`, :func:`shaker`), tested on its own.

With the shaker model on (decision 0025) the drive P in both equations is the force at the
impedance head, P = Bl i - k_a x_d - c_a x_d' - m_a x_d'' (x_d = x + h th, the drive point),
the armature mass m_a is part of the mass matrix, and a fifth state q = Bl i / F_s (the
coil force) follows the coil, tau q' = Pn - q - Bl^2/(R F_s) x_d' with tau = L/R and Pn the
blocked force (generator drive) over F_s; with L = 0, q is that algebraic value.  Reversals of the feed
motion are located inside the step exactly as in :mod:`sim._kernel` (the friction state
depends on u only).

``coef`` layout (float64 array, built by :func:`sim.plant_effects.coefficients`):
0 a11, 1 a12, 2 a21, 3 a22, 4 c x_s/F_s, 5 k x_s/F_s, 6 k3 x_s^3/F_s,
7 alpha x_s/v_ref, 8 h (m), 9 k_th/F_s, 10 c_th/F_s; the shaker (indices S_*): 11 on (1/0),
12 tau = L/R (s), 13 Bl^2/(R F_s) (s/m), 14 k_a/F_s (1/m), 15 c_a/F_s (s/m), 16 m_a/F_s
(s^2/m), 17 x_s (m); 18 c2 x_s^2/F_s (quadratic damping, Q_DAMP), 19 a (friction asymmetry, ASYM).
"""

from __future__ import annotations

import math

from numba import njit

from ._kernel import velocity_root
from .masing import active_depth, branch_force, friction, push_reversal

N_COEF = 20
S_ON, S_TAU, S_BEMF, S_KA, S_CA, S_MA, S_XS = 11, 12, 13, 14, 15, 16, 17
Q_DAMP, ASYM = 18, 19


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
def shaker(Pn, q, xd, xd_rate, coef):
    """Electrodynamic shaker (decision 0025): (drive force at the head without the armature's
    inertia, q') / F_s.  Pn: blocked force / F_s; q: coil force / F_s; x_d, x_d': drive point."""
    if coef[S_ON] == 0.0:
        return Pn, 0.0
    if coef[S_TAU] > 0.0:
        coil, dq = q, (Pn - q - coef[S_BEMF] * xd_rate) / coef[S_TAU]
    else:
        coil, dq = Pn - coef[S_BEMF] * xd_rate, 0.0
    return coil - coef[S_KA] * xd - coef[S_CA] * xd_rate, dq


@njit(cache=True, nogil=True, inline="always")
def _deriv(u, v, th, w, q, Pn, k, su, sF, d, lam, kind, p, coef):
    """(u'', th'', F_Masing/F_s, q', P_d/F_s) for the scaled blocked drive force Pn = P / F_s;
    P_d is the drive at the head without the armature's inertia (Pn itself, shaker off)."""
    F = friction(u, k, su, sF, d, lam, kind, p)
    Pd, dq = shaker(Pn, q, coef[S_XS] * u + coef[8] * th, coef[S_XS] * v + coef[8] * w, coef)
    r1 = (Pd - F * rate_factor(v, coef[7]) * (1.0 + coef[ASYM] * math.copysign(1.0, F)) - coef[4] * v
          - coef[Q_DAMP] * v * abs(v) - coef[5] * u - cubic_spring(u, coef[6]))
    r2 = pitch_moment(Pd, th, w, coef)
    a, al = accelerations(r1, r2, coef)
    return a, al, F, dq, Pd


@njit(cache=True, nogil=True)
def _step(u, v, th, w, q, h, P0, Ph, P1, k, su, sF, d, lam, kind, p, coef):
    """One classic RK4 step of the 5-state system; returns the new state and u'' at the start."""
    a1, b1, _, e1, _ = _deriv(u, v, th, w, q, P0, k, su, sF, d, lam, kind, p, coef)
    u2, v2, t2, w2, q2 = u + 0.5 * h * v, v + 0.5 * h * a1, th + 0.5 * h * w, w + 0.5 * h * b1, q + 0.5 * h * e1
    a2, b2, _, e2, _ = _deriv(u2, v2, t2, w2, q2, Ph, k, su, sF, d, lam, kind, p, coef)
    u3, v3, t3, w3, q3 = u + 0.5 * h * v2, v + 0.5 * h * a2, th + 0.5 * h * w2, w + 0.5 * h * b2, q + 0.5 * h * e2
    a3, b3, _, e3, _ = _deriv(u3, v3, t3, w3, q3, Ph, k, su, sF, d, lam, kind, p, coef)
    u4, v4, t4, w4, q4 = u + h * v3, v + h * a3, th + h * w3, w + h * b3, q + h * e3
    a4, b4, _, e4, _ = _deriv(u4, v4, t4, w4, q4, P1, k, su, sF, d, lam, kind, p, coef)
    un = u + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
    vn = v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    tn = th + h / 6.0 * (w + 2.0 * w2 + 2.0 * w3 + w4)
    wn = w + h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
    qn = q + h / 6.0 * (e1 + 2.0 * e2 + 2.0 * e3 + e4)
    return un, vn, tn, wn, qn, a1


@njit(cache=True, nogil=True)
def _step_at(u, v, th, w, q, t, h, k, su, sF, d, lam, kind, p, gamma, omega, phase, bias, coef):
    """RK4 step of arbitrary size from time t (used to split a step at a reversal)."""
    P0 = gamma * math.sin(omega * t + phase) + bias
    Ph = gamma * math.sin(omega * (t + 0.5 * h) + phase) + bias
    P1 = gamma * math.sin(omega * (t + h) + phase) + bias
    return _step(u, v, th, w, q, h, P0, Ph, P1, k, su, sF, d, lam, kind, p, coef)


@njit(cache=True, nogil=True)
def plant_run(u, v, th, w, q, t0, k, d, su, sF, lam, kind, p, gamma, omega, phase, bias, coef,
              h, nsteps, rec_every, rec):
    """Integrate ``nsteps`` RK4 steps of size ``h`` from time ``t0``.

    ``gamma``, ``bias``: drive amplitude and static (blocked) force over F_s; ``q``: coil
    force / F_s (shaker on).  ``rec`` is an (m, 7) array receiving (t, u, u', u'', th'',
    F_Masing/F_s, P/F_s) every ``rec_every`` steps, starting with the initial state; P is
    the force at the impedance head.  Returns (u, v, th, w, q, k, d, su, sF).
    """
    nrec = rec.shape[0]
    j = 0
    for i in range(nsteps + 1):
        t = t0 + i * h
        if j < nrec and i % rec_every == 0:
            Pn = gamma * math.sin(omega * t + phase) + bias
            a, al, F, _, Pd = _deriv(u, v, th, w, q, Pn, k, su, sF, d, lam, kind, p, coef)
            rec[j, 0] = t
            rec[j, 1] = u
            rec[j, 2] = v
            rec[j, 3] = a
            rec[j, 4] = al
            rec[j, 5] = F
            rec[j, 6] = Pd - coef[S_MA] * (coef[S_XS] * a + coef[8] * al)
            j += 1
        if i == nsteps:
            break
        un, vn, tn, wn, qn, a0 = _step_at(u, v, th, w, q, t, h, k, su, sF, d, lam, kind, p,
                                      gamma, omega, phase, bias, coef)
        if d == 0.0:
            if vn > 0.0:
                d = 1.0
            elif vn < 0.0:
                d = -1.0
            u, v, th, w, q = un, vn, tn, wn, qn
        elif d * vn < 0.0:
            # The feed motion reverses inside this step: split it at the zero of u'.
            if d * v > 0.0:
                Pe = gamma * math.sin(omega * (t + h) + phase) + bias
                a_end, _, _, _, _ = _deriv(un, vn, tn, wn, qn, Pe, k, su, sF, d, lam, kind, p, coef)
                theta = velocity_root(v, vn, a0 * h, a_end * h)
            else:
                theta = 0.0
            h1 = theta * h
            if h1 > 0.0:
                u, v, th, w, q, _ = _step_at(u, v, th, w, q, t, h1, k, su, sF, d, lam, kind, p,
                                          gamma, omega, phase, bias, coef)
            k = active_depth(u, k, su, d)
            F_r = branch_force(u, k, su, sF, lam, kind, p)
            k, su, sF = push_reversal(u, F_r, k, su, sF)
            d = -d
            u, v, th, w, q, _ = _step_at(u, v, th, w, q, t + h1, h - h1, k, su, sF, d, lam, kind, p,
                                      gamma, omega, phase, bias, coef)
        else:
            u, v, th, w, q = un, vn, tn, wn, qn
        k = active_depth(u, k, su, d)
    return u, v, th, w, q, k, d, su, sF
