"""Friction models of the pre-rolling regime behind one interface (decision 0073).

Each model is one module with one :class:`FrictionModel` subclass: its parameters declared
once (:class:`Parameter`), its steady periodic force along periodic displacement paths (what
the frequency responses and the identification compare with measured harmonics) and its
compiled time-domain update (what the simulation kernels integrate).  ``MODELS`` lists them
by the id that ``[rig.model] friction`` and ``analysis.json``'s ``friction_model`` use.

- ``masing``: Sakai's virgin curve with the Masing rule (the project's model);
- ``masing_iwan``: the Masing rule with a non-parametric virgin curve, N Maxwell-slip /
  Iwan elasto-plastic elements (identified linearly: :func:`iwan.design_matrix`);
- ``dahl``: Dahl's model (local memory, rate independent);
- ``lugre``: the LuGre bristle model (local memory, a Stribeck curve, rate dependent);
- ``gms``: the Generalized Maxwell-Slip model (N elements with non-local memory, a
  Stribeck curve and a frictional lag, rate dependent).

docs/friction-models.md gives each one's equations, parameters and signature in stepped-sine
data; decisions 0073 and 0074.
"""

from __future__ import annotations

from ..errors import ConfigurationError
from ._base import FrictionModel, Parameter, ParameterProblem, Problem
from ._periodic import path_velocity, sample_spacing
from .dahl import Dahl
from .gms import GMS
from .iwan import MasingIwan
from .lugre import LuGre
from .masing import Masing

MODELS: dict[str, FrictionModel] = {m.name: m for m in (Masing(), MasingIwan(), Dahl(), LuGre(), GMS())}

__all__ = ["MODELS", "FrictionModel", "Parameter", "ParameterProblem", "Problem", "friction_model", "path_velocity",
           "sample_spacing"]


def friction_model(name: str) -> FrictionModel:
    """The model called ``name``; ConfigurationError naming the ones there are otherwise."""
    try:
        return MODELS[name]
    except KeyError:
        raise ConfigurationError(f"unknown friction model {name!r}; one of: {', '.join(MODELS)}") from None
