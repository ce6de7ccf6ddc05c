"""Friction models of the pre-rolling regime behind one interface (decision 0073).

Each model is one module with one :class:`FrictionModel` subclass: its parameters declared
once (:class:`Parameter`), its steady periodic force along periodic displacement paths (what
the frequency responses and the identification compare with measured harmonics) and its
compiled time-domain update (what the simulation kernels integrate).  ``MODELS`` lists them
by the id that ``[rig.model] friction`` and ``analysis.json``'s ``friction_model`` use.

- ``masing``: Sakai's virgin curve with the Masing rule (the project's model);
- ``dahl``: Dahl's model (local memory, rate independent).
"""

from __future__ import annotations

from ..errors import ConfigurationError
from ._base import FrictionModel, Parameter, ParameterProblem, Problem
from .dahl import Dahl
from .masing import Masing

MODELS: dict[str, FrictionModel] = {m.name: m for m in (Masing(), Dahl())}

__all__ = ["MODELS", "FrictionModel", "Parameter", "ParameterProblem", "Problem", "friction_model"]


def friction_model(name: str) -> FrictionModel:
    """The model called ``name``; ConfigurationError naming the ones there are otherwise."""
    try:
        return MODELS[name]
    except KeyError:
        raise ConfigurationError(f"unknown friction model {name!r}; one of: {', '.join(MODELS)}") from None
