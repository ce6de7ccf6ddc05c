"""FREQ on the generator twin is phase-continuous, as on a 33500-series generator (a DDS:
FREQ loads a new phase increment and the phase accumulator goes on; Keysight's 33210A /
33120A user guides, "Direct Digital Synthesis": "changes in waveform frequency are
phase-continuous").  The phase-resonance loop (decision 0044) changes frequency between
blocks without waiting for a quarter phase, so a jump here would kick the carriage."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers._scpi_twin_model import ScpiGeneratorModel
from procedures.analysis import fit_harmonics
from sim.rig import RigModel, SimulatedRig

FS = 20_000.0


def drive_twin() -> tuple[ScpiGeneratorModel, SimulatedRig]:
    rig = SimulatedRig(RigModel(force_noise_N=0.0, disp_noise_m=0.0, accel_noise_m_s2=0.0))
    gen = ScpiGeneratorModel(rig)
    for cmd in ("OUTP:LOAD INF", "FREQ 70", "VOLT 0.2", "OUTP ON"):
        gen.execute(cmd)
    return gen, rig


def test_freq_keeps_the_drive_phase_and_the_motion():
    gen, rig = drive_twin()
    rig.run(int(FS), FS)                      # one second: the steady motion
    a = rig.run(2137, FS)                     # 7.48 periods at 70 Hz: ends mid-period
    assert gen.execute("FREQ 72") is None and gen.next_error()[0] == 0
    b = rig.run(2000, FS)
    sens = rig.model.force_sens_V_per_N
    fa = fit_harmonics(a.force_V / sens, FS, 70.0, 1)
    fb = fit_harmonics(b.force_V / sens, FS, 72.0, 1)
    end_of_a = fa.phase_rad[0] + 2 * math.pi * 70.0 * a.force_V.size / FS
    jump = (fb.phase_rad[0] - end_of_a + math.pi) % (2 * math.pi) - math.pi
    assert abs(jump) < 1e-6
    assert fb.amplitude[0] == pytest.approx(fa.amplitude[0], rel=1e-9)   # the same amplitude, only the rate changed
    # the carriage goes on from where it was: no step between the blocks beyond one sample's motion
    x = rig.model.disp_sens_V_per_m
    step = abs(b.disp_V[0] - a.disp_V[-1]) / x
    typical = np.max(np.abs(np.diff(a.disp_V))) / x
    assert step <= 1.5 * typical
