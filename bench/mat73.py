"""MATLAB v7.3 ``.mat`` files (HDF5) read as :func:`scipy.io.loadmat` with ``simplify_cells``
reads v5/v7: a dict of variables, a struct a dict of its fields, a struct array a list of such
dicts, a numeric array squeezed to NumPy's order.

MATLAB's layout (the one its ``save -v7.3`` and hdf5storage write): a variable is a dataset
or a group at the file's root; a struct is a group whose ``MATLAB_class`` is ``struct`` (its
fields in the attribute ``MATLAB_fields``); a struct array of n elements keeps each field as a
dataset of n object references into ``#refs#``; arrays are stored column-major, so their axes
come reversed.  Only what a frequency-response export needs is read (numbers, structs,
struct arrays, strings); anything else raises :class:`NotNumbers` (where, its MATLAB class).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

HEADER = b"MATLAB 7.3"          # the text header of a v7.3 file's 512-byte user block


class NotNumbers(ValueError):
    """A value that is neither numbers, a string, a struct nor a cell: ``args`` (where, class)."""


def is_v73(head: bytes) -> bool:
    """Whether a file's first bytes are a v7.3 (HDF5) MAT-file's."""
    return HEADER in head[:128] or head.startswith(b"\x89HDF")


def load_mat73(path: Path) -> dict[str, Any]:
    """The variables of a v7.3 MAT-file (h5py: OSError for a file HDF5 cannot open)."""
    import h5py
    with h5py.File(path, "r") as f:
        return {k: _value(f, f[k], k) for k in f if not k.startswith("#")}


def _cls(obj) -> str:
    c = obj.attrs.get("MATLAB_class", b"")
    return c.decode() if isinstance(c, bytes) else str(c)


def _fields(group) -> list[str]:
    names = group.attrs.get("MATLAB_fields")
    if names is None:
        return [k for k in group if not k.startswith("#")]
    return [b"".join(n).decode() if not isinstance(n, bytes) else n.decode() for n in names]


def _value(f, obj, where: str):
    import h5py
    if isinstance(obj, h5py.Group):
        fields = _fields(obj)
        refs = [obj[k] for k in fields if k in obj and isinstance(obj[k], h5py.Dataset)
                and obj[k].dtype == h5py.ref_dtype and _cls(obj[k]) != "cell"]
        if fields and len(refs) == len(fields) and _cls(obj) == "struct":      # a struct array
            idx = [r[()].ravel(order="F") for r in refs]
            items = [{k: _value(f, f[r[i]], f"{where}({i + 1}).{k}") for k, r in zip(fields, idx)}
                     for i in range(idx[0].size)]
            return items[0] if len(items) == 1 else items
        return {k: _value(f, obj[k], f"{where}.{k}") for k in fields if k in obj}
    cls = _cls(obj)
    if obj.attrs.get("MATLAB_empty", 0):
        return np.zeros(0)
    data = obj[()]
    if obj.dtype == h5py.ref_dtype:                                   # a cell array
        return [_value(f, f[r], f"{where}{{{i + 1}}}") for i, r in enumerate(np.asarray(data).ravel(order="F"))]
    if cls == "char":
        return "".join(map(chr, np.asarray(data).ravel()))
    arr = np.asarray(data)
    if arr.dtype.names and {"real", "imag"} <= set(arr.dtype.names):    # MATLAB's complex
        arr = arr["real"] + 1j * arr["imag"]
    if not np.issubdtype(arr.dtype, np.number):
        raise NotNumbers(where, cls or str(arr.dtype))
    arr = arr.T
    return arr.item() if arr.size == 1 else np.squeeze(arr)
