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
from enum import StrEnum
from pathlib import Path

import numpy as np

from .words import terminal_data as words

MODE_NUMBER = {"feed": 1, "pitch": 2}


class ModeId(StrEnum):
    """The ID lines of a mode's record in modes.uff (words: :data:`bench.words.terminal_data.EXPORT`)."""

    MODE_ID1 = "mode_id1"                   # mode, level_N, status, resonance_Hz, curve
    MODE_ID2 = "mode_id2"                   # fit: the fit's damping ratio in per cent
    MODE_ID3 = "mode_id3"                   # balance, half_power: theirs
    MODE_ID5 = "mode_id5"                   # run, mass: the energy balance's


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
            tags = " ".join(["bench", f"mode={e.mode}", f"level={e.level_N:g}", f"status={e.status.replace(' ', '_')}",
                             f"fr={e.resonance_Hz:.7g}", f"lo={e.resonance_low_Hz:.7g}", f"hi={e.resonance_high_Hz:.7g}"])
            out.append(dict(
                type=55, model_type=1, analysis_type=2, data_ch=2, spec_data_type=8, data_type=2,
                n_data_per_node=3, load_case=lc, mode_n=MODE_NUMBER.get(e.mode, 3),
                freq=float(f_n), modal_m=mass, modal_damp_vis=float(zeta), modal_damp_his=0.0,
                node_nums=np.array([1]), r1=np.array([1 / math.sqrt(mass) if mass else 1.0]),
                r2=np.array([0.0]), r3=np.array([0.0]),
                id1=words.said(ModeId.MODE_ID1, mode=e.mode, level_N=e.level_N, status=e.status,
                               resonance_Hz=e.resonance_Hz, curve=e.curve)[:80],
                id2=words.said(ModeId.MODE_ID2, fit=_pct(z["damping_fit_fraction"], z["damping_fit_low_fraction"],
                                                             z["damping_fit_high_fraction"]))[:80],
                id3=words.said(ModeId.MODE_ID3,
                               balance=_pct(z["damping_energy_balance_fraction"], z["damping_energy_balance_low_fraction"],
                                            z["damping_energy_balance_high_fraction"]),
                               half_power=_pct(z["damping_half_power_fraction"], z["damping_half_power_low_fraction"],
                                               z["damping_half_power_high_fraction"]))[:80],
                id4=tags[:80],
                id5=words.said(ModeId.MODE_ID5, run=run.label, mass=z["energy_balance_mass"])[:80]))
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
