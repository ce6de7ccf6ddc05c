"""Coverage of `bench modes`' intervals on imported FRFs the code under test did not make
(issue 42, decision record 0085): the independent Masing simulator of
benchtools/independent_masing.py (scipy's DOP853, written from the physics notes) at
force-controlled levels and at response-controlled levels (the force found per frequency
that holds the displacement's fundamental), each point with an analyser's noise, written as
UFF58 FRF records (pyuff, benchtools/frf_files.py) and as a pandas CSV, imported by
`bench import` and judged by `bench modes` against the simulator's own truth:

- the resonance: the peak of the simulator's |X1/F1| along the level (golden section);
- the energy balance: -Im(H) / (2 m w^2 |H|^2) of the simulator's H at that peak;
- the half-power ratio: (f2 - f1) / (2 f_r) with f1, f2 where the simulator's |H| crosses
  peak / sqrt(2) (root-found), f_r its peak;
- the single-mode fit: R + A / (w_r^2 - w^2 + 2 i zeta w_r w) fitted (scipy least squares,
  written here, not sim.modal's) to the simulator's noise-free H at 41 points across that
  half-power band.

Each trial: a grid of ``STEP_HZ`` steps whose placement about the peak is drawn (a lab's
grid lands anywhere), the FRF with complex Gaussian noise of ``NOISE`` relative sd (an
analyser's H1 estimate after averaging), one import per level kind.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import optimize

from benchtools.masing_peaks import golden_max, steady_state

MODEL = dict(F_s_N=10.0, x_s_m=1e-5, n=1.5, mass_kg=10.0)      # tests/bench/test_import_frfs.py's carriage
FORCE_LEVELS_N = (1.0, 2.0, 3.5)
HELD_M = (2e-6, 6e-6)                 # response-controlled: the displacement amplitude held
NOISE = 0.002                         # relative sd of each FRF value (complex Gaussian)
STEP_HZ, MARGIN = 1.5, 3              # the grid: 1.5 Hz steps across the half-power band and 3 beyond
QUANTITIES = ("resonance", "fit", "energy_balance", "half_power")
UFF_MAPPING = """[import]
level_from = "id1"
level_pattern = "at ([0-9.]+) N"
mass_kg = 10.0
"""
CSV_MAPPING = """[import]
mass_kg = 10.0
"""


@dataclass
class Simulator:
    """The steady state X1/F1 of the independent simulator (from rest, ``settle`` periods),
    per force level or per held displacement (the force per frequency found by iteration),
    cached."""

    settle: int = 30
    measure: int = 16            # 16 periods: |H| smooth in f to 2e-6 (4 periods: jumps of 1e-4, a flat peak's 0.1 Hz)
    rtol: float = 1e-7
    cache: dict = field(default_factory=dict)

    def at_force(self, force_N: float, f_Hz: float) -> complex:
        key = ("F", force_N, f_Hz)
        if key not in self.cache:
            self.cache[key] = steady_state(MODEL, force_N, f_Hz, self.settle, self.measure, self.rtol)[2]
        return self.cache[key]

    def at_held(self, held_m: float, f_Hz: float) -> tuple[complex, float]:
        """(X1/F1, the force amplitude) with |X1| = ``held_m`` to 1e-7 (else the best of 12 steps, within 1e-5)."""
        key = ("X", held_m, f_Hz)
        if key not in self.cache:
            near = [k for k in self.cache if k[0] == "X" and k[1] == held_m]
            P = (self.cache[min(near, key=lambda k: abs(k[2] - f_Hz))][1] if near
                 else held_m / abs(self.at_force(1.0, f_Hz)))
            logs: list[tuple[float, float]] = []
            best: tuple[float, complex, float] | None = None
            for _ in range(12):
                H = self.at_force(P, f_Hz)
                err = math.log(abs(H) * P / held_m)
                if best is None or abs(err) < best[0]:
                    best = (abs(err), H, P)
                if abs(err) < 1e-7:
                    break
                logs.append((math.log(P), err))
                if len(logs) >= 2 and logs[-1][1] != logs[-2][1]:       # secant in log P
                    (a, ea), (b, eb) = logs[-2:]
                    P = math.exp(b - eb * (b - a) / (eb - ea))
                else:
                    P *= math.exp(-err)
            assert best is not None
            if best[0] > 1e-5:          # the integrator's tolerance: |X1| jumps by ~1e-7-1e-6 between neighbouring forces
                raise RuntimeError(f"no force holds {held_m:g} m at {f_Hz:g} Hz")
            _, H, P = best
            self.cache[key] = (H, P)
        return self.cache[key]

    def H(self, kind: str, level: float, f_Hz: float) -> complex:
        return self.at_force(level, f_Hz) if kind == "force" else self.at_held(level, f_Hz)[0]


@dataclass(frozen=True)
class Truth:
    """The simulator's own resonance and named damping ratios of one level."""

    kind: str
    level: float
    resonance_Hz: float
    energy_balance: float
    half_power: float
    fit: float
    f1_Hz: float = math.nan
    f2_Hz: float = math.nan

    def of(self, quantity: str) -> float:
        return self.resonance_Hz if quantity == "resonance" else getattr(self, quantity)


