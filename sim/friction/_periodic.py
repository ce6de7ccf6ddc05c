"""The steady periodic force of any friction model along sampled periodic paths (decision 0073).

One contract for every model's time-domain update: an ``advance(p, state, dx, dt, v_end)``
function (numba, in the model's own module) moves the contact's state (a float64 array of
the model's ``state_size``) over a short segment of the motion, displacement ``dx`` (m) in
time ``dt`` (s), and returns the friction force (N) at the segment's end, where the
velocity is ``v_end`` (m/s).  The compiled loops here take that function as an argument
(numba specialises them per model and caches the result on disk), so a model is one
module and nothing here names it.

:func:`periodic_row`: the state at the start of a period is iterated to a fixed point of
the period map.  A one-float state (Dahl, LuGre) is solved by the secant method on that
float: the period map is a contraction (affine for Dahl with exponent 1, where the secant
step is exact), and a plain fixed-point iteration would need about F_c / (sigma X) periods
at small amplitudes.  A larger state (elements) is iterated period by period: an element
that slips in a period forgets where it started; one that sticks throughout carries a
constant offset, which has no harmonics.  The state starts virgin at x = 0 and is loaded
quasi-statically (``dt`` infinite, ``v_end`` 0) to the path's first sample, so on a path
centred on 0 such an element sits on its virgin line F_i = k_i x, symmetric, the Masing
model's convention (:func:`sim.identify.path_friction`); an ``advance`` must accept that
call.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

PERIODS_MAX = 60      # period-map evaluations per row, at most
TOL = 1e-12           # change of the state, relative to its scale, at which a period is steady


@njit(cache=True, nogil=True, inline="always")
def one_period(advance, p, state, x, v, dt, out):
    """One period along ``x`` from ``state`` (updated in place); each sample's force into
    ``out`` when it has the path's length (sample j's force is reached from sample j - 1)."""
    M = x.shape[0]
    write = out.shape[0] == M
    for j in range(M):
        jn = j + 1 if j + 1 < M else 0
        F = advance(p, state, x[jn] - x[j], dt, v[jn])
        if write:
            out[jn] = F


@njit(cache=True, nogil=True, inline="always")
def secant_state(period, advance, p, s, x, v, dt, out, scale):
    """The one-float state ``s[0]`` at the fixed point of ``period(advance, p, s, x, v, dt,
    out)`` (a period map that updates ``s``), by the secant method on g(s) = period(s) - s
    from ``s``; leaves it there and returns the number of period-map evaluations."""
    a = s[0]
    period(advance, p, s, x, v, dt, out)
    ga = s[0] - a
    b = s[0]
    used = 1
    while used < PERIODS_MAX:
        s[0] = b
        period(advance, p, s, x, v, dt, out)
        gb = s[0] - b
        used += 1
        if abs(gb) <= TOL * scale or gb == ga:
            break
        a, ga, b = b, gb, b - gb * (b - a) / (gb - ga)
    s[0] = b
    return used


@njit(cache=True, nogil=True, inline="always")
def periodic_row(advance, p, x, v, dt, state_size, scale, out):
    """Steady periodic force along one period ``x`` (m; velocity ``v``, m/s; samples ``dt``
    s apart) into ``out``; ``scale`` is the state's magnitude (the tolerance's unit).
    Returns the number of period-map evaluations it needed.

    Both loops here are inlined into the model's own compiled ``rows`` loop over the rows:
    numba caches a function that hands a compiled function to another only when every call
    that passes it on is inlined ("Cannot cache ... dynamic globals" otherwise)."""
    none = np.empty(0)
    s = np.zeros(state_size)
    advance(p, s, x[0], math.inf, 0.0)          # virgin, quasi-static, from 0 to the first sample
    used = 0
    if state_size == 1:
        used = secant_state(one_period, advance, p, s, x, v, dt, none, scale)
    else:
        prev = np.empty(state_size)
        while used < PERIODS_MAX:
            prev[:] = s
            one_period(advance, p, s, x, v, dt, none)
            used += 1
            if used >= 2 and np.max(np.abs(s - prev)) <= TOL * scale:
                break
    one_period(advance, p, s, x, v, dt, out)
    return used


def path_velocity(paths_m: np.ndarray, omega_rad_s: np.ndarray) -> np.ndarray:
    """The velocity (m/s) along rows of one-period paths at angular frequencies ``omega_rad_s``,
    by spectral differentiation (exact for a path made of harmonics below Nyquist)."""
    M = paths_m.shape[1]
    spec = np.fft.rfft(paths_m, axis=1)
    k = np.arange(spec.shape[1], dtype=np.float64)
    if M % 2 == 0:
        k[-1] = 0.0                                 # the Nyquist term has no derivative of its own
    return np.fft.irfft(1j * k * spec, M, axis=1) * omega_rad_s[:, None]


def sample_spacing(omega_rad_s: np.ndarray, M: int) -> np.ndarray:
    """Seconds between the M samples of one period at ``omega_rad_s``."""
    return 2 * math.pi / (omega_rad_s * M)
