"""Writes docs/howto/frf-examples/: one example file per format `bench import` reads, with its
mapping, made by the writers the tests use (benchtools/frf_files.py: pyuff, pandas,
scipy.io.savemat; none of the bench's code).  The data: a toy softening joint, one mode whose
frequency falls and whose damping rises with the level (not a physical model; the how-to's
files only show the layouts).  tests/bench/test_import_frfs.py checks that the files here are
what this writes and that each imports.

    python docs/gen_frf_examples.py [OUT]      (default: docs/howto/frf-examples)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from benchtools.frf_files import CSV_MAPPING, MAT_MAPPING, UFF_MAPPING, sdof, write_csv, write_mat, write_uff

OUT = Path(__file__).resolve().parent / "howto" / "frf-examples"
EXAMPLES = (("lab.unv", "lab-unv.toml"), ("frf.csv", "frf-csv.toml"), ("tests.mat", "tests-mat.toml"))


def _levels(levels, f):
    """Each level's X/F: the mode 2 % lower and its damping 0.5 % higher per step of level."""
    return {lv: (f, sdof(f, 62.0 * (1 - 0.02 * k), 0.02 + 0.005 * k)) for k, lv in enumerate(levels)}


def write_examples(out: Path = OUT) -> list[Path]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    f = np.linspace(45.0, 75.0, 41)
    paths = [write_uff(out / "lab.unv", _levels((1.0, 2.0, 4.0), f)), out / "lab-unv.toml",
             write_csv(out / "frf.csv", _levels((1.0, 2.0, 4.0), f)), out / "frf-csv.toml",
             write_mat(out / "tests.mat", _levels((1e-6, 3e-6), f)), out / "tests-mat.toml"]
    for name, text in (("lab-unv.toml", UFF_MAPPING), ("frf-csv.toml", CSV_MAPPING), ("tests-mat.toml", MAT_MAPPING)):
        (out / name).write_text(text)
    return [Path(p) for p in paths]


if __name__ == "__main__":
    for p in write_examples(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT):
        print(p)