# truth(Simulator(), kind, level) as benchmarks/bench_import_coverage.py prints it (about 20 s a
# force level, 75 s a held one): the test's sample reads them (resonance, energy balance,
# half-power, band fit, f1, f2).
TRUTHS = {
    ("force", 1.0): (67.86477813785646, 0.08159527138597196, 0.0886655394615288, 0.06404289220556937,
                     65.01214294302967, 77.04667727108969),
    ("force", 2.0): (61.9024734312796, 0.12372422253768525, 0.13185866935102994, 0.0995951439919602,
                     57.89492826181173, 74.21968381418375),
    ("force", 3.5): (55.39181768784733, 0.18659360135490433, 0.19397919730121163, 0.1549986379208945,
                     49.84478450623946, 71.33450517052682),
    ("disp", 2e-6): (72.74909620351136, 0.0546333498367497, 0.05465813768599569, 0.05427613372348915,
                     68.66727665866554, 76.61993689231208),
    ("disp", 6e-6): (60.065004093697254, 0.13936337403228344, 0.14048896955562956, 0.13518647893548588,
                     51.035380175906006, 67.9123212388624),
}


def stored_truth(kind: str, level: float) -> Truth:
    return Truth(kind, level, *TRUTHS[(kind, level)])


def fit_band(f_Hz: np.ndarray, H: np.ndarray) -> float:
    """zeta of R + A / (w_r^2 - w^2 + 2 i zeta w_r w) fitted to ``H`` (complex A, R)."""
    w = 2 * np.pi * np.asarray(f_Hz) / (2 * np.pi * f_Hz[np.argmax(np.abs(H))])
    s = np.max(np.abs(H))
    y = H / s

    def model(p):
        wr, z = p[0], p[1]
        return (p[2] + 1j * p[3]) / (wr * wr - w * w + 2j * z * wr * w) + p[4] + 1j * p[5]

    def res(p):
        r = model(p) - y
        return np.concatenate([r.real, r.imag])
    best = None
    for z0 in (0.02, 0.05, 0.1):
        d = 1.0 / (1.0 - w * w + 2j * z0 * w)
        coef = np.linalg.lstsq(np.column_stack([d, np.ones_like(d)]), y, rcond=None)[0]
        r = optimize.least_squares(res, [1.0, z0, coef[0].real, coef[0].imag, coef[1].real, coef[1].imag],
                                   method="lm", xtol=1e-12, ftol=1e-12)
        if best is None or r.cost < best.cost:
            best = r
    assert best is not None
    return abs(float(best.x[1]))


