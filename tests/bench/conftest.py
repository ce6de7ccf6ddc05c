"""A small stepped-sine run on the simulated rig, shared by the bench tests (read-only:
a test that changes a run works on a copy)."""

from __future__ import annotations

import os

import pytest

from bench.config import DEFAULTS, load_plan, load_rig
from bench.session import run_plan
from benchtools.plans import SMALL_PLAN


@pytest.fixture(scope="session")
def small_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("small_run")
    (tmp / "plan.toml").write_text(SMALL_PLAN)
    store = run_plan(load_plan(tmp / "plan.toml"), load_rig(DEFAULTS / "sim_rig.toml"), tmp / "run")
    assert store.metadata["status"] == "completed"
    return store


@pytest.fixture(scope="session")
def analysis_example():
    """An analysis dict computed from the rig's physics (tests/bench/analysis_example.py)."""
    from .analysis_example import build_example
    return build_example()


@pytest.fixture
def signal_in_a_finalizer(mocker):
    """``send(signum)`` delivers the signal while a ``__del__`` runs, where Python drops the
    handler's exception ("Exception ignored in"); ``send.dropped`` lists what it dropped."""
    dropped = []
    mocker.patch("sys.unraisablehook", side_effect=lambda u: dropped.append(u.exc_type))

    class Finalized:
        def __init__(self, signum):
            self.signum = signum

        def __del__(self):
            os.kill(os.getpid(), self.signum)
            for _ in range(10_000):          # the handler runs here, inside the finalizer
                pass

    def send(signum):
        Finalized(signum)                    # made and dropped: __del__ runs at once
    send.dropped = dropped
    return send


@pytest.fixture
def twins_of_run(mocker):
    """The spy's ``spy_return`` is the Twins the session started (None until it starts)."""
    import bench.session
    return mocker.spy(bench.session, "start_twins")


@pytest.fixture(scope="session", autouse=True)
def instrument_lock_dir(tmp_path_factory):
    """The instruments' locks (bench.runlock) of this test session in a directory of its own,
    inherited by the `bench` processes the tests start; /tmp keeps none of them."""
    path = tmp_path_factory.mktemp("instrument_locks")
    old = os.environ.get("GUIDEWAY_LOCK_DIR")
    os.environ["GUIDEWAY_LOCK_DIR"] = str(path)
    yield path
    if old is None:
        os.environ.pop("GUIDEWAY_LOCK_DIR", None)
    else:
        os.environ["GUIDEWAY_LOCK_DIR"] = old
