"""Monte-Carlo study of identification: how well a plan recovers F_s, x_s, n and m.

Before a test a technician knows roughly what the rig is (the ``[rig.expected]`` values)
and has a plan.  Each sample (a task) draws a rig around those values (F_s, x_s, m
log-uniform within a factor ``spread``; n uniform within +-``n_spread``, kept 0.15 away
from 1), a noise seed and the sensor noise of the rig scaled by ``noise_scale``; runs
the plan on the RK4 plant :class:`sim.rig.SimulatedRig` with the real stepped-sine
procedure (force control, ramps, settling; the plant is called in-process instead of
through the instrument twins' wire protocols, which change nothing in the data); and
identifies with :func:`sim.discrepancy.rigfit.identify_steps` (every harmonic each step's
record holds, decision 0064) started from the expected values.
A row per parameter gives truth, estimate, 95 % interval, relative error and whether the
interval covers the truth.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from enum import StrEnum

import numpy as np

from drivers import plan_block
from sim.errors import ConfigurationError
from sim.rig import RigModel, SimulatedRig

from ..words import terminal_data as words
from .engine import Engine, Outcome, Study

log = logging.getLogger(__name__)


class McRefusal(StrEnum):
    """A Monte-Carlo study's bad inputs (words: :data:`bench.words.terminal_data.STUDIES`)."""

    BAD_SAMPLES = "bad_samples"             # samples
    BAD_SPREAD = "bad_spread"               # spread
    NEGATIVE_SPREAD = "negative_spread"     # n_spread or noise_scale below 0
    NOT_SIMULATED = "not_simulated_rig"
    NO_N_DRAWN = "no_n_drawn"               # n, spread: the expected n and its spread

PARAMS = ("F_s_N", "x_s_m", "n", "mass_kg")
# Harmonics a sample's steps record (the DAQ sampling fast enough to keep them below Nyquist
# at the plan's top frequency, up to MAX_SAMPLE_RATE_HZ).  The identification rebuilds the displacement path, and the friction and
# |v| along it, from every harmonic the step's record holds (decision 0064), so the plan's
# count no longer decides it; fitted from the plans' default 5 alone, a large-slip step at a
# low frequency lost the sharp reversals and F_s, x_s were biased by 1-2 standard errors
# (issue 25, decision 0049).  The sampling rate this sets still bounds what the record holds.
RECORD_HARMONICS = 25
MAX_SAMPLE_RATE_HZ = 204_800.0     # the plans' own upper limit of min_sample_rate_Hz


class PlantGenerator:
    """The function generator's settings go straight into the plant."""

    def __init__(self, rig: SimulatedRig):
        self.rig = rig

    def set_frequency(self, freq_Hz: float) -> float:
        self.rig.set_generator(freq_Hz=freq_Hz)
        return float(freq_Hz)

    def set_amplitude(self, amplitude_Vpp: float) -> float:
        self.rig.set_generator(amplitude_Vpp=amplitude_Vpp)
        return float(amplitude_Vpp)

    def set_output(self, on: bool) -> None:
        self.rig.set_generator(output_on=on)


@dataclass
class PlantBlock:
    force_N: np.ndarray
    accel_m_s2: np.ndarray
    disp_m: np.ndarray
    fs_Hz: float
    t0_s: float
    block_id: int
    resends: int = 0

    @property
    def n_samples(self) -> int:
        return int(self.force_N.size)


class PlantDaq:
    """Blocks from the plant, volts converted with the rig's nominal sensitivities (what
    the DAQ driver does; a gain error of the model stays in the data)."""

    def __init__(self, rig: SimulatedRig):
        self.rig = rig
        self.blocks = 0

    def acquire_samples(self, rate_Hz: float, n_samples: int) -> PlantBlock:
        m = self.rig.model
        b = self.rig.run(n_samples, rate_Hz)
        self.blocks += 1
        return PlantBlock(b.force_V / m.force_sens_V_per_N, b.accel_V / m.accel_sens_V_per_m_s2,
                          b.disp_V / m.disp_sens_V_per_m, rate_Hz, b.t0_s, self.blocks)

    def acquire_periods(self, freq_Hz: float, n_periods: int, min_rate_Hz: float = 25_600.0) -> PlantBlock:
        rate, n = plan_block(freq_Hz, n_periods, min_rate_Hz)
        return self.acquire_samples(rate, n)


@dataclass(frozen=True)
class McSpec:
    """A Monte-Carlo identification study: plan and rig (parsed TOML dicts), samples."""

    plan: dict
    rig: dict
    samples: int = 20
    spread: float = 2.0
    n_spread: float = 0.5
    noise_scale: float = 1.0
    seed: int = 0

    def __post_init__(self):
        if self.samples < 1:
            raise words.refused(ConfigurationError, McRefusal.BAD_SAMPLES, samples=self.samples)
        if not self.spread >= 1:
            raise words.refused(ConfigurationError, McRefusal.BAD_SPREAD, spread=self.spread)
        if not (self.n_spread >= 0 and self.noise_scale >= 0):
            raise words.refused(ConfigurationError, McRefusal.NEGATIVE_SPREAD)
        _configs(self.plan, self.rig)          # validates both now, not on a worker

    def tasks(self) -> list[dict]:
        return [dict(sample=i, plan=self.plan, rig=self.rig, spread=self.spread, n_spread=self.n_spread,
                     noise_scale=self.noise_scale) for i in range(self.samples)]

    def to_dict(self) -> dict:
        return dict(plan=self.plan, rig=self.rig, samples=self.samples, spread=self.spread,
                    n_spread=self.n_spread, noise_scale=self.noise_scale)


