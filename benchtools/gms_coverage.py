"""GMS's 95 % intervals against the truth on the friction-choice test grid (decision 0090).

The GMS case of :mod:`benchtools.friction_cases` (the independent simulator's data, four
elements at 3, 6.5, 14 and 30 um) on tests/sim/test_friction_choice.py's 5 x 3 grid, settle 15,
one noise seed per run, fitted as the analysis fits it (:func:`sim.discrepancy.gms_rival.gms_fit`
on the Iwan grid, the fine grid always).  ``python -m benchtools.gms_coverage [--seeds 30]
[--noise 1] [--grid-only] [--sample-start]`` prints per seed the reduced chi-square, the fit's
CPU seconds, the values (a star: the truth outside the 95 % interval) and the slips, then the
counts; ``--grid-only --sample-start`` is main's fit before decision 0090.
"""

from __future__ import annotations

import tempfile
import time

from benchtools import friction_cases as fc

GRID = fc.small_grid(seed=3, n_levels=5, n_freqs=3)
SCALARS = ("F_c_N", "F_s_N", "v_s_m_per_s", "delta", "C_N_per_s", "sigma2_N_s_per_m", "mass_kg")


def gms_inputs(tmp, seed: int, noise_scale: float = 1.0):
    """(the rate rivals' setup, the Iwan grid, the truth with the mass) of one noise seed."""
    from bench.sources import load_source
    from sim.discrepancy import gms_rival, rivals
    from sim.discrepancy import rate_rivals as rr
    from sim.discrepancy.analysis import base_fit, data_from_steps

    noise = tuple(noise_scale * n for n in fc.NOISE)
    path, truth = fc.write_case("gms", tmp, levels=GRID[0], freqs=GRID[1], settle=15, measure=6, seed=seed,
                                noise=noise)
    steps = load_source(path).steps
    d = data_from_steps(steps, 9)
    base, W = base_fit(steps, d, None, 9)
    return rr.setup(d, W), rivals.iwan_grid(base, d, gms_rival.GMS_ELEMENTS), dict(truth["params"], mass_kg=truth["mass_kg"])


def covered(s, grid, truth, names=SCALARS):
    """({name: covered}, the fit's result, its parameters)."""
    from sim.discrepancy import gms_rival

    res, _, params = gms_rival.gms_fit(s, grid)
    return {n: params[n]["low"] <= truth[n] <= params[n]["high"] for n in names}, res, params


def main(seeds: int = 30, noise_scale: float = 1.0) -> dict:
    counts = dict.fromkeys(SCALARS, 0)
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(seeds):
            s, grid, truth = gms_inputs(tmp, seed, noise_scale)
            t0 = time.process_time()
            ok, res, p = covered(s, grid, truth)
            dt = time.process_time() - t0
            for n, v in ok.items():
                counts[n] += v
            rchi2 = res.chi2 / (res.n_data - res.n_params)
            vals = " ".join(f"{n}={p[n]['value']:.4g}{'' if ok[n] else '*'}" for n in SCALARS)
            slips = " ".join(f"{q['value'] * 1e6:.2f}" for q in p["slip_m"])
            print(f"seed {seed:2d} rchi2 {rchi2:7.3f} {dt:5.1f} s  {vals}  slips[um] {slips}", flush=True)
    print(counts, sum(counts.values()), "of", len(SCALARS) * seeds)
    return counts


if __name__ == "__main__":
    import argparse

    from sim.discrepancy import gms_rival
    from sim.discrepancy import rate_rivals as rr

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=30)
    ap.add_argument("--noise", type=float, default=1.0, help="x the rig's noise")
    ap.add_argument("--grid-only", action="store_true", help="no free slips (GMS_FREE_MAX 0)")
    ap.add_argument("--sample-start", action="store_true", help="periods from their largest sample (main before 0090)")
    a = ap.parse_args()
    gms_rival.GMS_FREE_MAX = 0 if a.grid_only else gms_rival.GMS_FREE_MAX
    rr.TIMED_PATHS = not a.sample_start
    main(a.seeds, a.noise)
