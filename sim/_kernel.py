"""Compiled RK4 kernel for a mass with Masing friction under a sinusoidal force.

One equation serves the seed's dimensionless Eq. 8 and the simulated rig:

    u'' = a_f * (-F(u)/F_s + gamma * sin(omega * t + phase) + bias) - c1 * u' - k1 * u

Eq. 8 is a_f = 1/beta^2, omega = 1 (t is tau), bias = c1 = k1 = 0.  The rig uses physical
time with a_f = omega_s^2, a static force (bias, from a generator offset) and the optional
viscous (c1) and spring (k1) terms.

The friction state (reversal stack, direction) changes only at motion reversals; a
reversal is located inside the RK4 step (cubic Hermite interpolation of the velocity),
the step is split there, and the new branch starts at the located point.

``rk4_run.py_func`` is the plain-Python reference of the same algorithm.
"""

from __future__ import annotations

import math

from numba import njit

from .masing import active_depth, branch_force, friction, push_reversal
from .virgin import virgin_g


@njit(cache=True, nogil=True, inline="always")
def _accel(u, v, P, k, su, sF, d, lam, kind, p, a_f, c1, k1):
    """u'' for the external force term P = gamma sin(omega t + phase)."""
    # Fast path: u has not reached the point where the present branch closes.
    if k == 0:
        F = virgin_g(kind, u, p) if u >= 0.0 else -virgin_g(kind, -u, p)
        return a_f * (P - F) - c1 * v - k1 * u
    close_u = su[k - 2] if k >= 2 else -su[0]
    if d * (u - close_u) < 0.0:
        s = (u - su[k - 1]) / lam
        if s >= 0.0:
            F = sF[k - 1] + lam * virgin_g(kind, s, p)
        else:
            F = sF[k - 1] - lam * virgin_g(kind, -s, p)
        return a_f * (P - F) - c1 * v - k1 * u
    F = friction(u, k, su, sF, d, lam, kind, p)
    return a_f * (P - F) - c1 * v - k1 * u


@njit(cache=True, nogil=True, inline="always")
def _rk4(u, v, h, P0, Ph, P1, k, su, sF, d, lam, kind, p, a_f, c1, k1):
    """One classic RK4 step; P0, Ph, P1 are the force terms at t, t + h/2, t + h."""
    a1 = _accel(u, v, P0, k, su, sF, d, lam, kind, p, a_f, c1, k1)
    u2 = u + 0.5 * h * v
    v2 = v + 0.5 * h * a1
    a2 = _accel(u2, v2, Ph, k, su, sF, d, lam, kind, p, a_f, c1, k1)
    u3 = u + 0.5 * h * v2
    v3 = v + 0.5 * h * a2
    a3 = _accel(u3, v3, Ph, k, su, sF, d, lam, kind, p, a_f, c1, k1)
    u4 = u + h * v3
    v4 = v + h * a3
    a4 = _accel(u4, v4, P1, k, su, sF, d, lam, kind, p, a_f, c1, k1)
    un = u + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
    vn = v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    return un, vn, a1


@njit(cache=True, nogil=True)
def _rk4_at(u, v, t, h, k, su, sF, d, lam, kind, p, a_f, gamma, omega, phase, bias, c1, k1):
    """RK4 step of arbitrary size (used to split a step at a reversal)."""
    P0 = gamma * math.sin(omega * t + phase) + bias
    Ph = gamma * math.sin(omega * (t + 0.5 * h) + phase) + bias
    P1 = gamma * math.sin(omega * (t + h) + phase) + bias
    return _rk4(u, v, h, P0, Ph, P1, k, su, sF, d, lam, kind, p, a_f, c1, k1)


