"""Online identification of F_s, x_s, n and m while a stepped-sine test runs.

After every step the identifier (sim.identify) is refitted, warm-started from the last
estimate with a small evaluation budget; each estimate, with its 95 % intervals and the
update's time, is appended to <run>/identification.jsonl.  At the end a full fit over
all steps is stored in run.json.

When the rig file declares modes or effects beyond the Masing carriage (``[rig.model]``: a
pitching mode, viscous damping, ...), both fit the analysis' model of the rig with them
(:mod:`sim.discrepancy.rigfit`, decision 0042): online with the declared effects held at
the rig file's values, at the end with them refitted.  F_s, x_s and m stay within
BOUND_FACTOR of the rig file's expected values online; an estimate on a bound says so.
"""

from __future__ import annotations

import json
import logging
import math
import os
import stat
import time

import numpy as np

from sim.discrepancy.rigfit import BOUND_FACTOR, OnlineRigFit, identify_steps, rig_effects
from sim.identify import Identifier, StepHarmonics
from sim.records import analyse_records
from sim.step_record import records_of
from sim.step_result import StepResult

from .plan import Plan, Rig

log = logging.getLogger(__name__)

MAX_HARMONICS = 9     # on a small-n rig 9 harmonics gave x_s within 1 %, 5 within 2 %
REWEIGHT_BUDGET = 4   # stale errors-in-variables weights refreshed per update (speed)


def identifiability(plan: Plan, rig: Rig) -> list[str]:
    """What the plan cannot pin down, judged with the rig's expected parameters."""
    F_s, x_s, m = rig.expected_F_s_N, rig.expected_x_s_m, rig.expected_mass_kg
    f_s = math.sqrt(F_s / (x_s * m)) / (2 * math.pi)
    freqs = np.array(plan.freqs_Hz)
    gammas = np.array(plan.levels_N) / F_s
    out = []
    if not np.any((gammas >= 0.3) & (gammas <= 0.9)):
        out.append(f"F_s, n: no force level between 0.3 and 0.9 of the expected F_s ({0.3 * F_s:.3g}-"
                   f"{0.9 * F_s:.3g} N), where the friction loop shows its shape")
    if not np.any(gammas >= 1.0):
        out.append(f"F_s: no force level at or above the expected F_s ({F_s:.3g} N): the rolling "
                   f"plateau is never reached")
    near = np.count_nonzero((freqs >= 0.5 * f_s) & (freqs <= 2.0 * f_s))
    if near < 3:
        out.append(f"x_s, n: only {near} frequencies within 0.5-2x the expected friction resonance "
                   f"({f_s:.3g} Hz); the resonance itself will not be seen")
    if not np.any(freqs >= 3.0 * f_s):
        out.append(f"mass: no frequency above 3x the expected friction resonance ({3 * f_s:.3g} Hz), "
                   f"where the mass dominates")
    return out


def choose_frequencies(sweep: list, values: dict | None, per_sweep: int) -> list:
    """Adaptive mode: the ``per_sweep`` steps of a sweep that say most about the friction.

    Around the resonance the response depends most on x_s and n: the grid frequencies
    closest (in log f) to the resonance the current estimate predicts at this force,
    plus the highest one, where the mass dominates.  Above F_s (gross rolling) the
    lowest frequencies, where the carriage rolls furthest, take the resonance's place.
    Without an estimate yet: evenly spread over the grid.  Returned in sweep order."""
    if per_sweep <= 0 or len(sweep) <= per_sweep:
        return list(sweep)
    freqs = np.array([s.freq_Hz for s in sweep])
    if values is None:
        pick = set(np.unique(np.round(np.linspace(0, len(sweep) - 1, per_sweep)).astype(int)).tolist())
    else:
        F_s, x_s, m = values["F_s_N"], values["x_s_m"], values["mass_kg"]
        n = values["n"] if abs(values["n"] - 1) > 0.02 else 1.02
        gamma0 = sweep[0].force_N / F_s
        f_s = math.sqrt(F_s / (x_s * m)) / (2 * math.pi)
        f_res = freqs.min()
        if gamma0 < 0.95:
            from sim.frf import find_peaks
            from sim.shooting import frf_shooting
            betas = np.geomspace(0.2, 6.0, 60)
            try:
                f_res = find_peaks(frf_shooting(betas, gamma0, n)[0])[0].beta * f_s
            except (ValueError, ArithmeticError) as e:
                log.warning("adaptive: no resonance predicted at %.3g N (%s)", sweep[0].force_N, e)
        top = int(np.argmax(freqs))
        near = [int(i) for i in np.argsort(np.abs(np.log(freqs / f_res))) if i != top]
        pick = {top, *near[:per_sweep - 1]}
    return [s for i, s in enumerate(sweep) if i in pick]


