"""The simulated rig: one plant that the three instrument twins share.

    generator voltage -> amplifier + shaker (gain, force limit) -> force P(t) at the
    impedance head -> carriage mass with Masing friction -> sensors -> DAQ inputs (V)

The amplifier and shaker are an exact gain ``amp_gain_N_per_V`` (an ideal force source)
unless the shaker model is on (``shaker_force_constant_N_per_A`` > 0, decision 0025): then
a voltage amplifier drives an electrodynamic shaker (coil R, L, back-EMF Bl x_d';
armature mass, suspension) coupled to the carriage, and the impedance head measures the
force actually delivered, which drops out at the structure's resonance.

    m x'' = -F_Masing(x) - c x' - k x + P(t)

With the optional effects of :mod:`sim.plant_effects` on (velocity-dependent friction, a
pitching mode, a cubic spring, quadratic damping, asymmetric friction) the plant becomes

    m x'' + m e th'' = P - F_Masing(x) (1 + alpha |x'| / v_ref) (1 + a sign F_Masing)
                       - c x' - c2 x'|x'| - k x - k3 x^3
    m e x'' + J th'' = h P - k_th th - c_th th'

and the accelerometer (at the drive point, height h) reads x'' + h th'' while the
eddy-current probe reads the feed displacement x.  A plant with none of them on runs the
plain kernel (:mod:`sim._kernel`), one with any of them the 2-DOF kernel
(:mod:`sim._plant_kernel`).

Time is virtual: it advances only when :meth:`SimulatedRig.run` is asked for samples
(by the DAQ twin), so simulated tests run faster than real time; noise comes from a
seeded generator, so a run is reproducible, and is reseeded from (seed, step key) when the
procedure marks a step's measurement (:meth:`SimulatedRig.mark_step`), so a step's noise
does not depend on what ran before it.

Sensors: impedance-head force (V/N), accelerometer (V/(m/s^2)), eddy-current probe
(V/m about a stand-off gap).  Each has Gaussian noise and clips at +-10 V; the DAQ twin
quantises.  Optional effects (all off by default): viscous damping, a linear spring,
a displacement-channel delay, sensor gain errors, velocity-dependent friction, the
pitching mode, a hardening cubic spring, and an interference line on one sensor
(``line_channel``, ``line_freq_Hz``, ``line_amplitude``: mains hum, at the rig's absolute
time, so not locked to the drive).  The amplifier's saturation is
modelled as a limit on the force amplitude (the drive stays sinusoidal).
"""

from __future__ import annotations

import hashlib
import logging
import math
import threading
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from . import _contact_kernel, _kernel, _plant_kernel, plant_effects, rig_friction
from .dynamics import FrictionState
from .errors import ConfigurationError
from .friction import MODELS
from .masing import LAMBDA_MASING
from .virgin import SakaiCurve, check_positive_finite

log = logging.getLogger(__name__)

OUTPUT_RANGE_V = 10.0
LINE_CHANNELS = ("", "disp", "force", "accel")
REVERSAL_RESOLUTION = 16      # extra RK4 steps at small-force n < 1 reversals


# ---------------------------------------------------------------------------- the model's keys
# Each field of RigModel declares itself once (decision 0058): its unit, its range as a
# [rig.model] key, what it means, its group and whether the plant implements it.  The TOML
# schema (bench.config.model_schema), the key reference (docs/gen_keys.py), the twin's "not
# in the plant" list, the plant-effect fields and what the drawn lines leave out are read
# from here.
GROUPS = {
    "friction": "the friction model of the contact (decision 0075)",
    "masing": "the Masing carriage",
    "drive": "amplifier and shaker as a force source",
    "sensor": "sensor sensitivities",
    "noise": "sensor noise",
    "linear": "linear damping and spring",
    "sensor_error": "sensor errors",
    "effect": "optional effects beyond the Masing model",
    "line": "an interference line on one sensor",
    "shaker": "the electrodynamic shaker (decision 0025)",
    "numerics": "the simulation itself",
}
# groups whose keys the model checks with validators of their own (plant_effects.validate, the line's)
OWN_CHECKS = ("effect", "shaker", "line")