@njit(cache=True, nogil=True)
def velocity_root(v0, v1, m0, m1):
    """Fraction theta in [0, 1] where the cubic Hermite v(theta) crosses zero.

    v0 and v1 have opposite signs (or v0 == 0); m0, m1 are the end slopes times h.
    """
    if v0 == 0.0:
        return 0.0
    lo, hi = 0.0, 1.0
    for _ in range(48):
        th = 0.5 * (lo + hi)
        t2 = th * th
        t3 = t2 * th
        vt = (2 * t3 - 3 * t2 + 1) * v0 + (t3 - 2 * t2 + th) * m0 + (-2 * t3 + 3 * t2) * v1 + (t3 - t2) * m1
        if (vt > 0.0) == (v0 > 0.0):
            lo = th
        else:
            hi = th
    return 0.5 * (lo + hi)


@njit(cache=True, nogil=True)
def rk4_run(u, v, t0, k, d, su, sF, lam, kind, p, a_f, gamma, omega, phase, bias, c1, k1, h, nsteps, rec_every, rec):
    """Integrate ``nsteps`` RK4 steps of size ``h`` from time ``t0``.

    ``rec`` is a (m, 5) array receiving (t, u, u', u'', F/F_s) every ``rec_every`` steps,
    starting with the initial state (m = 0 records nothing).
    Returns (u, v, k, d, su, sF, u_max, u_min, max_depth, n_reversals); the time at the
    end is exactly ``t0 + nsteps * h``.
    """
    umax = u
    umin = u
    max_depth = k
    n_rev = 0
    nrec = rec.shape[0]
    j = 0
    # The force's sine advances by rotations of omega h / 2 (two per step), re-anchored
    # on math.sin every 256 steps so rounding cannot accumulate.
    ch = math.cos(0.5 * omega * h)
    sh = math.sin(0.5 * omega * h)
    sn = 0.0
    cs = 1.0
    for i in range(nsteps + 1):
        t = t0 + i * h
        if (i & 255) == 0:
            sn = math.sin(omega * t + phase)
            cs = math.cos(omega * t + phase)
        if j < nrec and i % rec_every == 0:
            kk = active_depth(u, k, su, d)
            F = branch_force(u, kk, su, sF, lam, kind, p)
            rec[j, 0] = t
            rec[j, 1] = u
            rec[j, 2] = v
            rec[j, 3] = a_f * (gamma * sn + bias - F) - c1 * v - k1 * u
            rec[j, 4] = F
            j += 1
        if i == nsteps:
            break
        s_h = sn * ch + cs * sh
        c_h = cs * ch - sn * sh
        s_1 = s_h * ch + c_h * sh
        c_1 = c_h * ch - s_h * sh
        un, vn, a0 = _rk4(u, v, h, gamma * sn + bias, gamma * s_h + bias, gamma * s_1 + bias, k, su, sF, d, lam, kind, p, a_f, c1, k1)
        sn = s_1
        cs = c_1
        if d == 0.0:
            if vn > 0.0:
                d = 1.0
            elif vn < 0.0:
                d = -1.0
            u, v = un, vn
        elif d * vn < 0.0:
            # Motion reverses inside this step: split it at the zero of the velocity.
            if d * v > 0.0:
                a_end = _accel(un, vn, gamma * sn + bias, k, su, sF, d, lam, kind, p, a_f, c1, k1)
                theta = velocity_root(v, vn, a0 * h, a_end * h)
            else:
                theta = 0.0
            h1 = theta * h
            if h1 > 0.0:
                u, v, _ = _rk4_at(u, v, t, h1, k, su, sF, d, lam, kind, p, a_f, gamma, omega, phase, bias, c1, k1)
            k = active_depth(u, k, su, d)
            F_r = branch_force(u, k, su, sF, lam, kind, p)
            k, su, sF = push_reversal(u, F_r, k, su, sF)
            d = -d
            n_rev += 1
            if u > umax:
                umax = u
            if u < umin:
                umin = u
            u, v, _ = _rk4_at(u, v, t + h1, h - h1, k, su, sF, d, lam, kind, p, a_f, gamma, omega, phase, bias, c1, k1)
        else:
            u, v = un, vn
        k = active_depth(u, k, su, d)
        if k > max_depth:
            max_depth = k
        if u > umax:
            umax = u
        if u < umin:
            umin = u
    return u, v, k, d, su, sF, umax, umin, max_depth, n_rev
