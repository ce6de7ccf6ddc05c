"""Plain data types of a test: the plan, its steps, the rig and its limits.

They live here, below the application, because the procedure, the safety supervisor and
online identification use them; ``bench.config`` parses and validates the TOML files that
produce them.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field


@dataclass(frozen=True)
class Limits:
    drive_V: float          # peak generator output |offset| + Vpp/2
    force_N: float          # peak force at the impedance head
    disp_m: float           # peak displacement about the start position
    accel_m_s2: float       # peak acceleration


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

    def sweeps(self) -> list[tuple[str, tuple[float, ...]]]:
        up = ("up", self.freqs_Hz)
        down = ("down", tuple(reversed(self.freqs_Hz)))
        return {"up": [up], "down": [down], "both": [up, down]}[self.direction]

    def schedule(self) -> list[StepSpec]:
        """Every step of the test in order; a step's key identifies it across resumes."""
        steps, index = [], 0
        skip = set(self.skip)
        for li, level in enumerate(self.levels_N):
            for direction, freqs in self.sweeps():
                for f in freqs:
                    fi = self.freqs_Hz.index(f)
                    if (li, fi) not in skip:
                        steps.append(StepSpec(index, li, fi, direction, level, f))
                    index += 1     # keys stay the same whatever is skipped
        return steps

    def to_dict(self) -> dict:
        return asdict(self)

    def refined_key_ok(self, key: str) -> bool:
        """Whether ``key`` names a refinement step this plan may add (refine on, a level of
        the plan, its number within the budget, the level's last sweep's direction)."""
        m = REFINED_KEY.fullmatch(key)
        if not (self.refine and m):
            return False
        li, j, direction = int(m["level"]), int(m["n"]), m["dir"]
        last = [s for s in self.schedule() if s.level_index == li]
        return bool(last) and j < self.refine_steps and direction == last[-1].direction \
            and int(m["index"]) == last[-1].index and {"F": "feed", "P": "pitch"}[m["mode"]] in self.refine_modes


REFINED_KEY = re.compile(r"(?P<index>\d{5})-L(?P<level>\d{2})-R(?P<mode>[FP])(?P<n>\d{3})-(?P<dir>up|down)")


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

    @property
    def key(self) -> str:
        if self.refined >= 0:    # sorts after the level's sweep (its last step's index; R after F)
            return (f"{self.index:05d}-L{self.level_index:02d}-R{self.refined_mode[:1].upper()}{self.refined:03d}"
                    f"-{self.direction}")
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
    model: dict = field(default_factory=dict)   # sim.rig.RigModel keys (simulated rigs)

    def to_dict(self) -> dict:
        return asdict(self)
