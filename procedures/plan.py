"""Plain data types of a test: the plan, its steps, the rig and its limits.

They live here, below the application, because the procedure, the safety supervisor and
online identification use them; ``bench.config`` parses and validates the TOML files that
produce them.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

from .kind import ProcedureKind, Quantity, controlled_quantity, level_quantity

if TYPE_CHECKING:      # sim.rig compiles the plant's kernels: imported where a model is made
    from sim.rig import RigModel

# the rig file's [rig.expected] values, as every identification names its starting guess
GUESS_KEYS = ("F_s_N", "x_s_m", "n", "mass_kg")


@dataclass(frozen=True)
class Limits:
    drive_V: float          # peak generator output |offset| + Vpp/2
    force_N: float          # peak force at the impedance head
    disp_m: float           # peak displacement about the start position
    accel_m_s2: float       # peak acceleration


@dataclass(frozen=True)
class Backbone:
    """[plan.backbone]: the phase-resonance procedure's settings (decision record 0044).

    Phase convention: the phase of the response's fundamental minus the force's, in
    degrees, each from a fit A sin(w t + phi); a mass-spring at its natural frequency has
    the displacement at -90 (lagging), the acceleration at +90 (leading)."""

    start_Hz: float                     # near the mode at the first level
    mode: str = "feed"                  # the mode's name, in backbone.csv
    response: str = "disp"              # "disp" or "accel": whose phase is held
    phase_deg: float = -90.0            # target; default -90 for disp, +90 for accel
    gain: float = 0.7                   # fraction of the Newton step taken per block (0, 1]
    slope_deg_per_Hz: float = 0.0       # d phase / d f at start_Hz; 0 = estimated by probe blocks
    probe_step: float = 0.02            # relative frequency step of the probe blocks
    block_periods: int = 10             # periods per controller block
    phase_band_deg: float = 1.0         # settled: |phase error| within this ...
    amplitude_band: float = 0.01        # ... and the response amplitude within this (relative) ...
    settle_periods: int = 20            # ... for this many consecutive periods (NLtest's rule)
    max_step_Hz: float = 0.0            # largest frequency change per block; 0 = 5 % of start_Hz
    min_Hz: float = 0.0                 # the frequency window; 0 = start_Hz / 2 (>= 20 Hz) ...
    max_Hz: float = 0.0                 # ... 0 = 2 x start_Hz (<= 1000 Hz)
    max_blocks: int = 60                # controller blocks per level before the lock is given up
    lost_phase_deg: float = 45.0        # lock lost: |phase error| above this and growing 3 blocks
    collapse: float = 0.2               # lock lost: amplitude below this x the level's largest

    def resolved(self) -> Backbone:
        """Defaults that depend on start_Hz filled in."""
        from dataclasses import replace
        lo = self.min_Hz or max(20.0, self.start_Hz / 2)
        hi = self.max_Hz or min(1000.0, self.start_Hz * 2)
        return replace(self, max_step_Hz=self.max_step_Hz or 0.05 * self.start_Hz, min_Hz=lo, max_Hz=hi)


@dataclass(frozen=True)
class Plan:
    name: str
    levels_N: tuple[float, ...]
    freqs_Hz: tuple[float, ...]          # ascending grid
    direction: str                       # "up", "down" or "both"
    settle_cycles: int
    min_settle_s: float
    measure_cycles: int
    min_measure_s: float                 # measured block at least this long (noise at high f)
    control_cycles: int
    force_tolerance: float
    max_iterations: int
    harmonics: int
    ramp_s: float
    min_sample_rate_Hz: float
    max_extra_settle_blocks: int         # re-measure while a free vibration still decays
    limits: Limits | None                # optional, tighter than the rig's (a field None: the rig's)
    infeasible: str = "refuse"           # steps the limits cannot hold: "refuse" the plan or "skip" them
    adaptive_per_sweep: int = 0          # > 0: measure only this many frequencies per sweep, chosen online
    skip: tuple[tuple[int, int], ...] = ()   # (level index, frequency index) left out
    # [plan.resonance] (decision 0043): after each level's sweeps, refine each peak the data
    # show with extra steps until its frequency is known within refine_tolerance (relative),
    # at most refine_steps per mode and level; the modes refined ("feed", "pitch")
    refine: bool = False
    refine_tolerance: float = 0.002
    refine_steps: int = 10            # per mode and level
    refine_modes: tuple[str, ...] = ("feed", "pitch")
    dwell_cycles: int = 0             # > 0: after the refinement, one block this long at each refined resonance
    procedure: ProcedureKind = ProcedureKind.STEPPED_SINE   # phase resonance: freqs_Hz = (start_Hz,)
    backbone: Backbone | None = None     # [plan.backbone], phase_resonance only
    response: str = ""                   # response_controlled: "disp" or "accel"; levels_N then holds
                                         # response amplitudes in level_quantity's unit (m or m/s^2)

    @property
    def level_quantity(self) -> Quantity:
        """What ``levels_N`` holds amplitudes of (force, or the response held)."""
        return level_quantity(self.procedure, self.response)

    @property
    def controlled(self) -> Quantity:
        """What the controller holds at each point (force, response, or phase)."""
        return controlled_quantity(self.procedure, self.response)

    def describe(self) -> dict[str, str]:
        """The kind and quantities as run.json records them (``meta["procedure"]``)."""
        from .kind import describe
        return describe(self.procedure, self.response)

    def sweeps(self) -> list[tuple[str, tuple[float, ...]]]:
        up = ("up", self.freqs_Hz)
        down = ("down", tuple(reversed(self.freqs_Hz)))
        return {"up": [up], "down": [down], "both": [up, down]}[self.direction]

    def schedule(self) -> list[StepSpec]:
        """Every step of the test in order; a step's key identifies it across resumes."""
        steps, index = [], 0
        skip = set(self.skip)
        n = len(self.freqs_Hz)
        for li, level in enumerate(self.levels_N):
            for direction, _ in self.sweeps():
                for fi in (range(n) if direction == "up" else range(n - 1, -1, -1)):   # linear, not index()
                    if (li, fi) not in skip:
                        steps.append(StepSpec(index, li, fi, direction, level, self.freqs_Hz[fi]))
                    index += 1     # keys stay the same whatever is skipped
        return steps

    def to_dict(self) -> dict:
        return dict(asdict(self), procedure=self.procedure.value)

    def refined_key_ok(self, key: str) -> bool:
        """Whether ``key`` names a refinement step this plan may add (refine on, a level of
        the plan, its number within the budget, the level's last sweep's direction), or
        the dwell at a refined resonance (``dwell_cycles`` > 0: number 000)."""
        m = REFINED_KEY.fullmatch(key)
        if not (self.refine and m):
            return False
        li, j, direction = int(m["level"]), int(m["n"]), m["dir"]
        if m["kind"] == "W" and not (self.dwell_cycles > 0 and j == 0):
            return False
        last = [s for s in self.schedule() if s.level_index == li]
        return bool(last) and j < self.refine_steps and direction == last[-1].direction \
            and int(m["index"]) == last[-1].index and {"F": "feed", "P": "pitch"}[m["mode"]] in self.refine_modes


