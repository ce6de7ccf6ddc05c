"""Compiled RK4 kernel of the simulated rig with a friction model other than Masing (decision 0075).

The plant is :mod:`sim._plant_kernel`'s, every effect included (viscous damping, springs,
velocity-dependent and asymmetric friction, quadratic damping, the pitching mode, the
electrodynamic shaker), with the Masing force replaced by a model's time-domain update
``advance(p, state, dx, dt, v_end) -> F`` (the contract of :mod:`sim.friction._periodic`):

    m x'' + m e th'' = P - F(x, x') (1 + alpha |x'| / v_ref) (1 + a sign F) - c x' - c2 x'|x'|
                       - k x - k3 x^3
    m e x'' + J th'' = h P - k_th th - c_th th'

in physical units (x in m, forces in N: the coefficient array of
:func:`sim.plant_effects.coefficients` with F_s = x_s = 1).  The contact's state is moved
only along the accepted path: each RK4 stage's force is ``advance`` on a copy of the state
from the step's start to the stage's point (a straight segment of the stage's own time), and
the state itself is moved by the accepted step.  A step inside which the feed velocity
changes sign is split at its zero (cubic Hermite, as the Masing kernels do), so every
segment handed to ``advance`` is monotone, which Dahl's closed form follows exactly.

``advance`` arrives as a first-class function of one signature (:data:`ADVANCE`): numba then
compiles this kernel once for every model and caches it on disk (a kernel specialised on a
model's dispatcher is compiled afresh in every process).
"""

from __future__ import annotations

import math

from numba import njit, types

from ._kernel import velocity_root
from ._plant_kernel import ASYM, Q_DAMP, S_MA, S_XS, accelerations, cubic_spring, pitch_moment, rate_factor, shaker

_f8, _a1 = types.float64, types.float64[::1]
ADVANCE = types.FunctionType(_f8(_a1, _a1, _f8, _f8, _f8))
RUN_SIGNATURE = types.UniTuple(_f8, 7)(ADVANCE, _a1, _a1, _a1, *(_f8,) * 12, _a1, _f8, types.int64, types.int64,
                                       types.float64[:, ::1])


@njit(cache=True, nogil=True, inline="always")
def _rhs(u, v, th, w, q, Pn, F, coef):
    """(x'', th'', q', P_d) for the friction force ``F`` (N) and the blocked drive ``Pn`` (N)."""
    Pd, dq = shaker(Pn, q, coef[S_XS] * u + coef[8] * th, coef[S_XS] * v + coef[8] * w, coef)
    r1 = (Pd - F * rate_factor(v, coef[7]) * (1.0 + coef[ASYM] * math.copysign(1.0, F)) - coef[4] * v
          - coef[Q_DAMP] * v * abs(v) - coef[5] * u - cubic_spring(u, coef[6]))
    r2 = pitch_moment(Pd, th, w, coef)
    a, al = accelerations(r1, r2, coef)
    return a, al, dq, Pd


@njit(cache=True, nogil=True, inline="always")
def _stage(advance, p, state, trial, dx, dt, v):
    """The force at a stage point: ``advance`` from a copy of ``state``."""
    for i in range(state.shape[0]):
        trial[i] = state[i]
    return advance(p, trial, dx, dt, v)


@njit(cache=True, nogil=True, inline="always")
def _step(advance, p, state, trial, u, v, th, w, q, F0, h, P0, Ph, P1, coef):
    """One classic RK4 step from the force ``F0`` at its start; the new state, x'' at the
    start and the force at the trial end (the contact's ``state`` untouched)."""
    a1, b1, e1, _ = _rhs(u, v, th, w, q, P0, F0, coef)
    u2, v2, t2, w2, q2 = u + 0.5 * h * v, v + 0.5 * h * a1, th + 0.5 * h * w, w + 0.5 * h * b1, q + 0.5 * h * e1
    F2 = _stage(advance, p, state, trial, u2 - u, 0.5 * h, v2)
    a2, b2, e2, _ = _rhs(u2, v2, t2, w2, q2, Ph, F2, coef)
    u3, v3, t3, w3, q3 = u + 0.5 * h * v2, v + 0.5 * h * a2, th + 0.5 * h * w2, w + 0.5 * h * b2, q + 0.5 * h * e2
    F3 = _stage(advance, p, state, trial, u3 - u, 0.5 * h, v3)
    a3, b3, e3, _ = _rhs(u3, v3, t3, w3, q3, Ph, F3, coef)
    u4, v4, t4, w4, q4 = u + h * v3, v + h * a3, th + h * w3, w + h * b3, q + h * e3
    F4 = _stage(advance, p, state, trial, u4 - u, h, v4)
    a4, b4, e4, _ = _rhs(u4, v4, t4, w4, q4, P1, F4, coef)
    un = u + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
    vn = v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    tn = th + h / 6.0 * (w + 2.0 * w2 + 2.0 * w3 + w4)
    wn = w + h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
    qn = q + h / 6.0 * (e1 + 2.0 * e2 + 2.0 * e3 + e4)
    return un, vn, tn, wn, qn, a1


