"""Test-wide set-up."""

import pytest

from sim.kernel_cache import invalidate_stale_kernels


def pytest_configure(config):
    # numba's cache is keyed on a kernel's own file only: after an edit to sim/masing.py or
    # sim/virgin.py the cached kernels would keep the old physics (sim/kernel_cache.py)
    invalidate_stale_kernels()


# `make test` runs two pytest-xdist workers.  A module's tests share a worker, so its
# module-scoped fixtures (often a whole simulated run) are made once; the modules in SPLIT
# hold independent long cases and no shared fixture: their tests are dealt out one by one,
# or one worker would hold them all for ten minutes (decision 0046).  The grouping is a
# scheduler of our own (xdist's scope hook), not xdist_group markers: with pytest 9.2,
# pytest-xdist 3.8's loadgroup no longer renames the node ids it groups by, and every test
# was dealt out alone (test_identification's module fixture was made on both workers).
SPLIT = {"tests/sim/test_discrepancy.py"}

# Started first, longest first (figures of a full run, decision 0083), so that no long module
# is left for the end while the other worker idles.
FIRST = ("tests/bench/test_model_lines.py", "tests/sim/test_discrepancy.py", "tests/sim/test_paper.py",
         "tests/bench/test_studies.py", "tests/procedures/test_identification.py", "tests/bench/test_report.py",
         "tests/bench/test_procedure_words.py", "tests/bench/test_api.py", "tests/bench/test_analyze.py",
         "tests/bench/test_truth_id.py", "tests/bench/test_twin_causes.py", "tests/sim/test_discover.py",
         "tests/sim/test_identify_clean.py", "tests/sim/test_discrepancy_noise.py",
         "tests/sim/test_independent_cases.py", "tests/bench/test_twin.py")


def module_of(nodeid: str) -> str:
    return nodeid.split("::")[0]


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    from xdist.scheduler import LoadScopeScheduling

    class ModuleScheduling(LoadScopeScheduling):
        """Work units: a module, or one test of a module in SPLIT."""

        def _split_scope(self, nodeid: str) -> str:
            return nodeid if module_of(nodeid) in SPLIT else module_of(nodeid)

    return ModuleScheduling(config, log)


def pytest_collection_modifyitems(config, items):
    # the scheduler deals out work units in collection order
    rank = {path: i for i, path in enumerate(FIRST)}
    items.sort(key=lambda item: rank.get(module_of(item.nodeid), len(FIRST)))