@dataclass(frozen=True)
class ModelKey:
    """One [rig.model] key: unit, range (``lo`` excluded when ``lo_open``; ``hi`` included),
    meaning, group (:data:`GROUPS`), and whether the plant implements it (a key the plant
    does not yet simulate is still parsed; the twin lists a cause that needs it as not in
    the plant).  A text key is one of ``choices`` (its range unused)."""

    unit: str
    lo: float
    hi: float
    meaning: str
    group: str
    lo_open: bool = False
    integer: bool = False
    choices: tuple[str, ...] = ()
    in_plant: bool = True

    @property
    def off(self) -> str | float:
        """The value that turns this key's effect off ("" for a choice, else 0)."""
        return "" if self.choices else 0.0


def model_key(default, unit: str, lo: float, hi: float, meaning: str, group: str, **kw) -> Any:
    """A RigModel field declaring its [rig.model] key (:class:`ModelKey`)."""
    if group not in GROUPS:
        raise ValueError(f"unknown group {group!r}; allowed: {sorted(GROUPS)}")
    return field(default=default, metadata={"key": ModelKey(unit, lo, hi, meaning, group, **kw)})


def model_keys(*groups: str, model: type | None = None) -> dict[str, ModelKey]:
    """Every declared key of ``model`` (default: :class:`RigModel` as it is now), in field
    order; only those of ``groups`` when given."""
    return {f.name: f.metadata["key"] for f in fields(model or RigModel)
            if "key" in f.metadata and (not groups or f.metadata["key"].group in groups)}


