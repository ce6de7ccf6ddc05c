"""Sakai's Masing model (seed Eqs. 1-5) behind the friction-model interface.

The virgin curve F_s (u^n - n u) / (1 - n), u = x / x_s <= 1, F_s beyond; Masing branches
with the similarity ratio 2 and non-local memory (:mod:`sim.masing`).  Its steady periodic
force is the identification's own (:func:`sim.identify.path_friction`: virgin loading to a
period's largest displacement, then one period, which is the steady loop for a
rate-independent Masing element).  Its time-domain force is the rig's Masing kernel
(:mod:`sim._kernel`): a reversal stack has no fixed size, so it has no ``advance`` here.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..identify import N_BOUNDS, path_friction
from ._base import FrictionModel, Parameter


class Masing(FrictionModel):
    name = "masing"
    label = "Masing (Sakai)"
    reference = "T. Sakai, Nonlinear frictional dynamics on rolling contact, 2020 (seed Eqs. 1-5)"
    rate_dependent = False
    parameters = (
        Parameter("F_s_N", "N", 0.0, 1e6, "steady rolling friction force", 10.0),
        Parameter("x_s_m", "m", 0.0, 1.0, "starting rolling displacement", 1e-5),
        Parameter("n", "1", N_BOUNDS[0], N_BOUNDS[1], "shape factor of the virgin curve", 1.5, log=False,
                  lo_open=False, exclude=(1.0,)),
    )

    def friction_level(self, values: Mapping[str, float]) -> float:
        return float(values["F_s_N"])

    def periodic_force(self, values: Mapping[str, float], paths_m: np.ndarray, omega_rad_s: np.ndarray) -> np.ndarray:
        paths = np.atleast_2d(np.asarray(paths_m, dtype=np.float64))
        top = np.argmax(paths, axis=1)
        M = paths.shape[1]
        idx = (top[:, None] + np.arange(M)) % M                 # each row from its largest value
        rotated = np.take_along_axis(paths, idx, axis=1)
        F = values["F_s_N"] * path_friction(rotated, values["x_s_m"], values["n"])
        out = np.empty_like(F)
        np.put_along_axis(out, idx, F, axis=1)
        return out
