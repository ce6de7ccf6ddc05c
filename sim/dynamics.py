"""Steady-state response of the seed's Eq. 8, integrated with classic RK4.

    beta^2 u'' = -F(u)/F_s + gamma0 sin(tau)

The carriage starts at rest on the virgin curve (or from a given state, for warm-started
sweeps) and is integrated period by period (tau advances by 2 pi per period, so the
force is phase-continuous when beta changes between periods of a sweep).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace

import numpy as np

from . import _kernel
from .errors import ConfigurationError
from .masing import LAMBDA_MASING
from .virgin import SakaiCurve, VirginCurve, check_positive_finite

log = logging.getLogger(__name__)

TWO_PI = 2.0 * math.pi


@dataclass
class FrictionState:
    """Everything the model remembers: position, velocity and the reversal stack."""

    u: float = 0.0
    v: float = 0.0
    k: int = 0
    d: float = 0.0
    su: np.ndarray = field(default_factory=lambda: np.empty(64))
    sF: np.ndarray = field(default_factory=lambda: np.empty(64))

    def copy(self) -> FrictionState:
        return replace(self, su=self.su.copy(), sF=self.sF.copy())


@dataclass(frozen=True)
class TimeHistory:
    """Sampled steady cycles: tau, u, u' (= du/dtau), u'' and F/F_s."""

    tau: np.ndarray
    u: np.ndarray
    du: np.ndarray
    ddu: np.ndarray
    F: np.ndarray


@dataclass(frozen=True)
class SteadyState:
    """Result of one frequency point (seed Eq. 9 and what it took to get there)."""

    gamma0: float
    beta: float
    n: float
    G: float                 # (u_max - u_min) / (2 gamma0) over the last cycle
    u_max: float
    u_min: float
    cycles: int              # periods integrated
    converged: bool          # steady state reached before the cycle cap
    gross_rolling: bool      # branch travel beyond lam x_s (flat branch) or gamma0 >= 1
    drift_per_cycle: float   # change of the loop centre per period (steady loops: ~0)
    reversals_per_cycle: int
    max_depth: int           # deepest reversal stack seen
    history: TimeHistory | None = None
    state: FrictionState | None = None


@dataclass(frozen=True)
class Integrator:
    """Model and numerical settings shared by every frequency point."""

    n: float = 1.5
    lam: float = LAMBDA_MASING
    steps_per_period: int = 10_000
    curve: VirginCurve | None = None       # None: the Sakai curve of ``n``

    def __post_init__(self):
        if self.curve is None:
            object.__setattr__(self, "curve", SakaiCurve(self.n))
        check_positive_finite("similarity ratio lam", self.lam)
        if int(self.steps_per_period) < 100:
            raise ConfigurationError(f"steps_per_period must be >= 100, got {self.steps_per_period!r}")

    def run(self, state: FrictionState, gamma0: float, beta: float, periods: int,
            record_every: int = 0, record: np.ndarray | None = None):
        """Advance ``state`` in place by whole periods; returns the kernel's statistics."""
        N = int(self.steps_per_period)
        h = TWO_PI / N
        rec = record if record is not None else np.empty((0, 5))
        curve = self.curve
        assert curve is not None               # set in __post_init__
        (state.u, state.v, state.k, state.d, state.su, state.sF,
         umax, umin, depth, nrev) = _kernel.rk4_run(
            state.u, state.v, 0.0, state.k, state.d, state.su, state.sF,
            self.lam, curve.kind, curve.params,
            1.0 / (beta * beta), gamma0, 1.0, 0.0, 0.0, 0.0, 0.0,
            h, N * periods, max(record_every, 1), rec)
        return umax, umin, depth, nrev


def _check_forcing(gamma0: float, beta: float) -> tuple[float, float]:
    return (check_positive_finite("force amplitude gamma0 (P0/F_s)", gamma0),
            check_positive_finite("frequency ratio beta (omega/omega_s)", beta))


def steady_state(gamma0: float, beta: float, n: float = 1.5, *, integrator: Integrator | None = None,
                 state: FrictionState | None = None, rtol: float = 1e-6, agree_cycles: int = 5,
                 min_cycles: int = 8, max_cycles: int = 3000, history_samples: int = 0) -> SteadyState:
    """Integrate period by period until the response is periodic.

    Steady means: over ``agree_cycles`` consecutive periods the amplitude and the
    stroboscopic point (u - centre, u') each change by less than ``rtol`` (relative to the
    amplitude), and the extrapolated remaining change of the amplitude (geometric tail,
    which catches slow convergence) is below ``rtol`` as well.  A cap of ``max_cycles``
    always ends the run; ``converged`` tells which way it ended.

    ``state`` is advanced in place (warm start) if given, else the carriage starts at rest.
    ``history_samples`` > 0 records the last period with that many samples.
    """
    gamma0, beta = _check_forcing(gamma0, beta)
    it = integrator or Integrator(n=n)
    st = state if state is not None else FrictionState()
    amps: list[float] = []
    centres: list[float] = []
    strobe: list[tuple[float, float]] = []
    ok_streak = 0
    depth_max = 0
    nrev = 0
    converged = False
    cycles = 0
    umax = umin = st.u
    while cycles < max_cycles:
        umax, umin, depth, nrev = it.run(st, gamma0, beta, 1)
        cycles += 1
        depth_max = max(depth_max, depth)
        amp = 0.5 * (umax - umin)
        centre = 0.5 * (umax + umin)
        amps.append(amp)
        centres.append(centre)
        strobe.append((st.u - centre, st.v))
        if cycles < 3:
            continue
        scale = max(amp, 1e-12)
        d1 = abs(amps[-1] - amps[-2])
        d0 = abs(amps[-2] - amps[-3])
        r = min(d1 / d0, 0.999) if d0 > 0 else 0.0
        tail = d1 * r / (1.0 - r)
        ds = max(abs(strobe[-1][0] - strobe[-2][0]), abs(strobe[-1][1] - strobe[-2][1]))
        if d1 <= rtol * scale and tail <= rtol * scale and ds <= 10 * rtol * scale:
            ok_streak += 1
        else:
            ok_streak = 0
        if ok_streak >= agree_cycles and cycles >= min_cycles:
            converged = True
            break
    history = None
    if history_samples > 0:
        every = max(1, it.steps_per_period // history_samples)
        rec = np.empty((it.steps_per_period // every + 1, 5))
        umax, umin, depth, nrev = it.run(st, gamma0, beta, 1, every, rec)
        cycles += 1
        depth_max = max(depth_max, depth)
        history = TimeHistory(tau=rec[:, 0], u=rec[:, 1], du=rec[:, 2], ddu=rec[:, 3], F=rec[:, 4])
    amp = 0.5 * (umax - umin)
    drift = centres[-1] - centres[-2] if len(centres) >= 2 else 0.0
    if not converged:
        log.warning("no steady state after %d periods at gamma0=%g beta=%g n=%g (amplitude %.4g)",
                    cycles, gamma0, beta, it.n, amp)
    return SteadyState(
        gamma0=gamma0, beta=beta, n=it.n, G=amp / gamma0, u_max=umax, u_min=umin,
        cycles=cycles, converged=converged,
        gross_rolling=bool(gamma0 >= 1.0 or 2.0 * amp > it.lam),
        drift_per_cycle=drift, reversals_per_cycle=int(nrev), max_depth=int(depth_max),
        history=history, state=st)