# R: a refinement step, W: the dwell at the refined resonance (both after the level's sweep)
REFINED_KEY = re.compile(r"(?P<index>\d{5})-L(?P<level>\d{2})-(?P<kind>[RW])(?P<mode>[FP])(?P<n>\d{3})-(?P<dir>up|down)")


@dataclass(frozen=True)
class StepSpec:
    index: int
    level_index: int
    freq_index: int
    direction: str
    force_N: float
    freq_Hz: float
    refined: int = -1        # >= 0: the level's n-th refinement step of a mode (frequency chosen online)
    refined_mode: str = ""   # that mode: "feed" or "pitch"
    dwell_cycles: int = 0    # > 0: the dwell at the mode's refined resonance (refined = 0), a block this long

    @property
    def key(self) -> str:
        if self.refined >= 0:    # sorts after the level's sweep (its last step's index; R, W after F)
            return (f"{self.index:05d}-L{self.level_index:02d}-{'W' if self.dwell_cycles else 'R'}"
                    f"{self.refined_mode[:1].upper()}{self.refined:03d}-{self.direction}")
        return f"{self.index:05d}-L{self.level_index:02d}-F{self.freq_index:03d}-{self.direction}"


@dataclass(frozen=True)
class Rig:
    name: str
    notes: str
    simulated: bool
    generator_url: str
    sensor_url: str
    daq_url: str
    force_V_per_N: float
    accel_V_per_m_s2: float
    disp_V_per_m: float
    amp_gain_N_per_V: float              # estimate, for the first drive of each level
    limits: Limits
    expected_mass_kg: float
    expected_x_s_m: float
    expected_F_s_N: float
    expected_n: float
    model: RigModel | None = None        # the plant of a simulated rig (its [rig.model]); None otherwise

    def guess(self) -> dict[str, float]:
        """The expected F_s, x_s, n and m: every identification's starting point."""
        return {k: getattr(self, f"expected_{k}") for k in GUESS_KEYS}

    def to_dict(self) -> dict:
        """The stored layout (run.json's ``rig``): the model as every one of its keys
        (:meth:`sim.rig.RigModel.keys`: flat, a friction model's parameters among them)."""
        return dict(asdict(self), model=self.model.keys() if self.model else None)


def stored_model(rig: Mapping | None) -> RigModel | None:
    """The plant model of a stored rig (run.json's ``rig``), or None when it was not simulated
    or stored no model.  A run stored before decision 0058 holds only the keys its file gave
    (the rest at their defaults), a newer one every key: both read alike."""
    if not (rig and rig.get("simulated") and rig.get("model")):
        return None
    from sim.rig import RigModel
    return RigModel.from_dict(dict(rig["model"]))
