"""The base Masing model and its candidate extensions, as two residuals per harmonic.

For every step and harmonic k (Omega = k omega) the measured complex amplitudes of force
P, drive-point acceleration A and displacement X must satisfy

    force balance   r_F = P - m A - G(X, P)      G: friction and what else acts on the carriage
    kinematics      r_K = A - A_pred(X, P)       what the accelerometer should read

The base model is G = F_Masing(x) along the measured displacement and A_pred = -Omega^2 X
(a rigid carriage).  A sharp reversal for n < 1 needs far more harmonics of x than the
probe's noise leaves usable, so the friction follows :mod:`sim.identify`: x is rebuilt from
every harmonic, each the inverse-variance mean of the probe's X_k and of the
accelerometer's A_k mapped to displacement (:func:`sim.identify.displacement_harmonics`;
the probe carries the low harmonics, the accelerometer the high ones).  Both channels go
through the CANDIDATE's own kinematics before they are mixed (the probe through its sensor
delay or gain, the accelerometer through the rigid map or the pitching mode's transfer),
so the friction never assumes the agreement of the two channels that the kinematic
candidates test.  Each catalog effect changes one of these:

- ``viscous_damping``:   G += i Omega c X
- ``linear_spring``:     G += k X
- ``velocity_dependent_friction``: F = F_Masing(x) (1 + beta |v|) in the time domain;
  only beta = alpha / v_ref is identifiable (reported as alpha at a stated v_ref)
- ``sensor_delay``:      the probe lags: x_true,k = X_k exp(+i Omega tau)
- ``sensor_gain_error``: the probe's scale relative to the accelerometer: x_true = X / (1 + g)
- ``second_mode``:       a pitching mode (frequency f_p, damping ratio zeta) driven by the
  force at height h and coupled through the centre of gravity at e: with
  D = omega_p^2 - Omega^2 + 2 i zeta omega_p Omega, a = h^2 / J and r = e / h,
      h theta'' = -Omega^2 a (P + m r Omega^2 x) / D,
      A_pred += h theta'',  G += m (r - 1) h theta''
  (from m x'' + m e theta'' = P - F and m e x'' + J theta'' = h P - k_th theta - c_th theta';
  the accelerometer at h reads x'' + h theta'', the probe reads x).

The force effects (viscous damping, spring, velocity-dependent friction) and the library
of force terms outside the catalog are :class:`~sim.discrepancy.effects.Effect` objects with
a ``force`` function, added to G in :meth:`Model.terms`; only the kinematic effects are
written out here.

Everything is affine in P, so a model also predicts P and A from the measured X alone
(:meth:`Model.predict`): that is how compliance and accelerance are predicted for held-out
steps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigurationError
from ..friction import MODELS
from ..identify import POINTS_PER_PERIOD, path_friction, period_paths
from .effects import CATALOG, CENTRE, CENTRED, EFFECTS, LIBRARY, Effect, Path  # noqa: F401  (re-exported)

BASE_PARAMS = ("F_s_N", "x_s_m", "n", "mass_kg")
# the friction laws a Model's head (friction level, length, shape, log m) can be: Sakai-Masing,
# or Dahl's with F_c in the F_s slot, the pre-rolling length F_c / sigma in x_s's and its
# exponent in n's (decision 0078)
HEAD_FRICTIONS = ("masing", "dahl")
MOTION_EFFECTS = ("sensor_delay", "sensor_gain_error", "second_mode")   # they change the rebuilt x
MEMO_ENTRIES = 24




@dataclass(frozen=True)
class Data:
    """Harmonics of the steps as arrays (steps x K) and their standard errors (per step);
    for the friction, every harmonic of both motion channels (steps x Kf, zero-padded)."""

    omega: np.ndarray     # rad/s, per step
    P: np.ndarray
    A: np.ndarray
    X: np.ndarray
    sP: np.ndarray
    sA: np.ndarray
    sX: np.ndarray
    level: np.ndarray     # force-level group of each step (for leave-one-level-out)
    Xf: np.ndarray | None = None    # probe's displacement harmonics 1..Kf (m)
    XAf: np.ndarray | None = None   # accelerometer's, as a rigid carriage's displacement -A_k / (k w)^2
    wDf: np.ndarray | None = None   # the probe's weight in their inverse-variance mean
    Pf: np.ndarray | None = None    # force harmonics 1..Kf (the pitching mode's transfer needs them)
    x0: np.ndarray | None = None    # mean displacement of each step about the median step's (m)

    FIELDS = ("omega", "P", "A", "X", "sP", "sA", "sX", "level", "Xf", "XAf", "wDf", "Pf", "x0")

    @property
    def Omega(self) -> np.ndarray:
        return self.omega[:, None] * np.arange(1, self.X.shape[1] + 1)

    def friction_channels(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(X, XA, wD, P) over every harmonic at hand (the probe alone when only it is)."""
        if self.Xf is None or self.XAf is None or self.wDf is None or self.Pf is None:
            return self.X, np.zeros_like(self.X), np.ones(self.X.shape), self.P
        return self.Xf, self.XAf, self.wDf, self.Pf

    def subset(self, mask: np.ndarray) -> Data:
        return Data(*(None if getattr(self, f) is None else getattr(self, f)[mask]   # type: ignore[arg-type]
                      for f in self.FIELDS))


