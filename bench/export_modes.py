"""The modal results of a run as they leave the bench (decision record 0056):
``modes.csv`` (the columns of `bench modes`) and ``modes.uff``, universal dataset 55
(data at nodes), analysis type 2 (normal mode), one record per mode and force level that
has a value.

Why dataset 55: it is the universal file's record of a mode (frequency, modal mass,
modal viscous damping ratio, the shape at the nodes) that modal software imports as a
mode (pyuff reads and writes it; ME'scope, Simcenter Testlab and others import it);
dataset 58 is a function of frequency or time and has no field for a mode's damping.

Each record: load case = the level's index + 1, mode number 1 (feed) or 2 (pitch);
frequency = the single-mode fit's undamped natural frequency and viscous damping ratio =
the fit's zeta (a pole: the pair a modal model rebuilds an FRF from); modal mass = the
energy balance's mass (the carriage's for the feed mode, the rig model's drive-point modal
mass for the pitching mode; 0 when unknown); one node (1, the drive point) with the
displacement in +X, the mass-normalised shape 1 / sqrt(modal mass) (1 when the mass is
unknown).  The ID lines carry what the fields cannot: the resonance (peak of which curve)
with its 95 % interval, the three named damping ratios in per cent with theirs, the
status, the run's labels and units; ``bench`` tags in ID line 4 make them machine-readable.
A mode without a value (beyond the grid, not found) is only in modes.csv.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

MODE_NUMBER = {"feed": 1, "pitch": 2}


def _pct(v: float, lo: float, hi: float) -> str:
    if not math.isfinite(v):
        return "-"
    if math.isfinite(lo) and math.isfinite(hi):
        return f"{100 * v:.3g}[{100 * lo:.3g},{100 * hi:.3g}]"
    return f"{100 * v:.3g}"


def mode_datasets(runs) -> list[dict]:
    """Dataset-55 dicts (pyuff) of the modes of ``runs`` (bench.reports.RunModes)."""
    from .reports import damping_row
    out = []
    for run in runs:
        levels = sorted({e.level_N for e in run.modes})
        for e in run.modes:
            if not math.isfinite(e.resonance_Hz):
                continue
            z = damping_row(e)
            mass = z["energy_balance_mass_kg"]
            mass = float(mass) if isinstance(mass, float) and math.isfinite(mass) and mass > 0 else 0.0
            f_n = e.natural_Hz if math.isfinite(e.natural_Hz) else e.resonance_Hz
            zeta = e.damping_ratio if math.isfinite(e.damping_ratio) else 0.0
            lc = levels.index(e.level_N) + 1
            tags = (f"bench mode={e.mode} level={e.level_N:g} status={e.status.replace(' ', '_')} "
                    f"fr={e.resonance_Hz:.7g} lo={e.resonance_low_Hz:.7g} hi={e.resonance_high_Hz:.7g}")
            out.append(dict(
                type=55, model_type=1, analysis_type=2, data_ch=2, spec_data_type=8, data_type=2,
                n_data_per_node=3, load_case=lc, mode_n=MODE_NUMBER.get(e.mode, 3),
                freq=float(f_n), modal_m=mass, modal_damp_vis=float(zeta), modal_damp_his=0.0,
                node_nums=np.array([1]), r1=np.array([1 / math.sqrt(mass) if mass else 1.0]),
                r2=np.array([0.0]), r3=np.array([0.0]),
                id1=f"{e.mode} mode {e.level_N:g} N ({e.status}): resonance {e.resonance_Hz:.6g} Hz, peak of "
                    f"{e.curve}"[:80],
                id2=(f"freq = fit's undamped natural frequency (Hz); zeta fit %: "
                     f"{_pct(z['damping_fit_fraction'], z['damping_fit_low_fraction'], z['damping_fit_high_fraction'])}")[:80],
                id3=(f"zeta % energy balance {_pct(z['damping_energy_balance_fraction'], z['damping_energy_balance_low_fraction'], z['damping_energy_balance_high_fraction'])}"
                     f" half-power {_pct(z['damping_half_power_fraction'], z['damping_half_power_low_fraction'], z['damping_half_power_high_fraction'])}")[:80],
                id4=tags[:80],
                id5=(f"run {run.label}; modal mass kg: {z['energy_balance_mass'] or 'unknown'}")[:80]))
    return out


def export_modes(run_dir: Path, out: Path, write_uff: Callable[[Path, list[dict]], Path]) -> list[Path]:
    """modes.csv and (when any mode has a value) modes.uff of one run into ``out``."""
    from .reports import run_modes, write_modes_csv
    runs = [run_modes(Path(run_dir))]
    paths = [write_modes_csv(runs, Path(out) / "modes.csv")]
    sets = mode_datasets(runs)
    if sets:
        paths.append(write_uff(Path(out) / "modes.uff", sets))
    return paths
