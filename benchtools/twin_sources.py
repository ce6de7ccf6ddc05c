"""Generated sources for `bench twin` (the twin tests, tests/bench/test_analyze.py, benchmarks/bench_twin.py).

- foreign UFF58 files (another program's convention: no bench tags, one load case per
  step) of a case from :func:`sim.discrepancy.cases.make_case`, optionally with an
  interference line (a sinusoid at an absolute frequency, random phase per record) added to
  one channel: the artefact kind, made here and not by the plant;
- a run directory (``bench run``) on the simulated rig with a shaker whose parameters are
  not the defaults: the source whose drive-voltage-to-force ratio the twin fits.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np

from bench.config import DEFAULTS

# a shaker unlike bench/defaults/sim_rig.toml's (Bl 15 N/A, R 1.5 ohm, L 0.2 mH, m_a 0.3 kg,
# k_a 2e4 N/m, c_a 20 N s/m): a weaker coil with a lower electrical pole (R/(2 pi L) = 0.8 kHz),
# a heavier armature on a stiffer suspension, and a blocked force of 25 N/V
SHAKER = dict(amp_gain_N_per_V=25.0, shaker_force_constant_N_per_A=10.0, shaker_resistance_ohm=2.0,
              shaker_inductance_H=0.4e-3, shaker_armature_mass_kg=0.5, shaker_suspension_N_per_m=4.0e4,
              shaker_damping_N_s_per_m=30.0)


def write_foreign_uff(case, path: Path, periods: int = 8, line: dict | None = None, seed: int = 0) -> Path:
    """One averaged period per channel repeated, with fresh sensor noise in every period
    (the issue's levels), as a record of ``periods`` periods; ``line``: {channel ("force",
    "accel", "disp"), freq_Hz, amplitude (SI)} added to that channel of every step."""
    import pyuff
    rng = np.random.default_rng(seed)
    sets = []
    for s in case.steps:
        fs = s.fs_Hz
        for ch, sdt, unit, rec, noise in (("force", 13, "N", s.force_N, 0.003 * case.rig["F_s_N"]),
                                          ("accel", 12, "m/s^2", s.accel_m_s2, 0.005 * np.std(s.accel_m_s2)),
                                          ("disp", 8, "m", s.disp_m, 0.002 * case.rig["x_s_m"])):
            y = np.tile(rec, periods) + noise * rng.standard_normal(rec.size * periods)
            if line and line["channel"] == ch:
                t = np.arange(y.size) / fs
                y = y + line["amplitude"] * np.sin(2 * np.pi * line["freq_Hz"] * t + rng.uniform(0, 2 * np.pi))
            sets.append(pyuff.prepare_58(
                binary=1, id1=f"record {len(sets) + 1}", id2="other software", id3="NONE", id4="NONE", id5="NONE",
                func_type=1, ver_num=0, load_case_id=len(sets) // 3 + 1, rsp_ent_name="carriage", rsp_node=1,
                rsp_dir=1, ref_ent_name="shaker", ref_node=1, ref_dir=1, abscissa_spacing=1, abscissa_min=0.0,
                abscissa_inc=1.0 / fs, abscissa_spec_data_type=17, abscissa_axis_units_lab="s",
                ordinate_spec_data_type=sdt, ordinate_axis_units_lab=unit, orddenom_spec_data_type=0,
                data=y, x=np.arange(y.size) / fs))
    pyuff.UFF(str(path)).write_sets(sets, mode="add")
    return path


def shaker_rig(path: Path, shaker: dict | None = None, seed: int = 1) -> Path:
    """bench/defaults/sim_rig.toml with ``shaker`` (default :data:`SHAKER`) in [rig.model]
    and the calibration's amplifier estimate left at 20 N/V (the rig file's guess, not the
    truth: the control must find the force per volt)."""
    from bench.twin import to_toml
    rig = tomllib.loads((DEFAULTS / "sim_rig.toml").read_text())
    rig["rig"]["model"].update(SHAKER if shaker is None else shaker)
    rig["rig"]["model"]["seed"] = seed
    path.write_text(to_toml(rig))
    return path


def shaker_plan(path: Path, levels=(1.0, 3.0, 6.0), freqs=(30.0, 50.0, 65.0, 80.0, 100.0, 140.0, 200.0, 300.0)) -> Path:
    """The default rig (F_s 10 N, friction resonance ~80 Hz at small levels) below F_s,
    around its resonance, where the shaker's force drops out."""
    path.write_text(f"""
[plan]
name = "shaker rig"
levels_N = [{", ".join(f"{float(x):.6g}" for x in levels)}]
infeasible = "skip"
[plan.frequencies]
list_Hz = [{", ".join(f"{float(x):.6g}" for x in freqs)}]
direction = "up"
""")
    return path
