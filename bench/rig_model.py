"""A rig file's [rig.model] as the model of the seed's Figs. 15 and 17 (`bench paper --rig`)."""

from __future__ import annotations

from enum import StrEnum

from procedures.plan import Rig
from sim.errors import ConfigurationError
from sim.rig import RigModel
from sim.rig_response import line_model

from .words.terminal import refused


class PaperRule(StrEnum):
    """What `bench paper --rig` needs of a rig (its words: bench.words.terminal_config.RULE);
    field source (the rig file)."""

    NO_MODEL = "paper_no_model"             # a rig without [rig.model]
    NO_PITCH = "paper_no_pitch"             # a model without a pitching mode (pitch_inertia_kg_m2 = 0)


def paper_model(rig: Rig, source: str) -> RigModel:
    """The rig's [rig.model] without noise, line and shaker (what the drawn lines leave out,
    :data:`sim.rig_response.LEFT_OUT`: the seed's FRFs are per measured force, an ideal force
    source); a rig without a model or a pitching mode is a ConfigurationError naming the file."""
    if rig.model is None:
        raise refused(ConfigurationError, PaperRule.NO_MODEL, source=source)
    if not rig.model.pitch_inertia_kg_m2:
        raise refused(ConfigurationError, PaperRule.NO_PITCH, source=source)
    return line_model(rig.model)
