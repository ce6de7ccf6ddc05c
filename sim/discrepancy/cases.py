"""Generated test cases: a random rig with an effect hidden in it, measured step by step.

A case is what a technician would bring back from the rig: stepped-sine steps (5 force
levels 0.1-0.85 F_s, 18 log-spaced frequencies 0.3-3 times the friction resonance
f_res = omega_s / 2 pi, upward sweeps) with realistic noise: 0.3 % of F_s on the force,
0.5 % of the step's rms on the acceleration, 0.2 % of x_s on the displacement (rms per
sample).  The data come from the RK4 plant (:class:`sim.rig.SimulatedRig`, driven per
step directly: settle, then one block of whole periods); harmonics and their standard
errors are estimated from the records as the procedure does (least squares over whole
periods, noise from the residual), so nothing of the truth leaks into the analysis.

Effects are drawn at a strength above the sensitivity the issue requires (the factor
``margin``, 1.3-2.5x by default); see :data:`THRESHOLDS` for what "sensitivity" means for
each id.  ``cubic_spring`` is deliberately outside the analysis catalog.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import ConfigurationError
from ..identify import StepHarmonics
from ..records import harmonic_sigma, lsq_harmonics
from ..rig import RigModel, SimulatedRig
from ..synthetic import draw_rig, grid

log = logging.getLogger(__name__)

CATALOG = ("viscous_damping", "linear_spring", "second_mode", "velocity_dependent_friction",
           "sensor_delay", "sensor_gain_error")
OUTSIDE = ("cubic_spring", "quadratic_damping", "asymmetric_friction")
# the plant's forms outside the catalog and the library term that names each
FORMS = {"cubic_spring": "cubic_stiffness", "quadratic_damping": "quadratic_damping",
         "asymmetric_friction": "asymmetric_friction"}
# What the sensitivity means for each effect (the strength drawn is above it):
THRESHOLDS = {
    "viscous_damping": "equivalent damping ratio c / (2 m omega_res) of 3 %",
    "linear_spring": "k of 5 % of F_s / x_s",
    "second_mode": "a pitching mode at 2.5-4.5 times the friction resonance",
    "velocity_dependent_friction": "friction 15 % higher at the resonance speed omega_res x_s",
    "sensor_delay": "a displacement delay of 1 % of the resonance period",
    "sensor_gain_error": "a displacement/acceleration gain inconsistency of 5 %",
    "cubic_spring": "a hardening spring of 15 % of F_s at 2 x_s",
    "quadratic_damping": "c2 v|v| with the equivalent damping ratio of 3 % at the speed omega_res x_s",
    "asymmetric_friction": "friction 5 % higher in one direction than F_s, 5 % lower in the other (a = 0.05)",
}
SAMPLES_PER_PERIOD = 2048      # measured blocks: fine enough that n < 1 reversals do not alias
SETTLE_SAMPLES_PER_PERIOD = 64  # the plant still takes >= 400 RK4 steps per period
MAX_EXTRA_SETTLES = 6
RECORD_POINTS = 256             # one averaged period kept for loop plots
HARMONICS = 200                 # stored per step (the residuals use the first 9; the friction all)


@dataclass(frozen=True)
class Step:
    """One measured step, with the attribute names of ``bench.sources.MeasuredStep``."""

    key: str
    level_N: float
    freq_Hz: float
    harmonics: StepHarmonics
    fs_Hz: float
    force_N: np.ndarray        # one period, averaged over the measured block
    accel_m_s2: np.ndarray
    disp_m: np.ndarray
    direction: str = "up"


@dataclass(frozen=True)
class Case:
    seed: int
    rig: dict                  # F_s_N, x_s_m, n, mass_kg (the truth)
    effects: dict              # effect id -> RigModel fields set for it
    f_res_Hz: float
    steps: list[Step] = field(repr=False)

    @property
    def causes(self) -> tuple[str, ...]:
        return tuple(e for e in self.effects if e in CATALOG)

    @property
    def forms(self) -> tuple[str, ...]:
        """The library ids of the forms outside the catalog hidden in the case."""
        return tuple(FORMS[e] for e in self.effects if e in FORMS)


def truth_size(case: Case, effect: str) -> tuple[str | None, float | None]:
    """(parameter name in the analysis' cause parameters, its true value) for the effects
    whose reported size maps one to one onto the plant's settings; (None, None) otherwise."""
    fx = case.effects[effect]
    if effect == "viscous_damping":
        return "c", fx["viscous_N_s_per_m"]
    if effect == "linear_spring":
        return "k", fx["spring_N_per_m"]
    if effect == "sensor_delay":
        return "delay", fx["disp_delay_s"]
    if effect == "sensor_gain_error":   # displacement scale relative to the accelerometer
        return "gain_error", (1 + fx.get("disp_gain_error", 0.0)) / (1 + fx.get("accel_gain_error", 0.0)) - 1
    if effect == "velocity_dependent_friction":
        w_res = 2 * math.pi * case.f_res_Hz
        return "alpha", fx["friction_alpha"] * (w_res * case.rig["x_s_m"]) / fx["friction_v_ref_m_per_s"]
    if effect == "cubic_spring":
        return "k3", fx["cubic_spring_N_per_m3"]
    if effect == "quadratic_damping":
        return "c2", fx["quadratic_damping_N_s2_per_m2"]
    if effect == "asymmetric_friction":
        return "a", fx["friction_asymmetry"]
    if effect == "second_mode":         # the model's f_p is the mode with x held: sqrt(k_th / J)
        return "frequency", math.sqrt(fx["pitch_stiffness_N_m_per_rad"] / fx["pitch_inertia_kg_m2"]) / (2 * math.pi)
    return None, None


def observable_rig(case: Case) -> dict:
    """The rig's F_s_N, x_s_m, n, mass_kg as measurements can show them.  The analysis takes
    the accelerometer as the reference of scale (a gain error is the displacement's scale
    relative to it), so an accelerometer gain error g_a shows as x_s (1 + g_a) and
    m / (1 + g_a); nothing in the data can tell the two apart."""
    g_a = case.effects.get("sensor_gain_error", {}).get("accel_gain_error", 0.0)
    return dict(case.rig, x_s_m=case.rig["x_s_m"] * (1 + g_a), mass_kg=case.rig["mass_kg"] / (1 + g_a))


def random_rig(rng: np.random.Generator) -> dict:
    """F_s 2-40 N, x_s 2-100 um (log-uniform), n 0.35-3 at least 0.2 from 1, m 2-40 kg."""
    return draw_rig(rng, (0.35, 3.0), n_gap=0.2)


def friction_resonance_Hz(rig: dict) -> float:
    return math.sqrt(rig["F_s_N"] / (rig["x_s_m"] * rig["mass_kg"])) / (2 * math.pi)


def draw_effect(effect: str, rig: dict, rng: np.random.Generator, margin: tuple[float, float] = (1.3, 2.5)) -> dict:
    """RigModel fields for ``effect`` at a random strength ``margin`` times its threshold."""
    s = rng.uniform(*margin)
    m, F_s, x_s = rig["mass_kg"], rig["F_s_N"], rig["x_s_m"]
    w_res = 2 * math.pi * friction_resonance_Hz(rig)
    if effect == "viscous_damping":
        return dict(viscous_N_s_per_m=2 * 0.03 * s * m * w_res)
    if effect == "linear_spring":
        return dict(spring_N_per_m=0.05 * s * F_s / x_s)
    if effect == "velocity_dependent_friction":
        return dict(friction_alpha=0.15 * s, friction_v_ref_m_per_s=w_res * x_s)
    if effect == "sensor_delay":
        return dict(disp_delay_s=0.01 * s / (w_res / (2 * math.pi)))
    if effect == "sensor_gain_error":
        name = "disp_gain_error" if rng.uniform() < 0.5 else "accel_gain_error"
        return {name: float(0.05 * s * rng.choice([-1.0, 1.0]))}
    if effect == "second_mode":
        # a column of height ~2 h on the carriage: J about the contact line ~ m h^2 (1-2),
        # centre of gravity at 0.3-0.7 h; stiffness puts the mode at 2.5-4.5 f_res
        h = 0.1
        J = m * h * h * rng.uniform(1.0, 2.0)
        e = h * rng.uniform(0.3, 0.7)
        w_p = w_res * rng.uniform(2.5, 4.5)
        zeta = rng.uniform(0.01, 0.05)
        J_eff = J - m * e * e              # the mode with the carriage held by friction
        return dict(pitch_inertia_kg_m2=J, pitch_stiffness_N_m_per_rad=J_eff * w_p ** 2,
                    pitch_damping_N_m_s_per_rad=2 * zeta * J_eff * w_p, drive_height_m=h, cg_height_m=e)
    if effect == "cubic_spring":
        return dict(cubic_spring_N_per_m3=0.15 * s * F_s / (2 * x_s) ** 3)
    if effect == "quadratic_damping":    # c_eq = 8/(3 pi) c2 V at V = omega_res x_s
        return dict(quadratic_damping_N_s2_per_m2=2 * 0.03 * s * m * 3 * math.pi / (8 * x_s))
    if effect == "asymmetric_friction":
        return dict(friction_asymmetry=float(0.05 * s * rng.choice([-1.0, 1.0])))
    raise ConfigurationError(f"unknown effect {effect!r}; known: {CATALOG + OUTSIDE}")


# With friction higher one way than the other, a carriage driven into gross rolling walks off
# towards the easier direction every cycle (ratcheting: 0.4 mm within one step at 0.35 F_s
# near the resonance, until the probe clips); nothing holds it but friction.  Such cases are
# planned at forces that keep it in pre-rolling.
ASYMMETRIC_TOP_LEVEL = 0.3


def plan_grid(rig: dict, levels: int = 5, freqs: int = 18, top_level: float = 0.85) -> tuple[np.ndarray, np.ndarray]:
    """Force levels 0.1-``top_level`` F_s (N) and log-spaced frequencies 0.3-3 f_res (Hz)."""
    lv, fr = grid(rig["F_s_N"], friction_resonance_Hz(rig), levels, freqs)
    return 0.1 * rig["F_s_N"] + (lv - 0.1 * rig["F_s_N"]) * (top_level - 0.1) / 0.75, fr


def _harmonics(x: np.ndarray, periods: int, K: int) -> tuple[np.ndarray, float, np.ndarray]:
    """Complex harmonics C_k (of sin), their standard error and the one-period average
    (the kernel's fit over the ``periods`` whole periods of ``x``)."""
    N = x.size
    C, _offset, noise = lsq_harmonics(x, float(N), float(periods), K)     # time in records: f = periods
    one = x.reshape(periods, -1).mean(axis=0)
    return C, harmonic_sigma(noise, N), one[::max(1, one.size // RECORD_POINTS)]


def measure_steps(model: RigModel, levels_N, freqs_Hz, *, settle_periods: int = 150, measure_periods: int = 8,
                  harmonics: int = HARMONICS, noise: tuple[float, float, float] = (0.003, 0.005, 0.002),
                  seed: int = 0) -> list[Step]:
    """Drive the plant level by level, sweeping up in frequency, and measure each step.

    ``noise``: force rms / F_s, acceleration rms / the step's rms, displacement rms / x_s.
    The plant's own sensor noise is switched off; this noise is added to its outputs."""
    model = replace(model, force_noise_N=0.0, accel_noise_m_s2=0.0, disp_noise_m=0.0)
    rig = SimulatedRig(model)
    rng = np.random.default_rng(seed)
    M = SAMPLES_PER_PERIOD
    steps = []
    f_mid = math.sqrt(freqs_Hz[0] * freqs_Hz[-1])
    for li, level in enumerate(levels_N):
        for fi, f in enumerate(freqs_Hz):
            fs = f * M
            rig.set_generator(freq_Hz=f, amplitude_Vpp=2 * level / model.amp_gain_N_per_V, output_on=True)
            # free vibrations of the stiff small-amplitude friction decay over a number of
            # their own periods: settle longer above the resonance
            settle = int(settle_periods * max(1.0, f / f_mid))
            rig.run(settle * SETTLE_SAMPLES_PER_PERIOD, f * SETTLE_SAMPLES_PER_PERIOD)
            rig.run(2 * M, fs)     # the plant's delay line restarts when the sample rate changes
            b = rig.run(measure_periods * M, fs)
            # like the procedure: settle more while a free vibration still dies out (the
            # acceleration's residual, where ringing above the drive frequency shows most,
            # still falling by more than 10 % from block to block)
            ringing = _harmonics(b.accel_V, measure_periods, harmonics)[1]
            for _ in range(MAX_EXTRA_SETTLES):
                rig.run(settle * SETTLE_SAMPLES_PER_PERIOD, f * SETTLE_SAMPLES_PER_PERIOD)
                rig.run(2 * M, fs)
                nb = rig.run(measure_periods * M, fs)
                now = _harmonics(nb.accel_V, measure_periods, harmonics)[1]
                b = nb
                if not now < 0.9 * ringing:
                    break
                ringing = now
            g = (1 + model.force_gain_error, 1 + model.accel_gain_error, 1 + model.disp_gain_error)
            force = b.force_V / model.force_sens_V_per_N
            accel = b.accel_V / model.accel_sens_V_per_m_s2
            disp = b.disp_V / model.disp_sens_V_per_m
            force = force + noise[0] * model.F_s_N * g[0] * rng.standard_normal(force.size)
            accel = accel + noise[1] * np.std(accel) * rng.standard_normal(accel.size)
            disp = disp + noise[2] * model.x_s_m * g[2] * rng.standard_normal(disp.size)
            (P, sP, p1), (A, sA, a1), (X, sX, x1) = (_harmonics(s, measure_periods, harmonics)
                                                     for s in (force, accel, disp))
            h = StepHarmonics(freq_Hz=float(f), force=P, accel=A, disp=X, sigma_force=sP, sigma_accel=sA,
                              sigma_disp=sX)
            steps.append(Step(key=f"L{li:02d}-F{fi:03d}-up", level_N=float(abs(P[0])), freq_Hz=float(f),
                              harmonics=h, fs_Hz=f * p1.size, force_N=p1, accel_m_s2=a1, disp_m=x1))
        rig.set_generator(output_on=False)
        rig.run(settle_periods * SETTLE_SAMPLES_PER_PERIOD, freqs_Hz[-1] * SETTLE_SAMPLES_PER_PERIOD)
    return steps


def make_case(seed: int, effects: tuple[str, ...] | None = None, *, margin: tuple[float, float] = (1.3, 2.5),
              levels: int = 5, freqs: int = 18, noise: tuple[float, float, float] = (0.003, 0.005, 0.002)) -> Case:
    """A seeded case.  ``effects`` None draws one catalog effect at random (or none, with
    probability 1/7); ``()`` is a clean case."""
    rng = np.random.default_rng(seed)
    rig = random_rig(rng)
    if effects is None:
        pool = list(CATALOG) + ["clean"]
        pick = str(rng.choice(pool))
        effects = () if pick == "clean" else (pick,)
    fx = {}
    for e in effects:
        fx[e] = draw_effect(e, rig, rng, margin)
    params = dict(rig)
    for d in fx.values():
        params.update(d)
    model = RigModel(**params, seed=seed)
    top = ASYMMETRIC_TOP_LEVEL if "asymmetric_friction" in fx else 0.85
    levels_N, freqs_Hz = plan_grid(rig, levels, freqs, top)
    steps = measure_steps(model, levels_N, freqs_Hz, noise=noise, seed=seed)
    return Case(seed=seed, rig=rig, effects=fx, f_res_Hz=friction_resonance_Hz(rig), steps=steps)
