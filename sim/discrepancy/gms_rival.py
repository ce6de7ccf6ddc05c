"""GMS, the generalized Maxwell-slip rival, by variable projection (its model, the unit
elements, the grids and the starts: :mod:`sim.discrepancy.rate_rivals`' module doc; decisions
0086, 0089, 0090).  Split from rate_rivals, which keeps the common problem and LuGre."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..friction import sample_spacing
from ..identify import path_harmonics
from .rate_rivals import OUTER_NFEV, Result, _grad_var, _lin_q, _log_q, _Projected, _Setup, projected_fit

GMS_ELEMENTS = 40            # slip displacements on the coarse grid (the Iwan fit's range)
GMS_REFINE = 4               # the fine grid: each active coarse element's interval cut in this many
GMS_FINE_MAX = 96            # at most this many elements on the fine grid (fewer cuts where many are active)
POLISH_NFEV = 4              # on the fine grid, from the coarse fit
GMS_FREE_MAX = 8             # at most this many elements at free slips (more clusters: the fine grid's result)
FREE_NFEV = 20               # the free slips' fit, from the fine grid's
NO_POLISH = 100.0            # no fine grid when the coarse chi-square is this many times another model's
UNIT_TOL = 1e-7              # a unit element's steady state: change per period below this
PERIODS_MAX = 60


# ---------------------------------------------------------------- GMS
@njit(cache=True, nogil=True, inline="always")
def _s_n(r, v_s, delta, v):
    return 1.0 + (r - 1.0) * math.exp(-abs(v / v_s) ** delta)


@njit(cache=True, nogil=True)
def _gms_units(paths, vel, dts, slips, amp, r, v_s, delta, c, tol, out):
    """Steady unit-element forces u (rows x elements x samples) of the GMS with F_c = 1,
    F_s = r, C = c, alpha = 1 per element, k = 1 / slip: gms_advance's update, every element
    of a row at once (module doc).  Returns the most periods a row needed."""
    R, M = paths.shape
    N = slips.shape[0]
    s_mean = np.empty(M)
    s_end = np.empty(M)
    s_start = np.empty(M)
    decay = np.empty(M)
    u = np.empty(N)
    mode = np.empty(N)
    prev = np.empty(N)
    worst = 0
    for i in range(R):
        x = paths[i]
        n_act = 0
        for e in range(N):
            if slips[e] < amp[i]:
                n_act = e + 1
            else:
                for j in range(M):
                    out[i, e, j] = x[j] / slips[e]     # never slides: a spring
        if n_act == 0:
            continue
        dt = dts[i]
        for j in range(M):
            jn = j + 1 if j + 1 < M else 0
            dx = x[jn] - x[j]
            v_end = vel[i, jn]
            v_m = dx / dt
            s_mean[j] = _s_n(r, v_s, delta, v_m)
            s_end[j] = _s_n(r, v_s, delta, v_end)
            s_start[j] = _s_n(r, v_s, delta, 2.0 * v_m - v_end)
            decay[j] = math.exp(-c * dt / s_mean[j])
        # virgin, quasi-static to the first sample (the path starts at its largest value)
        sg0 = 1.0 if x[0] > 0.0 else -1.0
        for e in range(n_act):
            u[e] = x[0] / slips[e]
            mode[e] = 0.0
            if sg0 * u[e] > r:
                u[e] = sg0 * r
                mode[e] = 1.0
        direction = sg0 if x[0] != 0.0 else 0.0
        used = 0
        write = False
        while True:
            for e in range(n_act):
                prev[e] = u[e]
            for j in range(M):
                jn = j + 1 if j + 1 < M else 0
                dx = x[jn] - x[j]
                if dx != 0.0:
                    sg = 1.0 if dx > 0.0 else -1.0
                    if direction != sg:
                        for e in range(n_act):
                            mode[e] = 0.0
                        direction = sg
                    for e in range(n_act):
                        if mode[e] == 0.0:
                            un = u[e] + dx / slips[e]
                            after = sg * un - s_end[j]
                            if after <= 0.0:
                                u[e] = un
                                continue
                            before = sg * u[e] - s_start[j]
                            frac = before / (before - after) if before < 0.0 else 0.0
                            ui = u[e] + frac * dx / slips[e]
                            v0 = 2.0 * dx / dt - vel[i, jn]
                            ss = _s_n(r, v_s, delta, v0 + (vel[i, jn] - v0) * 0.5 * (1.0 + frac))
                            a = sg * ss
                            u[e] = a + (ui - a) * math.exp(-c * (1.0 - frac) * dt / ss)
                            mode[e] = 1.0
                        else:
                            a = sg * s_mean[j]
                            u[e] = a + (u[e] - a) * decay[j]
                if write:
                    for e in range(n_act):
                        out[i, e, jn] = u[e]
            if write:
                break
            used += 1
            change = 0.0
            for e in range(n_act):
                change = max(change, abs(u[e] - prev[e]))
            if (used >= 2 and change <= tol) or used >= PERIODS_MAX:
                write = True
        worst = max(worst, used)
    return worst


def gms_units(s: _Setup, slips: np.ndarray, r: float, v_s: float, delta: float, c: float,
              rows: np.ndarray) -> np.ndarray:
    """Harmonics (rows x K x elements) of the unit elements' steady force."""
    paths = np.ascontiguousarray(s.paths[rows])
    out = np.empty((paths.shape[0], slips.size, paths.shape[1]))
    _gms_units(paths, np.ascontiguousarray(s.vel[rows]), sample_spacing(s.d.omega[rows], paths.shape[1]), slips,
               s.amp[rows], r, v_s, delta, c, UNIT_TOL, out)
    H = path_harmonics(out.reshape(-1, out.shape[2]), np.repeat(s.starts[rows], slips.size), s.K)
    return H.reshape(paths.shape[0], slips.size, s.K).transpose(0, 2, 1)


