"""A rig file's [rig.model] as the model of the seed's Figs. 15 and 17 (`bench paper --rig`)."""

from __future__ import annotations

from procedures.plan import Rig
from sim.errors import ConfigurationError

# what the paper's figures leave out: sensor noise, an interference line, the electrodynamic
# shaker (the seed's FRFs are per measured force: an ideal force source here)
LEFT_OUT = ("force_noise_N", "accel_noise_m_s2", "disp_noise_m", "line_channel", "line_freq_Hz", "line_amplitude",
            "shaker_force_constant_N_per_A", "shaker_resistance_ohm", "shaker_inductance_H",
            "shaker_armature_mass_kg", "shaker_suspension_N_per_m", "shaker_damping_N_s_per_m")


def paper_model(rig: Rig, source: str) -> dict:
    """The rig's [rig.model] without noise, line and shaker; a rig without a model or a
    pitching mode is a ConfigurationError naming the file."""
    if not rig.model:
        raise ConfigurationError(f"{source}: no [rig.model]: bench paper --rig needs a simulated rig's model")
    if not rig.model.get("pitch_inertia_kg_m2"):
        raise ConfigurationError(f"{source}: [rig.model] has no pitching mode (pitch_inertia_kg_m2 = 0): "
                                 f"Figs. 15 and 17 need one")
    model = {k: v for k, v in rig.model.items() if k not in LEFT_OUT}
    model.update(force_noise_N=0.0, accel_noise_m_s2=0.0, disp_noise_m=0.0)
    return model
