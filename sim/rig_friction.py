"""The simulated rig's friction model: ``[rig.model] friction`` and its parameters (decision 0075).

``friction`` names a model of :data:`sim.friction.MODELS` (default ``masing``); the model's
parameters are flat ``[rig.model]`` keys named as the model declares them
(:class:`sim.friction.Parameter`), nothing here declares them again.  Masing's parameters
(``F_s_N``, ``x_s_m``, ``n``) are fields of :class:`sim.rig.RigModel` as they always were and
its plant keeps its own kernels; any other model's parameters are kept by the rig model as
(name, value) pairs, every one required, and its plant runs the contact kernel
(:mod:`sim._contact_kernel`) on the model's compiled ``advance``.  A key that is a parameter
of some model but not of the one in use is refused (:class:`FrictionKey`).

What the contact kernel's step size needs of a model it knows nothing about, the largest
tangent stiffness of its contact, is probed through ``advance`` itself
(:func:`contact_stiffness_N_per_m`): at rest, and just after a reversal from gross sliding
(Dahl's stiffness there is sigma 2^i, twice its rest stiffness for i = 1).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from .friction import MODELS, FrictionModel

MASING = "masing"
PROBE_SPEED_M_PER_S = 1e-6     # a slow probe: a rate-dependent model's damping terms stay small
SLIDE_SPEED_M_PER_S = 1e-3     # the gross sliding before the reversal
PROBE_STEP = 1e-6              # the probe's small step, relative to the friction level / rest stiffness
PROBE_SLIDE = 100.0            # the probe's gross sliding, in the same unit


class FrictionKey(StrEnum):
    """Why a [rig.model] key of a friction model is refused (its words:
    bench.words.terminal_config.RULE); fields source, key, model (the one in use), owners
    (the models whose parameter it is)."""

    NOT_OF_MODEL = "friction_not_of_model"


def parameter_owners() -> dict[str, tuple[str, ...]]:
    """Every friction model's parameter name -> the models declaring it (in MODELS' order)."""
    out: dict[str, tuple[str, ...]] = {}
    for name, model in MODELS.items():
        for p in model.parameters:
            out[p.name] = (*out.get(p.name, ()), name)
    return out


def own_parameters(friction: str) -> tuple[str, ...]:
    """The keys of ``friction``'s parameters that the rig model keeps as pairs (none for
    Masing, whose parameters are RigModel fields; none for a name not in MODELS)."""
    model = MODELS.get(friction)
    return () if model is None or friction == MASING else model.names


def misplaced(friction: str, keys) -> list[tuple[str, tuple[str, ...]]]:
    """(key, owners) for each of ``keys`` that is a parameter of some model but not of
    ``friction`` (a model not in MODELS owns none)."""
    owners = parameter_owners()
    mine = set(MODELS[friction].names) if friction in MODELS else set()
    return [(k, owners[k]) for k in keys if k in owners and k not in mine]


@dataclass(frozen=True)
class Contact:
    """A non-Masing model ready for the contact kernel: the model, its parameters as the
    kernel takes them, and the largest tangent stiffness the step size must resolve."""

    model: FrictionModel
    params: np.ndarray
    stiffness_N_per_m: float

    @property
    def state_size(self) -> int:
        return self.model.state_size


def contact(friction: str, values: Mapping[str, float]) -> Contact:
    """The :class:`Contact` of model ``friction`` (not Masing) at ``values``."""
    model = MODELS[friction]
    p = np.ascontiguousarray(model.kernel_params(values), dtype=np.float64)
    return Contact(model, p, contact_stiffness_N_per_m(model, p, model.friction_level(values)))


def contact_stiffness_N_per_m(model: FrictionModel, p: np.ndarray, level_N: float) -> float:
    """The larger of the contact's tangent stiffness at rest and just after a reversal from
    gross sliding, both probed through the model's ``advance`` with a slow, small step."""
    adv = type(model).advance

    def step(state, dx, speed=PROBE_SPEED_M_PER_S):
        return adv(p, state, dx, abs(dx) / speed, speed if dx > 0 else -speed)

    probe = 1e-9                                             # first guess of the rest stiffness's unit
    k_rest = step(np.zeros(model.state_size), probe) / probe
    x_unit = level_N / k_rest if k_rest > 0 and np.isfinite(k_rest) else 1e-6
    dx = PROBE_STEP * x_unit
    k_rest = step(np.zeros(model.state_size), dx) / dx
    s = np.zeros(model.state_size)
    F_slide = step(s, PROBE_SLIDE * x_unit, SLIDE_SPEED_M_PER_S)
    k_back = (F_slide - step(s, -dx)) / dx
    return float(max(k_rest, k_back))
