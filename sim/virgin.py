"""Virgin loading curves f(x) of the Masing friction model (seed Eq. 3, reconstructed).

A virgin curve is a replaceable part of the model. It is used in dimensionless form:
``g(s) = f(s * x_s) / F_s`` for ``s = x / x_s >= 0``, so that ``g(0) = 0`` and ``g -> 1`` in
the rolling region. A curve is a small object with

- ``kind``: an integer that :func:`virgin_g` dispatches on inside the compiled kernels;
- ``params``: a float64 array of its shape parameters, passed to the compiled kernels;
- ``stiffness0``: the initial slope dg/ds at s = 0 (inf where the curve has none).

To drop in another curve (the published Eq. 3, say), write an ``@njit`` function
``g(s, params)``, give it a kind number and a branch in :func:`virgin_g`, and a class like
:class:`SakaiCurve`; nothing else changes.  (A dispatch on an integer, rather than passing
the function itself into the kernels, keeps numba's on-disk cache valid across processes.)
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numba import njit

from .errors import ConfigurationError

log = logging.getLogger(__name__)


def check_positive_finite(name: str, value: float) -> float:
    """Return ``value`` as float or raise ValueError naming ``name`` and the allowed range."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigurationError(f"{name} must be a number > 0, got {value!r}") from None
    if not math.isfinite(v) or v <= 0.0:
        raise ConfigurationError(f"{name} must be finite and > 0, got {value!r}")
    return v


@njit(cache=True, nogil=True, inline="always")
def sakai_g(s, params):
    """Dimensionless virgin curve: (s^n - n s) / (1 - n) for 0 <= s <= 1, then 1."""
    n = params[0]
    if s >= 1.0:
        return 1.0
    if s <= 0.0:
        return 0.0
    return (s**n - n * s) / (1.0 - n)


CURVE_SAKAI = 0


@njit(cache=True, nogil=True, inline="always")
def virgin_g(kind, s, params):
    """g(s) of the curve ``kind`` (the one place to add a curve)."""
    if kind == CURVE_SAKAI:
        return sakai_g(s, params)
    return math.nan


class VirginCurve(Protocol):
    """What the kernels take of a virgin curve: its ``kind`` (CURVE_*) and ``params``."""

    @property
    def kind(self) -> int: ...
    @property
    def params(self) -> np.ndarray: ...


@dataclass(frozen=True)
class SakaiCurve:
    """f1 = A x^n + B x on [0, x_s], f2 = F_s beyond; A, B from seed Eqs. 4-5.

    ``n`` is the shape factor: n > 0, n != 1 (at n = 1 the two terms merge into one
    linear spring with no hysteresis, and A, B are singular).
    """

    n: float

    def __post_init__(self):
        n = check_positive_finite("shape factor n", self.n)
        if abs(n - 1.0) < 1e-9:
            raise ConfigurationError(
                f"shape factor n must be > 0 and != 1 (n = 1 is a linear spring with no "
                f"hysteresis; seed Eqs. 4-5 are singular there), got {self.n!r}"
            )
        object.__setattr__(self, "n", n)

    @property
    def params(self) -> np.ndarray:
        return np.array([self.n], dtype=np.float64)

    kind = CURVE_SAKAI

    @property
    def stiffness0(self) -> float:
        """dg/ds at s = 0: infinite for n < 1, n / (n - 1) for n > 1."""
        return math.inf if self.n < 1.0 else self.n / (self.n - 1.0)

    def coefficients(self, F_s: float, x_s: float) -> tuple[float, float]:
        """A, B of f1 = A x^n + B x in SI units (seed Eqs. 4-5)."""
        n = self.n
        return F_s / ((1.0 - n) * x_s**n), -n * F_s / ((1.0 - n) * x_s)

    def __call__(self, s):
        """Vectorised g(s) for s >= 0 (convenience; kernels call ``g`` directly)."""
        s = np.asarray(s, dtype=np.float64)
        if np.any(s < 0):
            raise ValueError("virgin curve is defined for s >= 0; use the odd extension for s < 0")
        out = np.ones_like(s)
        inside = s < 1.0
        si = s[inside]
        out[inside] = (si**self.n - self.n * si) / (1.0 - self.n)
        return out
