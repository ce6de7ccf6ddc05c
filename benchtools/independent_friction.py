"""An independent simulator of the rival pre-rolling friction models (issue 41), for test data
the package did not make.

Written from the models' equations and their references alone; it shares no code with
sim/ (it imports nothing from it).  Four friction laws, each a state ODE or an element
rule, integrated with the motion:

- ``dahl`` (Dahl 1968, 1976; the generalised form of Olsson et al. 1998):
  dF/dx = sigma |w|^i sgn(w), w = 1 - F/F_c sgn(v); parameters F_c_N, sigma_N_per_m,
  exponent (i > 0).  Integrated in time as dF/dt = v dF/dx.  For i < 1, w reaches 0 in a
  finite travel (F_c/(sigma (1 - i)) from F = 0) and, the law being non-Lipschitz there, the
  branch is held at F_c sgn(v) from that event to the next reversal (the forward solution is
  unique: w is driven to 0 from both sides).
- ``lugre`` (Canudas de Wit, Olsson, Astrom, Lischinsky, IEEE TAC 40(3) 1995):
  dz/dt = v - sigma_0 |v| z / g(v), g(v) = F_c + (F_s - F_c) exp(-(v/v_s)^2),
  F = sigma_0 z + sigma_1 dz/dt + sigma_2 v; parameters sigma0_N_per_m, sigma1_N_s_per_m,
  sigma2_N_s_per_m, F_c_N, F_s_N, v_s_m_per_s.  (The paper's g is a length, F_c/sigma_0 + ...;
  here g is in newtons and sigma_0 divides it, the same law.)  At the rig's scale
  (sigma_0 ~ 1e5-1e6 N/m, sliding speeds ~ 1e-2 m/s) the bristle relaxes over a length
  g/sigma_0 ~ 10-30 um, a few hundred per second: not stiff, DOP853 integrates it (no
  implicit method or reduced stiffness is needed).
- ``masing_iwan`` (Iwan, J. Appl. Mech. 33(4) 1966, the parallel-series model; Maxwell-slip):
  N elasto-plastic (Jenkins) elements in parallel, a spring k_i in series with a slider of
  slip force f_i; parameters k_N_per_m and f_N (sequences).  Exact element rule: element i's
  spring force is clip(k_i (x - p_i), -f_i, f_i) with p_i its slider's position, which is
  dragged along (p_i = x - F_i/k_i) and only needs updating at a reversal.  Virgin curve
  sum_i min(k_i x, f_i).
- ``gms``, the Generalized Maxwell-Slip model (Al-Bender, Lampaert, Swevers, IEEE TAC 50(11)
  1883-1887, 2005; Chaos 14, 2004; Lampaert, Al-Bender, Swevers, PhysCon 2003): N elements
  and the Stribeck curve s(v) = F_c + (F_s - F_c) exp(-|v/v_s|^delta).  An element sticks
  as a spring, dF_i/dt = k_i v, until it reaches its share, F_i sgn(v) = alpha_i s(v);
  then it slides by the attraction law of the TAC 2005 paper,

      dF_i/dt = sgn(v) C (alpha_i - F_i / s(v)),  s(v) taken with the sign of v,

  i.e. with the positive s(|v|) used here, dF_i/dt = C (alpha_i sgn(v) - F_i / s(v)): F_i is
  drawn towards alpha_i s(v) in the direction of motion, with the time constant s(v)/C.  It
  slides until the velocity goes through zero, then sticks again.  F = sum_i F_i + sigma_2 v.
  Parameters k_N_per_m, alpha (sequences, sum alpha_i = 1), F_c_N, F_s_N, v_s_m_per_s,
  delta, C_N_per_s, sigma2_N_s_per_m.  (The 2003/2004 papers write the rate
  C (1 - F_i/(alpha_i s(v))): the same attractor, a rate 1/alpha_i faster per element; the
  2005 form is the one used.  The paper's text was not found in the search corpora; the form
  is read the same way by two open implementations, jchristopherson/friction and the TUM
  thesis code phtarbiat/master_thesis, C alpha_i (1 - F_i/(alpha_i s)).)  With F_s = F_c the
  attractor is constant and an element that reaches it stays there: the GMS is then the
  Maxwell-slip model exactly, for any C.

Two entry points.  :func:`force_along` gives the force along a prescribed displacement
history x(t) from a virgin state (the path between samples is scipy's PCHIP interpolant,
monotone between samples, so it reverses only where the samples do; its derivative is the
velocity).  :func:`generate_uff` simulates force-driven up-sweeps per level of

    m x'' = P sin(w t) - F

from a virgin carriage at rest, each step ``settle`` periods then ``measure`` periods
sampled at a fixed rate that is not a multiple of the drive, and writes them as UFF58 time
records with the noise of benchtools/independent_masing.py (benchtools/uff_time_records.py),
which ``bench analyze FILE.uff`` reads.

Both integrate with scipy's DOP853 piece by piece: a piece ends at a reversal (v = 0) or at
a law's switching event (a GMS element starting to slide, a Dahl branch with i < 1 reaching
F_c), where the law's discrete state (modes, slider positions) is updated; within a piece
the direction of motion d = sgn(v) is a constant, so every law is smooth over a piece.

Noise scales (:func:`scales`): the force scale is the friction level (Dahl F_c, Iwan
sum f_i, LuGre and GMS F_s); the length scale is the friction level over the initial
stiffness (Dahl F_c/sigma, Iwan sum f_i / sum k_i, LuGre F_s/sigma_0, GMS F_s / sum k_i):
the pre-rolling length, as x_s is Masing's.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence

import numpy as np
from scipy.integrate import solve_ivp
from scipy.interpolate import PchipInterpolator

from benchtools.uff_time_records import add_noise, step_sets, write_sets

MODELS = ("dahl", "lugre", "masing_iwan", "gms")
PARAMS = {
    "dahl": ("F_c_N", "sigma_N_per_m", "exponent"),
    "lugre": ("sigma0_N_per_m", "sigma1_N_s_per_m", "sigma2_N_s_per_m", "F_c_N", "F_s_N", "v_s_m_per_s"),
    "masing_iwan": ("k_N_per_m", "f_N"),
    "gms": ("k_N_per_m", "alpha", "F_c_N", "F_s_N", "v_s_m_per_s", "delta", "C_N_per_s", "sigma2_N_s_per_m"),
}


class _Law:
    """A friction law over pieces of constant direction d.  Its continuous state q has shape
    (nq, k): k = 1 while integrating, k = the samples when evaluated along a piece; x and v are
    floats or arrays of k.  Guards are switching functions that end a piece when one rises
    through zero."""

    nq = 0
    n_guards = 0
    d = 1.0                             # the direction of the present piece

    def start(self) -> np.ndarray:
        return np.zeros((self.nq, 1))

    def virgin(self, x0: float) -> None:
        """Start virgin at x0."""

    def begin(self, x: float, q: np.ndarray, d: float) -> np.ndarray:
        """A piece in direction d starts at x (the virgin start or a reversal)."""
        return q

    def rates(self, x, v, q, d) -> np.ndarray:
        return np.zeros((0, 1))

    def force(self, x, v, q, d, qdot) -> np.ndarray:
        raise NotImplementedError

    def guards(self, x, v, q, d) -> np.ndarray:
        return np.zeros(0)

    def cross(self, k: int, q: np.ndarray, d: float) -> np.ndarray:
        return q


class _Dahl(_Law):
    nq = 1

    def __init__(self, F_c_N, sigma_N_per_m, exponent):
        self.F_c, self.sigma, self.i = float(F_c_N), float(sigma_N_per_m), float(exponent)
        self.n_guards = 1 if self.i < 1 else 0
        self.held = False               # a branch with i < 1 at F_c sgn(v)

    def begin(self, x, q, d):
        self.held = False
        return q

    def rates(self, x, v, q, d):
        if self.held:
            return np.zeros_like(q)
        w = 1.0 - d * q / self.F_c
        if self.i == 1.0:
            return self.sigma * v * w
        return self.sigma * v * np.abs(w) ** self.i * np.sign(w)

    def force(self, x, v, q, d, qdot):
        return q[0]

    def guards(self, x, v, q, d):
        return np.array([-1.0 if self.held else d * q[0, 0] / self.F_c - 1.0])

    def cross(self, k, q, d):
        self.held = True
        return np.full_like(q, d * self.F_c)


class _LuGre(_Law):
    nq = 1

    def __init__(self, sigma0_N_per_m, sigma1_N_s_per_m, sigma2_N_s_per_m, F_c_N, F_s_N, v_s_m_per_s):
        self.s0, self.s1, self.s2 = float(sigma0_N_per_m), float(sigma1_N_s_per_m), float(sigma2_N_s_per_m)
        self.F_c, self.F_s, self.v_s = float(F_c_N), float(F_s_N), float(v_s_m_per_s)

    def g(self, v):
        return self.F_c + (self.F_s - self.F_c) * np.exp(-((v / self.v_s) ** 2))

    def rates(self, x, v, q, d):
        return v - self.s0 * (d * v) * q / self.g(v)          # |v| = d v over a piece

    def force(self, x, v, q, d, qdot):
        return self.s0 * q[0] + self.s1 * qdot[0] + self.s2 * v


class _Iwan(_Law):
    def __init__(self, k_N_per_m, f_N):
        self.k = np.asarray(k_N_per_m, float).reshape(-1, 1)
        self.f = np.asarray(f_N, float).reshape(-1, 1)
        self.p = np.zeros_like(self.k)          # slider positions
        self.k_, self.f_ = self.k.ravel().tolist(), self.f.ravel().tolist()
        self.n_guards = self.k.shape[0]         # an element starting to slide: a kink in F(x)
        self.sliding = np.zeros(self.n_guards, bool)

    def virgin(self, x0):
        self.p = np.full_like(self.k, x0)

    def springs(self, x):
        return np.clip(self.k * (x - self.p), -self.f, self.f)

    def begin(self, x, q, d):
        self.p = x - self.springs(x) / self.k
        self.sliding[:] = False
        return q

    def force(self, x, v, q, d, qdot):
        if isinstance(x, float):            # while integrating: plain floats are faster
            return (sum(min(max(k * (x - p), -f), f) for k, p, f in zip(self.k_, self.p.ravel().tolist(), self.f_)),)
        return self.springs(x).sum(axis=0)

    def guards(self, x, v, q, d):
        return np.where(self.sliding, -1.0, (d * self.k * (x - self.p) - self.f)[:, 0])

    def cross(self, k, q, d):
        self.sliding[k] = True
        return q


class _GMS(_Law):
    def __init__(self, k_N_per_m, alpha, F_c_N, F_s_N, v_s_m_per_s, delta, C_N_per_s, sigma2_N_s_per_m):
        self.k = np.asarray(k_N_per_m, float).reshape(-1, 1)
        self.alpha = np.asarray(alpha, float).reshape(-1, 1)
        self.nq = self.n_guards = self.k.shape[0]
        self.F_c, self.F_s, self.v_s, self.delta = float(F_c_N), float(F_s_N), float(v_s_m_per_s), float(delta)
        self.C, self.s2 = float(C_N_per_s), float(sigma2_N_s_per_m)
        self.sliding = np.zeros((self.nq, 1), bool)

    def s(self, v):
        return self.F_c + (self.F_s - self.F_c) * np.exp(-np.abs(v / self.v_s) ** self.delta)

    def begin(self, x, q, d):
        self.sliding[:] = False                 # the velocity went through zero: all stick
        return q

    def rates(self, x, v, q, d):
        stick = self.k * v + 0.0 * q
        if not self.sliding.any():
            return stick
        return np.where(self.sliding, self.C * (self.alpha * d - q / self.s(v)), stick)

    def force(self, x, v, q, d, qdot):
        return q.sum(axis=0) + self.s2 * v

    def guards(self, x, v, q, d):
        return np.where(self.sliding[:, 0], -1.0, d * q[:, 0] - self.alpha[:, 0] * self.s(v))

    def cross(self, k, q, d):
        self.sliding[k] = True
        return q


def check_params(model: str, params: dict) -> None:
    """ValueError naming every key that is missing, unknown or out of range."""
    if model not in MODELS:
        raise ValueError(f"model {model!r}: not one of {', '.join(MODELS)}")
    want = PARAMS[model]
    problems = [f"{model}: {k} missing" for k in want if k not in params]
    problems += [f"{model}: {k} is not a parameter of this model" for k in params if k not in want]
    if not problems:
        p = params
        positive = [k for k in want if k not in ("k_N_per_m", "f_N", "alpha", "sigma1_N_s_per_m",
                                                 "sigma2_N_s_per_m")]
        problems += [f"{model}: {k} = {p[k]} must be > 0" for k in positive if not float(p[k]) > 0]
        problems += [f"{model}: {k} = {p[k]} must be >= 0" for k in ("sigma1_N_s_per_m", "sigma2_N_s_per_m")
                     if k in p and not float(p[k]) >= 0]
        vectors = [k for k in ("k_N_per_m", "f_N", "alpha") if k in p]
        sizes = {len(np.atleast_1d(p[k])) for k in vectors}
        if len(sizes) > 1:
            problems.append(f"{model}: {', '.join(vectors)} must have one length each (got {sorted(sizes)})")
        problems += [f"{model}: {k} must be > 0 element by element" for k in vectors
                     if not np.all(np.asarray(p[k], float) > 0)]
        if model == "gms" and not math.isclose(float(np.sum(p["alpha"])), 1.0, rel_tol=1e-9):
            problems.append(f"gms: alpha must sum to 1 (sums to {float(np.sum(p['alpha'])):.6g})")
        if "F_s_N" in p and "F_c_N" in p and float(p["F_s_N"]) < float(p["F_c_N"]):
            problems.append(f"{model}: F_s_N = {p['F_s_N']} must be >= F_c_N = {p['F_c_N']}")
    if problems:
        raise ValueError("; ".join(problems))


def make_law(model: str, params: dict) -> _Law:
    check_params(model, params)
    cls = {"dahl": _Dahl, "lugre": _LuGre, "masing_iwan": _Iwan, "gms": _GMS}[model]
    return cls(**params)


def scales(model: str, params: dict) -> tuple[float, float]:
    """(force scale N, length scale m) of a model: its friction level and that level over
    its initial stiffness (the noise's scales, and the pre-rolling length)."""
    check_params(model, params)
    p = params
    if model == "dahl":
        return p["F_c_N"], p["F_c_N"] / p["sigma_N_per_m"]
    if model == "lugre":
        return p["F_s_N"], p["F_s_N"] / p["sigma0_N_per_m"]
    if model == "masing_iwan":
        return float(np.sum(p["f_N"])), float(np.sum(p["f_N"]) / np.sum(p["k_N_per_m"]))
    return p["F_s_N"], p["F_s_N"] / float(np.sum(p["k_N_per_m"]))


def initial_stiffness_N_per_m(model: str, params: dict) -> float:
    force, length = scales(model, params)
    return force / length


def friction_resonance_Hz(model: str, params: dict, mass_kg: float) -> float:
    """The small-amplitude friction resonance sqrt(K0/m)/(2 pi), K0 the initial stiffness
    (Dahl sigma, LuGre sigma_0, Iwan and GMS sum k_i).  Larger levels soften it: a grid of
    0.3-3 times this frequency holds the resonance at every level below gross sliding."""
    return math.sqrt(initial_stiffness_N_per_m(model, params) / mass_kg) / (2 * math.pi)


def _q_scale(model: str, params: dict) -> float:
    """The size of a law's continuous state (LuGre's z is a length, the others are forces)."""
    F_scale, length = scales(model, params)
    return length if model == "lugre" else F_scale


def _last_step(sol, h):
    """The size of the last full step of a solution (a restart's first step), else ``h``."""
    steps = np.diff(sol.t)
    return float(steps[-2]) if steps.size >= 2 else h


def _first(h, t0, t1):
    return None if h is None else min(h, t1 - t0)


def _events(funcs):
    for f in funcs:
        f.terminal = True
    return funcs


def _guard_events(law, state_of):
    """solve_ivp events for the law's guards; ``state_of(t, y)`` -> (x, v, q)."""
    def guard(k):
        def ev(t, y):
            x, v, q = state_of(t, y)
            return law.guards(x, v, q, law.d)[k]
        ev.direction = 1
        return ev
    return [guard(k) for k in range(law.n_guards)]


def _cross_all(law, x, v, q, d, scale, tol=1e-9):
    """Switch every guard that has reached zero (several may switch at one instant)."""
    if law.n_guards:
        g = law.guards(x, v, q, d)
        for k in np.flatnonzero(g > -tol * scale):
            q = law.cross(int(k), q, d)
    return q


class _Path:
    """x(t) and v(t) of the PCHIP interpolant of the samples, in plain floats (fast)."""

    def __init__(self, t, x):
        pp = PchipInterpolator(t, x)
        self.knots = t.tolist()
        self.coef = pp.c.T.tolist()
        self.last = len(self.knots) - 2
        self.position = pp
        self.velocity = pp.derivative()

    def __call__(self, tt: float) -> tuple[float, float]:
        i = min(max(bisect.bisect_right(self.knots, tt) - 1, 0), self.last)
        h = tt - self.knots[i]
        c0, c1, c2, c3 = self.coef[i]
        return ((c0 * h + c1) * h + c2) * h + c3, (3.0 * c0 * h + 2.0 * c1) * h + c2


def _runs(x):
    """(first, last sample, direction) of the monotone runs of x (a pause continues the run)."""
    step = np.sign(np.diff(x))
    for j in range(1, step.size):
        if step[j] == 0:
            step[j] = step[j - 1]
    if step[0] == 0:
        nz = np.flatnonzero(step)
        step[:] = step[nz[0]] if nz.size else 1.0
    bounds = np.flatnonzero(np.diff(step) != 0) + 1         # sample indices of reversals
    return [(int(a), int(b), float(step[a])) for a, b in zip(np.r_[0, bounds], np.r_[bounds, x.size - 1])]


def force_along(model: str, params: dict, t_s, x_m, *, rtol: float = 1e-10) -> np.ndarray:
    """The friction force (N) at the samples of a prescribed displacement history x_m(t_s)
    from a virgin state at x = x_m[0]; the path between samples is the PCHIP interpolant.

    Dahl's law is rate-independent and is integrated in the travel of each monotone run
    (dF/dx, smooth there); LuGre's and GMS's in time, with the interpolant's velocity;
    Iwan's element rule is exact at the samples."""
    t = np.asarray(t_s, float)
    x = np.asarray(x_m, float)
    if t.ndim != 1 or t.shape != x.shape or t.size < 2 or not np.all(np.diff(t) > 0):
        raise ValueError("t_s, x_m: one-dimensional, the same length (>= 2), t_s increasing")
    law = make_law(model, params)
    path = _Path(t, x)
    in_travel = model == "dahl"
    F = np.empty(t.size)
    q = law.start()
    law.virgin(x[0])
    atol = rtol * _q_scale(model, params)
    for a, b, d in _runs(x):
        law.d = d
        q = law.begin(x[a], q, d)
        if in_travel:                       # s = d (x - x_a), v = d: dF/ds = rates(v = d)
            s_k = d * (x[a:b + 1] - x[a])

            def state_of(ss, y, a=a, d=d):
                return x[a] + d * ss, d, y.reshape(-1, 1)

            def motion(s_k, a=a, d=d):
                return x[a] + d * s_k, np.full(s_k.size, d)
        else:
            s_k = t[a:b + 1]

            def state_of(ss, y):
                xx, vv = path(ss)
                return xx, vv, y.reshape(-1, 1)

            def motion(s_k):
                return path.position(s_k), path.velocity(s_k)
        if a == 0:
            x0, v0 = motion(s_k[:1])
            F[0] = law.force(x0, v0, q, d, law.rates(x0, v0, q, d))[0]
        if law.nq == 0:
            F[a + 1:b + 1] = law.force(x[a + 1:b + 1], None, q, d, q)
            continue
        if s_k[-1] <= s_k[0]:               # a run of pauses only
            F[a + 1:b + 1] = F[a]
            continue

        def rhs(ss, y):
            xx, vv, qq = state_of(ss, y)
            return law.rates(xx, vv, qq, d).ravel()

        # in time, knot to knot: the interpolant's velocity has a kink at every sample, which
        # a step across it (and the dense output inside that step) would not resolve
        ends = s_k[-1:] if in_travel else s_k[1:]
        s0 = s_k[0]
        j = 1
        for end in ends:
            while s0 < end:
                sol = solve_ivp(rhs, (s0, end), q.ravel(), method="DOP853", rtol=rtol, atol=atol,
                                first_step=None if in_travel else end - s0,
                                events=_events(_guard_events(law, state_of)), dense_output=True)
                s_stop = sol.t[-1]
                k = j
                while k < s_k.size and s_k[k] <= s_stop:
                    k += 1
                if k > j:
                    qs = sol.sol(s_k[j:k])
                    xs, vs = motion(s_k[j:k])
                    F[a + j:a + k] = law.force(xs, vs, qs, d, law.rates(xs, vs, qs, d))
                    j = k
                q = sol.y[:, -1].reshape(-1, 1)
                s0 = s_stop
                if sol.status == 1:
                    xx, vv, _ = state_of(s_stop, sol.y[:, -1])
                    q = _cross_all(law, xx, vv, q, d, scales(model, params)[0])
                elif s_stop < end:
                    raise RuntimeError(f"force_along: {sol.message}")
    return F


def simulate_level(model: str, params: dict, mass_kg: float, level_N: float, freqs_Hz: Sequence[float],
                   settle: int, measure: int, fs_Hz: float, rtol: float = 1e-9):
    """Up-sweep through ``freqs_Hz`` at drive amplitude ``level_N`` from a virgin carriage at
    rest at x = 0.  Yields per step (t_s, x_m, accel_m_s2, force_N) sampled at ``fs_Hz``
    over the ``measure`` periods after ``settle``."""
    law = make_law(model, params)
    F_scale, length = scales(model, params)
    w0 = 2 * math.pi * friction_resonance_Hz(model, params, mass_kg)
    atol = rtol * np.r_[length, length * w0, np.full(law.nq, _q_scale(model, params))]
    y = np.r_[0.0, 0.0, law.start().ravel()]
    d = 1.0                             # from rest, the drive P sin(w t) pushes forwards
    law.d = d
    law.begin(0.0, law.start(), d)
    t = 0.0
    phase = 0.0

    def state_of(tt, yy):
        return float(yy[0]), float(yy[1]), yy[2:].reshape(-1, 1)

    h = None
    for f in freqs_Hz:
        w = 2 * math.pi * float(f)
        T = 1.0 / float(f)
        t_start, ph0 = t, phase

        def drive(tt):
            if isinstance(tt, float):
                return level_N * math.sin(w * (tt - t_start) + ph0)
            return level_N * np.sin(w * (tt - t_start) + ph0)

        def rhs(tt, yy):
            x, v, q = state_of(tt, yy)
            qd = law.rates(x, v, q, law.d)
            out = np.empty(yy.size)
            out[0] = v
            out[1] = (drive(tt) - law.force(x, v, q, law.d, qd)[0]) / mass_kg
            out[2:] = qd.ravel()
            return out

        def reversal(tt, yy):
            return yy[1]

        t_end = t_start + (settle + measure) * T
        grid = t_start + settle * T + np.arange(int(measure * T * fs_Hz)) / fs_Hz
        xs = np.empty(grid.size)
        acc = np.empty(grid.size)
        j = 0
        while t < t_end - 1e-12 * T:
            reversal.direction = -law.d
            sol = solve_ivp(rhs, (t, t_end), y, method="DOP853", rtol=rtol, atol=atol, first_step=_first(h, t, t_end),
                            events=_events([reversal, *_guard_events(law, state_of)]), dense_output=True)
            h = _last_step(sol, h)
            t_stop = sol.t[-1]
            k = j
            while k < grid.size and grid[k] <= t_stop:
                k += 1
            if k > j:
                ys = sol.sol(grid[j:k])
                q = ys[2:]
                qd = law.rates(ys[0], ys[1], q, law.d)
                F = law.force(ys[0], ys[1], q, law.d, qd)
                xs[j:k] = ys[0]
                acc[j:k] = (drive(grid[j:k]) - F) / mass_kg
                j = k
            y = sol.y[:, -1].copy()
            t = t_stop
            if sol.status == 1:
                x, v, q = state_of(t, y)
                if sol.t_events[0].size and sol.t_events[0][-1] == t_stop:        # a reversal
                    law.d = -law.d
                    y[1] = 0.0
                    q = law.begin(x, q, law.d)
                q = _cross_all(law, x, y[1], q, law.d, F_scale)
                y[2:] = q.ravel()
        phase = (ph0 + w * (t_end - t_start)) % (2 * math.pi)
        yield grid[:j], xs[:j], acc[:j], drive(grid[:j])


def generate_uff(path, model: str, params: dict, mass_kg: float, levels_N, freqs_Hz, *, settle: int = 25,
                 measure: int = 8, noise=(0.003, 0.005, 0.002), seed: int = 0, fs_Hz: float | None = None,
                 rtol: float = 1e-9) -> int:
    """Simulate the up-sweeps (one per level, each from a virgin carriage) and write them to
    ``path`` as UFF58 time records (no tags).  ``noise`` = (force, accel, disp) relative to
    the model's force scale, the acceleration's rms and the model's length scale
    (:func:`scales`).  Returns the number of steps written."""
    check_params(model, params)
    rng = np.random.default_rng(seed)
    fs = fs_Hz or 128.0 * max(freqs_Hz) * 1.037       # not a multiple of any step frequency
    F_scale, length = scales(model, params)
    sets: list[dict] = []
    case = 0
    for level in levels_N:
        for x, acc, P in _level_records(model, params, mass_kg, float(level), sorted(freqs_Hz), settle, measure, fs,
                                        rtol):
            case += 1
            force, accel, disp = add_noise(P, acc, x, noise, F_scale, length, rng)
            sets += step_sets(case, len(sets) + 1, fs, force, accel, disp)
    write_sets(path, sets)
    return case


# The noise-free sweeps of the levels simulated last in this process (the noise is drawn after
# them): a case written again with another noise seed, or at another noise scale, integrates
# nothing again.  The records are the same arrays the simulation yields, so the files are the
# same bytes with or without it.
_SWEEPS: dict[str, list] = {}
_SWEEPS_KEPT = 32


def _level_records(model, params, mass_kg, level, freqs, settle, measure, fs, rtol):
    key = repr((model, sorted((k, np.asarray(v, float).tolist()) for k, v in params.items()), float(mass_kg), level,
                [float(f) for f in freqs], settle, measure, float(fs), float(rtol)))
    if key not in _SWEEPS:
        while len(_SWEEPS) >= _SWEEPS_KEPT:
            del _SWEEPS[next(iter(_SWEEPS))]
        _SWEEPS[key] = [(x, acc, P) for _, x, acc, P in simulate_level(model, params, mass_kg, level, freqs, settle,
                                                                        measure, fs, rtol=rtol)]
    return _SWEEPS[key]
