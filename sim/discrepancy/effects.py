"""Every candidate cause as one kind of object: the six catalog effects and the library of
force terms the analysis may discover (issue 16).

An :class:`Effect` is a named set of parameters.  Force terms (everything acting on the
carriage) carry a ``force(ctx, p)`` that returns the harmonics 1..K of the force they add
to G in the force balance P - m A - G, given the parameters ``p`` and a :class:`Path`
context (the displacement rebuilt from every harmonic, sampled over one period, its
velocity and the Masing friction along it).  The kinematic catalog effects (sensor delay,
gain, the pitching mode) change how x is rebuilt and what the accelerometer should read;
they have ``force = None`` and live in :class:`~sim.discrepancy.models.Model`.

Library terms (``kind = "discovered"``), all with one coefficient that is 0 when absent:

==========================  =========================================  ==============
id                          added force                                coefficient
==========================  =========================================  ==============
``cubic_stiffness``         k3 (x - x_c)^3                             N/m^3
``quadratic_stiffness``     k2 (x - x_c) abs(x - x_c)   (odd)          N/m^2
``even_stiffness``          ke (x - x_c)^2  (even: a one-sided spring) N/m^2
``quadratic_damping``       c2 v abs(v)   (oil, air)                   N s^2/m^2
``cubic_damping``           c3 v^3                                     N s^3/m^3
``coulomb_friction``        F_c sign(v)   (constant-sign Coulomb)      N
``asymmetric_friction``     F_M (1 + a sign F_M) - F_M, the friction   1
                            saturates at +F_s(1+a), -F_s(1-a) (F_M
                            offset so its mean force is zero)
``similarity_ratio``        F_s (M_lambda - M_2): the Masing rule      1 (d = lambda - 2)
                            with branches F_r + lambda g((x-x_r)/lambda)
``virgin_curve_family``     w F_s (M[g_exp] - M[g_Sakai]),             1 (fraction w)
                            g_exp(s) = 1 - exp(-3 s)
``amplitude_dependent_n``   F_s b ln(X/x_s) dM/dn: n grows by b per    1
                            e-fold of the step's amplitude X
==========================  =========================================  ==============

(M: the dimensionless Masing friction along the path; F_M = F_s M; x: the step's mean
displacement relative to the median step's plus the motion; x_c: the springs' rest position
on that scale, :data:`CENTRE`, a parameter of the model from the first stiffness term on,
shared by all of them, decision record 0038.)  Each is linear in its
coefficient except ``similarity_ratio`` (exact in lambda), ``asymmetric_friction`` (exact
in a) and ``amplitude_dependent_n`` (first order in b).  ``step`` is the coefficient change the cheap screen uses
(:func:`sim.discrepancy.select.screen`): 1 for the linear terms.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ..identify import path_friction, path_harmonics
from ..masing import active_depth, push_reversal

EXP_RATE = 3.0          # the other virgin family: g(s) = 1 - exp(-EXP_RATE s)
DN = 1e-3               # central difference in n for amplitude_dependent_n


@dataclass(frozen=True)
class Effect:
    """One candidate cause: its parameters (names, units) as the fit sees them, its kind
    (``catalog`` or ``discovered``), its formula, and how it adds force (None: kinematic)."""

    id: str
    label: str
    names: tuple[str, ...]
    units: tuple[str, ...]
    kind: str = "catalog"
    formula: str = ""
    force: Callable | None = None
    bounds: tuple[tuple[float, float], ...] = ()
    step: float = 1.0
    words: str = ""          # what it usually is, for the sentence


@dataclass
class Path:
    """What the force terms need at one parameter vector: harmonics 1..K of the rebuilt
    displacement ``X`` (m), ``Om`` (rad/s, steps x K), one period of the displacement
    ``x`` along the path (m, steps x M), the Masing friction ``F`` along it (N) and a cache.
    ``cached(name, make, friction=False)`` remembers the harmonics of a basis per motion
    key (and per x_s, n when it depends on the friction)."""

    X: np.ndarray
    Om: np.ndarray
    x: np.ndarray
    starts: np.ndarray
    F_s: float
    x_s: float
    n: float
    M_dimless: np.ndarray
    xf: np.ndarray            # harmonics 1..Kf of the rebuilt displacement
    omega: np.ndarray
    cache: Callable           # (key, make) -> value
    mkey: tuple
    x0: np.ndarray | None = None
    centre: float = 0.0       # the springs' rest position relative to the median step's mean (m)
    _v: np.ndarray | None = field(default=None, repr=False)

    @property
    def x_abs(self) -> np.ndarray:
        """The path about the springs' rest position: the harmonics carry no mean, so the
        step's measured mean displacement ``x0`` (relative to the median step's) is added (a
        carriage that walked off under friction sits off centre, and a spring acts on where
        it is), and the rest position ``centre`` on that scale is subtracted."""
        x = self.x - self.x.mean(axis=1, keepdims=True)
        x = x if self.x0 is None else x + self.x0[:, None]
        return x - self.centre if self.centre else x

    @property
    def K(self) -> int:
        return self.X.shape[1]

    @property
    def v(self) -> np.ndarray:
        """Velocity along the path (m/s), rotated as the path is."""
        if self._v is None:
            def make():
                from ..identify import synthesize
                M = self.x.shape[1]
                Om = self.omega[:, None] * np.arange(1, self.xf.shape[1] + 1)
                vel = synthesize(1j * Om * self.xf, M)
                rows = np.arange(vel.shape[0])[:, None]
                return vel[rows, (self.starts[:, None] + np.arange(M)[None, :]) % M]
            self._v = self.cache(self.mkey + ("v",), make)
        return self._v

    def harm(self, samples: np.ndarray) -> np.ndarray:
        return path_harmonics(samples, self.starts, self.K)

    def basis(self, name: str, make, friction: bool = False) -> np.ndarray:
        key = self.mkey + ((self.x_s, self.n) if friction else ()) + (name,)
        return self.cache(key, lambda: self.harm(make()))


# ---------------------------------------------------------------- the other virgin family
@njit(cache=True, nogil=True, inline="always")
def _g_exp(s, c):
    if s >= 0.0:
        return 1.0 - math.exp(-c * s)
    return -(1.0 - math.exp(c * s))


@njit(cache=True, nogil=True)
def _loop_friction_exp(paths, lam, c, out):
    """As :func:`sim.identify`'s loop friction, with the virgin curve g_exp (the Masing rule
    is the same; only g differs)."""
    su = np.empty(16)
    sF = np.empty(16)
    for i in range(paths.shape[0]):
        k = 0
        top = paths[i, 0]
        d = 1.0 if top >= 0 else -1.0
        prev = top
        for j in range(paths.shape[1]):
            u = paths[i, j]
            if (u - prev) * d < 0.0:
                k = active_depth(prev, k, su, d)
                F_r = _g_exp(prev, c) if k == 0 else sF[k - 1] + lam * _g_exp((prev - su[k - 1]) / lam, c)
                k, su, sF = push_reversal(prev, F_r, k, su, sF)
                d = -d
            k = active_depth(u, k, su, d)
            out[i, j] = _g_exp(u, c) if k == 0 else sF[k - 1] + lam * _g_exp((u - su[k - 1]) / lam, c)
            prev = u


def exp_family_friction(paths: np.ndarray, x_s: float, lam: float = 2.0, c: float = EXP_RATE) -> np.ndarray:
    u = paths / x_s
    out = np.empty_like(u)
    _loop_friction_exp(u, lam, c, out)
    return out


# ---------------------------------------------------------------- force functions
def _viscous(ctx: Path, p):
    return 1j * ctx.Om * p[0] * ctx.X


def _spring(ctx: Path, p):
    return p[0] * ctx.X


def _rate_friction(ctx: Path, p):          # F (1 + beta |v|) - F
    return p[0] * ctx.F_s * ctx.basis("F|v|", lambda: ctx.M_dimless * np.abs(ctx.v), friction=True)


def _lin(name: str, fn, friction: bool = False, times_F_s: bool = False, centred: bool = False):
    def force(ctx: Path, p):
        b = ctx.basis(f"{name}@{ctx.centre!r}" if centred else name, lambda: fn(ctx), friction)
        return p[0] * (ctx.F_s if times_F_s else 1.0) * b
    return force


def _similarity(ctx: Path, p):
    lam = 2.0 + float(p[0])
    if lam == 2.0:
        return np.zeros_like(ctx.X)
    paths = ctx.x
    other = ctx.basis(f"lam={lam!r}", lambda: path_friction(paths, ctx.x_s, ctx.n, lam), friction=True)
    return ctx.F_s * (other - ctx.basis("M", lambda: ctx.M_dimless, friction=True))


def _amplitude_n(ctx: Path):
    dM = (path_friction(ctx.x, ctx.x_s, ctx.n + DN) - path_friction(ctx.x, ctx.x_s, ctx.n - DN)) / (2 * DN)
    amp = 0.5 * (ctx.x.max(axis=1) - ctx.x.min(axis=1))
    return dM * np.log(np.maximum(amp, 1e-300) / ctx.x_s)[:, None]


A_BOUND = 0.9
CENTRE = "spring_centre"    # the springs' rest position: a parameter of the model whenever a stiffness term is
CENTRED = ("cubic_stiffness", "quadratic_stiffness", "even_stiffness")   # one of these (their shared centre)
CENTRE_BOUND = 100.0        # |x_c| in its fit unit (x_s when the centre joined the model)


def _asymmetric(ctx: Path, p):
    """F_M (1 + a sign F_M) - F_M along the path.  The Masing element's loop is not centred
    on zero force once the friction is asymmetric: the carriage's mean force balance holds
    the total friction's mean at zero, so the element sits at F_M = F_c + F_loop with
    mean(h(F_c + F_loop)) = 0 for h(F) = F (1 + a sign F); F_c (per step) by Newton.  (To
    first order in a this is a |F_loop|; the offset matters at order a^2.)"""
    a = float(p[0])
    if a == 0.0:
        return np.zeros_like(ctx.X)

    def make():
        F = ctx.F_s * ctx.M_dimless
        Fc = -a * np.abs(F).mean(axis=1, keepdims=True)
        for _ in range(4):
            Ft = F + Fc
            g = (Ft + a * np.abs(Ft)).mean(axis=1, keepdims=True)
            Fc = Fc - g / (1.0 + a * np.sign(Ft).mean(axis=1, keepdims=True))
        Ft = F + Fc
        return ctx.harm(Ft + a * np.abs(Ft) - F)
    return ctx.cache(ctx.mkey + (ctx.x_s, ctx.n, ctx.F_s, "asym", a), make)

EFFECTS = {e.id: e for e in (
    # ---------------- catalog
    Effect("viscous_damping", "viscous damping", ("c",), ("N s/m",), formula="c v", force=_viscous),
    Effect("linear_spring", "linear spring", ("k",), ("N/m",), formula="k x", force=_spring),
    Effect("velocity_dependent_friction", "velocity-dependent friction", ("beta",), ("s/m",),
           formula="F_Masing(x) beta |v|", force=_rate_friction),
    Effect("sensor_delay", "displacement channel delay", ("delay",), ("s",), formula="x_true,k = X_k exp(i k w tau)"),
    Effect("sensor_gain_error", "displacement/acceleration gain error", ("gain",), ("1",),
           formula="x_true = X / (1 + g)"),
    Effect("second_mode", "second (pitching) mode", ("f_p", "zeta", "a", "r"), ("Hz", "1", "1/kg", "1"),
           formula="pitching mode seen by the accelerometer, not the probe"),
    # ---------------- library (discovered)
    Effect("cubic_stiffness", "cubic stiffness", ("k3",), ("N/m^3",), "discovered", "k3 x^3",
           _lin("x^3", lambda c: c.x_abs ** 3, centred=True), words="a spring that stiffens (k3 > 0) or softens with amplitude"),
    Effect("quadratic_stiffness", "odd quadratic stiffness", ("k2",), ("N/m^2",), "discovered", "k2 x |x|",
           _lin("x|x|", lambda c: c.x_abs * np.abs(c.x_abs), centred=True), words="a spring whose stiffness grows in proportion to the "
                                                              "amplitude"),
    Effect("even_stiffness", "one-sided (even) stiffness", ("ke",), ("N/m^2",), "discovered", "ke x^2",
           _lin("x^2", lambda c: c.x_abs ** 2, centred=True), words="a spring stiffer in one direction than in the other (a preload, "
                                                   "a one-sided stop)"),
    Effect("quadratic_damping", "quadratic damping", ("c2",), ("N s^2/m^2",), "discovered", "c2 v |v|",
           _lin("v|v|", lambda c: c.v * np.abs(c.v)), words="damping growing with the square of the speed (oil, air)"),
    Effect("cubic_damping", "cubic damping", ("c3",), ("N s^3/m^3",), "discovered", "c3 v^3",
           _lin("v^3", lambda c: c.v ** 3), words="damping growing with the cube of the speed"),
    Effect("coulomb_friction", "Coulomb friction", ("F_c",), ("N",), "discovered", "F_c sign(v)",
           _lin("sign v", lambda c: np.sign(c.v)), words="a constant friction that flips with the direction of "
                                                          "motion (a seal, a wiper)"),
    Effect("asymmetric_friction", "asymmetric friction", ("a",), ("1",), "discovered",
           "a |F_Masing|: saturates at +F_s (1 + a), -F_s (1 - a)",
           _asymmetric, bounds=((-A_BOUND, A_BOUND),), step=0.02, words="friction higher in one direction than in the other (a tilted "
                                                 "guideway, an uneven preload, a seal that rubs one way)"),
    Effect("similarity_ratio", "Masing similarity ratio other than 2", ("d",), ("1",), "discovered",
           "branches F_r + lambda g((x - x_r)/lambda), lambda = 2 + d", _similarity, bounds=((-0.9, 4.0),),
           step=0.05, words="loops wider or narrower than the Masing rule predicts from the virgin curve"),
    Effect("virgin_curve_family", "virgin curve of another family", ("w",), ("1",), "discovered",
           "F_s [(1 - w) M_Sakai + w M_exp], g_exp(s) = 1 - exp(-3 s)",
           _lin("Mexp-M", lambda c: exp_family_friction(c.x, c.x_s) - c.M_dimless, friction=True, times_F_s=True),
           words="a virgin curve whose stiffness falls with amplitude unlike the Sakai curve's"),
    Effect("amplitude_dependent_n", "exponent n changing with amplitude", ("b",), ("1",), "discovered",
           "n(X) = n + b ln(X / x_s)", _lin("dM/dn ln X", _amplitude_n, friction=True, times_F_s=True),
           words="a friction curve whose shape changes with the amplitude"),
    # ---------------- the stiffness terms' shared rest position (no force of its own)
    Effect(CENTRE, "the springs' rest position", ("x_c",), ("m",), "centre",
           "stiffness terms act on x - x_c (x: the step's mean displacement relative to the median step's, plus "
           "the motion)", bounds=((-CENTRE_BOUND, CENTRE_BOUND),),
           words="where the spring force's odd part is centred, relative to the median step's mean displacement"),
)}
CATALOG = tuple(e for e in EFFECTS if EFFECTS[e].kind == "catalog")
LIBRARY = tuple(e for e in EFFECTS if EFFECTS[e].kind == "discovered")
