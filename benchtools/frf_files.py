"""Measured-FRF files as other software writes them, for `bench import`'s tests and the
how-to's example files (docs/gen_frf_examples.py writes docs/howto/frf-examples/ with
these functions; tests/bench/test_import_frfs.py writes its own with them and imports
both).  None of them uses the bench's code:

- :func:`write_uff`: pyuff, accelerance (ordinate label ``g``), the level in id line 1's
  words ("Accelerance at 2 N"), two response points per level (the drive point 1 and node
  7, the reference 1), the force's auto spectrum |F1|^2 after each level (function type 2:
  pyuff writes no type 12), no bench tags;
- :func:`write_csv`: pandas, mobility in mm/s per newton, amplitude and phase in degrees,
  the force beside it, units in the header;
- :func:`write_mat`: scipy.io.savemat, a struct array ``tests`` of response-controlled
  tests (held displacement in um, frequency, |X/F| in um/N, phase in rad).

``levels`` maps each level to (frequencies in Hz, compliance X1/F1 in m/N).
"""

from __future__ import annotations

import numpy as np

G = 9.80665

UFF_MAPPING = """[import]
level_from = "id1"                  # the level is in id line 1 ...
level_pattern = "at ([0-9.]+) N"    # ... as these words say (the first group)
mass_kg = 10.0                      # the energy balance's mass (used where the force is in the file)
"""

CSV_MAPPING = """[import]
response = "vel"                    # the FRF is a mobility V/F
mass_kg = 10.0

[import.fields]                     # the header's names (the units are in its brackets)
frequency = "f"
amplitude = "|V/F|"
phase = "arg"
"""

MAT_MAPPING = """[import]
variable = "tests"                  # the struct array
level_kind = "disp"                 # response-controlled: the displacement amplitude held

[import.fields]                     # the struct's field names
level = "held_um"
frequency = "freq"
amplitude = "mag"
phase = "ph"

[import.units]
level = "um"
response = "um/N"                   # a compliance X/F
phase = "rad"
"""


def sdof(f, f_n: float = 60.0, zeta: float = 0.03, m: float = 10.0):
    """X/F of a single mode: 1 / (m (w_n^2 - w^2 + 2 i zeta w_n w))."""
    w, wn = 2 * np.pi * np.asarray(f, float), 2 * np.pi * f_n
    return 1 / (m * (wn * wn - w * w + 2j * zeta * wn * w))


def write_uff(path, levels: dict, *, force: bool = True):
    from pathlib import Path

    import pyuff
    Path(path).unlink(missing_ok=True)          # pyuff adds to a file that exists
    sets = []
    common = dict(type=58, id2="lab shaker", id3="NONE", id4="NONE", id5="NONE", rsp_dir=1, ref_node=1, ref_dir=1,
                  load_case_id=3, abscissa_spacing=0, abscissa_spec_data_type=18, abscissa_axis_units_lab="Hz")
    for P, (f, X) in levels.items():
        f = np.asarray(f, float)
        A = -(2 * np.pi * f) ** 2 * np.asarray(X) / G            # in g per newton
        for node, scale in ((7, 0.4), (1, 1.0)):
            sets.append(dict(common, func_type=4, id1=f"Accelerance at {P:g} N", rsp_node=node,
                             ordinate_spec_data_type=12, ordinate_axis_units_lab="g", orddenom_spec_data_type=13,
                             orddenom_axis_units_lab="N", x=f, data=A * scale))
        if force:
            sets.append(dict(common, func_type=2, id1=f"Force at {P:g} N", rsp_node=1, ordinate_spec_data_type=13,
                             ordinate_axis_units_lab="N^2", orddenom_spec_data_type=13, orddenom_axis_units_lab="N",
                             x=f, data=np.full(f.size, P * P, complex)))
    pyuff.UFF(str(path)).write_sets(sets, mode="add")
    return path


def write_csv(path, levels: dict):
    import pandas as pd
    rows = []
    for P, (f, X) in levels.items():
        V = 1j * 2 * np.pi * np.asarray(f) * np.asarray(X) * 1e3           # mm/s per newton
        rows += [{"Level [N]": P, "f [Hz]": x, "|V/F| [mm/s/N]": abs(v), "arg [deg]": np.degrees(np.angle(v)),
                  "Force [N]": P} for x, v in zip(f, V, strict=True)]
    pd.DataFrame(rows).to_csv(path, index=False, float_format="%.8g")
    return path


def write_mat(path, levels_m: dict, *, version: str = "5"):
    """``levels_m``: held displacement (m) -> (frequencies, X/F); ``version`` "5" through
    scipy.io.savemat, "7.3" (HDF5, MATLAB's layout) through hdf5storage, neither the bench's."""
    import scipy.io
    tests = np.zeros(len(levels_m), dtype=[("held_um", "O"), ("freq", "O"), ("mag", "O"), ("ph", "O")])
    for i, (level, (f, X)) in enumerate(levels_m.items()):
        tests[i] = (level * 1e6, np.asarray(f, float), np.abs(X) * 1e6, np.angle(X))
    if version == "7.3":
        import hdf5storage
        rows = tests.reshape(1, -1)             # MATLAB's 1 x n struct array, each vector a row
        for name in tests.dtype.names:
            for j in range(rows.shape[1]):
                rows[name][0, j] = np.atleast_2d(np.asarray(rows[name][0, j], float))
        hdf5storage.savemat(str(path), {"tests": rows}, format="7.3", matlab_compatible=True,
                            store_python_metadata=False)
        return path
    scipy.io.savemat(str(path), {"tests": tests})
    return path
