"""The real plant for the driver tests, and what the tests need around it.

The twins run against ``sim.rig.SimulatedRig``; :class:`RecordingRig` only remembers the
last generator settings pushed into it. Channel sensitivities come from the plant's own
``RigModel``, so the DAQ converts volts with the figures the sensors were modelled with.
"""

from __future__ import annotations

import math

import numpy as np

from drivers import Channel, ChannelSpec
from sim.rig import RigModel, SimulatedRig


def channel_specs(model: RigModel) -> tuple[ChannelSpec, ...]:
    """The DAQ channels of the simulated rig, in the DAQ's order."""
    return (ChannelSpec(Channel.FORCE, model.force_sens_V_per_N, "N"),
            ChannelSpec(Channel.ACCELERATION, model.accel_sens_V_per_m_s2, "m/s^2"),
            ChannelSpec(Channel.DISPLACEMENT, model.disp_sens_V_per_m, "m"))


class RecordingRig:
    """The real plant, remembering the last generator settings the twins pushed into it
    (``None`` until set). Everything else is the plant's own."""

    def __init__(self, plant: SimulatedRig) -> None:
        self.plant = plant
        self.freq_Hz = self.amplitude_Vpp = self.offset_V = self.output_on = None

    def set_generator(self, *, freq_Hz=None, amplitude_Vpp=None, offset_V=None, output_on=None):
        for name, value in (("freq_Hz", freq_Hz), ("amplitude_Vpp", amplitude_Vpp),
                            ("offset_V", offset_V), ("output_on", output_on)):
            if value is not None:
                setattr(self, name, value)
        self.plant.set_generator(freq_Hz=freq_Hz, amplitude_Vpp=amplitude_Vpp,
                                 offset_V=offset_V, output_on=output_on)

    def __getattr__(self, name: str):
        return getattr(self.plant, name)


def fundamental(x: np.ndarray, fs_Hz: float, freq_Hz: float) -> complex:
    """Complex amplitude (sine + j cosine part) of ``freq_Hz`` in ``x``: least-squares
    fit with an offset over the block (IEEE 1057 three-parameter fit)."""
    t = np.arange(x.size) / fs_Hz
    w = 2.0 * math.pi * freq_Hz
    basis = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    coef = np.linalg.lstsq(basis, x, rcond=None)[0]
    return complex(coef[0], coef[1])
