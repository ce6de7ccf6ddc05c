"""An independent simulator of the rig, for test data the package did not make.

Written from ../shared/notes/physics.md alone (it shares no code with sim/): the virgin
curve F_s (u^n - n u)/(1 - n) for u = x/x_s <= 1 and F_s beyond; Masing branches
F_r + 2 f((x - x_r)/2) after a reversal at (x_r, F_r); a branch that reaches the start of
the previous branch closes that inner loop (both reversal points dropped), the first
branch after virgin loading rejoins the virgin curve at the mirror point -x_r.  The motion
m x'' = P sin(w t) - F(x) is integrated by scipy's DOP853 with tight tolerances, stopping
at every reversal (velocity zero) and every loop closure (terminal events) to update the
reversal stack.  Steps are swept upwards per force level from a virgin carriage; records
are sampled at a fixed rate that is not a multiple of the frequency, as other software
writes them, and exported as UFF58 with pyuff (function type 1, one load case per step,
ordinate data types 13/12/8, no tags).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

from benchtools.uff_time_records import add_noise, step_sets, write_sets


class MasingCarriage:
    """Dimensionless state: u = x/x_s, time t' = omega_s t, force in units of F_s."""

    def __init__(self, n: float):
        self.n = n
        self.stack: list[tuple[float, float]] = []     # (u_r, F_r), oldest first
        self.d = 0.0                                    # direction of motion

    def virgin(self, u: float) -> float:
        a = abs(u)
        g = 1.0 if a >= 1.0 else (a ** self.n - self.n * a) / (1.0 - self.n)
        return math.copysign(g, u)

    def force(self, u: float) -> float:
        if not self.stack:
            return self.virgin(u)
        u_r, F_r = self.stack[-1]
        return F_r + 2.0 * self.virgin((u - u_r) / 2.0)

    def closure(self) -> float | None:
        """Where the present branch ends (u), or None on the virgin curve."""
        if len(self.stack) >= 2:
            return self.stack[-2][0]
        if len(self.stack) == 1:
            return -self.stack[0][0]
        return None