def dahl_dimless(paths: np.ndarray, length_m: float, exponent: float, omega: np.ndarray) -> np.ndarray:
    """Dahl's steady friction over F_c along rows of ``paths`` (sim.friction.Dahl with F_c = 1
    and sigma = 1 / length): a function of x / length and the exponent alone."""
    return MODELS["dahl"].periodic_force(dict(F_c_N=1.0, sigma_N_per_m=1.0 / length_m, exponent=exponent),
                                          paths, omega)


class Model:
    """Base Masing model plus a set of effects; parameters as one flat vector.

    The vector holds log F_s, log x_s, n, log m, then each effect's parameters in the
    units of :data:`EFFECTS` (f_p in log Hz)."""

    def __init__(self, effects: tuple[str, ...] = (), harmonics: int = 9, points_per_period: int = POINTS_PER_PERIOD,
                 scales: dict | None = None, friction: str = "masing"):
        if friction not in HEAD_FRICTIONS:
            raise ConfigurationError(f"friction {friction!r}: the fitted head is one of {HEAD_FRICTIONS}")
        self.friction = friction
        unknown = [e for e in effects if e not in EFFECTS]
        if unknown:
            raise ConfigurationError(f"unknown effects {unknown}; catalog: {CATALOG}; library: {LIBRARY}")
        self.effects = tuple(effects)
        self.M = points_per_period
        self.K = harmonics
        self.slices = {}
        i = len(BASE_PARAMS)
        for e in self.effects:
            self.slices[e] = slice(i, i + len(EFFECTS[e].names))
            i += len(EFFECTS[e].names)
        self.size = i
        # library coefficients are fitted as multiples of a scale that makes them O(1)
        # (a cubic stiffness in N/m^3 is ~1e16 on a micrometre rig: a finite-difference
        # step of 1 would not move the force at all)
        self.scales = {e: float((scales or {}).get(e, 1.0)) for e in self.effects}
        self.scale = np.ones(i)
        for e, sl in self.slices.items():
            self.scale[sl] = self.scales[e]
        self._memo: dict = {}        # (data, key) -> what depends on the key only (see _cached)

    def __getstate__(self) -> dict:
        return dict(self.__dict__, _memo={})        # the memo is a cache, not state

    # ------------------------------------------------------------------ parameters
    def values(self, theta: np.ndarray) -> dict:
        """Physical values by name (effects' names prefixed by their id)."""
        out = dict(F_s_N=math.exp(theta[0]), x_s_m=math.exp(theta[1]), n=float(theta[2]),
                   mass_kg=math.exp(theta[3]))
        for e in self.effects:
            p = theta[self.slices[e]]
            for name, v in zip(EFFECTS[e].names, p):
                out[f"{e}.{name}"] = math.exp(v) if name == "f_p" else float(v) * self.scales[e]
        return out

    def extend(self, theta: np.ndarray, effect: str, init: np.ndarray, scale: float = 1.0) -> tuple[Model, np.ndarray]:
        """This model with one more effect, and the parameter vector warm-started from ``theta``
        (``scale``: the new effect's coefficient unit, see ``scales``).

        A stiffness term (:data:`CENTRED`) brings the springs' rest position x_c with it
        unless the model has it already (one shared per run, fitted in units of the current
        x_s; ``init`` may then carry its start as a second entry, else it starts at the
        median step's mean displacement, 0)."""
        if effect in CENTRED and CENTRE not in self.effects:
            m = Model(self.effects + (effect, CENTRE), self.K, self.M,
                      dict(self.scales, **{effect: scale, CENTRE: math.exp(theta[1])}), self.friction)
            init = np.asarray(init, float)
            return m, np.concatenate([theta, init[:1], init[1:2] if init.size > 1 else np.zeros(1)])
        m = Model(self.effects + (effect,), self.K, self.M, dict(self.scales, **{effect: scale}), self.friction)
        return m, np.concatenate([theta, init])

    # ------------------------------------------------------------------ physics
    def _sensor(self, v: dict, X: np.ndarray, Om: np.ndarray) -> np.ndarray:
        """The true displacement harmonics behind the probe's (delay and gain undone)."""
        if "sensor_delay" in self.effects:
            X = X * np.exp(1j * Om * v["sensor_delay.delay"])
        if "sensor_gain_error" in self.effects:
            X = X / (1.0 + v["sensor_gain_error.gain"])
        return X

    def _pitch(self, v: dict, Om: np.ndarray) -> tuple[np.ndarray, float, float, float]:
        """(D, a, r, m) of the pitching mode at the angular frequencies ``Om``."""
        w_p = 2 * math.pi * v["second_mode.f_p"]
        D = w_p ** 2 - Om ** 2 + 2j * v["second_mode.zeta"] * w_p * Om
        return D, v["second_mode.a"], v["second_mode.r"], v["mass_kg"]

    def _displacement(self, v: dict, d: Data) -> np.ndarray:
        """The true displacement's harmonics 1..Kf, rebuilt from both motion channels, each
        through this model's kinematics (module doc).

        The probe reads x through its sensor (delay, gain).  The accelerometer reads
        XA = -A / Omega^2 = g x + a P / D with g = 1 + a m r Omega^2 / D under the pitching
        mode (g = 1 for a rigid carriage).  Its estimate of x, (XA - a P / D) / g, has the
        noise variance of XA over |g|^2, so its inverse-variance weight against the probe
        becomes w = wD / (wD + |g|^2 (1 - wD)) (wD: the rigid carriage's weight).  At the
        coupled mode of a free carriage (g -> 0) the accelerometer carries no information on
        x and the probe takes over; written as below nothing divides by g."""
        X, XA, wD, P = d.friction_channels()
        Om = d.omega[:, None] * np.arange(1, X.shape[1] + 1)
        xp = self._sensor(v, X, Om)
        if "second_mode" not in self.effects:
            return wD * xp + (1.0 - wD) * XA
        D, a, r, m = self._pitch(v, Om)
        g = 1.0 + a * m * r * Om ** 2 / D
        den = np.maximum(wD + np.abs(g) ** 2 * (1.0 - wD), 1e-300)
        return (wD * xp + np.conj(g) * (1.0 - wD) * (XA - a * P / D)) / den

    def _cached(self, d: Data, key: tuple, make):
        """``make()`` for this data and key, remembered for the last few keys.  A Jacobian
        by finite differences moves one parameter at a time: the rebuilt displacement and
        its sampled period depend only on the motion effects' parameters (and m under the
        pitching mode), the Masing friction along it also on x_s and n, so most columns
        reuse both (F_s scales the friction; m, c, k, beta do not touch it)."""
        entry = self._memo.get(key)
        if entry is not None and entry[0] is d:
            return entry[1]
        value = make()
        if len(self._memo) >= MEMO_ENTRIES:
            self._memo.pop(next(iter(self._memo)))
        self._memo[key] = (d, value)
        return value

    def _motion_key(self, theta: np.ndarray) -> tuple:
        key = [float(v) for e in MOTION_EFFECTS if e in self.slices for v in theta[self.slices[e]]]
        if "second_mode" in self.slices:
            key.append(float(theta[3]))
        return ("x", *key)

    def _friction(self, theta: np.ndarray, v: dict, d: Data) -> tuple[np.ndarray, Path]:
        """(Harmonics 1..K of the Masing friction, the :class:`Path` the force terms use):
        the friction along the displacement rebuilt from every harmonic (module doc).  The
        measured force enters only the pitching mode's map of the accelerometer, so the
        result does not depend on a trial force (:meth:`predict` relies on that)."""
        mkey = self._motion_key(theta)

        def motion():
            x = self._displacement(v, d)
            paths, starts = period_paths(x, self.M)
            return x, paths, starts
        x, paths, starts = self._cached(d, mkey, motion)
        if self.friction == "dahl":
            n = v["n"]
            M = self._cached(d, mkey + (float(theta[1]), n), lambda: dahl_dimless(paths, v["x_s_m"], n, d.omega))
        else:
            n = v["n"] if abs(v["n"] - 1.0) >= 1e-6 else 1.0 + 1e-6
            M = self._cached(d, mkey + (float(theta[1]), n), lambda: path_friction(paths, v["x_s_m"], n))
        K = d.X.shape[1]
        ctx = Path(X=x[:, :K], Om=d.Omega, x=paths, starts=starts, x0=d.x0, centre=v.get(f"{CENTRE}.x_c", 0.0),
                   F_s=v["F_s_N"], x_s=v["x_s_m"], n=n, M_dimless=M, xf=x, omega=d.omega, cache=lambda key, make: self._cached(d, key, make), mkey=mkey)
        F = v["F_s_N"] * ctx.basis("M", lambda: M, friction=True)
        return F, ctx

    def context(self, theta: np.ndarray, d: Data) -> Path:
        """The :class:`Path` at ``theta`` (for screening terms not in the model)."""
        return self._friction(theta, self.values(theta), d)[1]

    def terms(self, theta: np.ndarray, d: Data, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(G, A_pred) for force harmonics ``P`` (the measured ones, or a trial).

        Everything acting on the carriage (G) follows the rebuilt displacement, the least
        noisy estimate of x at every harmonic; the rigid-body term of A_pred follows the
        probe alone, so that the kinematic residual compares the two channels."""
        v = self.values(theta)
        Om = d.Omega
        G, ctx = self._friction(theta, v, d)
        x = ctx.X
        for e in self.effects:
            force = EFFECTS[e].force
            if force is not None:
                G = G + force(ctx, theta[self.slices[e]] * self.scales[e])
        A_pred = -Om ** 2 * self._sensor(v, d.X, Om)
        if "second_mode" in self.effects:
            D, a, r, m = self._pitch(v, Om)
            h_th = -Om ** 2 * a * (P + m * r * Om ** 2 * x) / D
            A_pred = A_pred + h_th
            G = G + m * (r - 1.0) * h_th
        return G, A_pred

    def residuals(self, theta: np.ndarray, d: Data) -> tuple[np.ndarray, np.ndarray]:
        G, A_pred = self.terms(theta, d, d.P)
        m = math.exp(theta[3])
        return d.P - m * d.A - G, d.A - A_pred

    def predict(self, theta: np.ndarray, d: Data) -> tuple[np.ndarray, np.ndarray]:
        """(P, A) the model predicts from the measured displacement alone.

        P solves P = m A_pred(P) + G(P); both are affine in P, so two evaluations give it."""
        m = math.exp(theta[3])
        G0, A0 = self.terms(theta, d, np.zeros_like(d.P))
        f0 = m * A0 + G0
        if "second_mode" not in self.effects:
            return f0, A0
        G1, A1 = self.terms(theta, d, d.P)
        slope = (m * A1 + G1 - f0) / np.where(d.P == 0, 1.0, d.P)
        P = f0 / (1.0 - slope)
        return P, A0 + (A1 - A0) / np.where(d.P == 0, 1.0, d.P) * P
