"""Masing with a non-parametric virgin curve: the Maxwell-slip / Iwan model of N
elasto-plastic (Jenkins) elements (Iwan, J. Appl. Mech. 33(4), 893-900, 1966, the
parallel-series model; Al-Bender, Lampaert, Swevers 2004 for friction).

Element i is a spring k_i in series with a slider of slip force f_i, all in parallel.  Its
force moves with the displacement, F_i <- clip(F_i + k_i dx, -f_i, f_i) (exact for a
monotone travel dx: :func:`iwan_advance`, rate independent), and F = sum_i F_i.  It obeys
the Masing rules exactly (the branch after a reversal at (x_r, F_r) is
F_r + 2 f((x - x_r)/2), non-local memory) with the piecewise-linear virgin curve

    f(x) = sum_i clip(k_i x, -f_i, f_i)                        (:func:`virgin_force`)

as flexible as N allows.  Steady periodic force (:func:`iwan_rows`): virgin loading from 0
to the path's first sample, one period to forget it, then the period recorded; for a path
centred on 0 every element that never slips has F_i = k_i x, as on the virgin curve (the
Masing model's convention, :func:`sim.identify.path_friction`).

**Linear identification.**  Choose the elements' slip displacements d_i = f_i / k_i on a
fixed grid; the force along any path is then linear in the stiffnesses,
F = sum_i k_i b_i(path), b_i the force of an element of unit stiffness and slip
displacement d_i (metres: :func:`design_matrix`), and the virgin curve too
(:func:`virgin_basis`).  Non-negative least squares (scipy.optimize.nnls) on the measured
harmonics of ``design_matrix`` columns identifies k >= 0 with no nonlinear optimisation, and
the virgin curve's interval follows from the covariance of k through ``virgin_basis``
(:func:`virgin_interval`; :func:`values_from_grid` turns the grid and k into this model's
parameters).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numba import njit

from ._base import FrictionModel, Parameter
from ._periodic import one_period


@njit(cache=True, nogil=True)
def iwan_advance(p, state, dx, dt, v_end):
    """The elements' forces ``state`` (N) after a travel ``dx`` (m); their sum (N).  ``p`` is
    k_1..k_N (N/m) then f_1..f_N (N); rate independent (``dt``, ``v_end`` unused)."""
    N = p.shape[0] // 2
    F = 0.0
    for i in range(N):
        f = p[N + i]
        s = state[i] + p[i] * dx
        if s > f:
            s = f
        elif s < -f:
            s = -f
        state[i] = s
        F += s
    return F


@njit(cache=True, nogil=True)
def _steady_row(p, x, out):
    """The steady periodic force along one period ``x`` (module doc) into ``out``."""
    state = np.zeros(p.shape[0] // 2)
    none = np.empty(0)
    v = np.zeros(x.shape[0])
    iwan_advance(p, state, x[0], 0.0, 0.0)          # virgin loading from 0 to the first sample
    one_period(iwan_advance, p, state, x, v, 0.0, none)
    one_period(iwan_advance, p, state, x, v, 0.0, out)


@njit(cache=True, nogil=True)
def iwan_rows(p, paths, vel, dts, state_size, scale, out):
    for i in range(paths.shape[0]):
        _steady_row(p, paths[i], out[i])
    return 2


@njit(cache=True, nogil=True)
def _basis(paths, slip, out):
    """out[r, :, i]: the steady force (per N/m of stiffness, m) of element i alone along row r."""
    one = np.empty(2)
    row = np.empty(paths.shape[1])
    for r in range(paths.shape[0]):
        for i in range(slip.shape[0]):
            one[0] = 1.0
            one[1] = slip[i]
            _steady_row(one, paths[r], row)
            out[r, :, i] = row


def design_matrix(paths_m: np.ndarray, slip_m: np.ndarray) -> np.ndarray:
    """The steady periodic force of each element of unit stiffness (1 N/m) and slip
    displacement ``slip_m[i]`` (m) along each row of ``paths_m`` (one period each, as
    :meth:`FrictionModel.periodic_force` takes them): shape (rows, M, N), in metres, so that
    the model's force with stiffnesses k (N/m) is ``design_matrix(paths, slip) @ k``.
    Rate independent: no frequencies needed."""
    paths = np.ascontiguousarray(np.atleast_2d(paths_m), dtype=np.float64)
    slip = np.ascontiguousarray(np.atleast_1d(slip_m), dtype=np.float64)
    if np.any(~np.isfinite(slip)) or np.any(slip <= 0.0):
        raise ValueError("slip_m: every slip displacement must be a finite number > 0 m")
    out = np.empty((paths.shape[0], paths.shape[1], slip.shape[0]))
    _basis(paths, slip, out)
    return out


def virgin_basis(x_m: np.ndarray, slip_m: np.ndarray) -> np.ndarray:
    """The virgin curve of each element of unit stiffness: clip(x, -d_i, d_i) (m), shape
    (len(x), N); the virgin curve with stiffnesses k is ``virgin_basis(x, slip) @ k``."""
    x = np.atleast_1d(np.asarray(x_m, dtype=np.float64))[:, None]
    d = np.atleast_1d(np.asarray(slip_m, dtype=np.float64))[None, :]
    return np.clip(x, -d, d)


def virgin_interval(x_m: np.ndarray, slip_m: np.ndarray, k_N_per_m: np.ndarray, cov_k: np.ndarray,
                    z: float = 1.959964) -> tuple[np.ndarray, np.ndarray]:
    """The identified virgin curve at ``x_m`` and the half-width of its interval (N):
    ``virgin_basis(x, slip) @ k`` and z sqrt(diag(B cov B')) for the stiffnesses' covariance
    ``cov_k`` (N x N, (N/m)^2; the curve is linear in k, so this is exact for a Gaussian k;
    z = 1.96: 95 %)."""
    B = virgin_basis(x_m, slip_m)
    k = np.asarray(k_N_per_m, dtype=np.float64)
    var = np.einsum("ij,jk,ik->i", B, np.asarray(cov_k, dtype=np.float64), B)
    return B @ k, z * np.sqrt(np.maximum(var, 0.0))


def virgin_force(values: Mapping[str, Any], x_m: np.ndarray) -> np.ndarray:
    """The virgin curve f(x) = sum_i clip(k_i x, -f_i, f_i) (N) at displacements ``x_m``."""
    k = np.asarray(values["k_N_per_m"], dtype=np.float64)[None, :]
    f = np.asarray(values["f_N"], dtype=np.float64)[None, :]
    x = np.atleast_1d(np.asarray(x_m, dtype=np.float64))[:, None]
    return np.clip(k * x, -f, f).sum(axis=1)


def values_from_grid(slip_m: np.ndarray, k_N_per_m: np.ndarray) -> dict[str, list[float]]:
    """This model's parameters from the slip-displacement grid and the stiffnesses on it."""
    k = np.asarray(k_N_per_m, dtype=np.float64)
    return dict(k_N_per_m=k.tolist(), f_N=(k * np.asarray(slip_m, dtype=np.float64)).tolist())


class MasingIwan(FrictionModel):
    name = "masing_iwan"
    label = "Masing (Iwan elements)"
    reference = ("W. D. Iwan, A distributed-element model for hysteresis and its steady-state dynamic response, "
                 "J. Applied Mechanics 33(4), 893-900, 1966")
    rate_dependent = False
    advance = staticmethod(iwan_advance)
    rows = staticmethod(iwan_rows)
    parameters = (
        Parameter("k_N_per_m", "N/m", 0.0, 1e12, "stiffness k_i of element i", 2e5, log=False, lo_open=False,
                  elements=True, typical_elements=(6e5, 4e5, 2.5e5, 1.7e5, 1e5, 6e4)),
        Parameter("f_N", "N", 0.0, 1e6, "slip force f_i of element i", 2.0, log=False, lo_open=False,
                  elements=True, typical_elements=(1.2, 1.6, 2.0, 2.4, 2.4, 2.4)),
    )

    def friction_level(self, values: Mapping[str, Any]) -> float:
        return float(np.sum(np.asarray(values["f_N"], dtype=np.float64)))

    @property
    def state_size(self) -> int:
        raise NotImplementedError(f"{self.name}: the state grows with the number of elements; use state_length(values)")

    def state_length(self, values: Mapping[str, Any]) -> int:
        return self.n_elements(values)
