"""The soft ramp (decision 0083, third addendum): one amplitude step per period over at
least 40 periods, each change at a quarter of the force's phase (pi/2 and 3 pi/2 in turn,
where the steady velocity is zero), and one acquisition per step: the step's period and
the wait to the next quarter come as one block.

The plant is the demo's simulated rig (shaker on), called in-process.  The quarters are
checked from the force the blocks carry (this test's own least-squares fit of each block,
extrapolated to the instant of the change), not from the procedure's phase tracking.

Flips tried: the wait computed from the phase at the block's start instead of after its
period (changes land off the quarters: red), a ramp of one period then a separate wait (the
code before: twice the acquisitions, red).
"""

from __future__ import annotations

import math
import tomllib

import numpy as np

from bench.config import DEFAULTS, parse_plan, parse_rig
from bench.studies.montecarlo import PlantDaq, PlantGenerator
from procedures.stepped_sine import SteppedSine
from sim.rig import SimulatedRig

RIG = parse_rig(tomllib.loads((DEFAULTS / "sim_rig.toml").read_text()))
DEMO = tomllib.loads((DEFAULTS / "demo_plan.toml").read_text())["plan"]
F_HZ = 97.3


class Recorded(PlantDaq):
    def __init__(self, rig):
        super().__init__(rig)
        self.log: list = []                  # ("block", t0, fs, force) and ("set", t, Vpp)

    def acquire_samples(self, rate_Hz, n_samples):
        b = super().acquire_samples(rate_Hz, n_samples)
        self.log.append(("block", b.t0_s, b.fs_Hz, b.force_N))
        return b


class Generator(PlantGenerator):
    def __init__(self, rig, log):
        super().__init__(rig)
        self._log = log

    def set_amplitude(self, amplitude_Vpp):
        self._log.append(("set", self.rig.time_s, amplitude_Vpp))
        return super().set_amplitude(amplitude_Vpp)


def ramp_up(target_Vpp=0.4):
    plan = parse_plan({"plan": {"levels_N": [1.0], "control": dict(DEMO["control"]),
                                "frequencies": {"list_Hz": [F_HZ]}}})
    plant = SimulatedRig(RIG.model)
    daq = Recorded(plant)
    proc = SteppedSine(plan, Generator(plant, daq.log), daq, amp_gain_N_per_V=RIG.amp_gain_N_per_V)
    proc.ramp(target_Vpp, F_HZ)
    steps = max(40, math.ceil(plan.ramp_s * F_HZ))
    return daq.log, steps


def _phase_at(block, t):
    """The force fundamental's phase (sine convention) at time ``t``, from the block."""
    _, t0, fs, force = block
    tt = t0 + np.arange(force.size) / fs
    w = 2 * math.pi * F_HZ
    A = np.column_stack([np.sin(w * tt), np.cos(w * tt), np.ones_like(tt)])
    a, b, _ = np.linalg.lstsq(A, force, rcond=None)[0]
    return (math.atan2(b, a) + w * t) % (2 * math.pi)


def test_each_ramp_step_is_one_acquisition_and_the_amplitude_rises_evenly():
    log, steps = ramp_up()
    sets = [e for e in log if e[0] == "set"]
    ramp_sets = sets[1:]                               # the first is the start at the minimum drive
    assert len(ramp_sets) == steps
    assert np.allclose([e[2] for e in ramp_sets], 0.4 * np.arange(1, steps + 1) / steps, rtol=0, atol=1e-12)
    blocks_after_first_set = [e for e in log[log.index(ramp_sets[0]):] if e[0] == "block"]
    assert len(blocks_after_first_set) == steps        # one block per step (before: one more per wait)


def test_every_change_after_the_first_period_is_at_a_quarter_of_the_forces_phase_in_turn():
    log, steps = ramp_up()
    quarters, errors = [], []
    for i, e in enumerate(log):
        if e[0] != "set" or i == 0 or log[i - 1][0] != "block":
            continue
        prev = log[i - 1]
        if prev[3].size < 0.9 * prev[2] / F_HZ:       # only blocks of a period and more
            continue
        phi = _phase_at(prev, e[1])
        q = round(phi / (math.pi / 2))
        quarters.append(q)
        errors.append(abs(phi - q * math.pi / 2) / (2 * math.pi * F_HZ / prev[2]))   # in samples
    assert len(quarters) >= steps - 3
    assert set(quarters) <= {1, 3}, quarters
    assert all(a != b for a, b in zip(quarters, quarters[1:])), quarters     # pi/2 and 3 pi/2 in turn
    # within a sample (the change is placed to the nearest one); the first changes' fits
    # carry the start's transient (up to 1.8 samples measured)
    assert np.median(errors) < 0.5 and max(errors) < 2.5, errors