def gms_problem(s: _Setup, slips: np.ndarray) -> _Projected:
    def basis(theta, rows):
        return None, gms_units(s, slips, math.exp(theta[0]), math.exp(theta[1]), float(theta[2]), math.exp(theta[3]),
                               rows)
    return _Projected(s, basis, lin_viscous=True)


def refine(slips: np.ndarray, active: np.ndarray, parts: int = GMS_REFINE) -> np.ndarray:
    """The geometric grid ``slips`` with each active element's neighbourhood (to the next
    element either side) cut into ``parts`` per interval, fewer where that would make more
    than :data:`GMS_FINE_MAX` (a smooth virgin curve, many elements active, needs none)."""
    ratio = float(slips[1] / slips[0]) if slips.size > 1 else 2.0
    while parts > 1:
        sub = [slips[i] * ratio ** (k / parts) for i in active for k in range(1 - parts, parts)]
        fine = np.unique(np.concatenate([slips, np.array(sub, dtype=float)]))
        if fine.size <= GMS_FINE_MAX:
            return fine
        parts -= 1
    return slips


def clusters(slips: np.ndarray, active: np.ndarray, gap: float) -> list[np.ndarray]:
    """The sorted ``active`` grid indices in runs whose neighbours' slips are at most the
    ratio ``gap`` apart (each run one cluster)."""
    if active.size == 0:
        return []
    cut = np.flatnonzero(np.diff(np.log(slips[active])) > math.log(gap) * (1 + 1e-9)) + 1
    return np.split(active, cut)


def gms_free_problem(s: _Setup, fixed: np.ndarray) -> _Projected:
    """GMS with the first elements' log-slips free (theta[4:]) and ``fixed`` slips after them."""
    def basis(theta, rows):
        slips = np.concatenate([np.exp(theta[4:]), fixed])
        return None, gms_units(s, slips, math.exp(theta[0]), math.exp(theta[1]), float(theta[2]), math.exp(theta[3]),
                               rows)
    return _Projected(s, basis, lin_viscous=True)


def gms_free(s: _Setup, slips: np.ndarray, z: np.ndarray, ratio: float) -> tuple | None:
    """The free-slip problem from a grid fit (module doc): each cluster of active grid
    elements (neighbours at most one coarse interval ``ratio`` apart) that slides at some step becomes one element at a free log-slip (start: the
    cluster's force-weighted mean log-slip, bounds one coarse interval ``ratio`` beyond it),
    the springs' elements (slip above every amplitude) stay on the grid.  (problem, start
    of the slips, their bounds, the fixed slips), or None for more than :data:`GMS_FREE_MAX`."""
    f = z[1:1 + slips.size]
    free, fixed = [], []
    for c in clusters(slips, np.flatnonzero(f > 0), ratio):
        if slips[c].min() < s.amp.max():
            free.append(c)
        else:
            fixed.extend(c.tolist())
    if not free or len(free) > GMS_FREE_MAX:
        return None
    ls = np.log(slips)
    start = np.array([float(np.average(ls[c], weights=f[c])) for c in free])
    lo = np.array([ls[c].min() for c in free]) - math.log(ratio)
    hi = np.array([ls[c].max() for c in free]) + math.log(ratio)
    fixed_s = slips[np.array(fixed, dtype=int)]
    return gms_free_problem(s, fixed_s), start, lo, hi, fixed_s


