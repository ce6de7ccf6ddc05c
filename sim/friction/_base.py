"""What every friction model declares and offers (decision 0073).

A friction model is the force F(t) that the carriage's contact exerts against its feed
displacement x(t).  Each model in this package is one module with one class that

- declares its parameters once (:class:`Parameter`: name, unit, range, meaning, whether it
  is fitted on a log scale), the way :class:`sim.rig.RigModel` declares its keys;
- gives the **steady periodic force** along periodic displacement paths
  (:meth:`FrictionModel.periodic_force`): the force over one period once the transient of
  the contact's state has died away.  This is what the frequency-response engine and the
  identification compare with measured harmonics;
- gives the **time-domain force** for the simulation kernels: a compiled ``advance``
  function (the contract is in :mod:`sim.friction._periodic`), its parameters as a float64
  array (:meth:`FrictionModel.kernel_params`) and the size of its state; the steady periodic
  force is the same ``advance`` run to a periodic state (:func:`_periodic.periodic_row`,
  through the model's own compiled ``rows`` loop), so a model's physics is written once.

Every model here is translation invariant (the force depends on displacement differences
and on the velocity, never on x itself): a path may be centred anywhere.  Rate-independent
models ignore the angular frequency handed to :meth:`periodic_force`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, ClassVar

import numpy as np

from ._periodic import path_velocity, sample_spacing


class ParameterProblem(StrEnum):
    """Why a set of friction parameters is refused (the words are made by the renderers)."""

    UNKNOWN = "unknown"            # a name the model does not have
    MISSING = "missing"            # a parameter the model needs and was not given
    NOT_A_NUMBER = "not_a_number"  # not a finite number
    OUT_OF_RANGE = "out_of_range"  # outside the declared range
    EXCLUDED = "excluded"          # a value the model excludes (Sakai's n = 1)


@dataclass(frozen=True)
class Problem:
    """One refused parameter: the model, the parameter's name, the problem, the value, the range."""

    model: str
    name: str
    problem: ParameterProblem
    value: object = None
    lo: float = math.nan
    hi: float = math.nan


@dataclass(frozen=True)
class Parameter:
    """One parameter of a friction model: ``name`` (its key, unit in the name as the rig's
    keys have it), ``unit``, the range ``lo`` <= value <= ``hi`` (``lo`` excluded when
    ``lo_open``), what it means, and whether the fit works on its logarithm (positive
    quantities spanning decades) or on the value itself; ``typical`` is a value at the rig's
    scale (a carriage of about 10 kg on a guideway with friction of about 10 N), for
    examples, the kernels' warm-up and the documentation."""

    name: str
    unit: str
    lo: float
    hi: float
    meaning: str
    typical: float
    log: bool = True
    lo_open: bool = True
    exclude: tuple[float, ...] = ()     # single values outside the model (n = 1 for Sakai's curve)

    def problem(self, value: object) -> ParameterProblem | None:
        """Why ``value`` is refused, or None."""
        try:
            v = float(value)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            return ParameterProblem.NOT_A_NUMBER
        if not math.isfinite(v):
            return ParameterProblem.NOT_A_NUMBER
        if v < self.lo or (self.lo_open and v == self.lo) or v > self.hi:
            return ParameterProblem.OUT_OF_RANGE
        if any(abs(v - x) < 1e-9 for x in self.exclude):
            return ParameterProblem.EXCLUDED
        return None


class FrictionModel:
    """The interface of a friction model (module doc).  A subclass sets the class attributes,
    ``advance`` (its compiled time-domain update) and ``rows`` (its compiled loop of
    :func:`~sim.friction._periodic.periodic_row` over rows, ``advance`` bound), or overrides
    :meth:`periodic_force` where it has a faster exact form (Masing)."""

    name: ClassVar[str]                   # the id: [rig.model] friction, analysis.json's friction_model
    label: ClassVar[str]                  # short name for people ("Dahl")
    reference: ClassVar[str]              # where its equations come from
    rate_dependent: ClassVar[bool]        # does the loop depend on how fast it is run through?
    advance: ClassVar[Any] = None         # compiled advance(p, state, dx, dt, v_end) -> force (N)
    rows: ClassVar[Any] = None            # compiled rows(p, paths, vel, dts, state_size, scale, out)
    parameters: tuple[Parameter, ...] = ()

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    def problems(self, values: Mapping[str, object]) -> list[Problem]:
        """Every problem of ``values`` at once: unknown names, missing ones, values out of range."""
        out = [Problem(self.name, k, ParameterProblem.UNKNOWN, values[k]) for k in values if k not in self.names]
        for p in self.parameters:
            if p.name not in values:
                out.append(Problem(self.name, p.name, ParameterProblem.MISSING, None, p.lo, p.hi))
                continue
            why = p.problem(values[p.name])
            if why is not None:
                out.append(Problem(self.name, p.name, why, values[p.name], p.lo, p.hi))
        return out

    def typical(self) -> dict[str, float]:
        """Every parameter at its typical value."""
        return {p.name: p.typical for p in self.parameters}

    def vector(self, values: Mapping[str, float]) -> np.ndarray:
        """The parameters as the fit's vector (log where declared)."""
        return np.array([math.log(values[p.name]) if p.log else float(values[p.name]) for p in self.parameters])

    def values(self, theta: np.ndarray) -> dict[str, float]:
        """Inverse of :meth:`vector`."""
        return {p.name: (math.exp(t) if p.log else float(t)) for p, t in zip(self.parameters, theta)}

    def friction_level(self, values: Mapping[str, float]) -> float:
        """The force (N) the friction saturates at in steady sliding at low speed: what a
        force level is compared with (1.5 F_c, 0.85 F_s)."""
        raise NotImplementedError

    def kernel_params(self, values: Mapping[str, float]) -> np.ndarray:
        """The parameters as the compiled kernels take them (float64 array)."""
        return np.array([float(values[p.name]) for p in self.parameters], dtype=np.float64)

    @property
    def state_size(self) -> int:
        """Floats of state the time-domain kernel carries for this model."""
        return 1

    def state_scale(self, values: Mapping[str, float]) -> float:
        """The state's magnitude, the unit of the periodic state's tolerance."""
        return self.friction_level(values)

    def periodic_force(self, values: Mapping[str, float], paths_m: np.ndarray, omega_rad_s: np.ndarray) -> np.ndarray:
        """Steady periodic friction force (N) along each row of ``paths_m``: one period of a
        periodic displacement (m), M samples uniform in time, row i at angular frequency
        ``omega_rad_s[i]``; the first sample follows the last.  Same shape as ``paths_m``."""
        paths = np.ascontiguousarray(np.atleast_2d(paths_m), dtype=np.float64)
        omega = np.ascontiguousarray(np.broadcast_to(np.asarray(omega_rad_s, dtype=np.float64), (paths.shape[0],)))
        out = np.empty_like(paths)
        type(self).rows(self.kernel_params(values), paths, path_velocity(paths, omega),
                        sample_spacing(omega, paths.shape[1]), self.state_size, self.state_scale(values), out)
        return out
