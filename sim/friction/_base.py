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

A model of N elements (the Maxwell-slip / Iwan and the GMS models) declares its per-element
parameters once with ``elements=True``: their values are sequences of one value per element
(all of one length N, chosen by the user or the fit), each element checked against the
declared range.  The fit's vector and the kernels' array flatten them in declaration order
(:meth:`FrictionModel.flat_parameters` names the entries), the state's size follows N
(:meth:`FrictionModel.state_length`).

Every model here is translation invariant (the force depends on displacement differences
and on the velocity, never on x itself): a path may be centred anywhere.  Rate-independent
models ignore the angular frequency handed to :meth:`periodic_force`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
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
    LENGTH = "length"              # per-element values: not one per element (value: how many; lo = hi: how many wanted, nan: any >= 1)
    SUM = "sum"                    # per-element shares that must sum to lo = hi (GMS's alpha: 1); value: the sum
    BELOW = "below"                # below another parameter (``other``; lo: its value): LuGre's and GMS's F_s below F_c


@dataclass(frozen=True)
class Problem:
    """One refused parameter: the model, the parameter's name, the problem, the value, the range."""

    model: str
    name: str
    problem: ParameterProblem
    value: object = None
    lo: float = math.nan
    hi: float = math.nan
    other: str = ""                 # the parameter a BELOW problem compares with


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
    elements: bool = False              # one value per element (a sequence of N); ``typical`` is one element's
    typical_elements: tuple[float, ...] = ()    # a typical set of element values (``elements`` only)

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
    # compiled advance(p, state, dx, dt, v_end) -> force (N) and rows(p, paths, vel, dts,
    # state_size, scale, out), each a staticmethod: the same function from the class and from
    # an instance (a bare numba dispatcher would bind the instance as its first argument)
    advance: ClassVar[Any] = None
    rows: ClassVar[Any] = None
    parameters: tuple[Parameter, ...] = ()

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def has_elements(self) -> bool:
        """Whether the model is made of N elements (some parameters are one value per element)."""
        return any(p.elements for p in self.parameters)

    def problems(self, values: Mapping[str, Any]) -> list[Problem]:
        """Every problem of ``values`` at once: unknown names, missing ones, values out of
        range, per-element values not one per element, the model's own constraints
        (:meth:`constraints`, looked at when the parameters they involve are sound)."""
        out = [Problem(self.name, k, ParameterProblem.UNKNOWN, values[k]) for k in values if k not in self.names]
        n_wanted = math.nan
        for p in self.parameters:
            if p.name not in values:
                out.append(Problem(self.name, p.name, ParameterProblem.MISSING, None, p.lo, p.hi))
                continue
            v = values[p.name]
            if p.elements:
                items = _elements(v) or []
                n = len(items)
                if n == 0 or (not math.isnan(n_wanted) and n != n_wanted):
                    out.append(Problem(self.name, p.name, ParameterProblem.LENGTH, n, n_wanted, n_wanted))
                    continue
                n_wanted = n                 # the first sound per-element parameter sets N
                why = next((w for w in map(p.problem, items) if w is not None), None)
            else:
                why = p.problem(v)
            if why is not None:
                out.append(Problem(self.name, p.name, why, v, p.lo, p.hi))
        if not out:
            out += self.constraints(values)
        return out

    def constraints(self, values: Mapping[str, Any]) -> list[Problem]:
        """Problems between parameters (each one sound on its own); none by default."""
        return []

    def typical(self) -> dict[str, Any]:
        """Every parameter at its typical value (a per-element one: its typical set)."""
        return {p.name: (list(p.typical_elements) if p.elements else p.typical) for p in self.parameters}

    def n_elements(self, values: Mapping[str, Any]) -> int:
        """N, the number of elements of ``values`` (0 for a model without elements)."""
        return next((len(_as_array(values[p.name])) for p in self.parameters if p.elements), 0)

    def flat_parameters(self, n_elements: int = 0) -> tuple[Parameter, ...]:
        """The entries of the fit's vector and the kernels' array for N = ``n_elements``: the
        parameters in declaration order, a per-element one once per element, named
        ``name[i]`` (the scalar models: :attr:`parameters` itself)."""
        out: list[Parameter] = []
        for p in self.parameters:
            if p.elements:
                out += [replace(p, name=f"{p.name}[{i}]", elements=False, typical_elements=())
                        for i in range(n_elements)]
            else:
                out.append(p)
        return tuple(out)

    def _flat(self, values: Mapping[str, Any]) -> list[tuple[Parameter, float]]:
        out: list[tuple[Parameter, float]] = []
        for p in self.parameters:
            out += [(p, float(v)) for v in _as_array(values[p.name])] if p.elements else [(p, float(values[p.name]))]
        return out

    def vector(self, values: Mapping[str, Any]) -> np.ndarray:
        """The parameters as the fit's vector (log where declared; entries as :meth:`flat_parameters`)."""
        return np.array([math.log(v) if p.log else v for p, v in self._flat(values)])

    def values(self, theta: np.ndarray) -> dict[str, Any]:
        """Inverse of :meth:`vector` (N follows from the vector's length)."""
        scalars = [p for p in self.parameters if not p.elements]
        per = [p for p in self.parameters if p.elements]
        n = (len(theta) - len(scalars)) // len(per) if per else 0
        out: dict[str, Any] = {}
        i = 0
        for p in self.parameters:
            take = n if p.elements else 1
            vals = [math.exp(t) if p.log else float(t) for t in theta[i:i + take]]
            out[p.name] = vals if p.elements else vals[0]
            i += take
        return out

    def friction_level(self, values: Mapping[str, Any]) -> float:
        """The force (N) the friction saturates at in steady sliding at low speed: what a
        force level is compared with (1.5 F_c, 0.85 F_s)."""
        raise NotImplementedError

    def kernel_params(self, values: Mapping[str, Any]) -> np.ndarray:
        """The parameters as the compiled kernels take them (float64 array; entries as
        :meth:`flat_parameters`)."""
        return np.array([v for _, v in self._flat(values)], dtype=np.float64)

    @property
    def state_size(self) -> int:
        """Floats of state the time-domain kernel carries for this model (a model of
        elements: per :meth:`state_length`, which every caller may use)."""
        return 1

    def state_length(self, values: Mapping[str, Any]) -> int:
        """Floats of state the time-domain kernel carries for these values (a model of N
        elements: a number that grows with N; otherwise :attr:`state_size`)."""
        return self.state_size

    def state_scale(self, values: Mapping[str, Any]) -> float:
        """The state's magnitude, the unit of the periodic state's tolerance."""
        return self.friction_level(values)

    def periodic_force(self, values: Mapping[str, Any], paths_m: np.ndarray, omega_rad_s: np.ndarray) -> np.ndarray:
        """Steady periodic friction force (N) along each row of ``paths_m``: one period of a
        periodic displacement (m), M samples uniform in time, row i at angular frequency
        ``omega_rad_s[i]``; the first sample follows the last.  Same shape as ``paths_m``."""
        paths = np.ascontiguousarray(np.atleast_2d(paths_m), dtype=np.float64)
        omega = np.ascontiguousarray(np.broadcast_to(np.asarray(omega_rad_s, dtype=np.float64), (paths.shape[0],)))
        out = np.empty_like(paths)
        type(self).rows(self.kernel_params(values), paths, path_velocity(paths, omega),
                        sample_spacing(omega, paths.shape[1]), self.state_length(values), self.state_scale(values), out)
        return out


def stribeck_order(model: str, values: Mapping[str, Any]) -> list[Problem]:
    """A Stribeck curve falls from F_s at rest to F_c in sliding (LuGre, GMS): F_s_N below
    F_c_N is refused."""
    F_c, F_s = float(values["F_c_N"]), float(values["F_s_N"])
    if F_s < F_c:
        return [Problem(model, "F_s_N", ParameterProblem.BELOW, F_s, F_c, math.nan, other="F_c_N")]
    return []


def _as_array(v: object) -> np.ndarray:
    return np.atleast_1d(np.asarray(v, dtype=np.float64)).ravel()


def _elements(v: object) -> list[object] | None:
    """A per-element value as its list of items (a single number: one element), None if it
    is neither a number nor a flat sequence."""
    if isinstance(v, str | bytes):
        return None
    if isinstance(v, Sequence) or isinstance(v, np.ndarray):
        items = list(np.asarray(v, dtype=object).ravel()) if isinstance(v, np.ndarray) else list(v)
        return None if any(isinstance(x, Sequence | np.ndarray) and not isinstance(x, str) for x in items) else items
    return [v]