def step_harmonics(result: StepResult, raw: dict | None = None) -> StepHarmonics:
    """A step for the identifier: from the analysis its record keeps (format version 2:
    every harmonic the block holds, noise from the scatter of its periods, decision 0047);
    a version-1 step from its raw block when there is one, else from the stored fits."""
    rec = records_of(result)
    if rec is not None:
        return StepHarmonics.from_records(rec)
    if raw is None:
        return StepHarmonics.from_result(result)
    rec = analyse_records(raw["force_N"], raw["accel_m_s2"], raw["disp_m"], float(raw["fs_Hz"]),
                          result["freq_Hz"])
    return StepHarmonics.from_records(rec)


class OnlineIdentification:
    def __init__(self, run_dir, rig: Rig, harmonics: int = 5, budget: int = 25):
        self.path = run_dir / "identification.jsonl"
        self.guess = rig.guess()
        self.rig_model = rig.model
        K = min(harmonics, MAX_HARMONICS)
        # the rig's declared modes: the analysis' model with them (else the Masing carriage)
        self.rigfit = OnlineRigFit(self.guess, self.rig_model, K) if rig_effects(self.rig_model) else None
        self.ident = Identifier(self.guess, harmonics=K, bound_factor=BOUND_FACTOR)
        self.steps: list[StepHarmonics] = []
        self.budget = budget
        self.update_times_s: list[float] = []

    def current(self) -> dict | None:
        """The latest estimate's values (None before the first fit)."""
        if self.rigfit is not None:
            return self.rigfit.estimate["values"] if self.rigfit.estimate else None
        return self.ident.estimate.values if self.ident.estimate else None

    def _add(self, h: StepHarmonics) -> None:
        self.steps.append(h)
        (self.rigfit or self.ident).add(h)

    def preload(self, results: list[StepResult], raw_of=None) -> None:
        """Steps already measured (resume): fitted once before new steps arrive.
        ``raw_of(key)`` gives a step's raw block (for every harmonic it holds)."""
        for r in results:
            self._add(step_harmonics(r, raw_of(r["key"]) if raw_of else None))
        if results:
            if self.rigfit is not None:
                self.rigfit.fit(max_nfev=200)
            else:
                self.ident.fit(max_nfev=200)

    def update(self, result: StepResult, raw: dict | None = None) -> dict | None:
        """Add a step (with its raw block when there is one) and refit."""
        t = time.perf_counter()
        try:
            self._add(step_harmonics(result, raw))
            if self.rigfit is not None:
                est = self.rigfit.fit(max_nfev=self.budget)
            else:
                est = self.ident.fit(max_nfev=self.budget, reweight_rounds=0, reweight_budget=REWEIGHT_BUDGET,
                                     tol=1e-5).as_dict()
                est["source"] = "online"
        except Exception as e:  # noqa: BLE001 - identification must never stop a test
            log.warning("identification update failed after step %s: %s", result.get("key"), e)
            return None
        dt = time.perf_counter() - t
        self.update_times_s.append(dt)
        rec = dict(step=result.get("key"), update_s=dt, **est)
        # never through a symbolic link placed in the run directory (as bench.storage)
        # nor into a FIFO (O_NONBLOCK: no waiting for a reader; then not a regular file)
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK
                         | os.O_CLOEXEC, 0o666)
            with os.fdopen(fd, "a") as fh:
                if not stat.S_ISREG(os.fstat(fd).st_mode):
                    raise OSError(f"{self.path}: not a regular file")
                fh.write(json.dumps(rec) + "\n")
        except OSError as e:
            log.warning("identification history not written: %s", e)
        return rec

    def final(self) -> dict:
        """The full fit over all steps; a failure is reported, never raised (the test's
        data are complete and safe whatever happens here)."""
        try:
            # the one identification `bench identify` gives too: the plain carriage's in the
            # noise of its own residuals (the online Identifier's intervals ignore their
            # correlation: the demo's x_s and n 2.4-2.7 standard errors out, decision 0064)
            est = identify_steps(self.steps, self.guess, self.rig_model, harmonics=MAX_HARMONICS)
            check_finite(est)
        except Exception as e:  # noqa: BLE001
            log.error("final identification failed: %s", e)
            return {"error": f"{type(e).__name__}: {e}", "source": "final fit"}
        for w in est["warnings"]:
            log.warning("identification: %s", w)
        times = np.array(self.update_times_s) if self.update_times_s else np.array([np.nan])
        return dict(est, update_ms_median=float(np.median(times) * 1e3),
                    update_ms_max=float(np.max(times) * 1e3))


def check_finite(est: dict) -> None:
    """An estimate whose values or intervals overflowed is a failed fit, not a result."""
    for part in ("values", "low", "high"):
        for k, v in (est.get(part) or {}).items():
            if not (isinstance(v, (int, float)) and math.isfinite(v) and (part == "values" or v >= 0 or k == "n")):
                raise ArithmeticError(f"{part} of {k} is not a finite number ({v!r})")
        vals = est.get("values") or {}
        if any(k != "n" and not (1e-30 < abs(v) < 1e30) for k, v in vals.items()):
            raise ArithmeticError(f"absurd value: {vals}")


def history(run_dir) -> list[dict]:
    p = run_dir / "identification.jsonl"
    out = []
    if p.exists():
        for line in p.read_text().splitlines():
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError:
                pass
    return out
