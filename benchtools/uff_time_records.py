"""The independent simulators' records as a rig gives them: noise and UFF58 time records.

Shared by benchtools/independent_masing.py and benchtools/independent_friction.py (neither
shares code with sim/).  Noise, per channel, white and Gaussian: the force relative to a
force scale of the friction (``force_scale_N``), the acceleration relative to its own rms
over the record, the displacement relative to a length scale of the friction
(``length_scale_m``).  Records are written as UFF58 with pyuff, the convention of
docs/uff58-input.md: function type 1, one load case per step, ordinate data types 13/12/8
(force N, acceleration m/s^2, displacement m), abscissa increment 1/fs, no tags.
"""

from __future__ import annotations

import numpy as np


def add_noise(force, accel, disp, noise, force_scale_N, length_scale_m, rng):
    """(force, accel, disp) with the relative noise ``noise`` = (force, accel, disp) added,
    drawn in that order from ``rng``."""
    force = force + noise[0] * force_scale_N * rng.standard_normal(force.size)
    accel = accel + noise[1] * np.std(accel) * rng.standard_normal(accel.size)
    disp = disp + noise[2] * length_scale_m * rng.standard_normal(disp.size)
    return force, accel, disp


def step_sets(load_case: int, first_id: int, fs_Hz: float, force, accel, disp) -> list[dict]:
    """The three UFF58 datasets of one step (function ids from ``first_id``)."""
    sets = []
    for sdt, unit, label, x in ((13, "N", "force", force), (12, "m/s^2", "acceleration", accel),
                                (8, "m", "displacement", disp)):
        sets.append(dict(type=58, func_type=1, func_id=first_id + len(sets), ver_num=0, load_case_id=load_case,
                         id1=f"{label} time response", id2="independent simulator",
                         id3="NONE", id4="NONE", id5="NONE",
                         rsp_ent_name="carriage", rsp_node=1, rsp_dir=1,
                         ref_ent_name="shaker", ref_node=1, ref_dir=1,
                         abscissa_spacing=1, abscissa_min=0.0, abscissa_inc=1.0 / fs_Hz,
                         abscissa_spec_data_type=17, abscissa_axis_lab="time",
                         abscissa_axis_units_lab="s",
                         ordinate_spec_data_type=sdt, ordinate_axis_lab=label,
                         ordinate_axis_units_lab=unit,
                         orddenom_spec_data_type=0, orddenom_axis_units_lab="NONE",
                         x=np.arange(x.size) / fs_Hz, data=x.astype(float)))
    return sets


def write_sets(path, sets: list[dict]) -> None:
    import pyuff

    uff = pyuff.UFF(str(path))
    uff.write_sets(sets, mode="overwrite")
