"""A realistic analysis dict (analysis.json's schema, contract 3) computed from the project's
own physics, so the analysis page is tested on real-shaped data, not numbers typed in.

The "measurement": the simulated rig's RK4 plant (n = 0.46, F_s 8.66 N, x_s 23 um,
m 9.22 kg) with viscous damping of 5 % equivalent damping ratio at the friction
resonance and sensor noise, 3 force levels x 6 frequencies, harmonics by the procedure's
least-squares fit.  One more step has a non-finite displacement record and is rejected.

The "analysis": the base fit is ``sim.identify.Identifier`` (F_s, x_s, n, m).  Each
candidate adds one term to the harmonic balance P - m a = F_Masing(x) + theta R, fitted
by weighted linear least squares on the base residual (R: i k w X for viscous damping,
X for a spring, the directional derivatives of the Masing friction for a displacement
gain error and a delay, F |v| / v_ref for speed-dependent friction).  Scores: delta BIC,
and the held-out error of the first harmonic (leave one force level out), which is the
relative error of compliance and accelerance predicted from the measured motion.
Causes are named greedily while delta BIC < -10 and the held-out error falls by 20 %.
The base and final models' FRFs are simulated with the rig's plant without noise.

This stands in for ``sim.discrepancy`` (the `causes` helper) until it lands; it is a
test fixture, not the product's analysis.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares

from procedures.analysis import fit_harmonics
from sim.identify import Identifier, StepHarmonics, analyse, synthesize
from sim.rig import RigModel, SimulatedRig

K = 5                       # harmonics
SAMPLES_PER_PERIOD = 128
SETTLE_PERIODS, MEASURE_PERIODS = 20, 4
LOOP_POINTS = 128
F_S, X_S, N_EXP, MASS = 8.66, 23e-6, 0.46, 9.22
OMEGA_S = math.sqrt(F_S / (X_S * MASS))
C_TRUE = 2 * 0.05 * MASS * OMEGA_S          # 5 % equivalent damping ratio at omega_s
LEVELS = (0.2 * F_S, 0.5 * F_S, 0.85 * F_S)
FREQS = tuple(OMEGA_S / (2 * math.pi) * np.geomspace(0.5, 2.5, 6))
Z95 = 1.959964


def truth_model(**effects) -> RigModel:
    return RigModel(F_s_N=F_S, x_s_m=X_S, n=N_EXP, mass_kg=MASS, force_noise_N=0.003 * F_S,
                    accel_noise_m_s2=0.004, disp_noise_m=0.002 * X_S, seed=11, **effects)


def simulate_step(model: RigModel, level_N: float, freq_Hz: float):
    """Settle, record MEASURE_PERIODS periods; force, acceleration, displacement in SI."""
    rig = SimulatedRig(model)
    rig.set_generator(freq_Hz=freq_Hz, amplitude_Vpp=2 * level_N / model.amp_gain_N_per_V, output_on=True)
    fs = SAMPLES_PER_PERIOD * freq_Hz
    rig.run(SETTLE_PERIODS * SAMPLES_PER_PERIOD, fs)
    b = rig.run(MEASURE_PERIODS * SAMPLES_PER_PERIOD, fs)
    return (b.force_V / model.force_sens_V_per_N, b.accel_V / model.accel_sens_V_per_m_s2,
            (b.disp_V / model.disp_sens_V_per_m), fs)


def harmonics(record: np.ndarray, fs: float, freq_Hz: float) -> tuple[np.ndarray, float]:
    fit = fit_harmonics(record - record.mean(), fs, freq_Hz, K)
    return fit.amplitude * np.exp(1j * fit.phase_rad), fit.noise_rms * math.sqrt(2.0 / record.size)


def first_harmonics(model: RigModel, level_N: float, freq_Hz: float) -> tuple[complex, complex]:
    """(compliance, accelerance) first harmonics of a noise-free simulation of ``model``."""
    P, A, X, fs = simulate_step(model, level_N, freq_Hz)
    p, _ = harmonics(P, fs, freq_Hz)
    a, _ = harmonics(A, fs, freq_Hz)
    x, _ = harmonics(X - X.mean(), fs, freq_Hz)
    return x[0] / p[0], a[0] / p[0]


def _pair(z: complex) -> list[float]:
    return [float(z.real), float(z.imag)]


def _interval(value: float, se: float, unit: str = "") -> dict:
    d = {"value": value, "low": value - Z95 * se, "high": value + Z95 * se}
    return d | ({"unit": unit} if unit else {})


def build_example() -> dict:
    truth = truth_model(viscous_N_s_per_m=C_TRUE)
    steps, keys, levels, rejected = [], [], [], []
    for li, level in enumerate(LEVELS):
        for fi, f in enumerate(FREQS):
            P, A, X, fs = simulate_step(truth, level, f)
            (p, sp), (a, sa), (x, sx) = harmonics(P, fs, f), harmonics(A, fs, f), harmonics(X, fs, f)
            steps.append(StepHarmonics(f, p, a, x, sp, sa, sx))
            keys.append(f"L{li}-F{fi:02d}-up")
            levels.append(abs(p[0]))
    # a step whose displacement record has a dropout: rejected with its reason, never used
    P, A, X, fs = simulate_step(truth, LEVELS[0], FREQS[0])
    X[100:110] = np.nan
    bad = [name for name, r in (("force", P), ("acceleration", A), ("displacement", X)) if not np.isfinite(r).all()]
    rejected.append({"step": "L0-F00-down", "reason": f"non-finite samples in the {', '.join(bad)} record"})

    guess = dict(F_s_N=1.3 * F_S, x_s_m=0.7 * X_S, n=0.8, mass_kg=1.1 * MASS)
    ident = Identifier(guess, harmonics=K)
    for s in steps:
        ident.add(s)
    est = ident.fit(max_nfev=200)
    F_s, x_s, n, m = (est.values[k] for k in ("F_s_N", "x_s_m", "n", "mass_kg"))

    Xh = np.array([s.disp for s in steps])
    Ph = np.array([s.force for s in steps])
    Ah = np.array([s.accel for s in steps])
    w = 2 * np.pi * np.array([s.freq_Hz for s in steps])[:, None]
    kk = np.arange(1, K + 1)[None, :]
    k_eff = np.abs((Ph - m * Ah)[:, 0]) / np.abs(Xh[:, 0])
    sigma = np.sqrt(np.array([s.sigma_force for s in steps]) ** 2 + (m * np.array([s.sigma_accel for s in steps])) ** 2
                    + (k_eff * np.array([s.sigma_disp for s in steps])) ** 2)[:, None]
    groups = np.array([int(np.argmin(np.abs(np.array(LEVELS) - lv))) for lv in levels])
    h = 1e-3
    v_ref = X_S * OMEGA_S
    catalog = {     # id -> (label, parameter, unit, regressor(F_s, x_s, n, X, w, F_masing))
        "viscous_damping": ("viscous damping", "c", "N s/m", lambda p, X, w, F: 1j * kk * w * X),
        "linear_spring": ("linear spring", "k", "N/m", lambda p, X, w, F: X),
        "sensor_gain_error": ("displacement gain error", "gain_error", "",
                              lambda p, X, w, F: -(ident.model_friction(*p, X * (1 + h)) - F) / h),
        "sensor_delay": ("displacement channel delay", "delay", "s",
                         lambda p, X, w, F: (ident.model_friction(*p, X + h * 1j * kk * w * X) - F) / h),
        "velocity_dependent_friction": ("speed-dependent friction", "alpha", "",
                                        lambda p, X, w, F: analyse(synthesize(F, LOOP_POINTS) * np.abs(
                                            synthesize(1j * kk * w * X, LOOP_POINTS)) / v_ref, K)),
    }

    def model(th, terms, rows):
        """Friction harmonics of the base model plus the terms; th = (ln F_s, ln x_s, n, ln m, coefficients)."""
        p = (math.exp(th[0]), math.exp(th[1]), th[2] if abs(th[2] - 1) > 1e-6 else 1 + 1e-6)
        F = ident.model_friction(*p, Xh[rows])
        extra = sum(c * catalog[t][3](p, Xh[rows], w[rows], F) for c, t in zip(th[4:], terms))
        return F + extra, math.exp(th[3])

    def residual(th, terms, rows):
        F, mass = model(th, terms, rows)
        r = (Ph[rows] - mass * Ah[rows] - F) / sigma[rows]
        return np.concatenate([r.real.ravel(), r.imag.ravel()])

    def fit(terms, rows=slice(None)):
        th0 = np.concatenate([[math.log(F_s), math.log(x_s), n, math.log(m)], np.zeros(len(terms))])
        res = least_squares(residual, th0, args=(terms, rows), x_scale="jac", max_nfev=200)
        chi2 = float(res.fun @ res.fun)
        cov = np.linalg.pinv(res.jac.T @ res.jac) * max(chi2 / max(res.fun.size - th0.size, 1), 1.0)
        return res.x, np.sqrt(np.clip(np.diag(cov), 0, None)), chi2

    def heldout(terms) -> float:
        """rms over left-out force levels of |P1 - m A1 - F1| / |P1|: the relative error of compliance
        and accelerance predicted from the measured motion."""
        errs = []
        for g in range(len(LEVELS)):
            th = fit(terms, groups != g)[0]
            F, mass = model(th, terms, groups == g)
            errs.extend(np.abs((Ph - mass * Ah)[groups == g, 0] - F[:, 0]) / np.abs(Ph[groups == g, 0]))
        return float(np.sqrt(np.mean(np.square(errs))))

    N = 2 * Ph.size
    named, candidates, terms = [], {}, []
    th_base, _, chi2_base = fit([])
    th_now, chi2_now, err_now = th_base, chi2_base, heldout([])
    base_err = err_now
    while len(terms) < len(catalog):
        scores = {}
        for cid in catalog:
            if cid in terms:
                continue
            th, se, chi2 = fit(terms + [cid])
            scores[cid] = (chi2 - chi2_now + math.log(N), heldout(terms + [cid]), th, se, chi2)
            candidates.setdefault(cid, {"id": cid, "delta_bic": scores[cid][0], "heldout_error": scores[cid][1],
                                        "named": False})
        best = min(scores, key=lambda c: scores[c][0])
        dbic, err, th, se, chi2 = scores[best]
        if not (dbic < -10 and err < 0.8 * err_now):
            break
        terms.append(best)
        candidates[best].update(named=True, delta_bic=dbic, heldout_error=err)
        label, pname, unit, _ = catalog[best]
        named.append({"id": best, "label": label,
                      "parameters": {pname: _interval(float(th[-1]), float(se[-1]), unit)},
                      "gain": {"heldout_error_before": err_now, "heldout_error_after": err, "delta_bic": dbic}})
        th_now, chi2_now, err_now = th, chi2, err
    for c, t in zip(named, terms):      # the coefficients of the final joint fit
        c["_theta"] = float(th_now[4 + terms.index(t)])
    dof = N - th_now.size
    chi2_final = chi2_now / dof
    unexplained = chi2_final > 2.0
    F_base, _ = model(th_base, [], slice(None))
    F_final, m_final = model(th_now, terms, slice(None))
    r = Ph - math.exp(th_base[3]) * Ah - F_base
    F_s, x_s, n, m = math.exp(th_now[0]), math.exp(th_now[1]), th_now[2], m_final

    effects = {"viscous_damping": "viscous_N_s_per_m", "linear_spring": "spring_N_per_m",
               "sensor_delay": "disp_delay_s", "sensor_gain_error": "disp_gain_error"}
    quiet = dict(F_s_N=F_s, x_s_m=x_s, n=n, mass_kg=m, force_noise_N=0.0, accel_noise_m_s2=0.0, disp_noise_m=0.0)
    base_model = RigModel(**(quiet | dict(F_s_N=math.exp(th_base[0]), x_s_m=math.exp(th_base[1]), n=th_base[2],
                                          mass_kg=math.exp(th_base[3]))))
    final_model = RigModel(**quiet, **{effects[c["id"]]: c["_theta"] for c in named if c["id"] in effects})
    out_steps = []
    for key, s, lv, res in zip(keys, steps, levels, np.abs(r) / np.abs(Ph[:, :1])):
        C_b, A_b = first_harmonics(base_model, lv, s.freq_Hz)
        C_f, A_f = first_harmonics(final_model, lv, s.freq_Hz) if named else (C_b, A_b)
        out_steps.append({"key": key, "level_N": lv, "freq_Hz": s.freq_Hz, "direction": "up",
                          "measured": {"compliance": _pair(s.disp[0] / s.force[0]),
                                       "accelerance": _pair(s.accel[0] / s.force[0])},
                          "base": {"compliance": _pair(C_b), "accelerance": _pair(A_b)},
                          "final": {"compliance": _pair(C_f), "accelerance": _pair(A_f)},
                          "residual_by_harmonic": [float(v) for v in res]})

    loops = []
    for key in (keys[2], keys[len(FREQS) + 2], keys[-4]):
        i = keys.index(key)
        loops.append({"key": key, "level_N": levels[i], "freq_Hz": steps[i].freq_Hz,
                      "disp_m": synthesize(Xh[i:i + 1], LOOP_POINTS)[0].tolist(),
                      "friction_meas_N": synthesize((Ph - m * Ah)[i:i + 1], LOOP_POINTS)[0].tolist(),
                      "friction_base_N": synthesize(F_base[i:i + 1], LOOP_POINTS)[0].tolist(),
                      "friction_final_N": synthesize(F_final[i:i + 1], LOOP_POINTS)[0].tolist()})

    base_params = {k: {"value": est.values[k], "low": est.low[k], "high": est.high[k]}
                   for k in ("F_s_N", "x_s_m", "n", "mass_kg")}
    se = fit(terms)[1] if terms else None
    params = base_params if not terms else {
        k: {"value": v, "low": lo, "high": hi} for k, v, lo, hi in (
            ("F_s_N", F_s, F_s * math.exp(-Z95 * se[0]), F_s * math.exp(Z95 * se[0])),
            ("x_s_m", x_s, x_s * math.exp(-Z95 * se[1]), x_s * math.exp(Z95 * se[1])),
            ("n", n, n - Z95 * se[2], n + Z95 * se[2]),
            ("mass_kg", m, m * math.exp(-Z95 * se[3]), m * math.exp(Z95 * se[3])))}
    if named:
        parts = [f"{c['label']} {next(iter(c['parameters']))} = {c['_theta']:.3g} "
                 f"{next(iter(c['parameters'].values())).get('unit', '')}".rstrip() for c in named]
        verdict = (f"The Masing model alone misses the measured response by {100 * base_err:.2g} % (held-out, "
                   f"first harmonic). The data are explained by {' and '.join(parts)}; the out-of-sample "
                   f"error falls from {100 * base_err:.2g} % to "
                   f"{100 * named[-1]['gain']['heldout_error_after']:.2g} %.")
    else:
        verdict = "The Masing model explains the data within the noise; no cause is named."
    if unexplained:
        verdict += " Structure remains in the residuals that no candidate explains."
    return {
        "schema": "guideway-bench/analysis/2", "source": "simulated rig (test fixture)",
        "software_version": "test",
        "parameters": params,
        "base": {"parameters": base_params, "reduced_chi2": est.cost,
                 "diagnostics": {"reduced_chi2_after_causes": chi2_final, "chi2_base": chi2_base, "points": N,
                                 "heldout_error_base": base_err}},
        "causes": [{k: v for k, v in c.items() if not k.startswith("_")} for c in named],
        "unexplained": unexplained, "verdict": verdict,
        "candidates": list(candidates.values()),
        "steps_used": keys, "steps_rejected": rejected,
        "steps": out_steps, "loops": loops,
    }
