"""Masing rule with non-local memory (seed Eqs. 1-2, Figs. 1 and 3), dimensionless.

Units: u = x / x_s, F/F_s. The state of the model is

- a stack of reversal points (u_r, F_r), oldest first, of depth ``k``;
- the direction of motion ``d`` (+1 or -1) on the present branch.

With ``k == 0`` the carriage is on the virgin curve (Eq. 1), ``F = sign(u) g(|u|)``.
Otherwise it is on the branch that started at the newest reversal point (Eq. 2),
``F = F_r + lam * sign(u - u_r) * g(|u - u_r| / lam)``.

Memory rules:

- The branch from reversal ``k`` closes when it reaches reversal ``k-1`` (where the
  previous branch started): both points are dropped and motion goes on along the
  branch from reversal ``k-2`` (an inner loop has closed, Fig. 1 "aba").
- The first branch after virgin loading rejoins the virgin curve at the mirror
  point ``-u_1`` (the largest earlier excursion), Fig. 3.  With ``lam = 2`` the branch
  meets the virgin curve there exactly; with another ``lam`` the force jumps there,
  which is one way the loops lose their symmetry.
- Gross rolling needs no rule: ``g`` is flat beyond s = 1, so a branch is flat once
  its travel exceeds ``lam`` (2 x_s for lam = 2).

The stack is a growable array (doubling, never silently overflowing).  Functions
here are numba-compiled; each takes the virgin curve's ``kind`` and ``params`` as
arguments so any curve from :mod:`sim.virgin` can be used.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from .errors import ConfigurationError
from .virgin import SakaiCurve, VirginCurve, virgin_g

log = logging.getLogger(__name__)

LAMBDA_MASING = 2.0


@njit(cache=True, nogil=True, inline="always")
def active_depth(u, k, su, d):
    """Depth of the stack after the loops that position ``u`` closes (no mutation)."""
    while k > 0:
        if k >= 2:
            close_u = su[k - 2]
        else:
            close_u = -su[0]
        if d * (u - close_u) >= 0.0:
            k -= 2 if k >= 2 else 1
        else:
            break
    return k


@njit(cache=True, nogil=True, inline="always")
def branch_force(u, k, su, sF, lam, kind, p):
    """F/F_s at ``u`` on the branch from reversal ``k`` (virgin curve for k == 0)."""
    if k == 0:
        if u >= 0.0:
            return virgin_g(kind, u, p)
        return -virgin_g(kind, -u, p)
    s = (u - su[k - 1]) / lam
    if s >= 0.0:
        return sF[k - 1] + lam * virgin_g(kind, s, p)
    return sF[k - 1] - lam * virgin_g(kind, -s, p)


@njit(cache=True, nogil=True, inline="always")
def friction(u, k, su, sF, d, lam, kind, p):
    """F/F_s at ``u`` reached by moving in direction ``d`` from the present state."""
    return branch_force(u, active_depth(u, k, su, d), su, sF, lam, kind, p)


@njit(cache=True)
def push_reversal(u_r, F_r, k, su, sF):
    """Append a reversal point, growing the stack if needed. Returns (k, su, sF)."""
    if k >= su.shape[0]:
        cap = max(8, 2 * su.shape[0])
        su2 = np.empty(cap)
        sF2 = np.empty(cap)
        su2[:k] = su[:k]
        sF2[:k] = sF[:k]
        su, sF = su2, sF2
    su[k] = u_r
    sF[k] = F_r
    return k + 1, su, sF


@njit(cache=True)
def quasi_static_path(path, lam, kind, p, k, su, sF, d):
    """Friction along a sampled displacement path; a reversal is taken at the sample
    where the direction changes.  Returns (F, k, su, sF, d, max_depth)."""
    n = path.shape[0]
    out = np.empty(n)
    max_depth = k
    for i in range(n):
        u = path[i]
        if i > 0:
            step = u - path[i - 1]
            if step * d < 0.0:
                prev = path[i - 1]
                k = active_depth(prev, k, su, d)
                F_r = branch_force(prev, k, su, sF, lam, kind, p)
                k, su, sF = push_reversal(prev, F_r, k, su, sF)
                d = -d
            elif d == 0.0 and step != 0.0:
                d = 1.0 if step > 0 else -1.0
        k = active_depth(u, k, su, d)
        if k > max_depth:
            max_depth = k
        out[i] = branch_force(u, k, su, sF, lam, kind, p)
    return out, k, su, sF, d, max_depth


@dataclass
class MasingFriction:
    """Stateful friction element for quasi-static use: feed it displacements, get forces.

    ``curve`` is a virgin curve from :mod:`sim.virgin`; ``lam`` the similarity ratio.
    Works dimensionless (u, F/F_s); :meth:`force_SI` converts with F_s and x_s.
    """

    curve: VirginCurve = field(default_factory=lambda: SakaiCurve(1.5))
    lam: float = LAMBDA_MASING
    k: int = 0
    d: float = 0.0
    max_depth: int = 0

    def __post_init__(self):
        lam = float(self.lam)
        if not np.isfinite(lam) or lam <= 0:
            raise ConfigurationError(f"similarity ratio lam must be finite and > 0, got {self.lam!r}")
        self.lam = lam
        self._su = np.empty(16)
        self._sF = np.empty(16)
        self._last = 0.0

    @property
    def reversals(self) -> np.ndarray:
        """The live reversal points as an array of shape (k, 2): (u_r, F_r), oldest first."""
        return np.column_stack([self._su[: self.k], self._sF[: self.k]])

    def force(self, u) -> np.ndarray:
        """F/F_s along the path ``u`` (continuing from the previous call)."""
        path = np.concatenate([[self._last], np.atleast_1d(np.asarray(u, dtype=np.float64))])
        if not np.all(np.isfinite(path)):
            raise ValueError("displacement path contains NaN or inf")
        F, self.k, self._su, self._sF, self.d, depth = quasi_static_path(
            path, self.lam, self.curve.kind, self.curve.params, self.k, self._su, self._sF, self.d
        )
        self.max_depth = max(self.max_depth, depth)
        self._last = path[-1]
        return F[1:]

    def force_SI(self, x_m, F_s_N: float, x_s_m: float) -> np.ndarray:
        """Friction force in N along the displacement path ``x_m`` in m."""
        return F_s_N * self.force(np.asarray(x_m, dtype=np.float64) / x_s_m)