@dataclass(frozen=True)
class RigModel:
    """Physical parameters of the simulated rig (SI units).  Each field is a [rig.model] key
    declared with :func:`model_key`: adding an effect is one field here and its physics.
    ``friction`` names the contact's model (:data:`sim.friction.MODELS`); a model other than
    Masing keeps its parameters, as that model declares them, in ``friction_parameters``
    (decision 0075; Masing's are the fields F_s_N, x_s_m and n)."""

    friction: str = model_key(rig_friction.MASING, "", 0, 0, "the friction model of the contact; a model other "
                              "than masing takes its parameters as keys of this table (the friction models' "
                              "table below)", "friction", choices=tuple(MODELS))
    F_s_N: float = model_key(10.0, "N", 0, 1e4, "F_s, the friction force the Masing curve saturates at",
                             "masing", lo_open=True)
    x_s_m: float = model_key(10e-6, "m", 0, 1e-2, "x_s, the starting rolling displacement", "masing", lo_open=True)
    n: float = model_key(1.5, "1", 0, 10, "n, the exponent of the virgin curve (not 1)", "masing", lo_open=True)
    mass_kg: float = model_key(10.0, "kg", 0, 1e4, "m, the carriage mass", "masing", lo_open=True)
    amp_gain_N_per_V: float = model_key(20.0, "N/V", 0, 1e4, "generator volt (amplitude) -> shaker force; the "
                                        "blocked force per volt at DC when the shaker model is on", "drive",
                                        lo_open=True)
    amp_force_limit_N: float = model_key(150.0, "N", 0, 1e4, "the amplifier's largest force amplitude", "drive",
                                         lo_open=True)
    force_sens_V_per_N: float = model_key(0.0225, "V/N", 0, 100, "impedance head, 22.5 mV/N", "sensor", lo_open=True)
    accel_sens_V_per_m_s2: float = model_key(0.0102, "V/(m/s^2)", 0, 100, "accelerometer, 100 mV/g", "sensor",
                                             lo_open=True)
    disp_sens_V_per_m: float = model_key(8000.0, "V/m", 0, 1e7, "eddy-current probe, 8 V/mm", "sensor", lo_open=True)
    probe_standoff_m: float = model_key(1.1e-3, "m", 0, 0.1, "the probe's gap at x = 0, mid-range of a 0.1-2.1 mm "
                                        "probe", "sensor")
    force_noise_N: float = model_key(0.002, "N", 0, 1e3, "Gaussian noise of the force channel", "noise")
    accel_noise_m_s2: float = model_key(0.002, "m/s^2", 0, 1e4, "Gaussian noise of the acceleration channel",
                                        "noise")
    disp_noise_m: float = model_key(2e-9, "m", 0, 1e-2, "Gaussian noise of the displacement channel", "noise")
    # optional effects, off by default
    viscous_N_s_per_m: float = model_key(0.0, "N s/m", 0, 1e6, "c, viscous damping c x'", "linear")
    spring_N_per_m: float = model_key(0.0, "N/m", 0, 1e9, "k, a linear spring k x", "linear")
    disp_delay_s: float = model_key(0.0, "s", 0, 0.1, "a delay of the displacement channel", "sensor_error")
    force_gain_error: float = model_key(0.0, "relative", -0.5, 0.5, "the force sensor reads (1 + this) x the "
                                        "force, e.g. 0.02 = 2 % high", "sensor_error")
    accel_gain_error: float = model_key(0.0, "relative", -0.5, 0.5, "the accelerometer's relative gain error",
                                        "sensor_error")
    disp_gain_error: float = model_key(0.0, "relative", -0.5, 0.5, "the displacement probe's relative gain error",
                                       "sensor_error")
    friction_alpha: float = model_key(0.0, "1", 0, 100, "alpha: F = F_Masing(x) (1 + alpha |v| / v_ref)", "effect")
    friction_v_ref_m_per_s: float = model_key(0.0, "m/s", 0, 10, "v_ref of the speed-dependent friction, > 0 "
                                              "when friction_alpha > 0", "effect")
    pitch_inertia_kg_m2: float = model_key(0.0, "kg m^2", 0, 1e3, "J about the guideway contact line; must exceed "
                                           "mass_kg * cg_height_m^2; 0 = no pitching mode", "effect")
    pitch_stiffness_N_m_per_rad: float = model_key(0.0, "N m/rad", 0, 1e9, "k_th, > 0 when the pitch is on",
                                                   "effect")
    pitch_damping_N_m_s_per_rad: float = model_key(0.0, "N m s/rad", 0, 1e6, "c_th, the pitching mode's damping",
                                                   "effect")
    drive_height_m: float = model_key(0.0, "m", 0, 10, "h: shaker force and accelerometer above the guideway",
                                      "effect")
    cg_height_m: float = model_key(0.0, "m", 0, 10, "e: centre of gravity above the guideway", "effect")
    cubic_spring_N_per_m3: float = model_key(0.0, "N/m^3", 0, 1e20, "k3, a hardening spring k3 x^3", "effect")
    # an interference line on one sensor (mains hum), not locked to the drive: off when ""
    line_channel: str = model_key("", "", 0, 0, "the sensor an interference line (mains hum) adds to; "
                                  "\"\" = none", "line", choices=LINE_CHANNELS)
    line_freq_Hz: float = model_key(0.0, "Hz", 0, 1e5, "the interference line's frequency, > 0 when "
                                    "line_channel is set", "line")
    line_amplitude: float = model_key(0.0, "unit of line_channel: m, N or m/s^2", 0, 1e4,
                                      "the interference line's amplitude", "line")
    quadratic_damping_N_s2_per_m2: float = model_key(0.0, "N s^2/m^2", 0, 1e9, "c2, quadratic damping c2 x'|x'| "
                                                     "(oil, air)", "effect")
    friction_asymmetry: float = model_key(0.0, "1", -0.5, 0.5, "a: friction saturates at +F_s(1+a), -F_s(1-a); "
                                          "|a| < 0.5", "effect", lo_open=True)
    # electrodynamic shaker (decision 0025): on when the force constant Bl > 0; then
    # amp_gain_N_per_V is the blocked force per generator volt at DC
    shaker_force_constant_N_per_A: float = model_key(0.0, "N/A", 0, 1e3, "Bl; 0 = an ideal force source", "shaker")
    shaker_resistance_ohm: float = model_key(0.0, "ohm", 0, 1e3, "R (coil + amplifier output), > 0 when the "
                                             "shaker is on", "shaker")
    shaker_inductance_H: float = model_key(0.0, "H", 0, 1, "L, the electrical pole at R / (2 pi L)", "shaker")
    shaker_armature_mass_kg: float = model_key(0.0, "kg", 0, 100, "m_a (armature + stinger), moves with the drive "
                                               "point", "shaker")
    shaker_suspension_N_per_m: float = model_key(0.0, "N/m", 0, 1e8, "k_a, armature suspension to ground", "shaker")
    shaker_damping_N_s_per_m: float = model_key(0.0, "N s/m", 0, 1e5, "c_a, the armature's damping", "shaker")
    steps_per_period: int = model_key(400, "steps", 20, 1e5, "RK4 steps per drive period (minimum)", "numerics",
                                      integer=True)
    seed: int = model_key(0, "", 0, 2**63 - 1, "seed of the sensor noise", "numerics", integer=True)
    # a friction model other than Masing: its parameters, (name, value) in its declared order
    friction_parameters: tuple[tuple[str, float], ...] = ()

    def __post_init__(self):
        SakaiCurve(self.n)  # validates n (> 0 and not 1), with its own words
        self._validate_friction()
        # from the declarations (decision 0066): a range open at 0 must be > 0, one closed at
        # 0 >= 0; effect, shaker and line keys are checked by their own validators below
        for f in fields(self):
            key = f.metadata.get("key")
            if key is None or key.lo != 0 or key.integer or key.choices or key.group in OWN_CHECKS:
                continue
            v = getattr(self, f.name)
            if key.lo_open:
                check_positive_finite(f.name, v)
            elif isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
                raise ConfigurationError(f"{f.name} must be finite and >= 0, got {v!r}")
        plant_effects.validate(self)
        self._validate_line()

    def _validate_line(self) -> None:
        if self.line_channel not in LINE_CHANNELS:
            raise ValueError(f"line_channel must be one of {list(LINE_CHANNELS)}, got {self.line_channel!r}")
        for name in ("line_freq_Hz", "line_amplitude"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
        if self.line_channel and not self.line_freq_Hz > 0:
            raise ValueError(f"line_freq_Hz must be > 0 when line_channel is set, got {self.line_freq_Hz!r}")

    def _validate_friction(self) -> None:
        model = MODELS.get(self.friction)
        if model is None:
            raise ConfigurationError(f"friction must be one of {list(MODELS)}, got {self.friction!r}")
        given = dict(self.friction_parameters)
        if self.friction == rig_friction.MASING:
            if given:
                raise ConfigurationError(f"friction parameters {sorted(given)} are not masing's (its parameters "
                                         "are the fields F_s_N, x_s_m and n)")
            return
        problems = model.problems(given)
        if problems:
            raise ConfigurationError(f"{self.friction} parameters refused: "
                                     + ", ".join(f"{p.name} ({p.problem}, got {p.value!r})" for p in problems))

    @property
    def friction_values(self) -> dict[str, float]:
        """The friction model's parameters by name (Masing's from its fields)."""
        if self.friction == rig_friction.MASING:
            return {"F_s_N": self.F_s_N, "x_s_m": self.x_s_m, "n": self.n}
        return dict(self.friction_parameters)

    @property
    def friction_level_N(self) -> float:
        """The force (N) the friction saturates at: F_s for Masing, the model's own otherwise."""
        return float(MODELS[self.friction].friction_level(self.friction_values))

    @classmethod
    def from_dict(cls, d: dict) -> RigModel:
        """The model of flat [rig.model] keys (as :meth:`keys` gives them): a friction model's
        parameters among them; one that is not the named model's is refused."""
        d = dict(d)
        friction = d.get("friction", rig_friction.MASING)
        given = tuple(tuple(kv) for kv in d.pop("friction_parameters", ()))   # asdict's layout of the same model
        pairs = given + tuple((k, d.pop(k)) for k in rig_friction.own_parameters(friction) if k in d)
        wrong = rig_friction.misplaced(friction, [k for k in d if k != "friction"])
        if wrong:
            raise ConfigurationError("rig model keys of another friction model than " + repr(friction) + ": "
                                     + ", ".join(f"{k} ({' or '.join(o)})" for k, o in wrong))
        known = {f.name for f in fields(cls) if "key" in f.metadata}
        unknown = set(d) - known
        if unknown:
            raise ConfigurationError(f"unknown rig model keys {sorted(unknown)}; allowed: {sorted(known)}")
        return cls(**d, friction_parameters=pairs) if pairs else cls(**d)

    def keys(self) -> dict:
        """The model as flat [rig.model] keys (run.json's ``rig.model``): every declared key in
        field order, then a friction model's parameters; Masing's model as it was before
        decision 0075 (no ``friction`` key), another without Masing's keys."""
        masing = self.friction == rig_friction.MASING
        skip = {"friction"} if masing else set(MODELS[rig_friction.MASING].names)
        out = {f.name: getattr(self, f.name) for f in fields(self) if "key" in f.metadata and f.name not in skip}
        return {**out, **dict(self.friction_parameters)}

    @property
    def omega_s(self) -> float:
        """Natural angular frequency at the starting rolling displacement (rad/s)."""
        return math.sqrt(self.F_s_N / (self.x_s_m * self.mass_kg))


@dataclass
class RigBlock:
    """Sampled sensor voltages at the DAQ inputs."""

    t0_s: float
    fs_Hz: float
    force_V: np.ndarray
    accel_V: np.ndarray
    disp_V: np.ndarray


@dataclass
class _Generator:
    freq_Hz: float = 1000.0
    amplitude_Vpp: float = 0.1
    offset_V: float = 0.0
    output_on: bool = False


class SimulatedRig:
    """The plant behind the twins.  Hold ``lock`` when calling from several threads."""

    def __init__(self, model: RigModel | None = None):
        self.model = model or RigModel()
        self.lock = threading.RLock()
        self.curve = SakaiCurve(self.model.n)
        self.state = FrictionState()
        self.pitch_rad = 0.0            # pitch angle and rate (2-DOF plant only)
        self.pitch_rate_rad_s = 0.0
        self.coil_force_N = 0.0         # Bl i (shaker model with an inductance only)
        self._coef = plant_effects.coefficients(self.model)
        # a friction model other than Masing: its contact's state (state.u, state.v in m, m/s)
        self.contact: rig_friction.Contact | None = None
        self.contact_state = np.zeros(0)
        self.contact_force_N = 0.0
        self.contact_direction = 0.0
        if self.model.friction != rig_friction.MASING:
            self.contact = rig_friction.contact(self.model.friction, self.model.friction_values)
            self.contact_state = np.zeros(self.contact.state_size)
            self._coef = plant_effects.coefficients(self.model, physical=True)
        self._resolution_key: float | None = None
        self._resolution = 1.0
        self.gen = _Generator()
        self._t = 0.0
        self._phase = 0.0
        self._rng = np.random.default_rng(self.model.seed)
        self._disp_tail = np.zeros(0)   # recent true displacement, for the delay effect
        self._fs_tail = 0.0

    @property
    def time_s(self) -> float:
        return self._t

    def set_generator(self, *, freq_Hz: float | None = None, amplitude_Vpp: float | None = None,
                      offset_V: float | None = None, output_on: bool | None = None) -> None:
        with self.lock:
            if freq_Hz is not None:
                self.gen.freq_Hz = check_positive_finite("freq_Hz", freq_Hz)
            if amplitude_Vpp is not None:
                if not (math.isfinite(amplitude_Vpp) and amplitude_Vpp >= 0):
                    raise ConfigurationError(f"amplitude_Vpp must be finite and >= 0, got {amplitude_Vpp!r}")
                self.gen.amplitude_Vpp = float(amplitude_Vpp)
            if offset_V is not None:
                if not math.isfinite(offset_V):
                    raise ConfigurationError(f"offset_V must be finite, got {offset_V!r}")
                self.gen.offset_V = float(offset_V)
            if output_on is not None:
                self.gen.output_on = bool(output_on)

    def mark_step(self, key: str) -> None:
        """A step's measurement starts: reseed the sensor noise from (seed, key), so a step
        gets the same noise whatever ran before it (a resumed run stores what an
        uninterrupted one does).  Sent by the SCPI twin's ``SIM:STEP``."""
        digest = hashlib.sha256(str(key).encode()).digest()
        self._rng = np.random.default_rng([self.model.seed, int.from_bytes(digest[:8], "little")])
        log.debug("plant noise reseeded for step %s", key)

    def drive_force(self) -> tuple[float, float]:
        """(amplitude, static part) of the shaker force in N for the present settings (the
        blocked force, before the shaker model, when that is on)."""
        m, g = self.model, self.gen
        if not g.output_on:
            return 0.0, 0.0
        amp = min(m.amp_gain_N_per_V * 0.5 * g.amplitude_Vpp, m.amp_force_limit_N)
        dc = float(np.clip(m.amp_gain_N_per_V * g.offset_V, -m.amp_force_limit_N, m.amp_force_limit_N))
        return amp, dc

    def gap_m(self) -> float:
        with self.lock:
            return self.model.probe_standoff_m + self.state.u * (self.model.x_s_m if self.contact is None else 1.0)

    def run(self, n_samples: int, fs_Hz: float) -> RigBlock:
        """Advance the plant by ``n_samples / fs_Hz`` seconds and sample the sensors."""
        n_samples = int(n_samples)
        if n_samples <= 0:
            raise ConfigurationError(f"n_samples must be > 0, got {n_samples}")
        fs_Hz = check_positive_finite("fs_Hz", fs_Hz)
        with self.lock:
            return self._run(n_samples, fs_Hz)

    def _resolution_factor(self, P_amp: float) -> float:
        """How much finer than ``steps_per_period`` the time step must be at this force.

        For n < 1 the virgin curve's initial stiffness is infinite, so the step is sized for
        10 F_s/x_s; at small force the loop's secant stiffness g(u)/u is far higher (about
        200 F_s/x_s at 0.1 F_s for n = 0.36) and the turn at each reversal is singular.
        Unresolved, the plant's acceleration and the second derivative of its displacement
        then disagree by up to 30 % at the fundamental (a spurious "sensor" effect).  The
        step shrinks with the secant natural frequency at the static deflection under the
        drive amplitude (an upper bound of the stiffness), x16 for the reversals, which
        brings the disagreement to about 1e-4 (decision 0014)."""
        m = self.model
        if m.n >= 1 or P_amp <= 0:
            return 1.0
        if self._resolution_key != P_amp:
            gamma, n = min(P_amp / m.F_s_N, 0.99), m.n
            lo, hi = 0.0, 1.0            # virgin curve g(u) = (u^n - n u)/(1 - n) = gamma
            for _ in range(60):
                u = 0.5 * (lo + hi)
                lo, hi = (u, hi) if (u ** n - n * u) / (1 - n) < gamma else (lo, u)
            ratio = math.sqrt(gamma / max(u, 1e-12) / 10.0)
            self._resolution_key, self._resolution = P_amp, (REVERSAL_RESOLUTION * ratio if ratio > 1 else 1.0)
        return self._resolution

    def _run(self, n: int, fs: float) -> RigBlock:
        if self.contact is not None:
            return self._sensors(n, fs, *self._run_contact(n, fs))
        m, st = self.model, self.state
        P_amp, P_dc = self.drive_force()
        omega = 2 * math.pi * self.gen.freq_Hz
        # Resolve the drive period and the friction's small-amplitude natural period.
        k0 = self.curve.stiffness0 if math.isfinite(self.curve.stiffness0) else 10.0
        f_nat = plant_effects.highest_linear_frequency_Hz(m, k0 * m.F_s_N / m.x_s_m + m.spring_N_per_m)
        f_res = max(self.gen.freq_Hz, f_nat)
        sub = max(1, math.ceil(m.steps_per_period * self._resolution_factor(P_amp) * f_res / fs))
        if plant_effects.shaker_on(m) and m.shaker_inductance_H > 0:   # RK4 step <= L/R / 2
            sub = max(sub, math.ceil(2.0 * m.shaker_resistance_ohm / (m.shaker_inductance_H * fs)))
        h = 1.0 / (fs * sub)
        if self._coef is None:
            rec = np.empty((n, 5))
            (st.u, st.v, st.k, st.d, st.su, st.sF, *_rest) = _kernel.rk4_run(
                st.u, st.v, 0.0, st.k, st.d, st.su, st.sF, LAMBDA_MASING, self.curve.kind, self.curve.params,
                m.omega_s ** 2, P_amp / m.F_s_N, omega, self._phase, P_dc / m.F_s_N,
                m.viscous_N_s_per_m / m.mass_kg, m.spring_N_per_m / m.mass_kg,
                h, n * sub, sub, rec)
            accel = rec[:, 3] * m.x_s_m
        else:
            rec = np.empty((n, 7))
            (st.u, st.v, self.pitch_rad, self.pitch_rate_rad_s, q, st.k, st.d, st.su, st.sF) = _plant_kernel.plant_run(
                st.u, st.v, self.pitch_rad, self.pitch_rate_rad_s, self.coil_force_N / m.F_s_N, 0.0,
                st.k, st.d, st.su, st.sF,
                LAMBDA_MASING, self.curve.kind, self.curve.params, P_amp / m.F_s_N, omega, self._phase,
                P_dc / m.F_s_N, self._coef, h, n * sub, sub, rec)
            self.coil_force_N = q * m.F_s_N
            accel = rec[:, 3] * m.x_s_m + m.drive_height_m * rec[:, 4]
        t_rel = np.arange(n) / fs          # the drive's time base and the interference line's
        if plant_effects.shaker_on(m):
            force = rec[:, 6] * m.F_s_N
        else:
            force = P_amp * np.sin(omega * t_rel + self._phase) + P_dc
        return self._sensors(n, fs, force, accel, rec[:, 1] * m.x_s_m, omega)

    def _run_contact(self, n: int, fs: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """The plant with a friction model other than Masing on the contact kernel (physical
        units): (force, acceleration, displacement, omega) of ``n`` samples at ``fs``."""
        m, st, c = self.model, self.state, self.contact
        assert c is not None and self._coef is not None
        P_amp, P_dc = self.drive_force()
        omega = 2 * math.pi * self.gen.freq_Hz
        f_nat = plant_effects.highest_linear_frequency_Hz(m, c.stiffness_N_per_m + m.spring_N_per_m)
        sub = max(1, math.ceil(m.steps_per_period * max(self.gen.freq_Hz, f_nat) / fs))
        if plant_effects.shaker_on(m) and m.shaker_inductance_H > 0:   # RK4 step <= L/R / 2
            sub = max(sub, math.ceil(2.0 * m.shaker_resistance_ohm / (m.shaker_inductance_H * fs)))
        rec = np.empty((n, 7))
        (st.u, st.v, self.pitch_rad, self.pitch_rate_rad_s, self.coil_force_N, self.contact_force_N,
         self.contact_direction) = _contact_kernel.contact_run(
            type(c.model).advance, c.params, self.contact_state, np.empty(c.state_size), st.u, st.v,
            self.pitch_rad, self.pitch_rate_rad_s, self.coil_force_N, self.contact_force_N, self.contact_direction,
            0.0, P_amp, omega, self._phase, P_dc, self._coef, 1.0 / (fs * sub), n * sub, sub, rec)
        accel = rec[:, 3] + m.drive_height_m * rec[:, 4]
        if plant_effects.shaker_on(m):
            force = rec[:, 6]
        else:
            force = P_amp * np.sin(omega * np.arange(n) / fs + self._phase) + P_dc
        return force, accel, rec[:, 1], omega

    def _sensors(self, n: int, fs: float, force: np.ndarray, accel: np.ndarray, disp: np.ndarray,
                 omega: float) -> RigBlock:
        """The true force, acceleration and displacement through the sensors (delay, line,
        noise, gain errors, clipping); the rig's clock and the drive's phase moved on."""
        m = self.model
        t_rel = np.arange(n) / fs
        if m.disp_delay_s > 0:
            disp = self._delayed(disp, fs)
        if m.line_channel and m.line_amplitude > 0:      # on the sensor, at the rig's absolute time
            line = m.line_amplitude * np.sin(2 * math.pi * m.line_freq_Hz * (self._t + t_rel))
            force, accel, disp = (v + line if name == m.line_channel else v
                                  for name, v in (("force", force), ("accel", accel), ("disp", disp)))
        rng = self._rng
        out = RigBlock(
            t0_s=self._t, fs_Hz=fs,
            force_V=self._sensor(force, m.force_sens_V_per_N, m.force_gain_error, m.force_noise_N, rng),
            accel_V=self._sensor(accel, m.accel_sens_V_per_m_s2, m.accel_gain_error, m.accel_noise_m_s2, rng),
            disp_V=self._sensor(disp, m.disp_sens_V_per_m, m.disp_gain_error, m.disp_noise_m, rng))
        self._t += n / fs
        self._phase = math.fmod(self._phase + omega * n / fs, 2 * math.pi)
        return out

    def _delayed(self, disp: np.ndarray, fs: float) -> np.ndarray:
        """Displacement seen through a channel delay (linear interpolation of the past)."""
        if self._fs_tail != fs:
            self._disp_tail = np.full(1, disp[0])
            self._fs_tail = fs
        hist = np.concatenate([self._disp_tail, disp])
        lag = self.model.disp_delay_s * fs
        idx = np.arange(disp.size) + self._disp_tail.size - lag
        delayed = np.interp(idx, np.arange(hist.size), hist)
        self._disp_tail = hist[-(int(lag) + 2):]
        return delayed

    @staticmethod
    def _sensor(x, sens, gain_error, noise, rng) -> np.ndarray:
        v = (x + noise * rng.standard_normal(x.size)) * sens * (1.0 + gain_error)
        return np.clip(v, -OUTPUT_RANGE_V, OUTPUT_RANGE_V)