def simulate_level(n: float, gamma0: float, betas, periods_settle: int, periods_measure: int,
                   samples_per_unit_time: float, rtol: float = 1e-10, cubic: float = 0.0, quadratic: float = 0.0,
                   asymmetry: float = 0.0, viscous: float = 0.0, spring: float = 0.0, speed: float = 0.0,
                   delay: float = 0.0, pitch: tuple[float, float, float, float] | None = None,
                   settle_first: int | None = None, centre: float = 0.0):
    """Up-sweep through frequency ratios ``betas`` at force gamma0 (dimensionless).
    Yields per step (t', u, a, force) sampled over the measured periods at a fixed rate:
    u the displacement probe, a the accelerometer (both dimensionless).

    Effects outside the Masing model (dimensionless, 0 = off), written from the plant's
    documented equations (docs/decisions/0013, 0023), not from its code:

    - a spring ``cubic`` (u - ``centre``)^3 and ``spring`` (u - ``centre``) (the springs' rest
      position ``centre`` away from where the carriage starts, the probe's zero), a damping
      ``quadratic`` u'|u'| and ``viscous`` u';
    - friction higher one way, F (1 + ``asymmetry`` sign F), and faster,
      F (1 + ``speed`` |u'|) (``speed`` = alpha x_s omega_s / v_ref);
    - ``delay``: the probe reads u(t' - delay);
    - ``pitch`` = (a, r, kappa, zeta): a pitching column, a = m h^2 / J, r = e / h,
      kappa = k_th / (J omega_s^2), zeta = c_th / (J omega_s); with phi = th h / x_s

          u'' + r phi'' = P - F_total,   a r u'' + phi'' = a P - kappa phi - zeta phi',

      and the accelerometer (at the drive height) reads u'' + phi''.

    ``settle_first``: settle periods of the first step (from rest; default ``periods_settle``)."""
    car = MasingCarriage(n)

    def total(u, v):
        F = car.force(u)
        return (F * (1.0 + asymmetry * math.copysign(1.0, F)) * (1.0 + speed * abs(v)) + cubic * (u - centre) ** 3
                + quadratic * v * abs(v) + viscous * v + spring * (u - centre))

    if pitch is None:
        y = np.array([0.0, 0.0])
    else:
        a_c, r_c, kappa, zeta = pitch
        det = 1.0 - a_c * r_c * r_c
        if not det > 0:
            raise ValueError(f"pitch: J must exceed m e^2 (a r^2 = {a_c * r_c * r_c:.3g} >= 1)")
        y = np.array([0.0, 0.0, 0.0, 0.0])

    def accelerations(P, yy):
        """(u'', accelerometer) at drive force P."""
        if pitch is None:
            acc = P - total(yy[0], yy[1])
            return acc, acc
        f1 = P - total(yy[0], yy[1])
        f2 = a_c * P - kappa * yy[2] - zeta * yy[3]
        uu = (f1 - r_c * f2) / det
        pp = (f2 - a_c * r_c * f1) / det
        return uu, uu + pp

    t = 0.0
    phase = 0.0
    for i_step, beta in enumerate(betas):
        T = 2 * math.pi / beta
        t_start = t
        ph0 = phase
        settle = periods_settle if i_step or settle_first is None else settle_first

        def rhs(tt, yy):
            P = gamma0 * math.sin(beta * (tt - t_start) + ph0)
            uu, acc = accelerations(P, yy)
            if pitch is None:
                return [yy[1], uu]
            return [yy[1], uu, yy[3], acc - uu]

        def ev_rev(tt, yy):
            return yy[1]
        ev_rev.terminal = True

        def ev_close(tt, yy):
            c = car.closure()
            return 1.0 if c is None else car.d * (yy[0] - c) - 1e-15
        ev_close.terminal = True
        ev_close.direction = 1

        t_end = t_start + (settle + periods_measure) * T
        t_meas = t_start + settle * T
        dt = 1.0 / samples_per_unit_time
        grid = t_meas + dt * np.arange(int(periods_measure * T / dt))
        # what each sample time needs: the drive-side records at grid, the probe at grid - delay
        grids = (grid, grid - delay)
        a_s = np.empty(grid.size)
        u_s = np.empty(grid.size)
        jj = [0, 0]
        while t < t_end - 1e-12:
            ev_rev.direction = -car.d if car.d != 0 else 0
            sol = solve_ivp(rhs, (t, t_end), y, method="DOP853", rtol=rtol, atol=1e-12,
                            events=(ev_rev, ev_close), dense_output=True)
            t_stop = sol.t[-1]
            # sample the piece (the branch is fixed over it)
            for g_i, (g, out) in enumerate(zip(grids, (a_s, u_s))):
                j = jj[g_i]
                k = j
                while k < g.size and g[k] <= t_stop:
                    k += 1
                if k > j:
                    yy = sol.sol(g[j:k])
                    if g_i == 0:
                        P_k = gamma0 * np.sin(beta * (g[j:k] - t_start) + ph0)
                        out[j:k] = [accelerations(P, col)[1] for P, col in zip(P_k, yy.T)]
                    else:
                        out[j:k] = yy[0]
                    jj[g_i] = k
            y = sol.y[:, -1].copy()
            t = t_stop
            if sol.status == 1:
                if sol.t_events[0].size and sol.t_events[0][-1] == t_stop:       # reversal
                    if car.d != 0:
                        car.stack.append((y[0], car.force(y[0])))
                    car.d = -car.d if car.d != 0 else (1.0 if rhs(t, y)[1] > 0 else -1.0)
                    y[1] = 0.0
                else:                                                           # loop closed
                    if len(car.stack) >= 2:
                        del car.stack[-2:]
                    else:
                        car.stack.clear()
            elif car.d == 0 and abs(y[1]) > 0:
                car.d = 1.0 if y[1] > 0 else -1.0
            if car.d == 0:
                car.d = 1.0 if rhs(t, y)[1] >= 0 else -1.0
        phase = (ph0 + beta * (t_end - t_start)) % (2 * math.pi)
        P = gamma0 * np.sin(beta * (grid - t_start) + ph0)
        j = min(jj)
        yield grid[:j], u_s[:j], a_s[:j], P[:j]