def truth(sim: Simulator, kind: str, level: float, around_Hz: tuple[float, float] = (45.0, 90.0)) -> Truth:
    """The level's truth (module docstring); the peak searched in ``around_Hz``."""
    def mag(f):
        return abs(sim.H(kind, level, float(f)))
    coarse = np.arange(around_Hz[0], around_Hz[1], 2.0)
    i = int(np.argmax([mag(f) for f in coarse]))
    f_r = golden_max(mag, float(coarse[i - 1]), float(coarse[i + 1]), rel_tol=2e-5)
    peak = mag(f_r)
    Hr = sim.H(kind, level, f_r)
    w = 2 * math.pi * f_r
    eb = -Hr.imag / (2 * MODEL["mass_kg"] * w * w * abs(Hr) ** 2)

    def half(sign: int) -> float:
        f = f_r
        while mag(f) > peak / math.sqrt(2):
            f += sign * 2.0
        return optimize.brentq(lambda x: mag(x) - peak / math.sqrt(2), *sorted((f, f - sign * 2.0)), xtol=1e-6)
    f1, f2 = half(-1), half(1)
    band = np.linspace(f1, f2, 41)
    zf = fit_band(band, np.array([sim.H(kind, level, float(x)) for x in band]))
    return Truth(kind, level, f_r, eb, (f2 - f1) / (2 * f_r), zf, f1, f2)


def grid(t: Truth, rng: np.random.Generator, placements: int = 0) -> np.ndarray:
    """STEP_HZ steps from MARGIN steps below the truth's half-power band to MARGIN above it,
    their placement drawn uniformly over one step (``placements`` > 0: one of that many
    evenly spaced placements, so that seeds share the simulator's steady states)."""
    k = np.arange(math.floor((t.f1_Hz - t.resonance_Hz) / STEP_HZ) - MARGIN,
                  math.ceil((t.f2_Hz - t.resonance_Hz) / STEP_HZ) + MARGIN + 1)
    u = rng.uniform(-0.5, 0.5)
    if placements:
        u = (math.floor((u + 0.5) * placements) + 0.5) / placements - 0.5
    return t.resonance_Hz + STEP_HZ * (k + u)


def noisy(H: np.ndarray, rng: np.random.Generator, noise: float = NOISE) -> np.ndarray:
    return H * (1 + noise * (rng.standard_normal(H.size) + 1j * rng.standard_normal(H.size)) / math.sqrt(2))


def write_trial(sim: Simulator, truths: list[Truth], seed: int, where: Path, noise: float = NOISE,
                placements: int = 0) -> dict:
    """Seed ``seed``'s files in ``where``: the force levels as UFF58 accelerance with force
    spectra (benchtools.frf_files.write_uff), the held levels as a pandas CSV of X/F with
    the force per point.  {level kind: (file, mapping)}."""
    import pandas as pd

    from benchtools.frf_files import write_uff
    rng = np.random.default_rng(seed)
    where.mkdir(parents=True, exist_ok=True)
    out, uff, rows = {}, {}, []
    for t in truths:
        f = np.round(grid(t, rng, placements), 6)
        H = noisy(np.array([sim.H(t.kind, t.level, float(x)) for x in f]), rng, noise)
        if t.kind == "force":
            uff[t.level] = (f, H)
        else:
            P = [sim.at_held(t.level, float(x))[1] for x in f]
            rows += [{"level [m]": t.level, "frequency [Hz]": x, "re [m/N]": h.real, "im [m/N]": h.imag,
                      "force [N]": p} for x, h, p in zip(f, H, P, strict=True)]
    if uff:
        write_uff(where / "force.uff", uff)
        (where / "force.toml").write_text(UFF_MAPPING)
        out["force"] = (where / "force.uff", where / "force.toml")
    if rows:
        pd.DataFrame(rows).to_csv(where / "held.csv", index=False, float_format="%.10g")
        (where / "held.toml").write_text(CSV_MAPPING)
        out["disp"] = (where / "held.csv", where / "held.toml")
    return out


def intervals(e) -> dict:
    """{quantity: (value, low, high)} of one `bench modes` estimate (NaNs where none)."""
    nan = (math.nan, math.nan, math.nan)
    eb = e.extra.get("energy_balance")
    return {"resonance": (e.resonance_Hz, e.resonance_low_Hz, e.resonance_high_Hz),
            "fit": (e.damping_ratio, e.damping_ratio_low, e.damping_ratio_high),
            "energy_balance": (eb.value, eb.low, eb.high) if eb is not None else nan,
            "half_power": tuple(e.extra.get("half_power") or nan)}