@njit(cache=True, nogil=True, inline="always")
def _drive(t, gamma, omega, phase, bias):
    return gamma * math.sin(omega * t + phase) + bias


@njit(cache=True, nogil=True, inline="always")
def _step_at(advance, p, state, trial, u, v, th, w, q, F0, t, h, gamma, omega, phase, bias, coef):
    """An RK4 step of any size from time ``t`` (a whole step, or its parts at a reversal)."""
    return _step(advance, p, state, trial, u, v, th, w, q, F0, h, _drive(t, gamma, omega, phase, bias),
                 _drive(t + 0.5 * h, gamma, omega, phase, bias), _drive(t + h, gamma, omega, phase, bias), coef)


@njit(RUN_SIGNATURE, cache=True, nogil=True)
def contact_run(advance, p, state, trial, u, v, th, w, q, F, d, t0, gamma, omega, phase, bias, coef,
                h, nsteps, rec_every, rec):
    """Integrate ``nsteps`` RK4 steps of size ``h`` (s) from time ``t0``.

    ``state``: the contact's state (updated in place), ``trial`` a scratch array of its size;
    ``F``: the friction force (N) the state gives at the start, ``d`` the direction of the
    feed motion (+1, -1, 0 at rest); ``gamma``, ``bias``: drive amplitude and static
    (blocked) force (N); ``q``: coil force (N, shaker on).  ``rec`` is an (m, 7) array
    receiving (t, x, x', x'', th'', F, P) every ``rec_every`` steps, starting with the
    initial state; P is the force at the impedance head.  Returns (x, x', th, th', q, F, d).
    """
    nrec = rec.shape[0]
    j = 0
    for i in range(nsteps + 1):
        t = t0 + i * h
        if j < nrec and i % rec_every == 0:
            a, al, _, Pd = _rhs(u, v, th, w, q, _drive(t, gamma, omega, phase, bias), F, coef)
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
        un, vn, tn, wn, qn, a0 = _step_at(advance, p, state, trial, u, v, th, w, q, F, t, h,
                                          gamma, omega, phase, bias, coef)
        if d != 0.0 and d * vn < 0.0:
            # The feed motion reverses inside this step: split it at the zero of x'.
            theta = 0.0
            if d * v > 0.0:
                Fe = _stage(advance, p, state, trial, un - u, h, vn)
                a_end, _, _, _ = _rhs(un, vn, tn, wn, qn, _drive(t + h, gamma, omega, phase, bias), Fe, coef)
                theta = velocity_root(v, vn, a0 * h, a_end * h)
            h1 = theta * h
            if h1 > 0.0:
                ur, vr, th, w, q, _ = _step_at(advance, p, state, trial, u, v, th, w, q, F, t, h1,
                                               gamma, omega, phase, bias, coef)
                F = advance(p, state, ur - u, h1, vr)
                u, v = ur, vr
            d = -d
            un, vn, tn, wn, qn, _ = _step_at(advance, p, state, trial, u, v, th, w, q, F, t + h1, h - h1,
                                             gamma, omega, phase, bias, coef)
            F = advance(p, state, un - u, h - h1, vn)
        else:
            if d == 0.0:
                d = 1.0 if vn > 0.0 else -1.0 if vn < 0.0 else 0.0
            F = advance(p, state, un - u, h, vn)
        u, v, th, w, q = un, vn, tn, wn, qn
    return u, v, th, w, q, F, d
