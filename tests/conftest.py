"""Test-wide set-up."""

from sim.kernel_cache import invalidate_stale_kernels


def pytest_configure(config):
    # numba's cache is keyed on a kernel's own file only: after an edit to sim/masing.py or
    # sim/virgin.py the cached kernels would keep the old physics (sim/kernel_cache.py)
    invalidate_stale_kernels()
