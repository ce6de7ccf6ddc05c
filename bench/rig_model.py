"""A rig file's [rig.model] as the model of the seed's Figs. 15 and 17 (`bench paper --rig`)."""

from __future__ import annotations

from procedures.plan import Rig
from sim.errors import ConfigurationError
from sim.rig import RigModel
from sim.rig_response import line_model


def paper_model(rig: Rig, source: str) -> RigModel:
    """The rig's [rig.model] without noise, line and shaker (what the drawn lines leave out,
    :data:`sim.rig_response.LEFT_OUT`: the seed's FRFs are per measured force, an ideal force
    source); a rig without a model or a pitching mode is a ConfigurationError naming the file."""
    if rig.model is None:
        raise ConfigurationError(f"{source}: no [rig.model]: bench paper --rig needs a simulated rig's model")
    if not rig.model.pitch_inertia_kg_m2:
        raise ConfigurationError(f"{source}: [rig.model] has no pitching mode (pitch_inertia_kg_m2 = 0): "
                                 f"Figs. 15 and 17 need one")
    return line_model(rig.model)
