"""numba's cache is keyed on a kernel's own file; sim.kernel_cache keys it on every source.

A package laid out as sim/ is (a kernel in one file inlining a function of another, as
``_kernel.rk4_run`` inlines ``virgin.virgin_g`` through ``masing``) is built in a temporary
directory; its kernel is compiled and cached in one process, then the inlined function is
edited in its own file only.  numba alone loads the old machine code (shown: the kernel's
file did not change); after :func:`invalidate_stale_kernels` a new process computes the
new result.  (Small kernels: the real ones take a minute to compile on two cores.)"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from sim.kernel_cache import SIM_DIR, STAMP_NAME, invalidate_stale_kernels, sources_hash

CURVE = """from numba import njit


@njit(cache=True, nogil=True, inline="always")
def virgin_g(s):
    return {body}
"""
KERNEL = """from numba import njit

from .curve import virgin_g


@njit(cache=True, nogil=True)
def run(x):
    return virgin_g(x) + 1.0
"""


def kernel_of(tmp: Path) -> float:
    env = dict(os.environ, PYTHONPATH=str(tmp))
    env.pop("NUMBA_CACHE_DIR", None)
    out = subprocess.run([sys.executable, "-c", "from kcopy.kernel import run; print(repr(run(3.0)))"],
                         cwd=tmp, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return float(out.stdout)


@pytest.mark.timeout(300)
def test_an_edit_to_an_inlined_source_recompiles_the_kernel_that_inlines_it(tmp_path):
    pkg = tmp_path / "kcopy"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "curve.py").write_text(CURVE.format(body="s * s"))
    (pkg / "kernel.py").write_text(KERNEL)
    assert invalidate_stale_kernels(pkg) is True              # first sight: stamp written
    assert kernel_of(tmp_path) == 10.0                         # 3^2 + 1, compiled and cached
    assert {p.suffix for p in (pkg / "__pycache__").glob("kernel.run*")} == {".nbc", ".nbi"}
    assert invalidate_stale_kernels(pkg) is False              # unchanged: the cache stays

    (pkg / "curve.py").write_text(CURVE.format(body="s * s * s"))
    assert kernel_of(tmp_path) == 10.0                         # numba alone: the old code

    assert invalidate_stale_kernels(pkg) is True
    assert not list((pkg / "__pycache__").glob("*.nb[ic]"))
    assert kernel_of(tmp_path) == 28.0                         # 3^3 + 1
    assert (pkg / "__pycache__" / STAMP_NAME).read_text() == sources_hash(pkg)


def test_the_hash_covers_every_source_of_sim():
    names = {p.name for p in SIM_DIR.glob("*.py")}
    assert {"masing.py", "virgin.py", "_kernel.py", "_plant_kernel.py", "identify.py"} <= names


def test_an_edit_in_a_subpackage_clears_every_cached_kernel_of_the_package(tmp_path):
    # sim/friction's models inline the templates of sim/friction/_periodic.py
    sub = tmp_path / "friction"
    (sub / "__pycache__").mkdir(parents=True)
    (sub / "_periodic.py").write_text("x = 1\n")
    assert invalidate_stale_kernels(tmp_path) is True
    cached = sub / "__pycache__" / "dahl.dahl_rows-1.py311.nbi"
    cached.write_text("")
    assert invalidate_stale_kernels(tmp_path) is False
    (sub / "_periodic.py").write_text("x = 2\n")
    assert invalidate_stale_kernels(tmp_path) is True
    assert not cached.exists()


def test_the_hash_follows_content_not_times(tmp_path):
    (tmp_path / "a.py").write_text("x = 1\n")
    first = sources_hash(tmp_path)
    os.utime(tmp_path / "a.py", (0, 0))
    assert sources_hash(tmp_path) == first
    (tmp_path / "a.py").write_text("x = 2\n")
    assert sources_hash(tmp_path) != first
