"""Plain data types of a test: the plan, its steps, the rig and its limits.

They live here, below the application, because the procedure, the safety supervisor and
online identification use them; ``bench.config`` parses and validates the TOML files that
produce them.
"""

from __future__ import annotations

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
        return asdict(self)


@dataclass(frozen=True)
class StepSpec:
    index: int
    level_index: int
    freq_index: int
    direction: str
    force_N: float
    freq_Hz: float

    @property
    def key(self) -> str:
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