def run_trial(sim: Simulator, truths: list[Truth], seed: int, where: Path, noise: float = NOISE,
              placements: int = 0) -> list[dict]:
    """Import seed ``seed``'s files, run `bench modes`' estimator, judge every interval: one
    row per (level, quantity) with value, low, high, truth, held."""
    from bench.frf_run import import_frfs
    from bench.reports._modes import run_modes
    rows = []
    for kind, (src, mapping) in write_trial(sim, truths, seed, where, noise, placements).items():
        run, _ = import_frfs(src, where / f"run-{kind}", mapping)
        modes = [e for e in run_modes(run, model=False).modes if e.mode == "feed"]
        for t in truths:
            if (t.kind == "force") != (kind == "force"):
                continue
            e = next(e for e in modes if math.isclose(e.level_N, t.level, rel_tol=1e-9))
            for q, (v, lo, hi) in intervals(e).items():
                rows.append(dict(seed=seed, kind=t.kind, level=t.level, quantity=q, status=e.status, value=v,
                                 low=lo, high=hi, truth=t.of(q), held=bool(lo <= t.of(q) <= hi)))
    return rows


def binomial_range(n: int, p: float = 0.95, alpha: float = 0.01) -> tuple[int, int]:
    """The counts of n trials a true coverage p gives with probability 1 - alpha (two-sided)."""
    from scipy import stats
    return int(stats.binom.ppf(alpha / 2, n, p)), int(stats.binom.isf(alpha / 2, n, p))


# The simulator's steady states at the grid points of tests/bench/test_import_coverage.py's
# sample (decision 0083, third addendum): the test's 25-35 s of CPU were these integrations
# (the imports and `bench modes` of ten seeds: about 1 s).  Written by ``store_states``;
# the campaign version of the test integrates them live, and the sample checks two of them.
STATES = Path(__file__).with_name("frf_coverage_states.json")


def grid_points(t: Truth, placements: int) -> list[float]:
    """Every frequency ``write_trial`` can give ``t`` with ``placements`` placements."""
    k = np.arange(math.floor((t.f1_Hz - t.resonance_Hz) / STEP_HZ) - MARGIN,
                  math.ceil((t.f2_Hz - t.resonance_Hz) / STEP_HZ) + MARGIN + 1)
    return sorted({float(x) for j in range(placements)
                   for x in np.round(t.resonance_Hz + STEP_HZ * (k + (j + 0.5) / placements - 0.5), 6)})


def store_states(truths: list[Truth], placements: int, path: Path = STATES) -> None:
    """The simulator's X1/F1 (and the held levels' force) at every grid point, as JSON."""
    import json
    sim, rows = Simulator(), []
    for t in truths:
        for f in grid_points(t, placements):
            if t.kind == "force":
                H, P = sim.at_force(t.level, f), t.level
            else:
                H, P = sim.at_held(t.level, f)
            rows.append([t.kind, t.level, f, H.real, H.imag, P])
    head = json.dumps({"placements": placements, "model": MODEL, "settle": sim.settle, "measure": sim.measure,
                       "rtol": sim.rtol})
    path.write_text(head[:-1] + ', "states": [\n' + ",\n".join(json.dumps(r) for r in rows) + "\n]}\n")


def stored_simulator(path: Path = STATES) -> Simulator:
    """A Simulator whose cache holds the stored states (a point not stored is integrated)."""
    import json
    data = json.loads(path.read_text())
    sim = Simulator(settle=data["settle"], measure=data["measure"], rtol=data["rtol"])
    assert data["model"] == MODEL, "the stored states are of another model: run store_states"
    for kind, level, f, re, im, P in data["states"]:
        if kind == "force":
            sim.cache[("F", level, f)] = complex(re, im)
        else:
            sim.cache[("X", level, f)] = (complex(re, im), P)
    return sim
