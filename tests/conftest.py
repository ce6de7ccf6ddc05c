"""Test-wide set-up."""

import pytest

from sim.kernel_cache import invalidate_stale_kernels


def pytest_configure(config):
    # numba's cache is keyed on a kernel's own file only: after an edit to sim/masing.py or
    # sim/virgin.py the cached kernels would keep the old physics (sim/kernel_cache.py)
    invalidate_stale_kernels()


# `make test` runs two pytest-xdist workers with --dist loadgroup.  A module's tests share a
# worker, so its module-scoped fixtures (often a whole simulated run) are made once; the
# modules in SPLIT hold independent long cases and no shared fixture: their tests are dealt
# out one by one, or one worker would hold them all for ten minutes (decision 0046).
SPLIT = {"tests/sim/test_discrepancy.py"}


@pytest.hookimpl(tryfirst=True)       # before pytest-xdist reads the groups (it registers later, so it runs first)
def pytest_collection_modifyitems(config, items):
    for item in items:
        path = item.nodeid.split("::")[0]
        if path not in SPLIT:
            item.add_marker(pytest.mark.xdist_group(path))