def generate_uff(path, F_s_N, x_s_m, n, mass_kg, levels_N, freqs_Hz, *, fs_Hz=None, settle=25, measure=8,
                 noise=(0.003, 0.005, 0.002), seed=0, cubic_N_per_m3=0.0, quadratic_N_s2_per_m2=0.0,
                 asymmetry=0.0, viscous_N_s_per_m=0.0, spring_N_per_m=0.0, friction_alpha=0.0,
                 friction_v_ref_m_per_s=1.0, disp_delay_s=0.0, disp_gain_error=0.0, pitch=None,
                 line_Hz=0.0, line_m=0.0, rtol=1e-10, settle_first=None, spring_centre_m=0.0):
    """Simulate the up-sweeps and write them to ``path`` as UFF58 (no tags). Returns the
    number of steps written.  Effects in SI (0 = off): forms k3 x^3, c2 v|v|, friction
    asymmetry a; catalog c v, k x, friction F (1 + alpha |v| / v_ref), the probe delayed by
    ``disp_delay_s`` and scaled by 1 + ``disp_gain_error``, ``pitch`` = dict(J, k_th, c_th,
    h, e) (kg m^2, N m/rad, N m s/rad, m, m; equations in :func:`simulate_level`); the
    springs (k3, k) act about ``spring_centre_m`` on the probe's scale (each level's
    carriage starts at rest at the probe's zero).
    Artefacts: a line of ``line_m`` (amplitude) at ``line_Hz`` on the probe, on the
    simulation's own clock (not locked to the drive); a short ``settle`` leaves the
    transient of each frequency change in the record (``settle_first``: of the first step of
    each level, which starts from rest)."""
    return generate_uff_variants({path: (line_Hz, line_m)}, F_s_N, x_s_m, n, mass_kg, levels_N, freqs_Hz,
                                 fs_Hz=fs_Hz, settle=settle, measure=measure, noise=noise, seed=seed,
                                 cubic_N_per_m3=cubic_N_per_m3, quadratic_N_s2_per_m2=quadratic_N_s2_per_m2,
                                 asymmetry=asymmetry, viscous_N_s_per_m=viscous_N_s_per_m,
                                 spring_N_per_m=spring_N_per_m, friction_alpha=friction_alpha,
                                 friction_v_ref_m_per_s=friction_v_ref_m_per_s, disp_delay_s=disp_delay_s,
                                 disp_gain_error=disp_gain_error, pitch=pitch, rtol=rtol, settle_first=settle_first,
                                 spring_centre_m=spring_centre_m)


def generate_uff_variants(lines: dict, F_s_N, x_s_m, n, mass_kg, levels_N, freqs_Hz, *, fs_Hz=None, settle=25,
                          measure=8, noise=(0.003, 0.005, 0.002), seed=0, cubic_N_per_m3=0.0,
                          quadratic_N_s2_per_m2=0.0, asymmetry=0.0, viscous_N_s_per_m=0.0, spring_N_per_m=0.0,
                          friction_alpha=0.0, friction_v_ref_m_per_s=1.0, disp_delay_s=0.0, disp_gain_error=0.0,
                          pitch=None, rtol=1e-10, settle_first=None, spring_centre_m=0.0):
    """:func:`generate_uff` for several lines on one simulated plant: ``lines`` maps each
    output path to its probe line (``line_Hz``, ``line_m``; amplitude 0 = none).  The plant
    is integrated once; each file is the one :func:`generate_uff` with that line and the same
    ``seed`` writes (its own noise and line phase, drawn as there).  Returns the steps a file."""
    w_s = math.sqrt(F_s_N / (x_s_m * mass_kg))
    fs = fs_Hz or 128.0 * max(freqs_Hz) * 1.037       # not a multiple of any step frequency
    v_unit = x_s_m * w_s
    effects = dict(cubic=cubic_N_per_m3 * x_s_m ** 3 / F_s_N,
                   quadratic=quadratic_N_s2_per_m2 * v_unit ** 2 / F_s_N, asymmetry=asymmetry,
                   viscous=viscous_N_s_per_m * v_unit / F_s_N, spring=spring_N_per_m * x_s_m / F_s_N,
                   speed=friction_alpha * v_unit / friction_v_ref_m_per_s, delay=disp_delay_s * w_s,
                   centre=spring_centre_m / x_s_m)
    if pitch:
        J, h = pitch["J"], pitch["h"]
        effects["pitch"] = (mass_kg * h * h / J, pitch["e"] / h, pitch["k_th"] / (J * w_s ** 2),
                            pitch["c_th"] / (J * w_s))
    rngs = {path: np.random.default_rng(seed) for path in lines}
    phases = {path: rngs[path].uniform(0, 2 * math.pi) for path in lines}
    sets: dict = {path: [] for path in lines}
    case = 0
    for level in levels_N:
        betas = [2 * math.pi * f / w_s for f in sorted(freqs_Hz)]
        for t_dim, u, acc, P in simulate_level(n, level / F_s_N, betas, settle, measure, fs / w_s, rtol=rtol,
                                               settle_first=settle_first, **effects):
            case += 1
            force = P * F_s_N
            accel = acc * F_s_N / mass_kg
            for path, (line_Hz, line_m) in lines.items():
                disp = u * x_s_m * (1.0 + disp_gain_error)
                if line_m:
                    disp = disp + line_m * np.sin(2 * math.pi * line_Hz * t_dim / w_s + phases[path])
                f_n, a_n, d_n = add_noise(force, accel, disp, noise, F_s_N, x_s_m, rngs[path])
                sets[path] += step_sets(case, len(sets[path]) + 1, fs, f_n, a_n, d_n)
    for path, path_sets in sets.items():
        write_sets(path, path_sets)
    return case