def gms_fit(s: _Setup, slips: np.ndarray, other_chi2: float = math.inf) -> tuple[Result, dict, dict]:
    """GMS on the slip grid ``slips`` (module doc): (result, values, parameters).  The fine
    grid only where it can matter: with the coarse fit's chi-square above :data:`NO_POLISH`
    times ``other_chi2`` (the best other model's) the coarse fit is the result (the fine
    grid lowered it 15-fold on the issue's GMS case, decision 0086); else the fine grid's
    clusters become elements at free slips (:func:`gms_free`, decision 0090)."""
    speed = float(np.median(np.abs(s.vel).max(axis=1)))
    w = float(np.median(s.d.omega))
    lo = np.array([0.0, math.log(speed) - 7, 0.5, math.log(w) - 3])
    hi = np.array([math.log(5.0), math.log(speed) + 5, 5.0, math.log(w) + 9])
    th0 = np.array([math.log(1.2), math.log(speed), 2.0, math.log(20 * w)])
    coarse = gms_problem(s, slips)
    every = np.arange(s.d.X.shape[0])
    th1 = coarse.fit(th0, lo, hi, every, OUTER_NFEV)
    z1, r1, _ = coarse.solve(th1, every)
    n_free, grid = 0, slips
    if float(r1 @ r1) > NO_POLISH * other_chi2:
        res = projected_fit(coarse, th1, lo, hi, nfev=0)
    else:
        ratio = float(slips[1] / slips[0]) if slips.size > 1 else 2.0
        slips = grid = refine(slips, np.flatnonzero(z1[1:1 + slips.size] > 0))
        fine = gms_problem(s, slips)
        th2 = fine.fit(th1, lo, hi, every, POLISH_NFEV)
        z2, _, _ = fine.solve(th2, every)
        made = gms_free(s, slips, z2, ratio) if GMS_FREE_MAX > 0 else None
        if made is None:
            res = projected_fit(fine, th2, lo, hi, nfev=0)
        else:
            problem, ls0, ls_lo, ls_hi, fixed = made
            n_free = ls0.size
            res = projected_fit(problem, np.concatenate([th2, ls0]), np.concatenate([lo, ls_lo]),
                                np.concatenate([hi, ls_hi]), nfev=FREE_NFEV)
            slips = np.concatenate([np.exp(res.theta[4:]), fixed])
    return res, *_gms_report(res, slips, n_free, grid)


def _gms_report(res: Result, slips: np.ndarray, n_free: int, grid: np.ndarray) -> tuple[dict, dict]:
    """GMS's values and parameters with 95 % intervals from a fit whose first ``n_free``
    elements' log-slips are outer parameters 4.. (the others on the slip ``grid``: their
    slip's interval is its grid cell, between the geometric midpoints to its neighbours)."""
    th, z, cov = res.theta, res.z, res.cov
    nt = th.size
    N = slips.size
    f, m, s2 = z[1:1 + N], float(z[0]), float(z[-1])
    F_c = float(f.sum())
    r, v_s, delta, c = math.exp(th[0]), math.exp(th[1]), float(th[2]), math.exp(th[3])
    act = [int(i) for i in np.argsort(slips) if f[i] > 0]
    fi = nt + 1 + np.arange(N)               # f's entries in (theta, z)
    g_Fc = np.zeros(cov.shape[0])
    g_Fc[fi] = 1.0
    var_Fc = _grad_var(cov, g_Fc)
    rel_Fc = var_Fc / max(F_c, 1e-300) ** 2
    g = g_Fc / max(F_c, 1e-300)              # log F_c's gradient
    gs, gC = g.copy(), g.copy()
    gs[0] += 1.0
    gC[3] += 1.0
    values = dict(F_c_N=F_c, F_s_N=r * F_c, v_s_m_per_s=v_s, delta=delta, C_N_per_s=c * F_c, sigma2_N_s_per_m=s2,
                  k_N_per_m=[float(f[i] / slips[i]) for i in act], alpha=[float(f[i] / F_c) for i in act])
    ks, alphas, slip_q = [], [], []
    for i in act:
        k = float(f[i] / slips[i])
        gk = np.zeros(cov.shape[0])
        gk[fi[i]] = 1.0 / slips[i]
        ga = -g_Fc * f[i] / F_c ** 2
        ga[fi[i]] += 1.0 / F_c
        if i < n_free:
            gk[4 + i] = -k
            slip_q.append(_log_q(float(slips[i]), cov[4 + i, 4 + i], "m"))
        else:
            j = int(np.argmin(np.abs(grid - slips[i])))
            ratio = float(grid[1] / grid[0]) if grid.size > 1 else 2.0
            below = grid[j - 1] if j > 0 else slips[i] / ratio
            above = grid[j + 1] if j + 1 < grid.size else slips[i] * ratio
            slip_q.append(dict(value=float(slips[i]), low=float(math.sqrt(below * slips[i])),
                               high=float(math.sqrt(above * slips[i])), unit="m"))
        ks.append(_lin_q(k, _grad_var(cov, gk), "N/m"))
        alphas.append(_lin_q(float(f[i] / F_c), _grad_var(cov, ga), "1"))
    params = dict(F_c_N=_log_q(F_c, rel_Fc, "N"), F_s_N=_log_q(r * F_c, _grad_var(cov, gs), "N"),
                  v_s_m_per_s=_log_q(v_s, cov[1, 1], "m/s"),
                  delta=_lin_q(delta, cov[2, 2], "1", floor=None),
                  C_N_per_s=_log_q(c * F_c, _grad_var(cov, gC), "N/s"),
                  sigma2_N_s_per_m=_lin_q(s2, cov[-1, -1], "N s/m"), mass_kg=_lin_q(m, cov[nt, nt], "kg"),
                  k_N_per_m=ks, alpha=alphas, slip_m=slip_q)
    return values, params