def _configs(plan: dict, rig: dict):
    from bench.config import parse_plan, parse_rig
    p = parse_plan(plan)
    r = parse_rig(rig)
    if not r.simulated:
        raise words.refused(ConfigurationError, McRefusal.NOT_SIMULATED)
    # RECORD_HARMONICS below Nyquist at the top frequency: the DAQ samples faster if it must
    top = max(p.freqs_Hz)
    rate = min(max(p.min_sample_rate_Hz, 2 * top * (RECORD_HARMONICS + 1)), MAX_SAMPLE_RATE_HZ)
    harmonics = max(p.harmonics, min(RECORD_HARMONICS, math.ceil(rate / (2 * top)) - 1))
    return replace(p, infeasible="skip", harmonics=harmonics, min_sample_rate_Hz=rate), r


def draw_rig(expected: dict, spread: float, n_spread: float, rng: np.random.Generator) -> dict:
    """A rig around the expected values (see the module docstring)."""
    ls = math.log(spread)
    truth = {k: expected[k] * math.exp(rng.uniform(-ls, ls)) for k in ("F_s_N", "x_s_m", "mass_kg")}
    n = expected["n"] + rng.uniform(-n_spread, n_spread)
    for _ in range(1000):
        if n > 0.2 and abs(n - 1) >= 0.15:
            break
        n = expected["n"] + rng.uniform(-n_spread, n_spread)
    else:
        raise words.refused(ConfigurationError, McRefusal.NO_N_DRAWN, n=expected["n"], spread=n_spread)
    truth["n"] = n
    return truth


def simulate_plan(plan, rig, model: RigModel) -> list[dict]:
    """Run ``plan`` on the RK4 plant of ``model``; the step results."""
    from bench.session import check_envelope
    from procedures.factory import procedure_for
    from procedures.safety import tightest

    plan = check_envelope(plan, rig)
    plant = SimulatedRig(model)
    daq = PlantDaq(plant)
    rest = daq.acquire_periods(100.0, 10).disp_m
    proc = procedure_for(plan, PlantGenerator(plant), daq, amp_gain_N_per_V=rig.amp_gain_N_per_V,
                         mass_kg=rig.expected_mass_kg, drive_limit_V=tightest(rig.limits, plan.limits).drive_V)
    proc.disp_noise_floor_m = float(np.std(rest))
    results: list[dict] = []
    proc.run(set(), lambda step, res, raw: results.append(res))
    return results


def identification_sample(inputs: dict, seed: int) -> list[dict]:
    """One Monte-Carlo sample (a task): rows per parameter."""
    from sim.discrepancy.rigfit import identify_steps

    plan, rig = _configs(inputs["plan"], inputs["rig"])
    rng = np.random.default_rng(seed)
    expected = rig.guess()
    truth = draw_rig(expected, inputs["spread"], inputs["n_spread"], rng)
    m, k = rig.model or RigModel(), inputs["noise_scale"]       # simulated (_configs): a model
    model = replace(m, force_noise_N=k * m.force_noise_N, accel_noise_m_s2=k * m.accel_noise_m_s2,
                    disp_noise_m=k * m.disp_noise_m, **truth, seed=int(rng.integers(2 ** 31)))
    results = simulate_plan(plan, rig, model)
    # the model of the rig: the effects its file declares (decision 0042)
    est = identify_steps(results, expected, model)
    rows = []
    for p in PARAMS:
        v, t = est["values"][p], truth[p]
        lo, hi = est["low"][p], est["high"][p]
        rows.append(dict(sample=int(inputs["sample"]), plan=plan.name, parameter=p, truth=t, guess=expected[p],
                         estimate=float(v), low=float(lo), high=float(hi), rel_error=float(v / t - 1.0),
                         covered=bool(lo <= t <= hi), rel_std=float(est["rel_std"][p]),
                         steps=len(results), reduced_chi2=float(est["reduced_chi2"]), noise_seed=model.seed,
                         misfit=bool(est.get("misfit"))))
    return rows


def identification_mc(spec: McSpec, study_dir, *, scheduler: str | None = None, workers: int | None = None,
                      engine: Engine | None = None, progress=None, figure: bool = True) -> Outcome:
    """Run (or resume) a Monte-Carlo study; writes results.parquet and errors.png."""
    study = Study(study_dir, "identification-mc", spec.to_dict(), spec.tasks(), seed=spec.seed)
    out = study.run_on(identification_sample, engine, scheduler, workers, progress=progress)
    if figure and out.table_path.exists():
        from .figures import plot_identification_errors
        plot_identification_errors(out.table(), study.dir / "errors.png")
    return out
