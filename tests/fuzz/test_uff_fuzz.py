"""Fuzzing UFF58 reading: truncated and mutated files.

A valid ASCII UFF file (time records of force, acceleration and displacement for two
steps, without our tags, and one FRF) is cut short or has characters, lines or records
changed.  ``bench.sources.load_source`` (the one UFF58 reader) must give steps (or
rejected steps with their reason) or a ValueError naming the file, within a time bound;
nothing else.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
import pyuff
from hypothesis import given
from hypothesis import strategies as st

from bench.export import FUNC_FRF, FUNC_TIME, SDT_FREQ, SDT_TIME, _dset58
from bench.sources import load_source

from ._settings import TIME_BOUND_S, fuzz


@pytest.fixture(scope="module")
def valid_uff(tmp_path_factory) -> bytes:
    fs, f, n = 2560.0, 40.0, 512
    t = np.arange(n) / fs
    rng = np.random.default_rng(7)
    sets = []
    for step, amp in enumerate((1.0, 3.0)):
        x = 1e-6 * amp * np.sin(2 * np.pi * f * t - 0.3)
        sig = {13: (amp * np.sin(2 * np.pi * f * t), "N"), 12: (-(2 * np.pi * f) ** 2 * x, "m/s^2"), 8: (x, "m")}
        for sdt, (y, unit) in sig.items():
            y = y + 1e-3 * np.max(np.abs(y)) * rng.standard_normal(n)     # measured records are never noise-free
            sets.append(_dset58(func_type=FUNC_TIME, func_id=len(sets) + 1, x=t, data=y, id1=f"step {step}",
                                id2="", id3="", id4="", id5="", abscissa=(SDT_TIME, "s"), ordinate=(sdt, unit)))
    freqs = np.linspace(20, 200, 10)
    sets.append(_dset58(func_type=FUNC_FRF, func_id=len(sets) + 1, x=freqs, data=1e-6 / (1 + 1j * freqs / 50),
                        id1="compliance", id2="", id3="", id4="", id5="", abscissa=(SDT_FREQ, "Hz"),
                        ordinate=(8, "m"), denominator=(13, "N")))
    path = tmp_path_factory.mktemp("uff") / "valid.uff"
    pyuff.UFF(str(path)).write_sets(sets, mode="add")
    assert len(load_source(path).steps) == 2      # the seed is valid
    return path.read_bytes()


@st.composite
def mutations(draw, data: bytes):
    b = bytearray(data)
    kind = draw(st.sampled_from(["truncate", "bytes", "lines"]))
    if kind == "truncate":
        return bytes(b[:draw(st.integers(0, len(b) - 1))])
    if kind == "bytes":
        for _ in range(draw(st.integers(1, 8))):
            i = draw(st.integers(0, len(b) - 1))
            b[i] = draw(st.sampled_from(b"0123456789-+.eE DNa\n\x00\xff"))
        return bytes(b)
    lines = bytes(b).split(b"\n")
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, len(lines) - 1))
        op = draw(st.sampled_from(["drop", "repeat", "blank", "minus1"]))
        if op == "drop":
            del lines[i]
        elif op == "repeat":
            lines.insert(i, lines[i])
        elif op == "blank":
            lines[i] = b""
        else:
            lines[i] = b"    -1"
    return b"\n".join(lines)


@pytest.mark.filterwarnings("ignore::hypothesis.errors.HypothesisWarning")   # large example reprs
@given(data=st.data())
@fuzz(40)
def test_mutated_uff_files_give_steps_or_an_error_naming_the_file(valid_uff, tmp_path_factory, data):
    blob = data.draw(mutations(valid_uff))
    path = tmp_path_factory.mktemp("m") / "mutated.uff"
    path.write_bytes(blob)
    t = time.monotonic()
    try:
        out = load_source(path)
    except ValueError as e:
        assert str(path) in str(e), e
    else:
        assert all(s.key for s in out.steps) and all(r.step and r.reason for r in out.rejected)
    assert time.monotonic() - t < TIME_BOUND_S
