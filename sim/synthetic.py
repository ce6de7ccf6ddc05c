"""Stepped-sine time records generated through the RK4 plant, for tests and benchmarks.

The simulated rig (:class:`sim.rig.SimulatedRig`) is driven directly, without twins: per
force level a fresh (virgin) carriage is swept upwards through the frequencies; per step
the generator is set, ``settle`` periods run, then ``measure`` periods are recorded.  The
sample rate follows the DAQ's rule (an integer number of samples per period, at least
``min_rate_Hz``).  Sensor noise is added here, not by the rig, so that it can follow the
issue's recipe: a fraction of F_s on the force, of the step's rms on the acceleration and
of x_s on the displacement (white, Gaussian, seeded).

Plant effects (viscous damping, spring, delay, gain errors, ...) are whatever the given
:class:`~sim.rig.RigModel` carries; ``clean_model`` gives one with none.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

import numpy as np

from .rig import RigModel, SimulatedRig

log = logging.getLogger(__name__)

@dataclass(frozen=True)
class Noise:
    """Sensor noise (standard deviation per sample), relative to the rig or the step."""

    force_of_F_s: float = 0.003
    accel_of_rms: float = 0.005
    disp_of_x_s: float = 0.002


@dataclass
class SyntheticStep:
    key: str
    level_N: float
    freq_Hz: float
    fs_Hz: float
    force_N: np.ndarray
    accel_m_s2: np.ndarray
    disp_m: np.ndarray
    direction: str = "up"


def friction_resonance_Hz(model: RigModel) -> float:
    """omega_s / (2 pi), omega_s^2 = F_s / (x_s m)."""
    return model.omega_s / (2 * math.pi)


def grid(F_s_N: float, f_res_Hz: float, levels: int = 5, freqs: int = 18) -> tuple[np.ndarray, np.ndarray]:
    """The issue's grid: force levels 0.1-0.85 F_s, frequencies 0.3-3 x the friction resonance (log)."""
    return np.linspace(0.1, 0.85, levels) * F_s_N, np.geomspace(0.3 * f_res_Hz, 3.0 * f_res_Hz, freqs)


def issue_grid(model: RigModel, levels: int = 5, freqs: int = 18) -> tuple[np.ndarray, np.ndarray]:
    """:func:`grid` of ``model``."""
    return grid(model.F_s_N, friction_resonance_Hz(model), levels, freqs)


def draw_rig(rng: np.random.Generator, n_range: tuple[float, float], n_gap: float = 0.1) -> dict:
    """Parameters of a generated rig: F_s 2-40 N, x_s 2-100 um (log-uniform), m 2-40 kg,
    n uniform in ``n_range`` and at least ``n_gap`` away from 1."""
    n = rng.uniform(*n_range)
    while abs(n - 1) < n_gap:
        n = rng.uniform(*n_range)
    return dict(F_s_N=float(rng.uniform(2, 40)), x_s_m=float(math.exp(rng.uniform(math.log(2e-6), math.log(100e-6)))),
                n=float(n), mass_kg=float(rng.uniform(2, 40)))


def random_rig(seed: int, n_range: tuple[float, float]) -> dict:
    """:func:`draw_rig` seeded, n kept 0.1 away from 1."""
    return draw_rig(np.random.default_rng(seed), n_range)


def clean_model(F_s_N: float, x_s_m: float, n: float, mass_kg: float, seed: int = 0, **effects) -> RigModel:
    """A rig model with the given parameters, no sensor noise (added by :func:`generate`)."""
    return RigModel(F_s_N=F_s_N, x_s_m=x_s_m, n=n, mass_kg=mass_kg, force_noise_N=0.0,
                    accel_noise_m_s2=0.0, disp_noise_m=0.0, amp_force_limit_N=1e6, seed=seed, **effects)


def samples_per_period(freq_Hz: float, min_rate_Hz: float) -> int:
    return max(32, math.ceil(min_rate_Hz / freq_Hz - 1e-9))


def generate(model: RigModel, levels_N, freqs_Hz, *, settle: int = 25, measure: int = 8,
             noise: Noise | None = Noise(), min_rate_Hz: float = 25_600.0, seed: int = 0) -> list[SyntheticStep]:
    """Up-sweeps through ``freqs_Hz`` at each of ``levels_N``; one :class:`SyntheticStep` per
    step."""
    rng = np.random.default_rng(seed)
    out: list[SyntheticStep] = []
    for li, level in enumerate(levels_N):
        rig = SimulatedRig(replace(model, seed=model.seed + li))
        vpp = 2.0 * level / model.amp_gain_N_per_V
        rig.set_generator(amplitude_Vpp=vpp, output_on=True)
        for fi, f in enumerate(sorted(freqs_Hz)):
            spp = samples_per_period(f, min_rate_Hz)
            fs = spp * f
            rig.set_generator(freq_Hz=f)
            rig.run(settle * spp, fs)
            b = rig.run(measure * spp, fs)
            # read with the nominal sensitivities: a gain error of the rig stays in the data
            force = b.force_V / model.force_sens_V_per_N
            accel = b.accel_V / model.accel_sens_V_per_m_s2
            disp = b.disp_V / model.disp_sens_V_per_m
            if noise is not None:
                force = force + noise.force_of_F_s * model.F_s_N * rng.standard_normal(force.size)
                a_rms = float(np.sqrt(np.mean((accel - accel.mean()) ** 2)))
                accel = accel + noise.accel_of_rms * a_rms * rng.standard_normal(accel.size)
                disp = disp + noise.disp_of_x_s * model.x_s_m * rng.standard_normal(disp.size)
            out.append(SyntheticStep(key=f"{len(out):05d}-L{li:02d}-F{fi:03d}-up", level_N=float(level),
                                     freq_Hz=float(f), fs_Hz=float(fs), force_N=force, accel_m_s2=accel,
                                     disp_m=disp))
    return out
